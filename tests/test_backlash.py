"""Backlash terms: approach directions, the Jacobian column, identification, CLI."""

import json
import warnings

import numpy as np

from kincal.export.outputs import corrected_urdf_text
import pytest
from conftest import random_joint_values, tiago_urdf

from kincal.cli.main import main
from kincal.errors import DataError, KincalWarning, OptionError, ParameterError
from kincal.identification.problem import calibrate
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.models.backlash import MOVE_TOL, approach_directions
from kincal.planning.simulation import Truth, cube_poses, measure, true_positions
from kincal.robot import Robot
from kincal.rotations import base_rotation

BASE = np.array([0.9, -0.4, 0.2, 0.05, -0.1, 2.0])


def test_approach_directions_follow_the_last_real_motion():
    q = np.array([[0.0, 0.0], [0.5, 0.0], [0.5 + MOVE_TOL / 2, -0.2], [0.1, -0.2], [0.1, 0.3]])
    g = approach_directions(q)
    # joint 1: +, then a sub-tolerance step keeps +, then -, then still - (no motion)
    assert g[:, 0].tolist() == [0, 1, 1, -1, -1]
    assert g[:, 1].tolist() == [0, 0, -1, -1, 1]


def test_an_order_column_reorders_the_sequence():
    q = np.array([[0.0], [1.0], [2.0]])
    # acquired as rows 3, 1, 2: 2.0 -> 0.0 (down) -> 1.0 (up)
    g = approach_directions(q, order=np.array([20.0, 30.0, 10.0]))
    assert g[:, 0].tolist() == [-1, 1, 0]
    with pytest.raises(DataError, match="lines 2 and 4 have the same order value"):
        approach_directions(q, order=np.array([5.0, 6.0, 5.0]), rows=np.array([2, 3, 4]))


def test_order_column_from_csv(tmp_path):
    f = tmp_path / "d.csv"
    f.write_text("t,j1,x,y,z\n3,2.0,0.3,0,0\n1,0.0,0.1,0,0\n2,1.0,0.2,0,0\n")
    d = Measurements.from_csv(f, ["j1"], order_column="t")
    assert d.approach[:, 0].tolist() == [1, 0, 1]
    assert d.order_source == "column 't'" and "t" not in d.ignored_columns
    assert Measurements.from_csv(f, ["j1"]).approach[:, 0].tolist() == [0, -1, 1]
    with pytest.raises(DataError, match="no order column 'time'"):
        Measurements.from_csv(f, ["j1"], order_column="time")
    # a measured value is not an order (it was taken as one: --order-column x1 on TIAGo)
    for col, what in (("x", "a position column"), ("j1", "a joint column")):
        with pytest.raises(DataError, match=f"order column '{col}' is {what}; expected"):
            Measurements.from_csv(f, ["j1"], order_column=col)


@pytest.mark.parametrize("name,tip", [("ur5", "tool0"), ("tiago_file", "wrist_ft_tool_link")])
def test_backlash_columns_match_central_differences(name, tip, rng):
    robot = Robot.load(tiago_urdf() if name == "tiago_file" else name, tip=tip)
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, 30)
    g = rng.choice([-1.0, 0.0, 1.0], size=q.shape)
    joints = robot.joint_names[:1] + robot.joint_names[-2:]  # the TIAGo torso is prismatic
    mm = MeasurementModel(model, q, g, joints)
    x = mm.space.join(model.table, BASE, [0.05, 0.02, 0.1], rng.normal(size=3) * 0.01)
    x = x + rng.normal(size=x.size) * 1e-3
    _, J = mm.jacobian(x)
    h = 1e-6
    for c in np.flatnonzero(mm.space.is_backlash | mm.space.is_kinematic):
        e = np.zeros_like(x)
        e[c] = h
        fd = (mm.predict(x + e) - mm.predict(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        assert np.abs(J[:, :, c] - fd).max() / scale < 1e-6, mm.space.names[c]
    # a backlash term is the joint's own motion: equal to moving the joint values
    b = mm.space.backlash_values(x)
    q_eff = q.copy()
    for k, i in enumerate(mm.space.backlash_joint_index):
        q_eff[:, i] += b[k] * g[:, i]
    plain = MeasurementModel(model, q_eff)
    assert np.abs(mm.predict(x) - plain.predict(x[:plain.space.size])).max() < 1e-15


def _ur10_with_backlash(seed=3, n=80):
    rng = np.random.default_rng(seed)
    robot = Robot.load("ur10", tip="tool0")
    model = mdh.extract(robot.geometry)
    tool = np.array([0.05, 0.02, 0.10])
    q = cube_poses(robot, n, [0.6, 0.2, 0.4], 0.4, tool, rng)
    truth = Truth(model.table, BASE, tool, backlash={"wrist_2_joint": np.radians(0.05),
                                                      "elbow_joint": -np.radians(0.02)})
    return rng, robot, model, q, truth


def test_planted_backlash_is_recovered_and_the_result_carries_it(tmp_path):
    rng, robot, model, q, truth = _ur10_with_backlash()
    data = measure(model, truth, q, 0.0, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("error", KincalWarning)  # both directions are well covered
        res = calibrate(robot, data, method="ls", backlash=("wrist_2_joint", "elbow_joint"))
    assert res.space.backlash == ("elbow_joint", "wrist_2_joint")  # chain order
    assert res.parameter("wrist_2_joint.backlash").status == "identified"
    assert res.backlash["wrist_2_joint"] == pytest.approx(np.radians(0.05), abs=1e-10)
    assert res.backlash["elbow_joint"] == pytest.approx(-np.radians(0.02), abs=1e-10)
    assert res.after.max < 1e-9
    # prediction with the approach directions reproduces the truth; without: mid-play
    assert np.abs(res.predict(q, data.approach) - true_positions(model, truth, q)).max() < 1e-10
    assert np.abs(res.predict(q) - true_positions(model, truth, q)).max() > 1e-5
    frames = res.frames_dict()
    assert set(frames["backlash"]) == {"elbow_joint", "wrist_2_joint"}
    assert "backlash" in res.summary() and "the order of the samples" in res.summary()
    # the exported URDF carries the kinematics only: the robot in the middle of its play
    path = tmp_path / "c.urdf"
    path.write_text(corrected_urdf_text(res))
    T = Robot.load(path, tip="tool0").tip_poses(q)
    P = (T[:, :3, 3] + T[:, :3, :3] @ res.tool) @ base_rotation(*res.base[3:]).T + res.base[:3]
    assert np.abs(P - res.predict(q)).max() < 1e-10


def test_without_the_term_backlash_stays_in_the_residuals():
    rng, robot, model, q, truth = _ur10_with_backlash()
    data = measure(model, truth, q, 0.0, rng)
    plain = calibrate(robot, data, method="ls")
    assert plain.after.rms > 0.05  # [mm] 0.05 deg of play on the wrist is visible


def test_one_sided_approach_warns_and_drops_the_term_not_the_offset():
    rng, robot, model, q, truth = _ur10_with_backlash()
    data = measure(model, truth, q, 1e-5, rng)
    one_sided = Measurements(data.joint_names, data.joint_values, data.positions,
                             approach=np.ones_like(data.joint_values))
    with pytest.warns(KincalWarning, match="wrist_2_joint.backlash: 80 samples approached"):
        res = calibrate(robot, one_sided, method="ls", backlash=("wrist_2_joint",))
    assert res.parameter("wrist_2_joint.backlash").status == "dropped"
    assert res.parameter("wrist_2_joint.theta").status == "identified"


def test_bad_backlash_options():
    rng, robot, model, q, truth = _ur10_with_backlash(n=20)
    data = measure(model, truth, q, 0.0, rng)
    with pytest.raises(ParameterError, match="no chain joint 'wrist_9_joint'.*wrist_1_joint"):
        calibrate(robot, data, backlash=("wrist_9_joint",))
    with pytest.raises(OptionError, match="backlash terms need method l2 or ls"):
        calibrate(robot, data, method="frames", backlash=("wrist_2_joint",))


def test_cli_backlash_on_the_tiago_files_beats_figaroh_best(tmp_path, capsys):
    """Real data: training day only; the held-out day with the training frames and backlash."""
    urdf = tiago_urdf()
    train = urdf.parent / "qualisys_2021-11-30_static_postures.csv"
    held = urdf.parent / "qualisys_2021-11-26_static_postures.csv"
    common = ["--tip", "wrist_ft_tool_link", "--position-columns", "x1", "y1", "z1",
              "--order-column", "t_start_robot"]
    out, frames = tmp_path / "cal.urdf", tmp_path / "frames.json"
    assert main(["calibrate", str(urdf), str(train), *common, "--backlash", "arm_6_joint",
                 "--out", str(out), "--frames-out", str(frames), "--quiet"]) == 0
    saved = json.loads(frames.read_text())
    assert set(saved["backlash"]) == {"arm_6_joint"}
    capsys.readouterr()
    assert main(["evaluate", str(out), str(held), *common, "--frames", str(frames)]) == 0
    text = capsys.readouterr().out
    assert "with backlash of arm_6_joint" in text
    rms = float(text.split("RMS")[1].split()[0])
    assert rms < 3.22  # FIGAROH's best published held-out RMS on these files [mm]


def test_evaluate_rejects_backlash_of_a_joint_not_in_the_chain(tmp_path, capsys):
    rng, robot, model, q, truth = _ur10_with_backlash(n=20)
    data = measure(model, truth, q, 0.0, rng)
    csv = tmp_path / "d.csv"
    csv.write_text(data.to_csv_text())
    frames = tmp_path / "frames.json"
    frames.write_text(json.dumps({"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), BASE)),
                                  "tool": {"x": 0.05, "y": 0.02, "z": 0.1},
                                  "backlash": {"arm_6_joint": 0.01}}))
    code = main(["evaluate", "ur10", str(csv), "--tip", "tool0", "--frames", str(frames)])
    err = capsys.readouterr().err
    assert code == 1 and "frames.json: no chain joint 'arm_6_joint' for a backlash term" in err


def test_cli_analyze_lists_backlash_terms_and_the_tool_point(tmp_path, capsys):
    rng, robot, model, q, truth = _ur10_with_backlash(n=40)
    csv = tmp_path / "d.csv"
    csv.write_text(measure(model, truth, q, 0.0, rng).to_csv_text())
    assert main(["analyze", "ur10", str(csv), "--tip", "tool0", "--backlash", "wrist_2_joint",
                 "--model", "mdh"]) == 0
    out = capsys.readouterr().out
    assert "of 34 free parameters" in out  # 24 MD-H + 9 frames + 1 backlash
    tool_mm = json.loads(out.split("tip frame): ")[1].split(" mm")[0])
    assert np.allclose(tool_mm, truth.tool * 1e3, atol=5.0)  # not the backlash value


def test_an_unused_time_column_is_pointed_out(tmp_path):
    rng, robot, model, q, truth = _ur10_with_backlash(n=40)
    lines = measure(model, truth, q, 0.0, rng).to_csv_text().splitlines()
    csv = tmp_path / "d.csv"
    csv.write_text("\n".join([lines[0] + ",timestamp"]
                             + [f"{row},{k}" for k, row in enumerate(lines[1:])]) + "\n")
    data = Measurements.from_csv(csv, robot.joint_names)
    with pytest.warns(KincalWarning, match="'timestamp' that looks like a time stamp"):
        calibrate(robot, data, method="ls", backlash=("wrist_2_joint",))
    ordered = Measurements.from_csv(csv, robot.joint_names, order_column="timestamp")
    with warnings.catch_warnings():
        warnings.simplefilter("error", KincalWarning)
        calibrate(robot, ordered, method="ls", backlash=("wrist_2_joint",))


def _reversed_with_time(tmp_path, n=40):
    """The UR10 backlash data written last sample first, with a column giving the true order."""
    rng, robot, model, q, truth = _ur10_with_backlash(n=n)
    lines = measure(model, truth, q, 0.0, rng).to_csv_text().splitlines()
    csv = tmp_path / "d.csv"
    rows = [f"{row},{k}" for k, row in enumerate(lines[1:])][::-1]
    csv.write_text("\n".join([lines[0] + ",t"] + rows) + "\n")
    return csv


def test_model_auto_takes_the_order_column_its_backlash_terms_need(tmp_path, capsys):
    """--model auto (the default) weighs backlash terms, and the time-stamp warning tells the
    user to give --order-column: it was refused ("it needs --backlash")."""
    csv = _reversed_with_time(tmp_path)
    out, frames = tmp_path / "cal.urdf", tmp_path / "frames.json"
    code = main(["calibrate", "ur10", str(csv), "--tip", "tool0", "--order-column", "t",
                 "--out", str(out), "--frames-out", str(frames), "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert "wrist_2_joint" in json.loads(frames.read_text())["backlash"]
    code = main(["calibrate", "ur10", str(csv), "--tip", "tool0", "--order-column", "t",
                 "--model", "complete", "--out", str(tmp_path / "x.urdf")])
    err = capsys.readouterr().err
    assert code == 1 and "needs --backlash, or --model auto" in err
    assert not (tmp_path / "x.urdf").exists()


def test_evaluate_refuses_an_order_column_no_backlash_term_uses(tmp_path, capsys):
    """evaluate ignored --order-column when FRAMES.json had no backlash (or with --fit-frames);
    calibrate and analyze refuse it there."""
    rng, robot, model, q, truth = _ur10_with_backlash(n=20)
    csv = _reversed_with_time(tmp_path, n=20)
    frames = tmp_path / "frames.json"
    frames.write_text(json.dumps({"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), BASE)),
                                  "tool": {"x": 0.05, "y": 0.02, "z": 0.1}}))
    report = tmp_path / "r.json"
    for how in (["--frames", str(frames)], ["--fit-frames"]):
        code = main(["evaluate", "ur10", str(csv), "--tip", "tool0", "--order-column", "t",
                     *how, "--report", str(report)])
        err = capsys.readouterr().err
        assert code == 1 and "--order-column gives the approach directions" in err, err
        assert len(err.strip().splitlines()) == 1 and not report.exists()
