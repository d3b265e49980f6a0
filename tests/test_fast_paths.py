"""The batched paths of the performance work against the arithmetic they replace: each new
path is compared with the old one (Pinocchio calls per pose, dense residual and Jacobian,
the per-pose loops) on seeded data, to 1e-9 or better."""

from __future__ import annotations

import numpy as np
import pytest
from chains import random_chain, random_tree

from kincal.identification import plausibility
from kincal.robot import Robot


def _robots(tmp_path):
    out = [Robot.load("ec66")]
    for seed in (3, 4):
        text, _ = random_chain(np.random.default_rng(seed), cases=("prismatic", "parallel",
                                                                   "gimbal", "general"))
        path = tmp_path / f"chain_{seed}.urdf"
        path.write_text(text)
        out.append(Robot.load(path, tip="tip"))
    text, _ = random_tree(np.random.default_rng(5))
    path = tmp_path / "tree.urdf"
    path.write_text(text)
    out.append(Robot.load(path, base="atip", tip="btip"))
    return out


def test_gate_tool_points_match_pinocchio(tmp_path):
    """The gate's tool points through the vectorised chain equal Pinocchio's, per pose."""
    rng = np.random.default_rng(0)
    for robot in _robots(tmp_path):
        g = robot.geometry
        lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
        hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
        q = rng.uniform(lo, hi, (40, g.n))
        q[0] = 0.0
        tool = rng.normal(size=3) * 0.1
        T = robot.tip_poses(q)
        want = T[:, :3, 3] + T[:, :3, :3] @ tool
        assert np.abs(plausibility._tool_points(robot, q, tool) - want).max() < 1e-12
