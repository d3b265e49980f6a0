"""Several points measured at each pose: data layout, Jacobian, identification, CLI."""

import json
import warnings

import numpy as np

from kincal.export.outputs import corrected_urdf
import pytest
from conftest import random_joint_values, tiago_urdf

from kincal.cli.main import main
from kincal.errors import DataError, KincalWarning
from kincal.identification.problem import calibrate
from kincal.identification.cross_validation import make_folds
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.planning.simulation import Truth, measure, planted_table, true_positions
from kincal.robot import Robot

BASE = np.array([0.9, -0.4, 0.2, 0.05, -0.1, 2.0])
TOOLS = np.array([[0.04, 0.03, 0.11], [-0.05, 0.02, 0.09], [0.01, -0.06, 0.13]])


def test_jacobian_with_three_points_and_backlash_matches_central_differences(rng):
    robot = Robot.load("ur5", tip="tool0")
    model = mdh.extract(robot.geometry)
    q = np.repeat(random_joint_values(robot.geometry, rng, 20), 3, axis=0)
    points = np.tile(np.arange(3), 20)
    g = np.repeat(rng.choice([-1.0, 1.0], size=(20, 6)), 3, axis=0)
    mm = MeasurementModel(model, q, g, ("elbow_joint",), points, 3)
    assert mm.space.names[24 + 6:24 + 15] == ("tool.x", "tool.y", "tool.z", "tool2.x", "tool2.y",
                                              "tool2.z", "tool3.x", "tool3.y", "tool3.z")
    x = mm.space.join(model.table, BASE, TOOLS, [0.01]) + rng.normal(size=mm.space.size) * 1e-3
    _, J = mm.jacobian(x)
    h = 1e-6
    for c in range(x.size):
        e = np.zeros_like(x)
        e[c] = h
        fd = (mm.predict(x + e) - mm.predict(x - e)) / (2 * h)
        assert np.abs(J[:, :, c] - fd).max() / max(np.abs(fd).max(), 1e-3) < 1e-6, mm.space.names[c]
    # a sample moves with its own point only
    assert np.all(J[points != 1][:, :, 24 + 9:24 + 12] == 0)


def test_csv_with_several_points_gives_one_sample_per_point_and_writes_back(tmp_path):
    f = tmp_path / "d.csv"
    f.write_text("j1,x1,y1,z1,x2,y2,z2,note\n0.1,1,2,3,4,5,6,a\n\n0.2,7,8,9,10,11,12,b\n")
    d = Measurements.from_csv(f, ["j1"], position_columns=("x1", "y1", "z1", "x2", "y2", "z2"))
    assert len(d) == 4 and d.n_points == 2
    assert d.points.tolist() == [0, 1, 0, 1] and d.poses.tolist() == [0, 0, 1, 1]
    assert d.rows.tolist() == [2, 2, 4, 4] and d.joint_values[:, 0].tolist() == [0.1, 0.1, 0.2, 0.2]
    assert d.positions[3].tolist() == [10, 11, 12]
    again = tmp_path / "again.csv"
    again.write_text(d.to_csv_text())
    e = Measurements.from_csv(again, ["j1"], position_columns=("x1", "y1", "z1", "x2", "y2", "z2"))
    assert np.array_equal(e.positions, d.positions) and np.array_equal(e.points, d.points)
    with pytest.raises(DataError, match="come in threes"):
        Measurements.from_csv(f, ["j1"], position_columns=("x1", "y1", "z1", "x2"))
    with pytest.raises(DataError, match="each of the 2 points once"):
        d.subset([0, 1, 2]).to_csv_text()


def test_folds_keep_the_points_of_a_pose_together():
    poses = np.repeat(np.arange(10), 4)
    folds = make_folds(len(poses), 5, 0, poses)
    assert sorted(np.concatenate(folds).tolist()) == list(range(40))
    for f in folds:
        assert len(f) == 8 and all(np.sum(poses[f] == p) in (0, 4) for p in range(10))
    one = make_folds(12, 3, 7)  # one point per pose: the folds of before
    assert all(np.array_equal(a, b) for a, b in zip(one, make_folds(12, 3, 7, np.arange(12))))


def test_planted_errors_and_three_points_are_recovered():
    rng = np.random.default_rng(5)
    robot = Robot.load("ur10", tip="tool0")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, 40)
    truth = Truth(planted_table(model, rng, 0.5e-3, np.radians(0.05)), BASE, TOOLS)
    data = measure(model, truth, q, 0.0, rng)
    assert len(data) == 120 and data.n_points == 3
    res = calibrate(robot, data, method="ls")
    assert res.after.max < 1e-6  # [mm] (unidentifiable planted errors go into the tool points)
    d = res.tools - res.tools[0]  # the points' layout on the tool is recovered exactly
    assert np.abs(np.linalg.norm(d, axis=1) - np.linalg.norm(TOOLS - TOOLS[0], axis=1)).max() < 1e-10
    q_val = random_joint_values(robot.geometry, rng, 50)
    for k in range(3):
        assert np.abs(res.predict(q_val, points=k) - true_positions(model, truth, q_val, k)).max() < 1e-9
    assert np.abs(res.predict_data(data) - data.positions).max() < 1e-9
    named = res.frames_dict()["sets"][0]["frames"]
    assert {"tool.x", "tool2.x", "tool3.z"} <= set(named) and "tool4.x" not in named
    assert named["tool.x"] == res.tools[0][0] and len(res.tools) == 3
    assert "3 measured points per pose" in res.summary() and "tool3.z" in res.summary()
    text = corrected_urdf(res, add_frames=True)[0]
    assert "kincal_tool_point_3" in text and 'name="kincal_tool_point"' in text


def test_a_second_point_off_the_last_axis_lifts_the_on_axis_warning():
    """One point on the flange axis leaves the tilt of that axis unseen (and warns); a
    second point off it sees it, as a single off-axis point would."""
    rng = np.random.default_rng(2)
    robot = Robot.load("ec66", tip="flange")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, 40)
    on_axis = Truth(model.table, BASE, np.array([0.0, 0.0, 0.1]))
    with pytest.warns(KincalWarning, match="from the axis of joint_6"):
        single = calibrate(robot, measure(model, on_axis, q, 1e-6, rng), method="ls")
    off_axis = Truth(model.table, BASE, np.array([0.05, 0.0, 0.1]))
    two = Truth(model.table, BASE, np.array([[0.0, 0.0, 0.1], [0.05, 0.0, 0.1]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error", KincalWarning)
        off = calibrate(robot, measure(model, off_axis, q, 1e-6, rng), method="ls")
        both = calibrate(robot, measure(model, two, q, 1e-6, rng), method="ls")
    kinematic = lambda r: [p.name for p in r.parameters[:24] if p.status == "identified"]  # noqa: E731
    assert kinematic(both) == kinematic(off)
    assert single.identifiability.notes  # the on-axis note is kept in the result


def test_cli_with_four_markers_on_the_tiago_files(tmp_path, capsys):
    """Training day, all four hand markers, backlash on arm_6; held-out day on marker 1."""
    urdf = tiago_urdf()
    train = urdf.parent / "qualisys_2021-11-30_static_postures.csv"
    held = urdf.parent / "qualisys_2021-11-26_static_postures.csv"
    markers = [f"{c}{k}" for k in range(1, 5) for c in "xyz"]
    common = ["--tip", "wrist_ft_tool_link", "--order-column", "t_start_robot"]
    out, frames = tmp_path / "cal.urdf", tmp_path / "frames.json"
    assert main(["calibrate", str(urdf), str(train), *common, "--position-columns", *markers,
                 "--backlash", "arm_6_joint", "--out", str(out), "--frames-out", str(frames),
                 "--report", str(tmp_path / "report.json"), "--quiet"]) == 0
    assert len(json.loads(frames.read_text())["tool_points"]) == 4
    assert "1 of 37 values outside its URDF limits" in capsys.readouterr().err  # poses, not samples
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["data"]["samples"] == 148 and report["data"]["points_per_pose"] == 4
    assert report["residuals"]["point"][:5] == [0, 1, 2, 3, 0]
    capsys.readouterr()
    assert main(["evaluate", str(out), str(held), *common, "--position-columns", "x1", "y1", "z1",
                 "--frames", str(frames)]) == 0
    rms = float(capsys.readouterr().out.split("RMS")[1].split()[0])
    assert rms < 3.22  # FIGAROH's best published held-out RMS on these files [mm]
    assert main(["evaluate", str(out), str(held), *common, "--position-columns", *markers[:6],
                 "--frames", str(frames)]) == 0
    assert "(n = 124)" in capsys.readouterr().out


def test_bad_multipoint_input_fails_cleanly_with_no_output(tmp_path, capsys):
    rng = np.random.default_rng(3)
    robot = Robot.load("ur10", tip="tool0")
    model = mdh.extract(robot.geometry)
    data = measure(model, Truth(model.table, BASE, TOOLS[:2]), random_joint_values(robot.geometry, rng, 20),
                   0.0, rng)
    csv = tmp_path / "two.csv"
    csv.write_text(data.to_csv_text())
    out = tmp_path / "cal.urdf"
    cols = ["--position-columns", "x1", "y1", "z1", "x2", "y2", "z2"]
    assert main(["calibrate", "ur10", str(csv), "--tip", "tool0", "--position-columns", "x1",
                 "y1", "z1", "x2", "--out", str(out)]) == 1
    assert "position columns come in threes" in capsys.readouterr().err and not out.exists()
    frames = tmp_path / "frames.json"
    frames.write_text(json.dumps({"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), BASE)),
                                  "tool": dict(zip("xyz", TOOLS[0]))}))
    assert main(["evaluate", "ur10", str(csv), "--tip", "tool0", *cols, "--frames", str(frames)]) == 1
    assert "has 2 measured points per pose" in capsys.readouterr().err
    frames.write_text(json.dumps({"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), BASE)),
                                  "tool": dict(zip("xyz", TOOLS[0])), "tool_points": []}))
    assert main(["evaluate", "ur10", str(csv), "--tip", "tool0", *cols, "--frames", str(frames)]) == 1
    assert "no tool point" in capsys.readouterr().err
    report = tmp_path / "r.json"
    assert main(["evaluate", "ur10", str(csv), "--tip", "tool0", *cols, "--fit-frames",
                 "--report", str(report)]) == 0 and report.exists()
