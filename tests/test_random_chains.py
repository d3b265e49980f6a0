"""Random serial chains with every degenerate case: MD-H layer and corrected model."""

import numpy as np
import pytest
from chains import random_chain
from conftest import random_joint_values

from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.robot import Robot


def _load(tmp_path, text, k):
    path = tmp_path / f"chain_{k}.urdf"
    path.write_text(text)
    return Robot.load(path, tip="tip")


@pytest.mark.parametrize("seed", range(40))
def test_random_chain_mdh_is_exact(seed, tmp_path):
    rng = np.random.default_rng(seed)
    text, cases = random_chain(rng)
    robot = _load(tmp_path, text, seed)
    model = mdh.extract(robot.geometry)
    # zero errors: the URDF joint frames come back
    assert np.abs(model.joint_frames() - robot.geometry.joint_frames).max() < 1e-13
    # the MD-H z axes are the joint axes (to the parallel tolerance)
    assert np.abs(model.screw_axes - [0, 0, 1]).max() < 1e-5
    # random errors in every parameter: Pinocchio on the corrected model = MD-H model
    table = model.table + rng.normal(size=model.table.shape) * 1e-3
    corrected = robot.with_joint_frames(model.joint_frames(table))
    q = random_joint_values(robot.geometry, rng, 200)
    R, p = MeasurementModel(model, q).tip_poses(table)
    T = corrected.tip_poses(q)
    assert np.abs(T[:, :3, 3] - p).max() < 1e-12, cases
    assert np.abs(T[:, :3, :3] - R).max() < 1e-12, cases


def test_degenerate_cases_are_noted(tmp_path):
    seen = set()
    for seed in range(60):
        rng = np.random.default_rng(seed)
        text, cases = random_chain(rng)
        model = mdh.extract(_load(tmp_path, text, seed).geometry)
        notes = " ".join(model.notes)
        for word in ("parallel", "intersect", "coincide", "prismatic", "first axis"):
            if word in notes:
                seen.add(word)
    assert seen == {"parallel", "intersect", "coincide", "prismatic", "first axis"}


def test_axes_parallel_only_within_tolerance_stay_exact(tmp_path):
    # found by hypothesis: j4 and j5 parallel to ~7e-8 rad, so MD-H frame 5 sits ~1e-8 m
    # off the joint axis; the joint must still turn about its true axis line
    rng = np.random.default_rng(151641461)
    text, _ = random_chain(rng, n=5, cases=("gimbal", "intersecting"))
    robot = _load(tmp_path, text, "near_parallel")
    model = mdh.extract(robot.geometry)
    assert "parallel" in model.notes[3]
    q = random_joint_values(robot.geometry, rng, 200)
    R, p = MeasurementModel(model, q).tip_poses(model.table)
    assert np.abs(robot.tip_poses(q)[:, :3, 3] - p).max() < 1e-12
