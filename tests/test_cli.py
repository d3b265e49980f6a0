"""The command line: every subcommand through main([...]), good and bad input."""

import json

import numpy as np
import pytest
from conftest import EC66

from kincal.cli.main import main
from kincal.robot import Robot


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "ec66", "--out", str(d / "cal.csv"), "--design", "tracker",
                 "--poses", "40", "--seed", "3", "--tool-m", "0.03", "0.02", "0.12",
                 "--truth-out", str(d / "truth.json")]) == 0
    assert main(["simulate", "ec66", "--out", str(d / "val.csv"), "--design", "tracker",
                 "--poses", "60", "--seed", "4", "--noise-mm", "0.01"]) == 0
    return d


def _one_line_error(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("kincal: error:")]
    assert len(errors) == 1, err
    assert not any("Traceback" in line for line in err)
    return errors[0]


def test_simulate_writes_csv_and_truth(sim):
    lines = (sim / "cal.csv").read_text().splitlines()
    assert lines[0].startswith("# made by kincal ")  # the provenance first, as # lines
    header = next(line for line in lines if not line.startswith("#")).split(",")
    assert header == [f"joint_{i}" for i in range(1, 7)] + ["x", "y", "z"]
    truth = json.loads((sim / "truth.json").read_text())
    assert len(truth["deviations_si"]) == 36 and truth["seed"] == 3  # 6 placement errors per joint


def test_calibrate_writes_urdf_frames_and_report(sim, tmp_path, capsys):
    out = tmp_path / "cal.urdf"
    code = main(["calibrate", "ec66", str(sim / "cal.csv"), "--tip", "flange", "--out", str(out),
                 "--frames-out", str(tmp_path / "frames.json"), "--report",
                 str(tmp_path / "report.json"), "--lambda", "cv"])
    assert code == 0
    text = capsys.readouterr().out
    assert "lambda" in text and "after:" in text and "joint_4.a" in text
    frames = json.loads((tmp_path / "frames.json").read_text())
    assert abs(frames["tool"]["z"] - 0.12) < 1e-3 and set(frames["base"]) == {"x", "y", "z", "rx", "ry", "rz"}
    report = json.loads((tmp_path / "report.json").read_text())
    assert len(report["parameters"]) == 35 and len(report["cross_validation"]["lambdas"]) == 50
    assert report["errors"]["after"]["mean_mm"] < report["errors"]["before"]["mean_mm"]
    # the corrected URDF differs from the input only on origin lines (and kincal's
    # provenance comment after the XML declaration), and loads
    new_text = out.read_text()
    head = new_text.index("<!-- made by kincal")
    new_text = new_text[:head] + new_text[new_text.index("-->", head) + 4:]
    old, new = EC66.read_text().splitlines(), new_text.splitlines()
    assert len(old) == len(new)
    assert all("<origin" in a for a, b in zip(old, new) if a != b)
    corrected = Robot.load(out, tip="flange")
    assert corrected.joint_names == Robot.load("ec66").joint_names


def test_calibrated_model_evaluates_better_on_held_out_data(sim, tmp_path, capsys):
    out = tmp_path / "cal.urdf"
    assert main(["calibrate", "ec66", str(sim / "cal.csv"), "--out", str(out), "--method", "ls",
                 "--frames-out", str(tmp_path / "f.json"), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out), str(sim / "val.csv"), "--tip", "flange", "--fit-frames",
                 "--report", str(tmp_path / "after.json")]) == 0
    assert main(["evaluate", "ec66", str(sim / "val.csv"), "--fit-frames",
                 "--report", str(tmp_path / "before.json")]) == 0
    after = json.loads((tmp_path / "after.json").read_text())["errors"]["mean_mm"]
    before = json.loads((tmp_path / "before.json").read_text())["errors"]["mean_mm"]
    assert after < 0.5 * before
    # frames from calibration, on the calibration data itself
    assert main(["evaluate", str(out), str(sim / "cal.csv"), "--tip", "flange",
                 "--frames", str(tmp_path / "f.json")]) == 0
    assert "mean" in capsys.readouterr().out


def test_analyze_reports_the_paper_selection(sim, capsys):
    assert main(["analyze", "ec66", str(sim / "cal.csv"), "--model", "mdh"]) == 0
    out = capsys.readouterr().out
    assert "25 of 33" in out and "dropped joint_2.d ~ +1 joint_4.d" in out


def test_same_inputs_give_byte_identical_outputs(sim, tmp_path, monkeypatch):
    # the same command in two folders; the provenance's time is SOURCE_DATE_EPOCH's
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    for k in (1, 2):
        (tmp_path / str(k)).mkdir()
        monkeypatch.chdir(tmp_path / str(k))
        assert main(["calibrate", "ec66", str(sim / "cal.csv"), "--out", "c.urdf",
                     "--report", "r.json", "--quiet"]) == 0
    for name in ("c.urdf", "r.json"):
        assert (tmp_path / "1" / name).read_bytes() == (tmp_path / "2" / name).read_bytes()
    assert "2023-11-14T22:13:20Z" in (tmp_path / "1" / "c.urdf").read_text()


@pytest.mark.parametrize("case", ["missing_data", "wrong_columns", "unknown_tip", "unknown_robot",
                                  "bad_lambda", "too_many_folds", "unknown_fix"])
def test_bad_input_fails_cleanly_with_no_output(case, sim, tmp_path, capsys):
    data = sim / "cal.csv"
    if case == "wrong_columns":
        data = tmp_path / "bad.csv"
        data.write_text((sim / "cal.csv").read_text().replace("joint_3", "joint_three", 1))
    args = {"missing_data": ["ec66", str(tmp_path / "nope.csv")],
            "wrong_columns": ["ec66", str(data)],
            "unknown_tip": ["ec66", str(data), "--tip", "flang"],
            "unknown_robot": ["ec77", str(data)],
            "bad_lambda": ["ec66", str(data), "--lambda", "much"],
            "too_many_folds": ["ec66", str(data), "--lambda", "cv", "--folds", "1000"],
            "unknown_fix": ["ec66", str(data), "--fix", "joint_9.a"]}[case]
    out = tmp_path / "out.urdf"
    assert main(["calibrate", *args, "--out", str(out), "--report", str(tmp_path / "r.json")]) == 1
    line = _one_line_error(capsys)
    expected = {"missing_data": "not found", "wrong_columns": "joint_3", "unknown_tip": "flange",
                "unknown_robot": "ec66", "bad_lambda": "lambda", "too_many_folds": "folds",
                "unknown_fix": "joint_9.a"}[case]
    assert expected in line
    assert not out.exists() and not (tmp_path / "r.json").exists()


def test_existing_output_and_input_urdf_are_protected(sim, tmp_path, capsys):
    src = tmp_path / "robot.urdf"
    src.write_text(EC66.read_text())
    before = src.read_bytes()
    assert main(["calibrate", str(src), str(sim / "cal.csv"), "--tip", "flange",
                 "--out", str(src)]) == 1
    assert "input file" in _one_line_error(capsys)
    assert src.read_bytes() == before
    existing = tmp_path / "existing.urdf"
    existing.write_text("keep me")
    assert main(["calibrate", str(src), str(sim / "cal.csv"), "--tip", "flange",
                 "--out", str(tmp_path / "new.urdf"), "--report", str(existing)]) == 1
    assert "already exists" in _one_line_error(capsys)
    assert existing.read_text() == "keep me" and not (tmp_path / "new.urdf").exists()
    assert main(["calibrate", str(src), str(sim / "cal.csv"), "--tip", "flange", "--quiet",
                 "--out", str(src), "--overwrite"]) == 0
    assert src.read_bytes() != before  # asked for: the input is replaced


def test_overwrite_never_replaces_what_a_command_read(sim, tmp_path, capsys):
    """--overwrite replaced an input by another kind of file: the measurements by a
    report (evaluate --report DATA.csv), the targets by joint values, FRAMES.json by a
    URDF's report, the robot's URDF by a report. Only the corrected URDF may replace its
    robot description (above); every other input is refused, with or without --overwrite."""
    import shutil

    data = tmp_path / "data.csv"
    shutil.copy(sim / "cal.csv", data)
    src = tmp_path / "robot.urdf"
    src.write_text(EC66.read_text())
    frames = tmp_path / "frames.json"
    assert main(["calibrate", str(src), str(data), "--tip", "flange", "--quiet", "--out",
                 str(tmp_path / "cal.urdf"), "--frames-out", str(frames)]) == 0
    kept = {p: p.read_bytes() for p in (data, src, frames)}
    for argv in (["evaluate", str(src), str(data), "--tip", "flange", "--fit-frames",
                  "--report", str(data)],
                 ["compensate", str(tmp_path / "cal.urdf"), str(data), "--tip", "flange",
                  "--frames", str(frames), "--out", str(data), "--flag-unreachable"],
                 ["compensate", str(tmp_path / "cal.urdf"), str(data), "--tip", "flange",
                  "--frames", str(frames), "--out", str(frames), "--flag-unreachable"],
                 ["calibrate", str(src), str(data), "--tip", "flange", "--out",
                  str(tmp_path / "x.urdf"), "--report", str(src)],
                 ["calibrate", str(src), str(data), "--tip", "flange", "--out", str(data)],
                 ["simulate", "ec66", "--poses-file", str(data), "--out", str(data)]):
        capsys.readouterr()
        assert main([*argv, "--overwrite"]) == 1, argv
        assert "with or without --overwrite" in _one_line_error(capsys)
    assert {p: p.read_bytes() for p in kept} == kept
    assert not (tmp_path / "x.urdf").exists()


def test_evaluate_needs_a_frames_choice(sim, capsys):
    assert main(["evaluate", "ec66", str(sim / "val.csv")]) == 1
    assert "--fit-frames" in _one_line_error(capsys)


def test_evaluate_rejects_a_bad_frames_file(sim, tmp_path, capsys):
    bad = tmp_path / "frames.json"
    bad.write_text('{"base": {"x": 1}}')
    assert main(["evaluate", "ec66", str(sim / "val.csv"), "--frames", str(bad)]) == 1
    assert "frames" in _one_line_error(capsys)


def test_usage_errors_exit_2():
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", "ec66"])
    assert exc.value.code == 2


def test_frames_can_be_added_to_the_urdf_on_request(sim, tmp_path):
    out = tmp_path / "with_frames.urdf"
    assert main(["calibrate", "ec66", str(sim / "cal.csv"), "--out", str(out), "--method", "ls",
                 "--add-frames", "--frames-out", str(tmp_path / "f.json"), "--quiet"]) == 0
    frames = json.loads((tmp_path / "f.json").read_text())
    robot = Robot.load(out, tip="kincal_tool_point")
    M = Robot.load(out, base="kincal_measurement_frame", tip="kincal_tool_point")
    q = np.zeros((1, 6)) + 0.3
    # the tool point seen from the measurement frame is the model's prediction
    T = M.tip_poses(q)[0]
    from kincal.rotations import base_rotation

    tool_in_base = robot.tip_poses(q)[0][:3, 3]
    b = frames["base"]
    expected = base_rotation(b["rx"], b["ry"], b["rz"]) @ tool_in_base + [b["x"], b["y"], b["z"]]
    assert np.abs(T[:3, 3] - expected).max() < 1e-12
    plain = tmp_path / "plain.urdf"
    assert main(["calibrate", "ec66", str(sim / "cal.csv"), "--out", str(plain), "--method", "ls",
                 "--quiet"]) == 0
    assert "kincal_tool_point" not in plain.read_text()


def test_demo_writes_tables_and_plots_whose_numbers_hold(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    printed, err = capsys.readouterr()
    assert err.strip().splitlines()[-1].startswith("kincal: done in ")  # as the README says
    results = json.loads((out / "results.json").read_text())["summary"]
    assert results["l2_rtest_validation_mean_mm"] < results["ls_rtest_validation_mean_mm"]
    assert results["ls_tracker_validation_mean_mm"] < results["l2_rtest_validation_mean_mm"]
    assert f"{results['l2_rtest_validation_mean_mm']:8.3f}" in printed
    for name in ("cv_curve.png", "point_sets.png", "validation_errors.png",
                 "parameter_deviations.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Table 2" in (out / "tables.md").read_text()
    # every file says which kincal and command made it (the robot: the bundled EC66)
    prov = json.loads((out / "results.json").read_text())["provenance"]
    assert prov["command"] == f"kincal demo --out {out}" and prov["gate"]["verdict"] == "no gate"
    assert prov["robot"]["path"].endswith("ec66.urdf") and prov["robot"]["sha256"]
    assert (out / "tables.md").read_text().startswith("<!-- made by kincal ")
    from PIL import Image

    for name in ("cv_curve.png", "point_sets.png"):  # the same object in every PNG
        text = Image.open(out / name).text
        assert "command: kincal demo --out" in text["Comment"]
        assert json.loads(text["kincal-provenance"]) == prov and text["Source"] == prov["command"]


@pytest.mark.parametrize("robot", ["ec66", "panda", "ur3", "ur5", "ur10"])
def test_simulate_works_out_of_the_box_for_every_robot_with_a_default_cube(robot, tmp_path):
    """The default cube of each known arm is reachable (the UR3's is smaller)."""
    for seed in (0, 1):
        out = tmp_path / f"{robot}-{seed}.csv"
        assert main(["simulate", robot, "--poses", "30", "--seed", str(seed), "--out", str(out)]) == 0
        assert len([r for r in out.read_text().splitlines() if not r.startswith("#")]) == 31
    report = tmp_path / "r.json"  # the default method: plain LS crawls on weak directions
    # of some draws (the UR3's small cube drawn on OpenBLAS's Sandybridge kernels)
    assert main(["calibrate", robot, str(out), "--out", str(tmp_path / "c.urdf"),
                 "--report", str(report), "--quiet"]) == 0
    result = json.loads(report.read_text())
    assert result["convergence"]["converged"]
    assert result["errors"]["after"]["rms_mm"] < result["errors"]["before"]["rms_mm"]
