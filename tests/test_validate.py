"""calibrate --validate HELD.csv and --residuals-out: held-out errors through evaluate's path."""

import csv
import json

import numpy as np
import pytest

from kincal.cli.main import main


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("val")
    for name, seed, n in (("cal", 3, 40), ("held", 4, 25)):
        assert main(["simulate", "ec66", "--out", str(d / f"{name}.csv"), "--poses", str(n),
                     "--seed", str(seed), "--tool-m", "0.03", "0.02", "0.12"]) == 0
    return d


def test_held_out_errors_match_evaluate_and_residuals_csv(data, tmp_path, capsys):
    out = tmp_path / "c.urdf"
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data / "cal.csv"), "--tip", "flange", "--lambda",
                 "0.01", "--out", str(out), "--frames-out", str(tmp_path / "f.json"),
                 "--validate", str(data / "held.csv"), "--report", str(tmp_path / "r.json"),
                 "--html", str(tmp_path / "r.html"),
                 "--residuals-out", str(tmp_path / "res.csv")]) == 0
    text = capsys.readouterr().out
    assert "held-out" in text and "rms per axis [mm]: x " in text
    v = json.loads((tmp_path / "r.json").read_text())["validation"]
    assert v["samples"] == 25 and v["errors"]["after"]["mean_mm"] < v["errors"]["before"]["mean_mm"]
    assert set(v["rms_per_axis_mm"]["after"]) == {"x", "y", "z"}
    # the same numbers as kincal evaluate with the calibration's frames
    assert main(["evaluate", str(out), str(data / "held.csv"), "--frames", str(tmp_path / "f.json"),
                 "--report", str(tmp_path / "e.json")]) == 0
    ev = json.loads((tmp_path / "e.json").read_text())["errors"]
    assert ev["mean_mm"] == pytest.approx(v["errors"]["after"]["mean_mm"], rel=1e-9)
    # the norm of the per-axis rms is the rms of the norm
    axis = np.array(list(v["rms_per_axis_mm"]["after"].values()))
    assert np.linalg.norm(axis) == pytest.approx(v["errors"]["after"]["rms_mm"], rel=1e-9)
    html = (tmp_path / "r.html").read_text()
    assert 'id="validation"' in html and "x (rms)" in html
    rows = [r for r in csv.reader(line for line in (tmp_path / "res.csv").open()
                                  if not line.startswith("#"))]
    assert rows[0][:7] == ["split", "set", "source", "kind", "row", "error_m",
                           "orientation_error_rad"]
    splits = [r[0] for r in rows[1:]]
    assert splits.count("training") == 40 and splits.count("held-out") == 25
    for r in rows[1:]:  # each error is its residual vector's norm; points have no angle
        assert float(r[5]) == pytest.approx(np.linalg.norm([float(x) for x in r[7:10]]), rel=1e-12)
        assert r[6] == ""
    prov = json.loads((tmp_path / "r.json").read_text())["provenance"]
    assert [d["path"] for d in prov["data"]] == [str(data / "cal.csv"), str(data / "held.csv")]


def test_validate_of_another_kind_is_one_line(data, tmp_path, capsys):
    held = tmp_path / "dist.csv"
    rows = list(csv.DictReader(line for line in (data / "held.csv").open()
                               if not line.startswith("#")))
    joints = [k for k in rows[0] if k.startswith("joint_")]
    with held.open("w", newline="") as f:  # joint columns only: not a point file
        w = csv.DictWriter(f, fieldnames=joints)
        w.writeheader()
        w.writerows({k: r[k] for k in joints} for r in rows)
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data / "cal.csv"), "--lambda", "0.01", "--out",
                 str(tmp_path / "c.urdf"), "--validate", str(held)]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(err) == 1 and err[0].startswith("kincal: error:")
    assert not (tmp_path / "c.urdf").exists()


def test_held_out_poses_give_orientation_statistics(tmp_path, capsys):
    """A pose file held out: the orientation error's mean and rms before and after, in the
    summary and REPORT.json (orientation_errors; orientation_mean_deg kept beside it),
    equal to kincal evaluate's with the calibration's frames."""
    for name, seed, n in (("cal", 3, 40), ("held", 4, 25)):
        assert main(["simulate", "ec66", "--kind", "pose", "--out", str(tmp_path / f"{name}.csv"),
                     "--poses", str(n), "--seed", str(seed)]) == 0
    out = tmp_path / "c.urdf"
    assert main(["calibrate", "ec66", str(tmp_path / "cal.csv"), "--out", str(out),
                 "--frames-out", str(tmp_path / "f.json"), "--validate",
                 str(tmp_path / "held.csv"), "--report", str(tmp_path / "r.json")]) == 0
    assert "orientation [deg]: mean " in capsys.readouterr().out
    v = json.loads((tmp_path / "r.json").read_text())["validation"]
    o = v["orientation_errors"]
    assert o["after"]["rms_deg"] < o["before"]["rms_deg"]
    assert v["orientation_mean_deg"] == {"before": o["before"]["mean_deg"],
                                         "after": o["after"]["mean_deg"]}
    assert main(["evaluate", str(out), str(tmp_path / "held.csv"), "--frames",
                 str(tmp_path / "f.json"), "--report", str(tmp_path / "e.json")]) == 0
    e = json.loads((tmp_path / "e.json").read_text())["orientation_errors"]
    assert e["rms_deg"] == pytest.approx(o["after"]["rms_deg"], rel=1e-9)


def test_held_out_before_is_the_nominal_model_with_compliance_terms_too(data, tmp_path):
    """'before' is the nominal kinematics with the frames the calibration started from; with
    --compliance it carried the fitted compliance (the backlash was dropped, the compliance
    kept): TALOS's held-out heights 'before' read 8.07 mm with the stance leg's terms and
    9.88 mm without. The same before with or without the terms."""
    before = []
    for k, terms in enumerate(([], ["--compliance", "joint_2", "joint_3"])):
        report = tmp_path / f"r{k}.json"
        assert main(["calibrate", "ec66", str(data / "cal.csv"), "--tip", "flange", "--lambda",
                     "0.01", "--out", str(tmp_path / f"c{k}.urdf"), *terms, "--validate",
                     str(data / "held.csv"), "--report", str(report), "-q"]) == 0
        report = json.loads(report.read_text())
        assert report["options"]["compliance"] == terms[1:]
        before.append(report["validation"]["errors"]["before"])
    assert before[1] == pytest.approx(before[0], rel=1e-12)


def test_held_out_points_on_a_pose_calibration_match_evaluate(tmp_path, capsys):
    """Points held out from a pose calibration are judged with the pose set's measurement
    frame and tool origin (as kincal evaluate --frames takes them; they were refused)."""
    for kind, seed, n in (("pose", 1, 40), ("point", 2, 20)):
        assert main(["simulate", "ec66", "--kind", kind, "--out", str(tmp_path / f"{kind}.csv"),
                     "--poses", str(n), "--seed", str(seed), "--truth-seed", "3", "-q"]) == 0
    out, frames = tmp_path / "c.urdf", tmp_path / "f.json"
    assert main(["calibrate", "ec66", str(tmp_path / "pose.csv"), "--lambda", "0.01", "--out",
                 str(out), "--frames-out", str(frames), "--validate",
                 str(tmp_path / "point.csv"), "--report", str(tmp_path / "r.json")]) == 0
    v = json.loads((tmp_path / "r.json").read_text())["validation"]
    assert v["samples"] == 20 and v["errors"]["after"]["mean_mm"] < 0.2
    assert main(["evaluate", str(out), str(tmp_path / "point.csv"), "--frames", str(frames),
                 "--report", str(tmp_path / "e.json")]) == 0
    ev = json.loads((tmp_path / "e.json").read_text())["errors"]
    assert ev["mean_mm"] == pytest.approx(v["errors"]["after"]["mean_mm"], rel=1e-9)


def test_held_out_poses_orientation_in_every_output(tmp_path, capsys):
    """A pose calibration's orientation errors wherever its position errors are: the
    held-out line and the HTML table give the max too; the residual CSV each sample's
    rotation vector in radians (not through the sigma ratio) and its angle, equal to a
    computation from the written URDF and FRAMES.json with scipy; REPORT.json each
    sample's angle; the residual figure a panel of them (it was labelled "position and
    orientation error (mm)" over the positions alone)."""
    from PIL import Image
    from scipy.spatial.transform import Rotation

    from kincal import Robot

    for name, seed, n in (("cal", 3, 40), ("held", 4, 25)):
        assert main(["simulate", "ec66", "--kind", "pose", "--out", str(tmp_path / f"{name}.csv"),
                     "--poses", str(n), "--seed", str(seed), "--orientation-format", "rpy-zyx",
                     "--orientation-noise-deg", "0.02", "-q"]) == 0
    out = tmp_path / "c.urdf"
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(tmp_path / "cal.csv"), "--orientation-format",
                 "rpy-zyx", "--model", "complete", "--out", str(out), "--frames-out",
                 str(tmp_path / "f.json"), "--validate", str(tmp_path / "held.csv"),
                 "--report", str(tmp_path / "r.json"), "--html", str(tmp_path / "r.html"),
                 "--residuals-out", str(tmp_path / "res.csv"), "--plots",
                 str(tmp_path / "plots")]) == 0
    text = capsys.readouterr().out
    report = json.loads((tmp_path / "r.json").read_text())
    o = report["validation"]["orientation_errors"]
    line = [t for t in text.splitlines() if "orientation [deg]: mean" in t][0]
    assert (f"max {o['before']['max_deg']:.4f} -> {o['after']['max_deg']:.4f}") in line
    assert "orientation: max [deg]" in (tmp_path / "r.html").read_text()
    rows = [r for r in csv.reader(line for line in (tmp_path / "res.csv").open()
                                  if not line.startswith("#"))]
    head, rows = rows[0], rows[1:]
    held = [r for r in rows if r[0] == "held-out"]
    assert len(held) == 25 and head[6] == "orientation_error_rad" and head[7:] == [
        f"r{k}" for k in range(1, 7)]
    # independently: the written robot and frames, scipy's rotations
    frames = json.loads((tmp_path / "f.json").read_text())["sets"][0]["frames"]
    robot = Robot.load(out, tip="flange")
    data = [r for r in csv.DictReader(line for line in (tmp_path / "held.csv").open()
                                      if not line.startswith("#"))]
    q = np.array([[float(r[j]) for j in robot.joint_names] for r in data])
    R_meas = Rotation.from_euler("xyz", [[float(r[k]) for k in ("roll", "pitch", "yaw")]
                                         for r in data]).as_matrix()
    T = robot.tip_poses(q)
    R_base = Rotation.from_euler("XYZ", [frames[f"base.r{a}"] for a in "xyz"]).as_matrix()
    R_tool = Rotation.from_euler("XYZ", [frames[f"tool.r{a}"] for a in "xyz"]).as_matrix()
    R_pred = R_base @ T[:, :3, :3] @ R_tool
    rotvec = Rotation.from_matrix(R_meas @ np.transpose(R_pred, (0, 2, 1))).as_rotvec()
    written = np.array([[float(v) for v in r[10:13]] for r in held])
    np.testing.assert_allclose(written, rotvec, atol=1e-12)
    np.testing.assert_allclose([float(r[6]) for r in held], np.linalg.norm(rotvec, axis=1),
                               atol=1e-12)
    training = [float(r[6]) for r in rows if r[0] == "training"]
    np.testing.assert_allclose(np.radians(report["sets"][0]["residuals"]["orientation_error_deg"]),
                               training, rtol=1e-12)
    np.testing.assert_allclose(np.radians(report["residuals"]["orientation_error_deg"]),
                               training, rtol=1e-12)
    # the residual figure: positions and, beside them, orientations (two panels)
    assert Image.open(tmp_path / "plots" / "residuals.png").size[0] > 1000


def test_residuals_csv_is_made_in_pieces_as_written(data):
    """--residuals-out's text comes to the writer a block of rows at a time (as compensate's
    CSV does), never as one string with a Python string per row of the whole file (at
    300,000 poses that was 128 MB over the command's peak): the pieces hold at most
    ``rows_per_piece`` rows each, after one piece of header lines, and join to the same
    text whatever their size."""
    import math

    from kincal.export.validation import residuals_csv
    from kincal.identification.problem import calibrate
    from kincal.measurements.sets import read_set_file
    from kincal.robot import Robot

    robot = Robot.load("ec66")
    result = calibrate(robot, read_set_file(data / "cal.csv", robot.joint_names),
                       method="ls")
    pieces = list(residuals_csv(result, (), "# a header line", rows_per_piece=7))
    assert all(isinstance(p, str) for p in pieces)
    assert len(pieces) == 1 + math.ceil(40 / 7)
    assert pieces[0].startswith("# residual vectors") and "# a header line\nsplit," in pieces[0]
    assert [p.count("\n") for p in pieces[1:]] == [7] * 5 + [5]
    assert "".join(pieces) == "".join(residuals_csv(result, (), "# a header line"))
