"""Candidates inside a measurement volume, I-optimal selection, and plan -> simulate end to end."""

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import ur10_path
from test_pose_selection import _normalised_jacobian

from kincal.cli.main import main
from kincal.errors import OptionError
from kincal.planning import i_optimal
from kincal.planning.candidates import read_candidates
from kincal.planning.pose_selection import select_poses
from kincal.planning.batch_ik import BatchKinematics
from kincal.planning.volume_candidates import (Volume, VolumeSpec, _cap_directions,
                                               volume_candidates, working_volume)
from kincal.collision import CollisionChecker
from kincal.robot import Robot

TOOL = (0.03, 0.02, 0.12)  # [m]
CUBE = ((0.4, 0.0, 0.25), 0.02)  # an R-test-like 20 mm cube in front of the EC66 [m]


@pytest.fixture(scope="module")
def ec66():
    return Robot.load("ec66", tip="flange")


@pytest.fixture(scope="module")
def spec60():
    return VolumeSpec(Volume.cube(*CUBE), TOOL, math.radians(60))


@pytest.fixture(scope="module")
def cands(ec66, spec60):
    return volume_candidates(ec66, spec60, 400, seed=3)


def _branch_signs(robot, Q):
    """UR-like arm configuration, computed independently of kincal (Pinocchio, joint values):
    elbow sign(sin q3), wrist sign(sin q5), and the sign of det J (6 x 6), whose third
    factor is the shoulder's (det J = sin q3 sin q5 x shoulder term for this geometry)."""
    m, d = robot.model, robot.model.createData()
    fid = m.getFrameId(robot.tip)
    out = []
    for q in np.atleast_2d(Q):
        J = pin.computeFrameJacobian(m, d, robot.configuration(q), fid, pin.LOCAL)
        out.append((np.sign(np.sin(q[2])), np.sign(np.sin(q[4])), np.sign(np.linalg.det(J))))
    return np.array(out)


def _check_constraints(robot, spec, Q, home):
    """Assert volume, tilt, limits and branch for every row of Q, with Pinocchio's FK."""
    T = robot.tip_poses(Q)
    P = T[:, :3, 3] + T[:, :3, :3] @ np.asarray(spec.tool)
    assert spec.volume.contains(P, tol=1e-7).all()
    tilt = np.degrees(np.arccos(np.clip(T[:, :3, 2] @ np.asarray(spec.tilt_direction), -1, 1)))
    assert tilt.max() <= math.degrees(spec.max_tilt) + 1e-6
    g = robot.geometry
    assert np.all(Q >= g.lower - 1e-12) and np.all(Q <= g.upper + 1e-12)
    signs = _branch_signs(robot, Q)
    assert np.all(signs == _branch_signs(robot, home)[0]), "a pose on another arm branch"
    return tilt


def test_every_candidate_satisfies_volume_tilt_limits_branch(ec66, spec60, cands):
    assert cands.joint_values.shape == (400, 6)
    tilt = _check_constraints(ec66, spec60, cands.joint_values, cands.home)
    assert tilt.max() > 45  # the cap is really used, not just its centre
    assert np.allclose(np.degrees(cands.tilts), tilt, atol=1e-6)
    assert cands.home_found and "no collision geometry" in cands.collision_note
    # spin about the tool axis spread by the random start of the last joint
    assert np.ptp(cands.joint_values[:, 5]) > 3.0


def test_deterministic_with_seed(ec66, spec60, cands):
    again = volume_candidates(ec66, spec60, 400, seed=3)
    assert np.array_equal(again.joint_values, cands.joint_values)
    other = volume_candidates(ec66, spec60, 50, seed=4)
    assert not np.allclose(other.joint_values, cands.joint_values[:50])


def test_sphere_and_given_home(ec66):
    home = np.array([-0.29, -1.75, 1.87, -1.69, 1.57, 0.8])
    spec = VolumeSpec(Volume.sphere((0.4, 0.0, 0.25), 0.05), TOOL, math.radians(20),
                      (0.0, 0.0, -1.0), tuple(home))
    c = volume_candidates(ec66, spec, 100, seed=0)
    assert not c.home_found and np.array_equal(c.home, home)
    _check_constraints(ec66, spec, c.joint_values, home)
    d = np.linalg.norm(c.points - np.array([0.4, 0.0, 0.25]), axis=1)
    assert d.max() <= 0.05 + 1e-9 and d.max() > 0.03


def test_other_branch_home_gives_other_branch(ec66):
    """An elbow-down home yields elbow-down candidates: the branch follows home."""
    spec = VolumeSpec(Volume.cube(*CUBE), TOOL, math.radians(30))
    up = volume_candidates(ec66, spec, 50, seed=0)
    kin = BatchKinematics(ec66, TOOL)
    starts = np.tile(up.home, (32, 1))
    starts[:, 2] = -up.home[2]  # flip the elbow
    starts[:, 1] += np.linspace(-1, 1, 32)
    Q, ok = kin.solve(np.tile(CUBE[0], (32, 1)), np.tile((0.0, 0, -1), (32, 1)), starts)
    down_home = Q[ok & (np.sign(np.sin(Q[:, 2])) != np.sign(np.sin(up.home[2])))][0]
    spec_down = VolumeSpec(Volume.cube(*CUBE), TOOL, math.radians(30), home=tuple(down_home))
    down = volume_candidates(ec66, spec_down, 50, seed=0)
    _check_constraints(ec66, spec_down, down.joint_values, down_home)
    assert np.all(np.sign(np.sin(down.joint_values[:, 2])) != np.sign(np.sin(up.home[2])))


def test_cap_directions_are_uniform_on_the_cap():
    u = np.array([0.0, 0.6, -0.8])
    v = _cap_directions(u, math.radians(60), 20000, np.random.default_rng(0))
    cos = v @ u
    assert np.allclose(np.linalg.norm(v, axis=1), 1) and cos.min() >= 0.5 - 1e-12
    # uniform on the cap: cos is uniform on [cos 60 deg, 1]
    assert abs(cos.mean() - 0.75) < 0.005 and abs(np.median(cos) - 0.75) < 0.01


@pytest.mark.parametrize("name", ["ec66", "panda", "tiago"])  # tiago: a prismatic torso
def test_batch_kinematics_match_pinocchio_and_central_differences(name):
    if name != "ec66":
        ur10_path()  # skips without example-robot-data
    robot = Robot.load(name)
    kin = BatchKinematics(robot, TOOL)
    rng = np.random.default_rng(1)
    Q = np.vstack([np.zeros(kin.n), rng.uniform(kin.lo, kin.hi, (5, kin.n))])
    R, P, Jp, Jw = kin.jacobians(Q)
    T = robot.tip_poses(Q)
    assert np.allclose(R, T[:, :3, :3], atol=1e-12)
    assert np.allclose(P, T[:, :3, 3] + T[:, :3, :3] @ np.asarray(TOOL), atol=1e-12)
    h = 1e-6
    for i in range(kin.n):
        dq = np.zeros(kin.n)
        dq[i] = h
        Rp, Pp = kin.poses(Q + dq)
        Rm, Pm = kin.poses(Q - dq)
        assert np.allclose((Pp - Pm) / (2 * h), Jp[:, :, i], atol=1e-8)
        W = np.einsum("nij,nkj->nik", (Rp - Rm) / (2 * h), R)  # skew(w)
        w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        assert np.allclose(w, Jw[:, :, i], atol=1e-8)
        F, J, _, _ = kin.task(Q)
        Fp, Fm = kin.task(Q + dq)[0], kin.task(Q - dq)[0]
        assert np.allclose((Fp - Fm) / (2 * h), J[:, :, i], atol=1e-7)


# ------------------------------------------------------------------ bad input
def test_unreachable_cube_says_move_it(ec66):
    spec = VolumeSpec(Volume.cube((1.6, 0.0, 0.25), 0.02), TOOL)
    with pytest.raises(OptionError, match="cannot reach the centre.*move the volume"):
        volume_candidates(ec66, spec, 10)


def test_tilt_without_solution_says_change_direction(ec66):
    spec = VolumeSpec(Volume.cube((0.0, 0.0, 0.9), 0.02), TOOL, math.radians(10))
    with pytest.raises(OptionError, match="not with the tip z axis.*--tilt-direction"):
        volume_candidates(ec66, spec, 10)


def test_too_few_candidates_names_the_constraint(ec66, monkeypatch):
    from kincal.planning import volume_candidates as vc

    monkeypatch.setattr(vc, "MAX_ATTEMPTS", 1)
    spec = VolumeSpec(Volume.cube((0.85, 0.0, 0.2), 0.3), TOOL, math.radians(30))
    with pytest.raises(OptionError, match=r"only \d+ of the 600 .*out of reach: shrink the "
                                          r"volume"):
        volume_candidates(ec66, spec, 600, batch=600)


def test_bad_values_are_refused():
    with pytest.raises(OptionError, match="edge must be a positive"):
        Volume.cube((0, 0, 0), -1)
    with pytest.raises(OptionError, match="tilt direction"):
        VolumeSpec(Volume.cube((0, 0, 0), 1), tilt_direction=(0, 0, 0))
    with pytest.raises(OptionError, match="between 0 and 180"):
        VolumeSpec(Volume.cube((0, 0, 0), 1), max_tilt=4.0)


def test_cli_fewer_candidates_than_poses(tmp_path, capsys):
    code = main(["plan", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--random", "10",
                 "--poses", "20", "--out", str(tmp_path / "c.csv")])
    err = capsys.readouterr().err
    assert code == 1 and "fewer than the 20 poses" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "c.csv").exists()


# ------------------------------------------------------------------ collisions
def test_collision_checker_and_floor(tmp_path):
    ur10_path()
    robot = Robot.load("ur10")
    checker = CollisionChecker(robot, floor_z=0.0)
    assert checker.has_geometry and any("kincal_floor" in p for p in checker.pairs)
    upright = np.array([0.0, -1.57, 0.0, -1.57, 0.0, 0.0])
    assert not checker.colliding(upright)[0]
    assert checker.colliding(np.zeros(6))[0]  # at zero the UR10's wrist lies on its floor
    down = np.array([0.0, 1.2, 0.0, 0.0, 0.0, 0.0])  # upper arm turned down into the floor
    assert checker.colliding(down)[0]
    assert not CollisionChecker(robot, floor_z=None).colliding(down)[0]
    folded = np.array([0.0, -1.57, 3.1, 0.0, 0.0, 0.0])  # forearm folded onto the upper arm
    assert CollisionChecker(robot, None).colliding(folded)[0]
    # near the floor: candidates that collide are turned down, the others are free
    spec = VolumeSpec(Volume.cube((0.6, 0.2, 0.05), 0.1), TOOL, math.radians(60))
    c = volume_candidates(robot, spec, 100, seed=1, batch=256)
    assert c.rejections.collision > 0 and "collision pairs checked" in c.collision_note
    assert not checker.colliding(c.joint_values).any()


def test_a_floor_that_is_the_cause_is_named(ec66):
    """A floor above the UR10's shoulder cuts its upper arm in every configuration, and a
    floor above the cube leaves the tool point under it: no volume or tilt helps, so the
    refusal says the floor (it said "move the volume or change --tilt-direction")."""
    ur10_path()
    robot = Robot.load("ur10")
    spec = VolumeSpec(Volume.cube((0.6, 0.2, 0.4), 0.1), TOOL, math.radians(45), floor_z=0.1)
    cut = (r"the floor at z = 0.1 m cuts upper_arm_link_0 in every one of the \d+ looked at "
           r"\(it is above part of the arm\)\)?: lower --floor \(or --no-floor\)")
    with pytest.raises(OptionError, match="collides .*" + cut):  # the home search
        volume_candidates(robot, spec, 20, seed=0)
    given = replace(spec, home=(0.0595, -1.667, 1.922, -1.826, -1.571, -1.72))  # floor 0's
    with pytest.raises(OptionError, match=r"only 0 of the 20 candidates .*" + cut):
        volume_candidates(robot, given, 20, seed=0, batch=256)
    low = VolumeSpec(Volume.cube(*CUBE), TOOL, math.radians(60), floor_z=0.3,
                     home=(-0.2928, -1.75, 1.871, -1.691, 1.571, 0.8006))
    with pytest.raises(OptionError, match=r"tool point or the tip is below the floor at "
                                          r"z = 0.3 m in every one\): move the volume above "
                                          r"the floor or lower --floor"):
        volume_candidates(ec66, low, 20, seed=0)


MISSING_MESH = "package://kincal_no_such_pkg/meshes/link_1.stl"


@pytest.fixture
def meshless(tmp_path):
    """The EC66 with a collision mesh whose file is nowhere (a description package checked
    out without its meshes), alone in a folder."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "urdf" / "ec66.urdf").read_text()
    text = text.replace('<link name="link_1">', '<link name="link_1">\n    <collision><geometry>'
                        f'<mesh filename="{MISSING_MESH}"/></geometry></collision>', 1)
    assert MISSING_MESH in text
    (tmp_path / "ec66_meshes.urdf").write_text(text)
    return tmp_path / "ec66_meshes.urdf"


VOLUME_RUNS = [["plan", "--in-cube", "0.4", "0", "0.25", "0.02", "--random", "100", "--poses",
                "12", "--criterion", "d"],
               ["simulate", "--in-cube", "0.4", "0", "0.25", "0.02", "--poses", "5"]]


@pytest.mark.parametrize("run", VOLUME_RUNS, ids=["plan", "simulate"])
def test_missing_collision_mesh_refused_with_the_ways_forward(meshless, capsys, run):
    """It said only that the mesh could not be found: not where it was looked for, nor that
    the poses can be drawn without the check."""
    folder = meshless.parent
    code = main([run[0], str(meshless), *run[1:], "--tip", "flange", "--out",
                 str(folder / "out.csv")])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("kincal: error:")]
    assert code == 1 and len(lines) == 1 and "Traceback" not in err
    assert f"the collision geometry could not be loaded (Mesh {MISSING_MESH} could not be " \
           "found)" in lines[0]
    assert f"under the folders above the URDF ({folder} up to /)" in lines[0]
    assert "ROS_PACKAGE_PATH" in lines[0] and "give --no-collision" in lines[0]
    assert sorted(p.name for p in folder.iterdir()) == ["ec66_meshes.urdf"]  # nothing written


@pytest.mark.parametrize("run", VOLUME_RUNS, ids=["plan", "simulate"])
def test_no_collision_draws_without_the_check_and_says_so(meshless, capsys, run):
    import json

    out = meshless.parent / "out.csv"
    base = [run[0], str(meshless), *run[1:], "--tip", "flange", "--out", str(out)]
    assert main(base + ["--no-collision"]) == 0
    said = capsys.readouterr().out
    note = ("self-collision NOT checked (--no-collision); only the tool point and tip kept "
            "above the floor at z = 0 m")
    assert note in said and out.exists()
    assert main(base + ["--no-collision", "--json", "--overwrite"]) == 0
    assert json.loads(capsys.readouterr().out)["collision"] == note
    # the spec carries it: the geometry is not even loaded
    spec = VolumeSpec(Volume.cube(*CUBE), TOOL, self_collision=False)
    c = volume_candidates(Robot.load(str(meshless), tip="flange"), spec, 20, seed=0)
    assert c.collision_note == note and c.spec.self_collision is False


# ------------------------------------------------------------------ I-optimality
def test_i_optimal_gain_formula_and_selection(ec66, cands):
    rng = np.random.default_rng(0)
    Jn = rng.normal(size=(40, 3, 5))
    A = i_optimal.target_moment(rng.normal(size=(30, 3, 5)))
    M = np.einsum("kip,kiq->pq", Jn[:6], Jn[:6])
    Minv = np.linalg.inv(M)
    gains = i_optimal._gains(Jn, Minv, A)
    for k in (7, 20, 39):
        direct = np.trace(Minv @ A) - np.trace(np.linalg.inv(M + Jn[k].T @ Jn[k]) @ A)
        assert gains[k] == pytest.approx(direct, rel=1e-9)

    targets = volume_candidates(ec66, VolumeSpec(Volume.cube((0.4, 0.0, 0.25), 0.4), TOOL),
                                60, seed=9).joint_values
    q = cands.joint_values
    s_i = select_poses(ec66, q, 30, tool=TOOL, method="I", targets=targets)
    s_d = select_poses(ec66, q, 30, tool=TOOL, method="D", targets=targets)
    assert s_i.criterion == "I" and s_i.n_targets == 60
    assert s_i.mean_variance < s_d.mean_variance < s_d.random_mean_variance
    # the reported figure is E|delta p|^2 / 3 over the targets after refitting the frame and
    # tool there: the least-squares estimate's covariance pushed through that refit, by
    # sampling, from Jacobians built independently
    _, Jc, space = _normalised_jacobian(ec66, q[list(s_i.indices)], s_i)
    _, Jt, _ = _normalised_jacobian(ec66, targets, s_i)
    frames = space.is_frame[space.indices(s_i.parameters)]
    G = np.einsum("kip,kiq->pq", Jc, Jc)
    d = np.linalg.cholesky(np.linalg.inv(G)) @ rng.normal(size=(G.shape[0], 4000))
    S = Jt.reshape(-1, G.shape[0])
    dp = S[:, ~frames] @ d[~frames]                        # what the kinematic errors move
    dp -= S[:, frames] @ np.linalg.lstsq(S[:, frames], dp, rcond=None)[0]  # refit frames
    V = np.mean(np.sum(dp ** 2, axis=0)) / len(Jt) / 3
    assert s_i.mean_variance == pytest.approx(V, rel=0.05)
    assert "I-optimal selection of 30" in s_i.summary()
    with pytest.raises(OptionError, match="needs target poses"):
        select_poses(ec66, q, 30, tool=TOOL, method="I")


def test_target_moment_counts_what_the_frame_refit_leaves():
    rng = np.random.default_rng(3)
    Jt = rng.normal(size=(25, 3, 7))
    frames = np.array([False, False, False, False, True, True, True])
    A = i_optimal.target_moment(Jt, frames)
    assert np.allclose(A[frames], 0) and np.allclose(A[:, frames], 0)
    S = Jt.reshape(-1, 7)
    for _ in range(3):
        d = rng.normal(size=7)
        r = S @ d
        r -= S[:, frames] @ np.linalg.lstsq(S[:, frames], r, rcond=None)[0]
        assert d @ A @ d == pytest.approx(r @ r / 25, rel=1e-9)
    # no frame columns: the plain moment
    assert np.allclose(i_optimal.target_moment(Jt, np.zeros(7, bool)),
                       np.einsum("kip,kiq->pq", Jt, Jt) / 25)


def test_default_working_volume_and_i_beats_d_on_its_own_measure(ec66, spec60, cands):
    work = working_volume(spec60, cands.home)
    assert work.volume == Volume.cube(spec60.volume.center, 0.4)
    assert (work.max_tilt, work.tilt_direction, work.floor_z) == (
        math.radians(30), spec60.tilt_direction, spec60.floor_z)  # the working tilt, not 60
    narrow = VolumeSpec(spec60.volume, TOOL, math.radians(10))
    assert working_volume(narrow, cands.home).max_tilt == math.radians(10)  # at most the plan's
    assert work.home == tuple(cands.home)
    targets = volume_candidates(ec66, work, 60, seed=1).joint_values
    q = cands.joint_values
    s_i = select_poses(ec66, q, 30, tool=TOOL, method="I", targets=targets)
    s_d = select_poses(ec66, q, 30, tool=TOOL, method="D", targets=targets)
    assert s_i.mean_variance < 0.9 * s_d.mean_variance < s_d.random_mean_variance
    assert s_d.log_det > s_i.log_det  # each criterion wins on its own measure


# ------------------------------------------------------------------ CLI, end to end
def test_plan_in_cube_cli_poses_satisfy_constraints(tmp_path, capsys, ec66, spec60):
    out = tmp_path / "chosen.csv"
    code = main(["plan", "ec66", "--in-cube", "400", "0", "250", "20", "--max-tilt", "60",
                 "--random", "300", "--poses", "30", "--tool-offset", "30", "20", "120",
                 "--length-unit", "mm", "--out", str(out), "--seed", "2"])
    text = capsys.readouterr().out
    assert code == 0 and "300 candidates in the 20 mm cube" in text and "I-optimal" in text
    assert ("1000 target poses in the 400 mm cube at (0.4, 0, 0.25) m around the measurement "
            "volume (default working volume; tilt <= 30 deg, same branch)" in text)
    q, _ = read_candidates(out, ec66)
    assert q.shape == (30, 6)
    home = np.array([float(v) for v in text.split("home (found):")[1].split("rad/m")[0].split()])
    _check_constraints(ec66, spec60, q, home)

    # simulate at the chosen poses, and a validation set in a large cube: calibrate, evaluate
    cal, val = tmp_path / "cal.csv", tmp_path / "val.csv"
    assert main(["simulate", "ec66", "--poses-file", str(out), "--out", str(cal),
                 "--tool-m", *map(str, TOOL)]) == 0
    assert main(["simulate", "ec66", "--in-cube", "0.4", "0", "0.25", "0.3", "--max-tilt", "30",
                 "--poses", "40", "--seed", "5", "--out", str(val), "--tool-m", *map(str, TOOL)]) == 0
    capsys.readouterr()
    from kincal.measurements.data import Measurements

    data = Measurements.from_csv(cal, ec66.joint_names)
    assert np.array_equal(data.joint_values, q)
    vq = Measurements.from_csv(val, ec66.joint_names).joint_values
    spec_val = VolumeSpec(Volume.cube((0.4, 0, 0.25), 0.3), TOOL, math.radians(30))
    _check_constraints(ec66, spec_val, vq, vq[0])
    urdf = tmp_path / "cal.urdf"
    assert main(["calibrate", "ec66", str(cal), "--out", str(urdf), "--tool-offset",
                 *map(str, TOOL), "--method", "ls", "--quiet"]) == 0
    assert main(["evaluate", str(urdf), str(val), "--tip", "flange", "--fit-frames"]) == 0
    after = float(capsys.readouterr().out.split("mean")[1].split()[0])
    assert main(["evaluate", "ec66", str(val), "--fit-frames"]) == 0
    before = float(capsys.readouterr().out.split("mean")[1].split()[0])
    assert after < 0.7 * before


def test_plan_criterion_i_cli(tmp_path, capsys):
    out = tmp_path / "chosen.csv"
    code = main(["plan", "ec66", "--in-sphere", "0.4", "0", "0.25", "0.01", "--max-tilt", "45",
                 "--random", "200", "--poses", "20", "--tool-offset", *map(str, TOOL),
                 "--criterion", "i", "--target-cube", "0.4", "0", "0.25", "0.3",
                 "--target-poses", "40", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0 and "I-optimal selection of 20" in text
    assert "predicted position std over the 40 target poses" in text
    # without a volume the candidates are the targets; the same CSV format either way
    assert main(["plan", "ec66", "--random", "50", "--poses", "20", "--tool-offset",
                 *map(str, TOOL), "--out", str(tmp_path / "i.csv")]) == 0
    text = capsys.readouterr().out
    assert "target poses: the candidates themselves" in text and "I-optimal" in text
    assert main(["plan", "ec66", "--random", "50", "--poses", "20", "--tool-offset",
                 *map(str, TOOL), "--criterion", "d", "--out", str(tmp_path / "d.csv")]) == 0
    assert "D-optimal selection of 20" in capsys.readouterr().out
    i_rows, d_rows = ([r for r in (tmp_path / f).read_text().splitlines() if r[:1] != "#"]
                      for f in ("i.csv", "d.csv"))
    assert i_rows[0] == d_rows[0] == ",".join(f"joint_{k}" for k in range(1, 7))
    assert len(i_rows) == len(d_rows) == 21 and i_rows != d_rows
    assert main(["plan", "ec66", "--random", "50", "--poses", "20", "--criterion", "d",
                 "--target-cube", "0.4", "0", "0.25", "0.3", "--out", str(tmp_path / "x.csv")]) == 1
    assert "--target-cube is the working volume of --criterion i" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["plan", "ec66", "--random", "50", "--poses", "20", "--max-tilt", "40"],
     "--max-tilt needs a volume"),
    (["plan", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--home", "0", "1", "--poses",
      "20"], "--home needs 6 values"),
    (["plan", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--in-sphere", "0.4", "0", "0.25",
      "0.02", "--poses", "20"], "at most one of --in-cube and --in-sphere"),
    (["plan", "ec66", "--in-cube", "1.6", "0", "0.25", "0.02", "--poses", "20"],
     "cannot reach the centre"),
    (["simulate", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--poses-file", "x.csv"],
     "either --poses-file or a volume"),
])
def test_cli_volume_option_errors(tmp_path, capsys, argv, message):
    out = tmp_path / "o.csv"
    assert main(argv + ["--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_simulate_in_cube_takes_the_design_tilt(tmp_path, capsys, ec66):
    out = tmp_path / "rt.csv"
    assert main(["simulate", "ec66", "--design", "rtest", "--in-cube", "0.4", "0", "0.25", "0.02",
                 "--poses", "30", "--tool-m", *map(str, TOOL), "--out", str(out)]) == 0
    assert "tilt <= 15 deg" in capsys.readouterr().out
    from kincal.measurements.data import Measurements

    q = Measurements.from_csv(out, ec66.joint_names).joint_values
    spec = VolumeSpec(Volume.cube(*CUBE), TOOL, math.radians(15))
    _check_constraints(ec66, spec, q, q[0])


def test_only_robot_py_imports_pinocchio_or_coal():
    """The one Pinocchio boundary: planning (IK, collisions) goes through kincal.robot and
    its collision geometry, kincal.collision, and its links' weights, kincal.gravity."""
    import ast
    from pathlib import Path

    import kincal

    root = Path(kincal.__file__).parent
    offenders = []
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n.split(".")[0] in ("pinocchio", "coal", "hppfcl") for n in names):
                offenders.append(str(path.relative_to(root)))
    assert sorted(set(offenders)) == ["collision.py", "gravity.py", "robot.py"]


def test_floor_without_collision_geometry_keeps_tool_and_tip_above(ec66):
    """The EC66 has no collision geometry: a cube reaching below the floor loses those poses."""
    spec = VolumeSpec(Volume.cube((0.4, 0.0, 0.0), 0.1), TOOL, math.radians(10), floor_z=0.0)
    c = volume_candidates(ec66, spec, 50, seed=0)
    T = ec66.tip_poses(c.joint_values)
    assert np.all(c.points[:, 2] > 0) and np.all(T[:, 2, 3] > 0)
    assert c.rejections.collision > 0 and "NOT checked" in c.collision_note
    free = volume_candidates(ec66, VolumeSpec(Volume.cube((0.4, 0.0, 0.0), 0.1), TOOL,
                                              math.radians(10), floor_z=None), 50, seed=0)
    assert free.rejections.collision == 0 and (free.points[:, 2] < 0).any()


@pytest.mark.parametrize("argv, says", [
    (["plan", "ec66", "--random", "300", "--poses", "10", "--target-cube", "3", "0", "0.25",
      "0.4"], "--target-cube: the arm cannot reach the centre [3.0, 0.0, 0.25] m"),
    (["plan", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--random", "100", "--poses",
      "10", "--target-cube", "0.4", "0", "0.25", "6", "--target-poses", "50"],
     "--target-cube: only"),
])
def test_a_target_cube_that_fails_is_named_not_the_measurement_volume(tmp_path, capsys, argv,
                                                                      says):
    """Audit of issue 12: a --target-cube out of reach said 'move the volume (--in-cube/
    --in-sphere centre)' (with no --in-cube given), and one too large 'only N of the 1000
    candidates asked for ... ask for fewer candidates' (the target poses, not --random)."""
    out = tmp_path / "o.csv"
    assert main(argv + ["--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and not out.exists()
    assert says in err and "--in-cube" not in err and "candidates" not in err, err


def test_a_given_home_in_collision_is_warned_about(ec66):
    """A --home in collision (here its tool point 0.14 m below the floor) was taken without
    a word: it only marks the branch and every planned pose is checked, but the robot cannot
    start there. A home clear of collisions gives no warning."""
    import warnings

    from kincal.errors import KincalWarning

    low = np.array([-0.29, -0.75, 1.87, -1.69, 1.57, 0.8])
    spec = VolumeSpec(Volume.sphere((0.4, 0.0, 0.25), 0.05), TOOL, math.radians(20),
                      (0.0, 0.0, -1.0), tuple(low))
    with pytest.warns(KincalWarning, match=r"the home given \(--home\) collides \(the tool "
                      r"point or tip below the floor at z = 0 m\): it only marks the arm branch"):
        c = volume_candidates(ec66, spec, 20, seed=0)
    assert c.points[:, 2].min() > 0.0  # the planned poses are above the floor
    clear = replace(spec, home=(-0.29, -1.75, 1.87, -1.69, 1.57, 0.8))
    with warnings.catch_warnings():
        warnings.simplefilter("error", KincalWarning)
        volume_candidates(ec66, clear, 20, seed=0)
