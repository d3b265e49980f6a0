"""Compensated joint values: batched kinematics, inverse kinematics, targets, program filter."""

import json

import numpy as np

from kincal.export.outputs import corrected_urdf_text
import pytest
from chains import random_chain
from conftest import TIAGO_URDF, random_joint_values

from kincal.cli.main import main
from kincal.compensation import CellFrames, IkOptions, Targets, compensate, filter_program
from kincal.rotations import quaternion_to_matrix, rotation_log
from kincal.models.kinematics import ChainKinematics
from kincal.descriptions import default_center
from kincal.errors import DataError
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh
from kincal.planning import simulation
from kincal.robot import Robot
from kincal.rotations import base_rotation, matrix_to_quaternion, quaternion_to_matrix

TOOL = np.array([0.03, 0.02, 0.12])


# ------------------------------------------------------------------ kinematics
def _robots(tmp_path):
    yield Robot.load("ec66", tip="flange")
    if TIAGO_URDF.exists():  # a prismatic torso + 7 joints; the random chains test the rest
        yield Robot.load(TIAGO_URDF, tip="wrist_ft_tool_link")
    for seed in range(6):  # parallel, intersecting, coincident, prismatic, gimbal-lock rpy
        text, _ = random_chain(np.random.default_rng(300 + seed))
        path = tmp_path / f"chain{seed}.urdf"
        path.write_text(text)
        yield Robot.load(path, tip="tip")


def test_batched_kinematics_match_pinocchio(tmp_path, rng):
    for robot in _robots(tmp_path):
        chain = ChainKinematics.of(robot.geometry)
        q = random_joint_values(robot.geometry, rng, 6)
        q[0] = 0.0  # q = 0 on purpose
        R, p, Jp, Jo = chain.evaluate(q, TOOL)
        T = robot.tip_poses(q)
        np.testing.assert_allclose(R, T[:, :3, :3], atol=1e-13)
        np.testing.assert_allclose(p, T[:, :3, 3] + T[:, :3, :3] @ TOOL, atol=1e-13)
        _, _, Jp0, Jo0 = chain.evaluate(q)
        for k in range(len(q)):
            J = robot.tip_jacobian(q[k])
            np.testing.assert_allclose(Jp0[k], J[:3], atol=1e-13)
            np.testing.assert_allclose(Jo0[k], J[3:], atol=1e-13)


def test_batched_jacobians_match_central_differences(tmp_path, rng):
    h = 1e-6
    for robot in _robots(tmp_path):
        chain = ChainKinematics.of(robot.geometry)
        q = random_joint_values(robot.geometry, rng, 4)
        R, _, Jp, Jo = chain.evaluate(q, TOOL)
        for i in range(chain.n):
            dq = np.zeros(chain.n)
            dq[i] = h
            Rp, pp, _, _ = chain.evaluate(q + dq, TOOL)
            Rm, pm, _, _ = chain.evaluate(q - dq, TOOL)
            np.testing.assert_allclose((pp - pm) / (2 * h), Jp[:, :, i], atol=1e-8)
            w = rotation_log(Rp @ np.swapaxes(Rm, 1, 2)) / (2 * h)  # angular velocity in B
            np.testing.assert_allclose(w, Jo[:, :, i], atol=1e-8)


def test_rotation_log_and_quaternions_near_pi_and_identity(rng):
    for angle in (0.0, 1e-12, 0.3, np.pi - 1e-7, np.pi):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        w = axis * angle
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
        got = rotation_log(R[None])[0]
        if angle > np.pi - 1e-6:  # axis up to sign at pi
            assert abs(np.linalg.norm(got) - angle) < 1e-6 and abs(abs(got @ axis) - angle) < 1e-6
        else:
            np.testing.assert_allclose(got, w, atol=1e-12)
        np.testing.assert_allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, atol=1e-15)


def test_rotation_log_is_exact_up_to_half_a_turn():
    """rotation_log to rounding at every angle, also within 1e-3..1e-9 rad of pi, where its
    axis from the antisymmetric part (of size sin(angle)) lost sig. digits (2e-7 rad off at
    pi - 1e-9), while the rotation-vector columns a pose file is written with
    (orientation_values, by quaternions) were exact: now one logarithm for both."""
    from scipy.spatial.transform import Rotation

    from kincal.measurements.orientation_columns import orientation_values
    from kincal.rotations import axis_rotations

    rng = np.random.default_rng(3)
    w = rng.normal(size=(400, 3))
    w /= np.linalg.norm(w, axis=1)[:, None]
    eps = 10.0 ** -rng.uniform(0, 11, 400)
    eps[:4] = 0.0, 1e-9, 2e-9, 0.0
    angle = np.where(np.arange(400) % 2, np.pi - eps, eps)  # near pi and near 0
    R = axis_rotations(w, angle)
    want = Rotation.from_matrix(R).as_rotvec()
    for got in (rotation_log(R), orientation_values(R, "rotvec")):
        sign = np.where(np.sum(got * want, axis=1) < 0, -1.0, 1.0)  # +-axis at exactly pi
        assert np.abs(got - sign[:, None] * want).max() < 1e-14
        assert np.abs(np.linalg.norm(got, axis=1) - angle).max() < 1e-14


# ------------------------------------------------------------- a calibrated EC66
@pytest.fixture(scope="module")
def cell():
    """A simulated EC66 with planted errors, calibrated (LS) from tracker-like data."""
    robot = Robot.load("ec66", tip="flange")
    model = mdh.extract(robot.geometry)
    rng = np.random.default_rng(7)
    truth = simulation.Truth(simulation.planted_table(model, rng),
                             np.array([0.8, 0.3, -0.2, 0.02, -0.03, 1.0]), TOOL)
    center = default_center("ec66")
    q = simulation.cube_poses(robot, 40, center, 0.4, TOOL, rng)
    data = simulation.measure(model, truth, q, 1e-5, rng)
    result = CalibrationProblem(robot, data, CalibrationOptions(method="ls")).solve()
    new_q = simulation.cube_poses(robot, 30, center, 0.3, TOOL, rng)
    return robot, result, CellFrames.from_dict(result.frames_dict()), new_q


def _targets_from(result, q, quaternions=False):
    """Targets the calibrated model reaches exactly at q (in the measurement frame)."""
    P = result.predict(q)
    quats = None
    if quaternions:
        R_MB = base_rotation(*result.base[3:])
        quats = np.array([matrix_to_quaternion(R_MB @ T[:3, :3])
                          for T in result.corrected.tip_poses(q)])
    return P, quats


def test_position_targets_are_reached_from_nearby_seeds_on_the_same_branch(cell):
    robot, result, frames, q = cell
    P, _ = _targets_from(result, q)
    seeds = q + np.radians(0.5) * np.random.default_rng(1).normal(size=q.shape)
    comp = compensate(result.corrected, frames, Targets(seeds, P, None, np.arange(len(q)) + 2))
    assert comp.reached.all()
    np.testing.assert_allclose(result.predict(comp.joint_values), P, atol=1e-9)
    assert comp.position_error.max() < 1e-9
    # the tool keeps the orientation it has at the seed (6 joints: exactly)
    R_seed = result.corrected.tip_poses(seeds)[:, :3, :3]
    R_sol = result.corrected.tip_poses(comp.joint_values)[:, :3, :3]
    np.testing.assert_allclose(R_sol, R_seed, atol=1e-9)
    # ... so the solution stays near the seed (same branch), not a flipped wrist or elbow
    assert np.abs(comp.joint_values - seeds).max() < np.radians(5)


def test_full_pose_targets_give_back_the_joint_values(cell):
    robot, result, frames, q = cell
    P, quats = _targets_from(result, q, quaternions=True)
    seeds = q + np.radians(1.0) * np.random.default_rng(2).normal(size=q.shape)
    comp = compensate(result.corrected, frames, Targets(seeds, P, quaternion_to_matrix(quats), np.arange(len(q)) + 2))
    assert comp.reached.all() and comp.orientation_required.all()
    np.testing.assert_allclose(comp.joint_values, q, atol=1e-8)


def test_pose_targets_are_orientations_of_the_calibrated_tool_frame(cell):
    """A pose calibration's tool frame is turned on the tip (tool.rx .ry .rz): targets
    written as its data were measured (the tool frame's pose in the measurement frame,
    T_MB T_tip(q) T_tip_tool) give back the joint values. compensate met the tip's
    orientation instead: joints 47 deg off, 'orientation max 5e-14 deg' in its summary."""
    from scipy.spatial.transform import Rotation

    robot, result, _, q = cell
    d = result.frames_dict()
    rx, ry, rz = 0.5, -0.2, 0.3  # a marker body mounted at an angle [rad]
    d["sets"][0]["kind"] = "pose"
    d["sets"][0]["frames"].update({"tool.rx": rx, "tool.ry": ry, "tool.rz": rz})
    frames = CellFrames.from_dict(d)
    R_tool = Rotation.from_euler("XYZ", [rx, ry, rz]).as_matrix()  # rotx roty rotz
    R_MB = Rotation.from_euler("XYZ", result.base[3:]).as_matrix()
    P = result.predict(q)
    R_wanted = R_MB @ result.corrected.tip_poses(q)[:, :3, :3] @ R_tool
    seeds = q + np.radians(1.0) * np.random.default_rng(3).normal(size=q.shape)
    comp = compensate(result.corrected, frames,
                      Targets(seeds, P, R_wanted, np.arange(len(q)) + 2))
    assert comp.reached.all()
    np.testing.assert_allclose(comp.joint_values, q, atol=1e-8)


def test_program_filter_reaches_the_nominal_poses(cell):
    robot, result, frames, q = cell
    comp = filter_program(robot, result.corrected, q, frames)
    assert comp.reached.all()
    T_nom = robot.tip_poses(q)
    T_cal = result.corrected.tip_poses(comp.joint_values)
    np.testing.assert_allclose(T_cal[:, :3, :3], T_nom[:, :3, :3], atol=1e-9)
    np.testing.assert_allclose(T_cal[:, :3, :3] @ TOOL + T_cal[:, :3, 3],
                               T_nom[:, :3, :3] @ TOOL + T_nom[:, :3, 3], atol=1e-9)
    assert np.abs(comp.joint_values - q).max() > 1e-5  # the calibration did change something
    same = filter_program(robot, robot, q, frames)  # nominal = calibrated: nothing to correct
    np.testing.assert_allclose(same.joint_values, q, atol=1e-12)


def test_fewer_than_six_joints_meet_the_position_and_keep_the_orientation_second():
    robot = Robot.load("ec66", tip="joint_5")  # 5 joints: position and orientation cannot both hold
    rng = np.random.default_rng(3)
    q = random_joint_values(robot.geometry, rng, 10) * 0.5
    tool = np.array([0.0, 0.05, 0.1])
    frames = CellFrames.of_points(np.zeros(6), tool[None], base_frame="base_link", tip_frame="joint_5")
    chain = ChainKinematics.of(robot.geometry)
    _, P, _, _ = chain.evaluate(q, tool)
    seeds = q + 0.02 * rng.normal(size=q.shape)
    comp = compensate(robot, frames, Targets(seeds, P, None, np.arange(10) + 2))
    assert comp.reached.all() and comp.position_error.max() < 1e-9
    assert "as far as the 5 joints allow" in comp.summary()


def test_a_pose_beyond_a_joint_limit_is_flagged_not_clipped(cell):
    """Poses of their own, not the fixture's: which poses cube_poses draws depends on the
    last bits of the machine's BLAS (its iterations from random seeds), and a position
    target whose elbow must pass its limit to follow is not reachable on the seed's branch
    (so it went on OpenBLAS's Haswell kernels). These three behave alike on OpenBLAS's Haswell,
    SkylakeX, Zen and Sandybridge kernels (OPENBLAS_CORETYPE)."""
    robot, result, frames, q = cell
    g = robot.geometry
    q_out = np.array([[-0.2, 0.0, 1.0, 0.8, -0.3, 0.0], [-1.2, 0.0, -1.0, 0.8, -0.3, 1.1],
                      [0.4, 0.0, -0.7, 0.3, -0.9, 0.5]])
    q_out[:, 1] = g.upper[1] + 0.3  # joint_2 beyond its upper limit
    P, quats = _targets_from(result, q_out, quaternions=True)
    seeds = np.clip(q_out, g.lower, g.upper)
    comp = compensate(result.corrected, frames, Targets(seeds, P, quaternion_to_matrix(quats), np.array([5, 6, 7])))
    assert not comp.reached.any()
    assert comp.at_limit[:, 1].all()
    assert (comp.joint_values <= g.upper).all() and (comp.joint_values >= g.lower).all()
    fails = comp.failures()
    assert len(fails) == 3 and fails[0].startswith("line 5:") and "joint_2 at a joint limit" in fails[0]
    # a position alone is reached with the other joints; the preferred orientation gives way
    comp = compensate(result.corrected, frames, Targets(seeds, P, None, np.array([5, 6, 7])))
    assert comp.reached.all() and comp.at_limit[:, 1].all()
    assert (comp.joint_values <= g.upper).all() and comp.orientation_error.min() > 1e-3
    assert "orientation gave way" in comp.summary()


def test_targets_in_millimetres_read_as_metres_are_refused(cell):
    robot, result, frames, q = cell
    P, _ = _targets_from(result, q)
    with pytest.raises(DataError, match="were they millimetres"):
        compensate(result.corrected, frames, Targets(q, P * 1e3, None, np.arange(len(q)) + 2))
    with pytest.raises(DataError, match="were they millimetres"):  # one target alone: by the reach
        compensate(result.corrected, frames, Targets(q[:1], P[:1] * 1e3, None, np.array([2])))
    with pytest.raises(DataError, match="metres read as millimetres"):
        compensate(result.corrected, frames, Targets(q, P * 1e-3, None, np.arange(len(q)) + 2),
                   length_unit="mm")


def test_frames_of_another_tip_or_robot_are_refused(cell):
    robot, result, frames, q = cell
    P, _ = _targets_from(result, q)
    targets = Targets(q, P, None, np.arange(len(q)) + 2)
    other_tip = Robot.load("ec66", tip="joint_6")
    with pytest.raises(DataError, match="tip frame 'flange'"):
        compensate(other_tip, frames, targets)
    d = result.frames_dict()
    d["joints"] = ["shoulder_pan_joint", "shoulder_lift_joint"]
    with pytest.raises(DataError, match="another robot"):
        compensate(result.corrected, CellFrames.from_dict(d), targets)


def test_backlash_in_the_frames_is_named_not_compensated(cell):
    robot, result, frames, q = cell
    d = result.frames_dict()
    d["backlash"] = {"joint_6": np.radians(0.5), "joint_5": -np.radians(0.25)}
    P, _ = _targets_from(result, q)
    comp = compensate(result.corrected, CellFrames.from_dict(d), Targets(q, P, None, np.arange(len(q)) + 2))
    # half the play either way: a negative coefficient (the joint lags behind its reading)
    # is the same play, not "+--0.25"
    assert "backlash not compensated (joint_6 +-0.5 deg, joint_5 +-0.25 deg)" in comp.summary()
    np.testing.assert_allclose(comp.joint_values, q, atol=1e-9)  # middle of the play


def test_ik_options_are_checked():
    with pytest.raises(Exception, match="position_tolerance"):
        IkOptions(position_tolerance=-1.0)


# ---------------------------------------------------------------------- the CLI
def _write_targets(path, names, q, P, scale=1.0):
    rows = [",".join([*names, "x", "y", "z"])]
    rows += [",".join(repr(float(v)) for v in (*qk, *(pk * scale))) for qk, pk in zip(q, P)]
    path.write_text("\n".join(rows) + "\n")


@pytest.fixture
def cli_cell(cell, tmp_path):
    robot, result, frames, q = cell
    urdf = tmp_path / "cal.urdf"
    urdf.write_text(corrected_urdf_text(result))
    fj = tmp_path / "frames.json"
    fj.write_text(json.dumps(result.frames_dict()))
    P, _ = _targets_from(result, q)
    return result, q, P, urdf, fj, tmp_path


def test_cli_compensate_writes_joint_values_in_the_input_units(cli_cell, capsys):
    result, q, P, urdf, fj, tmp = cli_cell
    t = tmp / "targets.csv"
    _write_targets(t, result.robot.joint_names, np.degrees(q - 0.005 * np.sign(q)), P, scale=1e3)
    out = tmp / "joints.csv"
    assert main(["compensate", str(urdf), str(t), "--tip", "flange", "--frames", str(fj),
                 "--out", str(out), "--angle-unit", "deg", "--length-unit", "mm"]) == 0
    table = np.genfromtxt(_uncommented(out), delimiter=",", names=True)
    assert ("# joint values in deg (revolute) and mm (prismatic), as the input"
            in out.read_text())  # labelled in the file, not only on the console
    q_out = np.radians(np.column_stack([table[j] for j in result.robot.joint_names]))
    np.testing.assert_allclose(result.predict(q_out), P, atol=1e-9)
    assert (table["reached"] == 1).all() and list(table["target_line"]) == list(range(2, len(q) + 2))
    printed = capsys.readouterr()
    assert "compensated 30 of 30 targets" in printed.out
    assert printed.err.strip().splitlines()[-1].startswith("kincal: done in ")  # as the README says


def test_cli_unreachable_targets_fail_listing_rows_and_write_nothing(cli_cell, capsys):
    result, q, P, urdf, fj, tmp = cli_cell
    P = P.copy()
    P[[3, 7]] += [2.0, 0.0, 0.0]  # 2 m away from the rest
    t = tmp / "targets.csv"
    _write_targets(t, result.robot.joint_names, q, P)
    out = tmp / "joints.csv"
    args = ["compensate", str(urdf), str(t), "--tip", "flange", "--frames", str(fj), "--out", str(out)]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.startswith("kincal: error: 2 of 30 targets cannot be reached") and err.count("\n") == 1
    assert "line 5:" in err and "line 9:" in err and not out.exists()
    assert main(args + ["--flag-unreachable"]) == 0
    table = np.genfromtxt(_uncommented(out), delimiter=",", names=True)
    assert list(np.flatnonzero(table["reached"] == 0)) == [3, 7]


@pytest.mark.parametrize("case", ["mm_as_m", "other_tip", "other_robot"])
def test_cli_bad_input_one_error_nothing_written(cli_cell, case, capsys):
    result, q, P, urdf, fj, tmp = cli_cell
    t = tmp / "targets.csv"
    _write_targets(t, result.robot.joint_names, q, P, scale=1e3 if case == "mm_as_m" else 1.0)
    robot, tip = str(urdf), "flange"
    if case == "other_tip":
        tip = "joint_6"
    if case == "other_robot":
        robot, tip = "ur10", "tool0"
    out = tmp / "joints.csv"
    assert main(["compensate", robot, str(t), "--tip", tip, "--frames", str(fj), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("kincal: error:") and err.count("\n") == 1 and not out.exists()
    # another robot given with its own tip: the recorded chain is the first thing that differs
    assert {"mm_as_m": "were they millimetres", "other_tip": "tip frame 'flange'",
            "other_robot": "does not match the tip frame 'flange'"}[case] in err


def _program(result, q, tmp):
    """A joint program file: the chain joints' columns, the rows q [rad]."""
    prog = tmp / "program.csv"
    prog.write_text(",".join(result.robot.joint_names) + "\n"
                    + "\n".join(",".join(repr(float(v)) for v in qk) for qk in q) + "\n")
    return prog

def test_cli_program_filter(cli_cell, tmp_path):
    result, q, P, urdf, fj, tmp = cli_cell
    prog = _program(result, q, tmp)
    out = tmp / "joints.csv"
    assert main(["compensate", str(urdf), "--program", str(prog), "--nominal", "ec66",
                 "--tip", "flange", "--frames", str(fj), "--out", str(out)]) == 0
    table = np.genfromtxt(_uncommented(out), delimiter=",", names=True)
    q_out = np.column_stack([table[j] for j in result.robot.joint_names])
    np.testing.assert_allclose(q_out, filter_program(result.robot, result.corrected, q,
                                                     CellFrames.read(fj)).joint_values, atol=1e-15)
    assert main(["compensate", str(urdf), "--program", str(prog), "--tip", "flange",
                 "--out", str(tmp / "x.csv")]) == 1  # --program without --nominal


@pytest.mark.parametrize("kind, options", [
    ("distance", []), ("plane", ["--on-plane"]),
    ("flush", ["--on-plane", "--flush", "--tool-offset", "0", "0", "0.12"])])
def test_program_filter_takes_the_tool_point_of_a_calibration_without_points(
        kind, options, tmp_path, capsys):
    """The program filter needs the tool point of FRAMES.json alone (docs/cell.md): with the
    frames of a distance or flush calibration it was refused, "no measurement set ... has a
    measurement frame and tool point ...; targets in a measurement frame need a point or
    pose calibration", a program having no targets in a measurement frame."""
    data, urdf, fj, out = (tmp_path / f for f in ("d.csv", "c.urdf", "f.json", "j.csv"))
    assert main(["simulate", "ec66", "--kind", kind, "--out", str(data), "--seed", "7",
                 "-q"]) == 0
    assert main(["calibrate", "ec66", str(data), *options, "--out", str(urdf),
                 "--frames-out", str(fj), "-q"]) == 0
    nominal, calibrated = Robot.load("ec66", tip="flange"), Robot.load(urdf, tip="flange")
    q = simulation.cube_poses(nominal, 10, default_center("ec66"), 0.3, TOOL,
                              np.random.default_rng(3))
    prog = tmp_path / "program.csv"
    prog.write_text(",".join(nominal.joint_names) + "\n"
                    + "".join(",".join(map(repr, row.tolist())) + "\n" for row in q))
    capsys.readouterr()
    assert main(["compensate", str(urdf), "--program", str(prog), "--nominal", "ec66",
                 "--frames", str(fj), "--out", str(out), "-q"]) == 0, capsys.readouterr().err
    table = np.genfromtxt(_uncommented(out), delimiter=",", names=True)
    q_out = np.column_stack([table[j] for j in nominal.joint_names])
    assert np.abs(q_out - q).max() > 1e-4  # [rad] the calibration corrected them
    frames = json.loads(fj.read_text())["sets"][0]["frames"]
    tool = np.array([frames[f"tool.{c}"] for c in "xyz"])
    want, got = nominal.tip_poses(q), calibrated.tip_poses(q_out)
    assert np.abs(want[:, :3, :3] @ tool + want[:, :3, 3]
                  - got[:, :3, :3] @ tool - got[:, :3, 3]).max() < 1e-12  # [m]
    assert np.abs(want[:, :3, :3] - got[:, :3, :3]).max() < 1e-12


def test_a_nominal_robot_of_another_model_is_refused(tmp_path, capsys):
    """--nominal of another model of the same chain (UR5 for a UR10: same joint names)
    was accepted, most targets "reached" with joint values for the wrong arm; now refused
    in one line, as far beyond what any calibration kincal writes moves the tool."""
    ur10 = Robot.load("ur10")
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (10, 6))
    prog = tmp_path / "prog.csv"
    prog.write_text(",".join(ur10.joint_names) + "\n"
                    + "".join(",".join(f"{v!r}" for v in row.tolist()) + "\n" for row in q))
    out = tmp_path / "joints.csv"
    assert main(["compensate", "ur10", "--program", str(prog), "--nominal", "ur5",
                 "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("kincal: error: the nominal robot") and err.count("\n") == 1
    assert "more than the gate lets a calibration move it" in err and not out.exists()
    with pytest.raises(DataError, match="mm RMS apart"):
        filter_program(Robot.load("ur5"), ur10, q)
    assert main(["compensate", "ur10", "--program", str(prog), "--nominal", "ur10",
                 "--out", str(out)]) == 0  # the same model: nothing to refuse


@pytest.mark.parametrize("given, said", [
    (["--frames", "FRAMES", "--position-columns", "a", "b", "c"], "a --program has joint values"),
    (["--point", "2"], "--point 2 picks a measured point of --frames")])
def test_cli_program_refuses_options_it_would_ignore(cli_cell, given, said, capsys):
    """A program has no positions to name, and without FRAMES.json no second tool point:
    both options were accepted and had no effect."""
    result, q, P, urdf, fj, tmp = cli_cell
    prog = _program(result, q, tmp)
    out = tmp / "joints.csv"
    assert main(["compensate", str(urdf), "--program", str(prog), "--nominal", "ec66",
                 "--tip", "flange", "--out", str(out)]
                + [str(fj) if g == "FRAMES" else g for g in given]) == 1
    err = capsys.readouterr().err
    assert err.startswith("kincal: error:") and err.count("\n") == 1 and said in err
    assert not out.exists()


def test_cli_full_pose_targets_and_bad_quaternions(cli_cell, capsys):
    result, q, P, urdf, fj, tmp = cli_cell
    _, quats = _targets_from(result, q, quaternions=True)
    names = list(result.robot.joint_names)
    t = tmp / "poses.csv"

    def write(cols, rows):
        t.write_text(",".join(names + ["x", "y", "z"] + cols) + "\n" + "\n".join(
            ",".join(repr(float(v)) for v in row) for row in rows) + "\n")

    seeds = q - 0.01 * np.sign(q)
    write(["qx", "qy", "qz", "qw"], np.hstack([seeds, P, quats]))
    out = tmp / "joints.csv"
    assert main(["compensate", str(urdf), str(t), "--tip", "flange", "--frames", str(fj),
                 "--out", str(out)]) == 0
    table = np.genfromtxt(_uncommented(out), delimiter=",", names=True)
    np.testing.assert_allclose(np.column_stack([table[j] for j in names]), q, atol=1e-8)
    for cols, rows, message in ((["qx", "qy", "qz"], np.hstack([seeds, P, quats[:, :3]]),
                                 "without qw"),
                                (["qx", "qy", "qz", "qw"], np.hstack([seeds, P, 2 * quats]),
                                 "has norm 2, not 1: give unit quaternions")):
        write(cols, rows)
        out.unlink(missing_ok=True)
        assert main(["compensate", str(urdf), str(t), "--tip", "flange", "--frames", str(fj),
                     "--out", str(out)]) == 1
        err = capsys.readouterr().err
        assert message in err and not out.exists()


def test_cli_targets_take_the_orientation_formats_of_pose_files(cli_cell, capsys):
    """Orientation targets written as rpy-zyx angles in degrees (joints in degrees too)
    give the joint values the quaternion targets give; angle columns without their format
    are refused, not dropped (a position-only solution would move the tool's orientation);
    the format options do not go with --program."""
    from kincal.measurements.orientation_columns import orientation_values

    result, q, P, urdf, fj, tmp = cli_cell
    _, quats = _targets_from(result, q, quaternions=True)
    names = list(result.robot.joint_names)
    rpy = orientation_values(quaternion_to_matrix(quats), "rpy-zyx", np.pi / 180)  # [deg]
    seeds = np.degrees(q - 0.01 * np.sign(q))
    t, out = tmp / "rpy.csv", tmp / "joints.csv"
    t.write_text(",".join(names + ["x", "y", "z", "roll", "pitch", "yaw"]) + "\n" + "\n".join(
        ",".join(repr(float(v)) for v in row) for row in np.hstack([seeds, P, rpy])) + "\n")
    base = ["compensate", str(urdf), str(t), "--tip", "flange", "--frames", str(fj), "--out",
            str(out), "--angle-unit", "deg"]
    assert main(base) == 1
    err = capsys.readouterr().err
    assert "orientation columns roll, pitch, yaw beside the position columns x y z would not be read" in err and not out.exists()
    assert main(base + ["--orientation-format", "rpy-zyx"]) == 0
    table = np.genfromtxt(_uncommented(out), delimiter=",", names=True)
    np.testing.assert_allclose(np.radians(np.column_stack([table[j] for j in names])), q,
                               atol=1e-8)
    assert table["orientation_error_deg"].max() < 1e-6
    assert main(["compensate", str(urdf), "--program", str(t), "--nominal", str(urdf), "--tip",
                 "flange", "--out", str(tmp / "p.csv"), "--orientation-format", "rpy-zyx"]) == 1
    assert "describe TARGETS.csv" in capsys.readouterr().err
    # the same angles read in the other order: valid rotations, tens of degrees from where
    # the calibrated model holds the tool at the seeds (the program): refused, not reached
    out.unlink()
    assert main(base + ["--orientation-format", "rpy-xyz"]) == 1
    err = capsys.readouterr().err
    assert err.count("kincal: error:") == 1 and not out.exists()
    assert "read as rpy-xyz lie a mean" in err and "is the file's convention rpy-zyx?" in err


def test_the_second_measured_point_can_be_targeted(cell):
    robot, result, frames, q = cell
    second = np.array([-0.05, 0.04, 0.1])
    d = result.frames_dict()
    d["sets"][0]["frames"].update({f"tool2.{c}": float(v) for c, v in zip("xyz", second)})
    del d["sets"][0]["T_tip_tool"]  # derived matrices are optional in a file
    two = CellFrames.from_dict(d)
    T = result.corrected.tip_poses(q)
    R_MB, t_MB = base_rotation(*result.base[3:]), result.base[:3]
    P2 = (T[:, :3, :3] @ second + T[:, :3, 3]) @ R_MB.T + t_MB
    seeds = q - 0.01 * np.sign(q)
    comp = compensate(result.corrected, two, Targets(seeds, P2, None, np.arange(len(q)) + 2), point=1)
    assert comp.reached.all()
    T = result.corrected.tip_poses(comp.joint_values)
    np.testing.assert_allclose((T[:, :3, :3] @ second + T[:, :3, 3]) @ R_MB.T + t_MB, P2, atol=1e-9)
    with pytest.raises(Exception, match="measured point 3"):
        compensate(result.corrected, two, Targets(seeds, P2, None, np.arange(len(q)) + 2), point=2)


def test_the_acceptance_script_one_seed():
    """scripts/compensation_demo.py at one seed: compensation beats the nominal joints and
    lands within 1.5x of the calibrated model's held-out error."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "compensation_demo.py"
    spec = importlib.util.spec_from_file_location("compensation_demo", path)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    robot = Robot.load("ec66", tip="flange")
    nominal, compensated, held_out, _ = demo.one_seed(robot, mdh.extract(robot.geometry), 2)
    assert compensated < 0.2 * nominal and compensated <= 1.5 * held_out


def test_compensation_imports_neither_pinocchio_nor_the_cli():
    """Plain numpy below the one Pinocchio boundary (robot.py); no import from a layer above."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "src" / "kincal"
    files = sorted((root / "compensation").glob("*.py")) + [root / "export" / "cell_exports.py"]
    assert len(files) >= 5
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                assert not name.startswith(("pinocchio", "kincal.cli", "kincal.experiments")), \
                    f"{path.name} imports {name}"


def _uncommented(path):
    """The lines of a CSV kincal wrote without its provenance (# lines): genfromtxt would
    take a first comment line for the header."""
    return [line for line in open(path) if not line.startswith("#")]


def test_a_target_missed_near_a_singular_configuration_says_so():
    """Targets missed near a singular configuration (seeds with the EC66's wrist axes
    aligned, joint_5 = 0, and a turn the wrist then cannot make) gave only the miss
    distance; their lines now say where the joints ended. A miss elsewhere (a target 5 mm
    beyond the stretched arm's tool point, the solver stalling bent) does not say so."""
    from kincal.rotations import rotx

    robot = Robot.load("ec66", tip="flange")
    tool = np.array([0.0, 0.0, 0.1])
    frames = CellFrames.of_points(np.zeros(6), tool[None], base_frame=robot.base,
                                  tip_frame=robot.tip)
    chain = ChainKinematics.of(robot.geometry)
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.5, 1.5, (60, 6))
    q[:, 4] = rng.uniform(-1e-3, 1e-3, 60)
    R, p = chain.tool_poses(q, tool)
    seeds = q.copy()
    seeds[:, 4] = 0.0
    c = compensate(robot, frames, Targets(seeds, p, R @ rotx(0.01), np.arange(2, 62)))
    missed = ~c.reached
    assert 5 <= missed.sum() < 40 and c.singular[missed].mean() > 0.9, (missed.sum(),
                                                                       c.singular[missed])
    assert not c.singular[c.reached].any()
    lines = c.failures()
    assert sum("the joints end near a singular configuration" in line for line in lines) \
        == c.singular.sum()
    q0 = np.array([[0.3, 0.0, 0.0, 0.0, 0.0, 0.0]])  # stretched: 5 mm further out
    _, p0 = chain.tool_poses(q0, tool)
    out = p0[0] * [1.0, 1.0, 0.0]
    p0[0] += 0.005 * out / np.linalg.norm(out)
    c = compensate(robot, frames, Targets(q0 + 0.01, p0, None, np.array([2])))
    assert not c.reached[0] and c.position_error[0] > 1e-3 and not c.singular[0]
    assert "singular" not in c.failures()[0]
