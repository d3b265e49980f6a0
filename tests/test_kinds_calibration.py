"""Calibration with every measurement kind, and with several sets at once: planted errors
recovered from noise-free data, per-set names, cross-validation by set, bad input."""

import numpy as np
import pytest
from conftest import random_joint_values

from kincal import models
from kincal.errors import DataError, IdentifiabilityError
from kincal.identification.cross_validation import make_folds
from kincal.identification.options import CalibrationOptions
from kincal.identification.problem import CalibrationProblem, calibrate
from kincal.measurements.plane import normal
from kincal.measurements.sets import read_set_file
from kincal.planning import kind_simulation as ks
from kincal.robot import Robot

BASE = np.array([1.0, 0.5, 0.2, 0.1, -0.2, 0.3])
TOOL = np.array([0.03, 0.02, 0.12])
PIVOT = np.array([0.4, 0.3, 0.1])
PLANES = np.array([[0.0, 0.0, 0.3], [np.pi / 2, 0.0, 0.2], [0.3, 1.2, 0.3]])


def simulate(kind, em, kin, q, rng, candidates=None):
    if kind == "point":
        return ks.simulate_points(em, kin, BASE, TOOL, q, 0.0, rng)
    if kind == "pose":
        return ks.simulate_poses(em, kin, BASE, np.r_[TOOL, 0.1, 0.2, -0.3], q, 0.0, 0.0, rng)
    if kind == "distance":
        return ks.simulate_distances(em, kin, PIVOT, TOOL, q, 0.0, rng)
    return ks.simulate_contacts(em, kin, TOOL, PLANES, candidates, 25, 0.0, rng)


@pytest.mark.parametrize("robot_name,tip", [("ec66", "flange"), ("ur10", "tool0")])
@pytest.mark.parametrize("kind", ["point", "pose", "distance", "plane"])
def test_planted_errors_recovered_for_every_kind(kind, robot_name, tip, rng):
    robot = Robot.load(robot_name, tip=tip)
    em = models.build("complete", robot.geometry)
    q = random_joint_values(robot.geometry, rng, 50)
    cand = random_joint_values(robot.geometry, rng, 1500)
    options = CalibrationOptions(method="ls")
    # which kinematic parameters this kind identifies (at the nominal robot)
    ident = CalibrationProblem(robot, [simulate(kind, em, em.nominal, q, rng, cand)],
                            options).analyze()
    kept = [em.names.index(n) for n in ident.kept if n in em.names]
    truth = em.nominal.copy()
    sd = np.where(em.is_length, 0.3e-3, np.radians(0.03))[kept]
    truth[kept] += rng.normal(size=len(kept)) * sd
    data = simulate(kind, em, truth, q, rng, cand)
    # what is redundant at nominal stays fixed: planted errors break exact redundancies
    # slightly, and a nearly redundant parameter kept would make the answer non-unique
    dropped = tuple(n for n in ident.dropped if n in em.names)
    result = calibrate(robot, [data], options, fix=dropped)
    assert result.converged
    assert np.abs(result.kinematic[kept] - truth[kept]).max() < 1e-9
    frames = result.sets[0].frames
    if kind == "plane":  # a plane is (n, d) or (-n, -d): compare the planes themselves
        for j, (rx, ry, d) in enumerate(frames[3:].reshape(-1, 3)):
            s = np.sign(normal(rx, ry) @ normal(*PLANES[j, :2]))
            assert np.allclose(s * normal(rx, ry), normal(*PLANES[j, :2]), atol=1e-9)
            assert abs(s * d - PLANES[j, 2]) < 1e-9
        assert np.allclose(frames[:3], TOOL, atol=1e-9)
    else:
        want = {"point": np.r_[BASE, TOOL], "pose": np.r_[BASE, TOOL, 0.1, 0.2, -0.3],
                "distance": np.r_[PIVOT, TOOL]}[kind]
        assert np.abs(frames - want).max() < 1e-9
    assert result.sets[0].after.max < 1e-6  # [mm]


def test_two_point_sets_share_kinematics_with_their_own_frames(rng):
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    q1 = random_joint_values(robot.geometry, rng, 40)
    q2 = random_joint_values(robot.geometry, rng, 15)
    base2 = np.array([-0.5, 1.0, 0.0, 0.0, 0.1, 2.0])
    ident = CalibrationProblem(robot, [ks.simulate_points(em, em.nominal, BASE, TOOL, q1, 0.0, rng)],
                            CalibrationOptions(method="ls")).analyze()
    truth = em.nominal.copy()
    for n in ident.kept:
        if n in em.names:  # planted errors only where one point set can see them
            truth[em.names.index(n)] += rng.normal() * (3e-4 if "." in n else 0)
    a = ks.simulate_points(em, truth, BASE, TOOL, q1, 0.0, rng)
    b = ks.simulate_points(em, truth, base2, TOOL + 0.01, q2, 0.0, rng)
    fix = tuple(n for n in ident.dropped if n in em.names)
    problem = CalibrationProblem(robot, [a, b], CalibrationOptions(method="ls", fix=fix))
    assert "base.x" in problem.layout.names and "set2.base.x" in problem.layout.names
    assert "set2.tool.z" in problem.layout.names
    result = problem.solve()
    assert np.abs(result.sets[1].frames - np.r_[base2, TOOL + 0.01]).max() < 1e-9
    assert max(s.after.max for s in result.sets) < 1e-6
    # l2 with cross-validation folds each set's poses on its own
    folds = make_folds(55, 5, 0, np.arange(55), np.repeat([0, 1], [40, 15]))
    assert all(np.sum(f < 40) == 8 and np.sum(f >= 40) == 3 for f in folds)
    assert sorted(np.concatenate(folds)) == list(range(55))
    cv = calibrate(robot, [a, b], method="l2", n_lambdas=4, folds=3, fix=fix)
    assert cv.cv is not None and cv.lam > 0


def _write(tmp_path, name, header, rows):
    p = tmp_path / name
    p.write_text(",".join(header) + "\n" + "\n".join(",".join(map(repr, r)) for r in rows) + "\n")
    return p


def test_bad_input_one_clear_error_each(tmp_path, rng):
    robot = Robot.load("ec66", tip="flange")
    j = list(robot.joint_names)
    q = random_joint_values(robot.geometry, rng, 6)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (6, 1))
    quat[3] = [0.1, 0.0, 0.0, 1.0]  # norm 1.005
    p = _write(tmp_path, "pose.csv", j + ["x", "y", "z", "qx", "qy", "qz", "qw"],
               np.hstack([q, rng.normal(size=(6, 3)), quat]).tolist())
    with pytest.raises(DataError, match=r"line 5: the quaternion .* norm 1\.00499"):
        read_set_file(p, j)
    p = _write(tmp_path, "dist.csv", j + ["distance"],
               np.hstack([q, [[0.5], [0.6], [-0.1], [0.5], [0.4], [0.3]]]).tolist())
    with pytest.raises(DataError, match="line 4: distance -0.1 is negative"):
        read_set_file(p, j)
    p = _write(tmp_path, "both.csv", j + ["x", "y", "z", "distance"],
               np.hstack([q, rng.normal(size=(6, 4))]).tolist())
    with pytest.raises(DataError, match="both a 'distance' column and position columns"):
        read_set_file(p, j)
    # a plane touched at poses that differ in the last joint only: one point, no tilt
    q_same = np.repeat(q[:1], 6, axis=0)
    q_same[:, 5] = np.linspace(0, 1, 6)
    p = _write(tmp_path, "plane.csv", j, q_same.tolist())
    data = read_set_file(p, j, on_plane=True)
    assert data.kind == "plane"
    with pytest.raises(IdentifiabilityError, match="cannot fix the plane: 6 contacts spread"):
        CalibrationProblem(robot, [data], CalibrationOptions(method="ls")).start()


def test_plan_for_every_kind_beats_random_subsets(rng):
    from kincal.errors import OptionError
    from kincal.planning.pose_selection import select_poses

    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    q = random_joint_values(robot.geometry, rng, 300)
    for kind, kw, n in (("pose", {}, 12), ("distance", {"pivot": PIVOT}, 40)):
        sel = select_poses(robot, q, n, tool=TOOL, kind=kind, random_subsets=5, **kw)
        assert sel.log_det > sel.random_log_det, kind
        assert "joint_1.theta" not in sel.parameters
    with pytest.raises(OptionError, match="pivot"):
        select_poses(robot, q, 40, tool=TOOL, kind="distance")
    contacts = ks.simulate_contacts(em, em.nominal, TOOL, PLANES, q, 20, 0.0, rng)
    sel = select_poses(robot, contacts.joint_values, 40, tool=TOOL, kind="plane",
                       planes=contacts.planes, random_subsets=5)
    assert sel.log_det > sel.random_log_det and "plane3.d" in sel.parameters


def test_measurement_kinds_script_runs_reduced():
    """scripts/measurement_kinds.py's scenarios at a coarse lambda grid (they cannot rot)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "measurement_kinds.py"
    spec = importlib.util.spec_from_file_location("measurement_kinds", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    options = CalibrationOptions(n_lambdas=4)
    for name in ("pose", "distance", "plane", "rtest+tracker"):
        mean, ratio, result = script.scenario(name, robot, em, 0, options)
        assert result.converged and 0.9 < ratio < 3.0, (name, mean, ratio)


@pytest.mark.parametrize("n", [60, 61])
def test_weak_sensitivity_is_an_rms_over_the_samples(n):
    """A weak parameter's sensitivity [mm per mm or deg] is its own part's RMS over the
    samples: the column's norm times its independence over sqrt(samples). Before, the rows
    were taken as samples of three (points) when their number was a multiple of 3: 60
    distances (1 row each) counted as 20 samples, sqrt(3) too high, 61 as 61 (poses, 6 rows
    each, as twice their number). A tool point 0.5 mm off the last axis makes joint_6 weak."""
    robot = Robot.load("ec66", tip="flange")
    rng = np.random.default_rng(3)
    em = models.build("complete", robot.geometry)
    q = random_joint_values(robot.geometry, rng, n)
    tool = np.array([0.0005, 0.0, 0.12])
    data = ks.simulate_distances(em, em.nominal, PIVOT, tool, q, 0.0, rng)
    problem = CalibrationProblem(robot, data, CalibrationOptions(method="ls",
                                                                 tool_guess=tuple(tool)))
    ident = problem.analyze()
    lay = problem.layout
    _, J = problem.residual_function()(problem.start() / problem.scale, True)
    norms = np.linalg.norm(J * lay.reporting_scale() / problem.scale, axis=0)  # [mm per unit]
    assert ident.weak
    for w in ident.weak:
        expected = w.independence * norms[lay.index(w.name)] / np.sqrt(n)
        assert w.sensitivity == pytest.approx(expected, rel=1e-6), w.name
