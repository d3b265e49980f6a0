"""The MD-H identification Jacobian against central finite differences on five robots,
UR5 and example-robot-data's TIAGo among them (the check itself, and every error model on
the others, are in tests/test_error_models.py)."""

import pytest
from conftest import tiago_urdf
from test_error_models import _check_jacobian

from kincal.models import mdh
from kincal.robot import Robot

CASES = [("ec66", "flange"), ("ur5", "tool0"), ("panda", "panda_link8"), ("tiago", "arm_tool_link"),
         ("tiago_file", "wrist_ft_tool_link")]


@pytest.mark.parametrize("name,tip", CASES)
def test_jacobian_matches_central_differences(name, tip, rng):
    robot = Robot.load(tiago_urdf() if name == "tiago_file" else name, tip=tip)
    _check_jacobian(mdh.extract(robot.geometry), robot, rng)
