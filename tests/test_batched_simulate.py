"""``cube_poses`` (the poses of ``kincal simulate``) solved in batches on the vectorised
chain against the per-pose path it replaces: the same joint values to rounding and the
random generator left in the same state, so a seed gives the same data set as before."""

from __future__ import annotations

import numpy as np
import pytest
from chains import random_tree

from kincal.models.kinematics import ChainKinematics
from kincal.planning import simulation
from kincal.planning.simulation import cube_poses, latin_hypercube, nearest_earlier
from kincal.robot import Robot
from kincal.rotations import rotx


def _per_pose(robot, n, center, size, tool, rng, max_tilt=np.radians(30), attempts=40):
    """kincal's cube_poses before batching: one pose after the other, each from the
    nearest solved pose (a plain scan), then the centre's solution, then random starts,
    with Pinocchio's inverse kinematics (Robot.inverse_kinematics)."""
    center, tool = np.asarray(center, float), np.asarray(tool, float)
    pts = center + latin_hypercube(n, rng) * size - size / 2
    R0 = rotx(np.pi)
    g = robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    search = np.random.default_rng(0)
    for _ in range(attempts):
        home, ok = robot.inverse_kinematics(center, tool, None if max_tilt is None else R0,
                                            start=search.uniform(lo, hi))
        if ok:
            break
    out, seen, seen_q = np.empty((n, g.n)), [center], [home]
    for k in np.argsort(np.linalg.norm(pts - center, axis=1)):
        p = pts[k]
        R = None if max_tilt is None else simulation.random_rotation_near(R0, max_tilt, rng)
        near = seen_q[int(np.argmin(np.linalg.norm(np.array(seen) - p, axis=1)))]
        for attempt in range(attempts):
            start = near if attempt == 0 else home if attempt == 1 else rng.uniform(lo, hi)
            if attempt >= 2 and attempt % 2 == 0 and max_tilt is not None:
                R = simulation.random_rotation_near(R0, max_tilt, rng)
            q, ok = robot.inverse_kinematics(p, tool, R, start=start, max_iterations=60)
            if ok:
                out[k] = q
                seen.append(p)
                seen_q.append(q)
                break
        else:
            raise AssertionError("the reference found no solution")
    return out


@pytest.mark.parametrize("name, n, center, size, tilt", [
    ("ec66", 120, (0.4, 0.0, 0.25), 0.4, 30.0),
    ("ec66", 60, (0.4, 0.0, 0.25), 0.02, 15.0),
    ("ur5", 60, (0.4, 0.0, 0.25), 0.3, 30.0),  # poses that need random restarts
    ("panda", 100, (0.4, 0.0, 0.4), 0.6, None),  # position only, with random restarts
])
def test_batched_cube_poses_equal_the_per_pose_path(name, n, center, size, tilt):
    robot = Robot.load(name)
    tilt = None if tilt is None else np.radians(tilt)
    for seed in (0, 1):
        a_rng, b_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        expected = _per_pose(robot, n, center, size, (0, 0, 0.12), a_rng, tilt)
        got = cube_poses(robot, n, center, size, (0, 0, 0.12), b_rng, max_tilt=tilt)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
        assert a_rng.random() == b_rng.random()  # the generator is where it was before


@pytest.mark.parametrize("name, n, center, size, tilt", [
    ("ur5", 60, (0.4, 0.0, 0.25), 0.3, 30.0),  # random restarts
    ("panda", 100, (0.4, 0.0, 0.4), 0.6, None),  # position only, with random restarts
])
def test_cube_poses_in_small_windows_equal_the_per_pose_path(name, n, center, size, tilt,
                                                              monkeypatch):
    """Rounds of WINDOW poses (a restart redoes only its window's rest, not all the poses
    after it): the same poses and draws, never the remaining poses' rotations at once."""
    robot = Robot.load(name)
    tilt = None if tilt is None else np.radians(tilt)
    counts = []
    real = simulation._rotations_near
    monkeypatch.setattr(simulation, "WINDOW", 7)
    monkeypatch.setattr(simulation, "_rotations_near",
                        lambda R0, a, rng, count, marks=None: counts.append(count) or real(
                            R0, a, rng, count, marks))
    a_rng, b_rng = np.random.default_rng(0), np.random.default_rng(0)
    expected = _per_pose(robot, n, center, size, (0, 0, 0.12), a_rng, tilt)
    got = cube_poses(robot, n, center, size, (0, 0, 0.12), b_rng, max_tilt=tilt)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert a_rng.random() == b_rng.random()
    assert tilt is None or (max(counts) == 7 and len(counts) > n // 7)


def test_batched_cube_poses_random_restarts_really_happen():
    # the ur5 case above is the one with random restarts: a test of them, not a no-op
    calls = []
    robot = Robot.load("ur5")
    real = robot.inverse_kinematics
    robot.inverse_kinematics = lambda *a, **k: calls.append(k.get("max_iterations")) or real(
        *a, **k)
    cube_poses(robot, 60, (0.4, 0.0, 0.25), 0.3, (0, 0, 0.12), np.random.default_rng(0),
               max_tilt=np.radians(30))
    assert calls.count(60) >= 2  # random starts (the centre's search has no limit given)


def test_batched_cube_poses_position_only_on_a_tree_path(tmp_path):
    # reversed and prismatic joints, orientation left free
    text, _ = random_tree(np.random.default_rng(5))
    path = tmp_path / "tree.urdf"
    path.write_text(text)
    robot = Robot.load(path, base="atip", tip="btip")
    center = ChainKinematics.of(robot.geometry).tip_points(np.zeros(robot.geometry.n))[0]
    a_rng, b_rng = np.random.default_rng(3), np.random.default_rng(3)
    expected = _per_pose(robot, 80, center, 0.03, (0, 0, 0), a_rng, None)
    got = cube_poses(robot, 80, center, 0.03, (0, 0, 0), b_rng, max_tilt=None)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert a_rng.random() == b_rng.random()


def test_batched_simulate_is_the_same_file_as_per_pose(tmp_path, monkeypatch):
    """The whole command: the CSV of ``kincal simulate`` equals the one the per-pose path
    writes (the same text but for rounding in the last digits)."""
    from kincal.cli.main import main

    main(["simulate", "ec66", "--poses", "80", "--seed", "4", "--out",
          str(tmp_path / "batched.csv"), "--quiet"])
    monkeypatch.setattr(simulation, "cube_poses",
                        lambda robot, n, c, s, tool, rng, max_tilt, progress=None:
                        _per_pose(robot, n, c, s, tool, rng, max_tilt))
    main(["simulate", "ec66", "--poses", "80", "--seed", "4", "--out",
          str(tmp_path / "per_pose.csv"), "--quiet"])
    a, b = (np.loadtxt([line for line in open(tmp_path / f) if not line.startswith("#")][1:],
                       delimiter=",") for f in ("batched.csv", "per_pose.csv"))  # provenance, header
    assert a.shape == (80, 9)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("n, shape", [(1, "cube"), (7, "cube"), (300, "cube"), (3000, "cube"),
                                      (3000, "plane"), (1000, "line"), (600, "one point")])
def test_nearest_earlier_is_what_a_scan_finds(n, shape):
    rng = np.random.default_rng(n)
    c, P = rng.random(3), rng.random((n, 3))
    P[n // 2:n // 2 + n // 4] = P[:n // 4]  # exact ties: the first of equals wins
    if shape == "plane":
        P[:, 2] = 0.5
    elif shape == "line":
        P[:, 1:] = 0.5
    elif shape == "one point":
        P[:] = c
    A = np.vstack([c[None], P])
    expected = [int(np.argmin(np.linalg.norm(A[:i + 1] - P[i], axis=1))) - 1 for i in range(n)]
    assert nearest_earlier(c, P).tolist() == expected


def test_damped_step_is_the_step_of_robot_inverse_kinematics():
    robot = Robot.load("ec66")
    g = robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    rng = np.random.default_rng(2)
    q0 = rng.uniform(-1, 1, (5, g.n))
    p = rng.normal(size=(5, 3)) * 0.1 + [0.4, 0.0, 0.3]
    R = np.array([simulation.random_rotation_near(rotx(np.pi), 0.5, rng) for _ in range(5)])
    tool = np.array([0.01, 0.0, 0.12])
    for rot in (R, None):
        _, q1 = ChainKinematics.of(g).damped_step(q0, tool, p, rot, lo, hi)
        for k in range(5):
            one, _ = robot.inverse_kinematics(p[k], tool, None if rot is None else rot[k],
                                              start=q0[k], max_iterations=1)
            np.testing.assert_allclose(q1[k], one, rtol=0, atol=1e-10)  # a long step


def test_measurements_csv_text_is_the_text_as_before():
    """Measurements.to_csv_text made from one table (several points per pose, sigma)."""
    from kincal.measurements.data import Measurements

    rng = np.random.default_rng(0)
    n, K = 20, 2
    m = Measurements(("a", "b", "c"), np.repeat(rng.normal(size=(n, 3)), K, axis=0),
                     rng.normal(size=(n * K, 3)), points=np.tile(np.arange(K), n),
                     poses=np.repeat(np.arange(n), K), sigma=np.full(n * K, 1e-4))
    lines = ["a,b,c,x1,y1,z1,x2,y2,z2,sigma"]
    for idx in np.lexsort((m.points, m.poses)).reshape(-1, K):  # as it was written before
        vals = list(m.joint_values[idx[0]]) + list(m.positions[idx].ravel()) + [m.sigma[idx[0]]]
        lines.append(",".join(repr(float(v)) for v in vals))
    assert m.to_csv_text() == "\n".join(lines) + "\n"
