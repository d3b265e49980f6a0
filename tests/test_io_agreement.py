"""Inputs and options that two commands (or two paths of one) read: read the same way.

Each test was written against a pair of copies of one concept that had drifted apart: one
subcommand accepting or checking what another refused or checked, through the CLI."""

import os
import subprocess
import sys

import pytest

from kincal.cli.main import main


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """ec66 points (m), the same points in millimetres, poses, flush contacts, FRAMES.json."""
    d = tmp_path_factory.mktemp("cell")
    assert main(["simulate", "ec66", "--out", str(d / "points.csv"), "--poses", "30",
                 "--tool-m", "0.03", "0.02", "0.12", "-q"]) == 0
    assert main(["simulate", "ec66", "--out", str(d / "poses.csv"), "--poses", "30",
                 "--kind", "pose", "-q"]) == 0
    assert main(["simulate", "ec66", "--out", str(d / "flush.csv"), "--poses", "30",
                 "--kind", "flush", "-q"]) == 0
    assert main(["calibrate", "ec66", str(d / "points.csv"), "--method", "ls", "-q",
                 "--out", str(d / "cal.urdf"), "--frames-out", str(d / "frames.json")]) == 0
    lines = [line for line in (d / "points.csv").read_text().splitlines()
             if not line.startswith("#")]
    header = lines[0].split(",")
    out = [lines[0]]
    for line in lines[1:]:
        cells = [float(v) for v in line.split(",")]
        out.append(",".join(repr(v * 1e3 if name in ("x", "y", "z") else v)
                            for name, v in zip(header, cells)))
    (d / "points_mm.csv").write_text("\n".join(out) + "\n")
    return d


def _errors(err: str) -> list[str]:
    assert "Traceback" not in err, err
    return [line for line in err.splitlines() if line.startswith("kincal: error:")]


@pytest.mark.parametrize("frames", [["--fit-frames"], ["--frames", "frames.json"]])
def test_evaluate_says_millimetres_read_as_metres_with_or_without_frames(cell, frames, capsys,
                                                                          monkeypatch):
    """calibrate and evaluate --fit-frames warned about positions in mm read as m;
    evaluate --frames (and so calibrate --validate) read the same file silently."""
    monkeypatch.chdir(cell)
    capsys.readouterr()
    assert main(["evaluate", "ec66", "points_mm.csv", *frames]) == 0
    err = capsys.readouterr().err
    assert "points_mm.csv: measured positions spread" in err, err
    assert "were they millimetres? Read them with --length-unit mm" in err
    # read in the right unit: no such warning
    assert main(["evaluate", "ec66", "points_mm.csv", "--length-unit", "mm", *frames]) == 0
    assert "were they millimetres" not in capsys.readouterr().err


def test_a_held_out_file_in_millimetres_is_warned_about(cell, tmp_path, capsys):
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(cell / "points.csv"), "--lambda", "0.01", "-q",
                 "--out", str(tmp_path / "c.urdf"),
                 "--validate", str(cell / "points_mm.csv")]) == 0
    err = capsys.readouterr().err
    assert "points_mm.csv: measured positions spread" in err, err


def _deep(path):
    path.write_text("[" * 100_000 + "]" * 100_000)
    return path


def test_a_fleet_prior_is_read_as_a_frames_file_is(cell, tmp_path, capsys):
    """FRAMES.json nested too deeply was one line; FLEET.json was a RecursionError."""
    deep = _deep(tmp_path / "deep.json")
    capsys.readouterr()
    assert main(["evaluate", "ec66", str(cell / "points.csv"), "--frames", str(deep)]) == 1
    (frames_line,) = _errors(capsys.readouterr().err)
    assert "JSON nested too deeply" in frames_line
    out = tmp_path / "c.urdf"
    assert main(["calibrate", "ec66", str(cell / "points.csv"), "--prior", str(deep),
                 "--lambda", "evidence", "-q", "--out", str(out)]) == 1
    (prior_line,) = _errors(capsys.readouterr().err)
    assert str(deep) in prior_line and "JSON nested too deeply" in prior_line
    assert not out.exists()


@pytest.mark.parametrize("content, said", [
    ("", "is empty"), ("{", "invalid JSON"), (b"\xff\xfe{}", "not a kincal fleet prior"),
    # a file given in another's place is named as what it is, as a CSV reader names a JSON
    # or URDF file (it said "invalid JSON: Expecting value: line 1 column 1 (char 0)")
    ('<?xml version="1.0"?>\n<robot name="r"/>\n', "is XML (a URDF or xacro file?), not a "
                                                  "kincal fleet prior"),
    ("# made by kincal\njoint_1,x,y,z\n0,1,2,3\n", "is a CSV file (a data file?), not a "
                                                  "kincal fleet prior")])
def test_a_broken_fleet_prior_is_one_line(cell, tmp_path, capsys, content, said):
    prior = tmp_path / "FLEET.json"
    (prior.write_bytes if isinstance(content, bytes) else prior.write_text)(content)
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(cell / "points.csv"), "--prior", str(prior),
                 "--lambda", "evidence", "-q", "--out", str(tmp_path / "c.urdf")]) == 1
    (line,) = _errors(capsys.readouterr().err)
    assert said in line, line


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fleet_prior_on_a_fifo_is_refused_as_a_frames_file_is(cell, tmp_path):
    """evaluate --frames FIFO was refused at once; calibrate --prior FIFO waited forever."""
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    for extra in (["evaluate", "ec66", str(cell / "points.csv"), "--frames", str(fifo)],
                  ["calibrate", "ec66", str(cell / "points.csv"), "--prior", str(fifo),
                   "--lambda", "evidence", "--out", str(tmp_path / "c.urdf")]):
        run = subprocess.run([sys.executable, "-m", "kincal", *extra], capture_output=True,
                             text=True, timeout=120, stdin=subprocess.DEVNULL)
        assert run.returncode == 1, run.stderr
        (line,) = _errors(run.stderr)
        assert "is a FIFO" in line, line


@pytest.mark.parametrize("value", ["100", "1e-9"])
def test_orientation_sigma_is_refused_alike_for_poses_and_flush_contacts(cell, value, capsys):
    """--orientation-sigma-deg is the noise of pose files or of flush tilts: 100 deg was
    refused for poses and accepted for flush contacts."""
    capsys.readouterr()
    lines = []
    for argv in (["analyze", "ec66", str(cell / "poses.csv")],
                 ["analyze", "ec66", str(cell / "flush.csv"), "--on-plane", "--flush"]):
        assert main([*argv, "--orientation-sigma-deg", value, "-q"]) == 1
        (line,) = _errors(capsys.readouterr().err)
        lines.append(line)
    assert lines[0] == lines[1]
    assert "orientation sigma must be between 1e-06 and 90 deg" in lines[0]


def test_analyze_refuses_its_accuracy_plot_before_the_work(cell, tmp_path, capsys):
    """Every output was checked before the work (nothing said, nothing computed) except
    analyze's --accuracy-plot, refused only after the analysis was printed."""
    taken = tmp_path / "map.png"
    taken.write_bytes(b"mine")
    capsys.readouterr()
    assert main(["analyze", "ec66", str(cell / "points.csv"), "--accuracy-map", "0.4", "0", "0.3",
                 "0.2", "--grid", "2", "--accuracy-plot", str(taken)]) == 1
    captured = capsys.readouterr()
    (line,) = _errors(captured.err)
    assert "already exists" in line and captured.out == ""
    assert taken.read_bytes() == b"mine"


def test_a_frames_file_with_a_byte_order_mark_is_read_as_a_csv_file_is(cell, tmp_path, capsys):
    """A data CSV saved with a UTF-8 byte-order mark (Windows editors) was read; the same
    editor's FRAMES.json was refused as invalid JSON."""
    bom = tmp_path / "frames_bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + (cell / "frames.json").read_bytes())
    capsys.readouterr()
    assert main(["evaluate", "ec66", str(cell / "points.csv"), "--frames", str(bom)]) == 0
    with_bom = capsys.readouterr().out
    assert main(["evaluate", "ec66", str(cell / "points.csv"), "--frames",
                 str(cell / "frames.json")]) == 0
    # the same output but for the file's name (a note names the FRAMES.json it read)
    same = with_bom.replace(str(bom), str(cell / "frames.json"))
    assert capsys.readouterr().out.split(":", 1)[1] == same.split(":", 1)[1]


def test_fleet_workers_load_the_robot_the_command_loaded(cell, tmp_path, monkeypatch, capsys):
    """The robot argument is resolved once, by kincal.descriptions: a name first, then a
    path. kincal fleet made it absolute for its workers whenever a file of that name
    existed, so a file 'ec66' in the working folder sent the workers to it while the
    command itself loaded the bundled EC66."""
    import kincal.fleet
    from kincal.errors import KincalError

    monkeypatch.chdir(tmp_path)
    (tmp_path / "ec66").write_text("not a URDF")
    seen = []

    def first_unit_only(robot, jobs, *args, **kwargs):
        seen.append((robot.source, jobs[0].load().source))
        raise KincalError("stopped by the test")

    monkeypatch.setattr(kincal.fleet, "calibrate_fleet", first_unit_only)
    capsys.readouterr()
    assert main(["fleet", "ec66", str(cell / "points.csv"), "--out-dir", "fleet"]) == 1
    (line,) = _errors(capsys.readouterr().err)
    assert "stopped by the test" in line, line
    assert seen and seen[0][0] == seen[0][1]


@pytest.mark.parametrize("value", ["1e-300", "1e9"])
def test_noise_mm_takes_one_range_in_calibrate_analyze_and_plan(cell, tmp_path, value, capsys):
    """--noise-mm is the measurement noise per axis in calibrate (evidence), analyze and
    plan (the predicted errors): calibrate refused 1e-300 mm and 1e9 mm, analyze and plan
    took them."""
    capsys.readouterr()
    lines = []
    for argv in (["calibrate", "ec66", str(cell / "points.csv"), "--lambda", "evidence",
                  "--out", str(tmp_path / "c.urdf")],
                 ["analyze", "ec66", str(cell / "points.csv")],
                 ["plan", "ec66", "--random", "50", "--poses", "5",
                  "--out", str(tmp_path / "chosen.csv")]):
        assert main([*argv, "--noise-mm", value, "-q"]) == 1
        (line,) = _errors(capsys.readouterr().err)
        lines.append(line)
    assert all("--noise-mm" in line and "1e-06" in line and "10000" in line for line in lines), lines
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("name, extra", [
    ("residuals_set2.png", ["poses.csv"]),  # a second data file: its residual figure
    ("accuracy_map.png", ["--accuracy-map", "0.4", "0", "0.3", "0.2", "--grid", "2"])])
def test_every_plot_calibrate_may_write_is_checked_before_the_work(cell, tmp_path, monkeypatch,
                                                                  capsys, name, extra):
    """calibrate --plots checked cv_curve, residuals and parameters before the work; the
    residual figure of a second file and the accuracy map were refused only at the end."""
    from kincal.identification.problem import CalibrationProblem

    monkeypatch.chdir(cell)
    plots = tmp_path / "plots"
    plots.mkdir()
    (plots / name).write_bytes(b"mine")

    def no_work(self):
        raise AssertionError("the calibration ran before the outputs were checked")

    monkeypatch.setattr(CalibrationProblem, "solve", no_work)
    capsys.readouterr()
    assert main(["calibrate", "ec66", "points.csv", *extra, "--method", "ls",
                 "--out", str(tmp_path / "c.urdf"), "--plots", str(plots)]) == 1
    (line,) = _errors(capsys.readouterr().err)
    assert f"{name}: already exists" in line, line
    assert (plots / name).read_bytes() == b"mine"


@pytest.mark.parametrize("extra, named", [
    (["--accuracy-map", "nan", "0", "0.3", "0.2"], "--accuracy-map CX CY CZ must be a finite number"),
    (["--accuracy-map", "0.4", "0", "0.3", "-1"], "--accuracy-map EDGE must be a finite number > 0"),
    (["--accuracy-map", "0.4", "0", "0.3", "0.2", "--grid", "0"], "--grid must be an integer")])
def test_accuracy_cube_options_are_named_in_their_refusal(cell, tmp_path, capsys, extra, named):
    """The cube's own checks refused these after the data were read, naming no option
    ("the cube centre must be 3 finite numbers, got array([nan, 0. , 0.3])")."""
    capsys.readouterr()
    for argv in (["analyze", "ec66", str(cell / "points.csv")],
                 ["calibrate", "ec66", str(cell / "points.csv"), "--out", str(tmp_path / "c.urdf")]):
        assert main([*argv, *extra, "-q"]) == 1
        (line,) = _errors(capsys.readouterr().err)
        assert named in line, line
