"""Simulated contacts and flush touches score their many candidates in blocks: the same
choice as scoring all at once, never more than a block of rows in the chain at a time."""

import numpy as np
from conftest import random_joint_values

from kincal import models
from kincal.planning import kind_simulation as ks
from kincal.robot import Robot

TOOL = np.array([0.03, 0.02, 0.12])


def test_nearest_is_the_argsort_of_all_scores(rng):
    scores = rng.normal(size=1000)
    rows = np.arange(1000)
    for block in (1, 7, 100, 999, 1000, 5000):
        got = ks.nearest(lambda c: scores[c], rows, 37, block=block)
        np.testing.assert_array_equal(got, np.argsort(scores)[:37])
    assert len(ks.nearest(lambda c: scores[c], rows, 5000, block=64)) == 1000


def test_blocks_choose_and_move_the_same_poses(rng, monkeypatch):
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    lo, hi = robot.geometry.ranges()
    cand = random_joint_values(robot.geometry, rng, 3000)
    c = np.mean(ks.tool_points(em, em.nominal, cand[:100], TOOL), axis=0)
    planes = np.array([[0.0, 0.0, c[2]], [0.0, np.pi / 2, c[0]]])
    seen = []
    real = ks.flush_offsets

    def counted(model, kin, q, *a):
        seen.append(len(q))
        return real(model, kin, q, *a)

    def both():
        p = ks.simulate_contacts(em, em.nominal, TOOL, planes, cand, 30, 1e-5,
                                 np.random.default_rng(2))
        f = ks.simulate_flush(em, em.nominal, np.r_[TOOL, 0.0, 0.0], planes[:1], cand, 20,
                              1e-5, 0.05, np.random.default_rng(3), limits=(lo, hi))
        return p, f

    whole_p, whole_f = both()
    monkeypatch.setattr(ks, "BLOCK", 256)
    monkeypatch.setattr(ks, "flush_offsets", counted)
    p, f = both()
    np.testing.assert_array_equal(p.joint_values, whole_p.joint_values)
    np.testing.assert_array_equal(p.planes, whole_p.planes)
    np.testing.assert_array_equal(f.joint_values, whole_f.joint_values)
    assert max(seen[:12]) == 256 and len(cand) not in seen  # scored in blocks only
