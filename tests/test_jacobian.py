"""The analytic identification Jacobian against central finite differences."""

import numpy as np
import pytest
from conftest import random_joint_values, tiago_urdf

from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.robot import Robot

CASES = [("ec66", "flange"), ("ur5", "tool0"), ("panda", "panda_link8"), ("tiago", "arm_tool_link"),
         ("tiago_file", "wrist_ft_tool_link")]


@pytest.mark.parametrize("name,tip", CASES)
def test_jacobian_matches_central_differences(name, tip, rng):
    robot = Robot.load(tiago_urdf() if name == "tiago_file" else name, tip=tip)
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, 40)
    q[0] = 0.0  # q = 0 on purpose
    mm = MeasurementModel(model, q)
    x = mm.space.join(model.table, rng.normal(size=6) * [0.5, 0.5, 0.5, 1, 1, 1],
                      rng.normal(size=3) * 0.1)
    x = x + rng.normal(size=x.size) * 1e-2
    P, J = mm.jacobian(x)
    assert np.array_equal(P, mm.predict(x))
    h = 1e-6
    for c in range(x.size):
        e = np.zeros_like(x)
        e[c] = h
        fd = (mm.predict(x + e) - mm.predict(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        assert np.abs(J[:, :, c] - fd).max() / scale < 1e-6, mm.space.names[c]
