"""Gravity torques of many poses at once (numpy, in blocks) against one Pinocchio pass per
pose: reversed chains, prismatic joints, a humanoid's tree, blocks smaller than the set."""

import re

import numpy as np
import pytest
from chains import random_tree
from conftest import random_joint_values

from kincal import gravity
from kincal.robot import Robot


@pytest.mark.parametrize("name, base, tip", [
    ("ec66", None, None), ("ur10", None, "tool0"), ("ur10", "wrist_3_link", "upper_arm_link"),
    ("panda", None, None)])
def test_vectorised_torques_equal_the_per_pose_pass(name, base, tip, rng, monkeypatch):
    robot = Robot.load(name, base=base, tip=tip)
    q = random_joint_values(robot.geometry, rng, 40)
    expected = gravity.gravity_torques_per_pose(robot, q)
    assert gravity._screws(robot) is not None  # the vectorised path, not the loop
    monkeypatch.setattr(gravity, "BLOCK", 7)
    got = gravity.gravity_torques(robot, q)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    assert np.abs(expected).max() > 1  # [N m] real torques


def _with_masses(text, rng):
    """Every link of the URDF given a mass at an offset centre of mass."""
    def link(match):
        c = rng.uniform(-0.1, 0.1, 3)
        return (f'<link name="{match.group(1)}"><inertial><origin xyz="{c[0]} {c[1]} {c[2]}"/>'
                f'<mass value="{rng.uniform(0.5, 3)}"/><inertia ixx="0.01" ixy="0" ixz="0" '
                'iyy="0.01" iyz="0" izz="0.01"/></inertial></link>')
    return re.sub(r'<link name="([^"]+)"/>', link, text)


def test_vectorised_torques_on_a_tree_with_prismatic_joints(tmp_path, rng):
    for seed in range(6):
        text = _with_masses(random_tree(np.random.default_rng(seed))[0], rng)
        path = tmp_path / f"tree{seed}.urdf"
        path.write_text(text)
        robot = Robot.load(path, base="atip", tip="btip")
        q = random_joint_values(robot.geometry, rng, 20)
        expected = gravity.gravity_torques_per_pose(robot, q)
        assert "prismatic" in robot.geometry.kinds and np.abs(expected).max() > 1
        assert gravity._screws(robot) is not None
        np.testing.assert_allclose(gravity.gravity_torques(robot, q), expected, rtol=0,
                                   atol=1e-10 * np.abs(expected).max())
