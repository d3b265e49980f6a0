"""Issue 24's command-line classes: options silently ignored (3), outputs checked before
the work (4), path and OS errors (5), console failures (6), misleading messages (8) and
foreign stderr lines (9). Every refusal is one ``kincal: error:`` line, exit code 1, no
traceback, no stderr line that is not kincal's, and the folder unchanged (names, bytes,
modification times)."""

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from kincal.cli.main import main


def snapshot(folder: Path) -> dict:
    out = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        data = p.read_bytes() if stat.S_ISREG(st.st_mode) else None
        out[str(p.relative_to(folder))] = (stat.S_IFMT(st.st_mode), data, st.st_mtime_ns)
    return out


def check_stderr(err: str, errors: int = 1) -> list[str]:
    lines = [line for line in err.splitlines() if line.strip()]
    assert not any("Traceback" in line for line in lines), err
    assert all(line.startswith("kincal: ") for line in lines), err  # nothing foreign
    found = [line for line in lines if line.startswith("kincal: error:")]
    assert len(found) == errors, err
    return found


def refused(capsys, argv, folder: Path, code: int = 1) -> str:
    capsys.readouterr()
    before = snapshot(folder)
    assert main(argv) == code
    line = check_stderr(capsys.readouterr().err)[0]
    assert snapshot(folder) == before
    return line


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    assert main(["simulate", "ec66", "--out", str(d / "points.csv"), "--poses", "30",
                 "--tool-m", "0.03", "0.02", "0.12"]) == 0
    assert main(["simulate", "ec66", "--out", str(d / "poses.csv"), "--poses", "30",
                 "--kind", "pose", "--seed", "1"]) == 0
    assert main(["calibrate", "ec66", str(d / "points.csv"), "--method", "ls", "--quiet",
                 "--out", str(d / "cal.urdf"), "--frames-out", str(d / "frames.json")]) == 0
    return d


@pytest.fixture
def work(inputs, tmp_path, monkeypatch):
    """A working folder holding copies of the inputs; the tests run in it."""
    for name in ("points.csv", "poses.csv", "cal.urdf", "frames.json"):
        shutil.copy2(inputs / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture
def readonly(work):
    """A folder no file can be made in, even by root (a read-only mount then)."""
    d = work / "ro"
    d.mkdir()
    if os.geteuid() != 0:
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(d)],
                          capture_output=True)
    if made.returncode != 0:
        pytest.skip("running as root without a way to make a read-only folder")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=True)


@pytest.fixture
def no_solving(monkeypatch):
    """Fail the test if a calibration is computed: the refusal must come first."""
    def solve(*args, **kwargs):
        raise AssertionError("the calibration ran before the refusal")

    from kincal.identification.problem import CalibrationProblem

    monkeypatch.setattr(CalibrationProblem, "solve", solve)


CAL = ["calibrate", "ec66", "points.csv", "--method", "ls", "--out", "c.urdf"]
PLAN = ["plan", "ec66", "--random", "50", "--poses", "5", "--out", "chosen.csv"]
SIM = ["simulate", "ec66", "--out", "s.csv", "--poses", "10"]

# ------------------------------------------------ 3: options silently ignored
IGNORED = [
    (CAL + ["--orientation-sigma-deg", "0.1"], "--orientation-sigma-deg is the orientation noise"),
    (CAL + ["--grid", "3"], "--grid is the number of grid points"),
    (["analyze", "ec66", "points.csv", "--noise-mm", "nan"], "--noise-mm must be a finite"),
    (["evaluate", "ec66", "points.csv", "--fit-frames", "--orientation-sigma-deg", "1"],
     "--orientation-sigma-deg"),
    (CAL + ["--positions-only"], "none of the data files has orientation columns"),
    (["evaluate", "ec66", "points.csv", "--fit-frames", "--positions-only"],
     "--positions-only reads a pose file's positions alone"),
    (["calibrate", "ec66", "poses.csv", "--positions-only", "--orientation-sigma-deg", "0.1",
      "--out", "c.urdf"], "none of the data files is one (read with --positions-only"),
    (PLAN + ["--in-cube", "0.4", "0", "0.3", "0.2", "--floor", "0.1", "--no-floor"],
     "--floor Z or --no-floor, not both"),
    (PLAN + ["--floor", "0.1"], "--floor is checked for poses drawn in a volume"),
    (PLAN + ["--pivot", "0", "0", "0.2"], "--pivot is the guess of the pivot of --kind distance"),
    (PLAN + ["--kind", "distance", "--pivot", "0", "0", "nan"], "--pivot must be a finite"),
    (PLAN + ["--target-poses", "50"], "--target-poses is the number of poses"),
    (PLAN + ["--in-cube", "0.4", "0", "0.3", "0.2", "--home", "0", "0", "0", "nan", "0", "0"],
     "--home must be a finite"),
    (SIM + ["--in-cube", "0.4", "0", "0.3", "0.4", "--size-mm", "400"],
     "--size-mm is not used with --in-cube"),
    (SIM + ["--in-sphere", "0.4", "0", "0.3", "0.2", "--center-m", "0.4", "0", "0.3"],
     "--center-m is not used with --in-cube"),
    (["simulate", "ec66", "--out", "s.csv", "--poses-file", "points.csv", "--poses", "5"],
     "--poses is not used with --poses-file"),
    (["simulate", "ec66", "--out", "s.csv", "--poses-file", "points.csv", "--center-m", "0.4",
      "0", "0.3"], "--center-m is not used with --poses-file"),
    (SIM + ["--orientation-noise-deg", "0.1"], "orientation noise of --kind pose"),
    (SIM + ["--kind", "pose", "--orientation-noise-deg", "-1"],
     "--orientation-noise-deg must be a finite number >= 0"),
    (SIM + ["--floor", "0"], "--floor is checked for poses drawn in a volume"),
    # audit of issue 12: --no-floor and --design were taken and did nothing
    (SIM + ["--no-floor"], "--no-floor is checked for poses drawn in a volume"),
    (PLAN + ["--no-floor"], "--no-floor is checked for poses drawn in a volume"),
    # --no-collision drops a check that only poses drawn in a volume have
    (SIM + ["--no-collision"], "--no-collision drops the self-collision check of poses drawn "
     "in a volume: it needs --in-cube or --in-sphere"),
    (PLAN + ["--no-collision"], "--no-collision drops the self-collision check of poses drawn "
     "in a volume: it needs --in-cube or --in-sphere (or --target-cube)"),
    (["simulate", "ec66", "--out", "s.csv", "--poses-file", "points.csv", "--design", "rtest"],
     "--design is not used with --poses-file"),
    (SIM + ["--in-cube", "0.4", "0", "0.3", "0.02", "--max-tilt", "40", "--design", "rtest"],
     "--design is not used with --in-cube/--in-sphere and --max-tilt"),
    # a size <= 0 was said in metres ("the sphere radius ... [m], got -0.005") whatever the unit
    (["plan", "ec66", "--in-sphere", "400", "0", "250", "-5", "--length-unit", "mm", "--poses",
      "5", "--out", "chosen.csv"], "--in-sphere R must be a finite number > 0 and <= 1e+06 mm, got -5"),
    (PLAN + ["--target-cube", "400", "0", "250", "0", "--length-unit", "mm"],
     "--target-cube EDGE must be a finite number > 0 and <= 1e+06 mm, got 0"),
    # no cross-validation runs: --cv-max-poses was accepted and ignored
    (CAL + ["--cv-max-poses", "10"], "--cv-max-poses is used only when lambda may be chosen"),
    (CAL[:3] + ["--lambda", "0.1", "--cv-max-poses", "10", "--out", "c.urdf"],
     "--cv-max-poses is used only when lambda may be chosen by cross-validation"),
    # each worker a process: 100,000 hung the machine starting them (6.7 GB)
    (["fleet", "ec66", "points.csv", "poses.csv", "--out-dir", "D", "--workers", "100000"],
     "--workers must be an integer >= 1 and <= "),
]


@pytest.mark.parametrize("argv, says", IGNORED, ids=[" ".join(a[3:]) for a, _ in IGNORED])
def test_an_option_that_would_be_ignored_or_is_out_of_range_is_refused(work, capsys, argv, says):
    assert says in refused(capsys, argv, work)


def test_the_defaults_of_options_that_can_be_refused_still_hold(work, capsys):
    assert main(SIM) == 0  # --poses 10 given; --orientation-noise-deg, --floor left alone
    assert len(_rows(work / "s.csv")) == 11
    assert main(["simulate", "ec66", "--out", "s60.csv"]) == 0  # --poses default 60
    assert len(_rows(work / "s60.csv")) == 61


# ------------------------------------------- 4: outputs checked before the work
def test_outputs_in_a_read_only_folder_are_refused_before_the_work(work, readonly, capsys,
                                                                  no_solving):
    for option, path in (("--plots", "ro/plots"), ("--html", "ro/r.html"),
                         ("--out", "ro/c.urdf"), ("--yaml-out", "ro/k.yaml"),
                         ("--report", "ro/r.json")):
        argv = CAL + [option, path] if option != "--out" else CAL[:-1] + [path]
        line = refused(capsys, argv, work)
        assert "cannot write in" in line and "read-only" in line, line


def test_truth_out_of_another_kind_is_refused_before_the_poses_are_solved(work, capsys,
                                                                          monkeypatch):
    from kincal.planning import simulation

    monkeypatch.setattr(simulation, "cube_poses", lambda *a, **k: pytest.fail("poses solved"))
    line = refused(capsys, SIM + ["--kind", "pose", "--truth-out", "t.json"], work)
    assert "--truth-out is written for --kind point only" in line
    assert not (work / "s.csv").exists()


def test_demo_in_a_read_only_folder_is_refused_at_once(work, readonly, capsys, monkeypatch):
    import kincal.experiments.paper_report as experiment

    monkeypatch.setattr(experiment, "demo", lambda *a, **k: pytest.fail("the demo ran"))
    assert "cannot write in" in refused(capsys, ["demo", "--out", "ro/demo"], work)
    assert "cannot write in" in refused(capsys, ["demo", "--out", "ro/a/b"], work)


def test_existing_outputs_are_refused_before_the_work(work, capsys, no_solving):
    (work / "k.yaml").write_text("kept\n")
    assert "already exists" in refused(capsys, CAL + ["--yaml-out", "k.yaml"], work)
    (work / "m.csv").write_text("kept\n")
    assert "already exists" in refused(capsys, CAL + ["--mdh-out", "m.csv"], work)
    several = ["calibrate", "ec66", "points.csv", "poses.csv", "--method", "ls"]
    (work / "c.urdf").write_text("kept\n")
    assert "already exists" in refused(capsys, several + ["--out", "c.urdf"], work)
    assert "same file" in refused(capsys, several + ["--out", "x.urdf", "--frames-out", "x.urdf"],
                                  work)
    assert "input file" in refused(capsys, several + ["--out", "poses.csv"], work)


# --------------------------------------------------------- 5: path and OS errors
def test_a_file_name_over_255_bytes_is_one_line(work, capsys):
    line = refused(capsys, CAL[:-1] + ["a" * 300 + ".urdf"], work)
    assert "file name too long" in line and len(line) < 300


def test_a_path_over_path_max_is_one_line(work, capsys):
    deep = "/".join(["d" * 200] * 25) + "/c.urdf"  # 5,000 characters
    assert "too long" in refused(capsys, CAL[:-1] + [deep], work)
    assert "too long" in refused(capsys, ["calibrate", "ec66", deep, "--out", "c.urdf"], work)


def test_an_output_that_is_a_symlink_loop_is_one_line(work, capsys):
    (work / "loop").symlink_to("loop")
    assert "symlink loop" in refused(capsys, CAL[:-1] + ["loop"], work)
    assert "symlink loop" in refused(capsys, CAL + ["--plots", "loop"], work)


def test_a_deleted_working_folder_is_one_line(work, capsys, monkeypatch):
    gone = work / "gone"
    gone.mkdir()
    monkeypatch.chdir(gone)
    gone.rmdir()
    line = refused(capsys, ["calibrate", "ec66", str(work / "points.csv"), "--method", "ls",
                            "--out", "c.urdf"], work)
    assert "working folder no longer exists" in line


# ----------------------------------------------------------- 6: console failures
def _kincal(argv, cwd, stdout=subprocess.PIPE, env=None, shell_suffix=None):
    if shell_suffix is not None:  # e.g. "2>&-": a redirection only a shell can make
        import shlex

        command = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "kincal", *argv])
        return subprocess.run(["sh", "-c", f"{command} {shell_suffix}"], cwd=cwd,
                              capture_output=True, text=True, timeout=300, env=env)
    return subprocess.run([sys.executable, "-m", "kincal", *argv], cwd=cwd, stdout=stdout,
                          stderr=subprocess.PIPE, text=True, timeout=300, env=env)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_stdout_on_a_full_disk_writes_nothing_and_says_one_line(work):
    for argv in (CAL, ["evaluate", "ec66", "points.csv", "--fit-frames", "--report", "r.json"],
                 ["analyze", "ec66", "points.csv"], SIM):
        before = snapshot(work)
        with open("/dev/full", "w") as full:
            run = _kincal(argv, work, stdout=full)
        assert run.returncode == 1, run.stderr
        assert "standard output" in check_stderr(run.stderr)[0]
        assert snapshot(work) == before


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_json_on_a_full_disk_says_no_file_was_written(work):
    """--json says the files written on stderr: it said "kincal: wrote c.urdf" and "wrote
    r.json" before stdout took the JSON, then "no output was written or changed" when it
    could not (and none was): three lines, two of them false. Now the one error line; the
    wrote lines come once stdout took the JSON."""
    argv = CAL + ["--report", "r.json", "--json"]
    before = snapshot(work)
    with open("/dev/full", "w") as full:
        run = _kincal(argv, work, stdout=full)
    assert run.returncode == 1 and snapshot(work) == before
    assert [line for line in run.stderr.splitlines() if line.strip()] == check_stderr(
        run.stderr), run.stderr  # the error line alone
    run = _kincal(argv, work)
    assert run.returncode == 0 and json.loads(run.stdout)["written"]
    assert "kincal: wrote" in run.stderr and "c.urdf" in run.stderr


def test_an_ascii_console_prints_a_non_ascii_path_escaped(work):
    (work / "é").mkdir()
    env = {**os.environ, "PYTHONIOENCODING": "ascii"}
    run = _kincal(CAL[:-1] + ["é/c.urdf"], work, env=env)
    assert run.returncode == 0, run.stderr
    check_stderr(run.stderr, errors=0)
    assert (work / "é" / "c.urdf").is_file() and "\\xe9" in run.stdout


def test_a_closed_stderr_still_runs_and_the_exit_code_tells(work):
    run = _kincal(CAL, work, shell_suffix="2>&-")
    assert run.returncode == 0 and (work / "c.urdf").is_file()
    before = snapshot(work)
    run = _kincal(CAL, work, shell_suffix="2>&-")  # c.urdf exists: refused, silently
    assert run.returncode == 1 and snapshot(work) == before


# ------------------------------------------------------- 8: misleading messages
def test_an_empty_frames_file_is_named_as_such(work, capsys):
    (work / "empty.json").write_text("")
    for argv in (["evaluate", "ec66", "points.csv", "--frames", "empty.json"],
                 ["compensate", "cal.urdf", "points.csv", "--frames", "empty.json",
                  "--out", "j.csv"]):
        assert "empty.json: the frames file is empty" in refused(capsys, argv, work)


def test_two_unnamed_columns_are_named_by_position(work, capsys):
    (work / "unnamed.csv").write_text("joint_1,,,x\n1,2,3,4\n")
    line = refused(capsys, ["calibrate", "ec66", "unnamed.csv", "--out", "c.urdf"], work)
    assert "columns 2-3 hold numbers but have no name" in line and "no name" in line


# ----------------------------------------------------- 9: foreign stderr lines
def test_a_read_only_home_gives_no_matplotlib_lines(work, readonly):
    env = {k: v for k, v in os.environ.items()
           if k not in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME")}
    env["HOME"] = str(readonly)
    run = _kincal(CAL + ["--plots", "plots"], work, env=env)
    assert run.returncode == 0, run.stderr
    check_stderr(run.stderr, errors=0)
    assert (work / "plots" / "residuals.png").is_file()


def test_a_volume_needs_no_default_cube(work, capsys):
    """kinova has no default cube: with --in-cube it needs none (no --center-m demanded)."""
    assert main(["simulate", "kinova", "--out", "k.csv", "--poses", "5",
                 "--in-cube", "0.4", "0", "0.3", "0.2"]) == 0
    check_stderr(capsys.readouterr().err, errors=0)
    line = refused(capsys, ["simulate", "kinova", "--out", "k2.csv", "--poses", "5"], work)
    assert "--center-m" in line  # without a volume the cube must be given


def test_an_unreachable_orientation_is_named_as_the_cause(work, capsys):
    """z1 reaches the points of this cube, but not with its tip pointing down."""
    argv = ["simulate", "z1", "--tip", "gripperMover", "--out", "z.csv", "--poses", "5",
            "--center-m", "0.3", "0", "0.2", "--size-mm", "100"]
    line = refused(capsys, argv, work)
    assert "orientation is the cause" in line and "move the cube" not in line
    assert main(argv + ["--tilt-deg", "180"]) == 0  # any orientation: reached


def test_a_chain_of_five_joints_reaches_a_point_at_any_orientation(work, capsys):
    """EC66 from link_1 (5 joints) reaches this cube's points, but no chosen orientation
    there: the refusal says so, and --tilt-deg 180 (any orientation) draws the poses with
    the orientation free (it sampled orientations the 5 joints cannot take, and failed
    naming the orientation even at 180 deg)."""
    argv = ["simulate", "ec66", "--base", "link_1", "--out", "e.csv", "--poses", "10",
            "--center-m", "0.35", "0.037", "-0.456", "--size-mm", "20"]
    line = refused(capsys, argv, work)
    assert "orientation is the cause" in line and "a chain of 5 joints cannot give" in line
    assert main(argv + ["--tilt-deg", "180"]) == 0
    check_stderr(capsys.readouterr().err, errors=0)


def _rows(path) -> list[str]:
    """Header and rows of a CSV kincal wrote, without its provenance (# lines)."""
    return [r for r in path.read_text().splitlines() if not r.startswith("#")]


@pytest.mark.parametrize("option", ["--tip", "--base", "--fix", "--validate"])
def test_an_option_of_several_values_before_the_data_names_what_it_took(option, capsys):
    """`kincal calibrate ur5 --tip tool0 poses.csv ...`: --tip takes one frame per data file
    and swallows the file, and argparse said only that the data are missing."""
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", "ur5", option, "tool0", "poses.csv", "--out", "c.urdf"])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert exc.value.code == 2 and "the following arguments are required: data" in last
    assert f"({option} took 'poses.csv' as one of its values: it takes several; give the " \
           "data files right after the robot" in last
    with pytest.raises(SystemExit):  # nothing swallowed: argparse's message alone
        main(["calibrate", "ur5", "--out", "c.urdf"])
    assert "took" not in capsys.readouterr().err


def _in_degrees(src: Path, dst: Path) -> None:
    """``src`` (a point file kincal wrote) with its joint columns in degrees."""
    import math

    rows = _rows(src)
    joints = [i for i, h in enumerate(rows[0].split(",")) if h.startswith("joint_")]
    dst.write_text("\n".join([rows[0]] + [",".join(
        repr(math.degrees(float(c))) if i in joints else c for i, c in enumerate(r.split(",")))
        for r in rows[1:]]) + "\n")


@pytest.mark.parametrize("how", ["program", "targets"])
def test_compensate_refuses_joint_values_in_degrees_read_as_radians(work, capsys, how):
    """A program (or targets' seeds) logged in degrees and read as radians: with
    --flag-unreachable a JOINTS.csv of nonsense was written, exit 0, behind two warnings;
    without it the one line blamed unreachable targets. Now: the unit, nothing solved."""
    _in_degrees(work / "points.csv", work / "deg.csv")
    argv = (["compensate", "cal.urdf", "--program", "deg.csv", "--nominal", "ec66"]
            if how == "program" else ["compensate", "cal.urdf", "deg.csv", "--frames",
                                      "frames.json"])
    argv += ["--tip", "flange", "--out", "j.csv"]
    for extra in ([], ["--flag-unreachable"]):
        line = refused(capsys, argv + extra, work)
        assert "deg.csv: joint_" in line and "outside its URDF limits" in line, line
        assert "were the joint values degrees? Read them with --angle-unit deg" in line, line
    assert main(argv + ["--angle-unit", "deg"]) == 0  # read as what they are: compensated


@pytest.mark.parametrize("argv", [
    ["plan", "ec66", "deg.csv", "--poses", "12", "--out", "p.csv"],
    ["plan", "ec66", "--random", "50", "--measured", "deg.csv", "--poses", "5", "--out", "p.csv"],
    ["simulate", "ec66", "--poses-file", "deg.csv", "--out", "s.csv"],
    ["analyze", "ec66", "points.csv", "--accuracy-poses", "deg.csv"],
])
def test_poses_in_degrees_read_as_radians_are_refused_where_they_are_read(work, capsys, argv):
    """Candidates, measured poses, poses to simulate at and map poses in degrees read as
    radians (358 rad, outside every limit): plan and simulate wrote poses of 358 rad behind a
    warning (the calibrate gate and compensate refuse the same clue). Now the one reader of
    pose files (read_candidates) refuses them, nothing written."""
    _in_degrees(work / "points.csv", work / "deg.csv")
    line = refused(capsys, argv, work)
    assert "deg.csv: joint_" in line and "outside its URDF limits" in line, line
    assert "were the joint values degrees? Read them with --angle-unit deg" in line, line


def test_candidates_that_identify_no_joint_parameter_are_refused(work, capsys):
    """Twenty copies of one pose as candidates identify the measurement frame's position
    alone: plan wrote five of them as a plan "optimised over 3 parameters", exit 0."""
    rows = _rows(work / "points.csv")
    (work / "same.csv").write_text("\n".join([rows[0]] + [rows[1]] * 20) + "\n")
    line = refused(capsys, ["plan", "ec66", "same.csv", "--poses", "5", "--out", "p.csv"], work)
    assert "the 20 candidates identify no parameter of the chain's joints, only base.x, " \
           "base.y, base.z" in line, line
    # planning for the frames alone, the joints fixed, stays possible
    assert main(["plan", "ec66", "points.csv", "--poses", "5", "--fix", "joint_*", "--out",
                 "p.csv"]) == 0


@pytest.mark.parametrize("argv, says", [
    (["calibrate", "ec66", "points.csv", "points.csv", "--out", "o.urdf"],
     "points.csv is given twice: a data file given twice counts each sample twice"),
    (["calibrate", "ec66", "points.csv", "copy.csv", "--out", "o.urdf"],
     "copy.csv has the same bytes as points.csv: a data file given twice"),
    (["analyze", "ec66", "points.csv", "points.csv"], "points.csv is given twice"),
    (["calibrate", "ec66", "points.csv", "--validate", "points.csv", "--out", "o.urdf"],
     "--validate points.csv is a data file: held-out errors judge a calibration on samples "
     "it did not see"),
    (["calibrate", "ec66", "points.csv", "--validate", "other.csv", "--out", "o.urdf"],
     "--validate other.csv: 30 of its 30 samples repeat samples of points.csv exactly"),
])
def test_data_given_twice_or_held_out_from_the_training_is_refused(work, capsys, argv, says):
    """A data file given twice (or a copy of its bytes) weighs every sample twice and puts a
    CV fold's validation samples in its training: a warning only, written (the fleet refuses
    one unit given twice). A --validate file that is a training file, or holds its samples,
    reported "held-out" errors of the training data without a word."""
    shutil.copy2(work / "points.csv", work / "copy.csv")
    (work / "other.csv").write_text("\n".join(_rows(work / "points.csv")) + "\n")
    line = refused(capsys, argv, work)
    assert says in line, line


@pytest.mark.parametrize("argv, says", [
    (["calibrate", "ec66", "cal.urdf", "--out", "o.urdf"],
     "cal.urdf: is XML (a URDF or xacro file?), not a CSV data file"),
    (["calibrate", "ec66", "frames.json", "--out", "o.urdf"],
     "frames.json: is JSON (a FRAMES.json, REPORT.json or FLEET.json?), not a CSV data file"),
    (["calibrate", "ec66", "points.csv", "--validate", "frames.json", "--out", "o.urdf"],
     "frames.json: is JSON"),
    (["compensate", "cal.urdf", "--program", "cal.urdf", "--nominal", "ec66", "--tip",
      "flange", "--out", "j.csv"], "cal.urdf: is XML (a URDF or xacro file?), not a CSV "
                                  "program file"),
    (["plan", "ec66", "cal.urdf", "--poses", "5", "--out", "p.csv"], "not a CSV candidates"),
    (["calibrate", "points.csv", "points.csv", "--tip", "flange", "--out", "o.urdf"],
     "points.csv: not XML (it begins '# made by kincal"),
    (["compensate", "cal.urdf", "--program", "points.csv", "--nominal", "frames.json",
      "--tip", "flange", "--out", "j.csv"], "frames.json: not XML (it begins '{')"),
])
def test_a_file_of_another_kind_is_named_as_such(work, capsys, argv, says):
    """A URDF or a JSON file given as a data file was read as a CSV whose header lacks the
    columns (with advice to hold joints with --joint-value) or as a header not fitting its
    rows (or decimal commas?); a data file given as the robot as malformed XML."""
    line = refused(capsys, argv, work)
    assert says in line, line
    assert "decimal commas" not in line and "--joint-value" not in line


def test_orientation_sigma_that_every_sigma_deg_column_overrides_is_refused(work, capsys):
    """A pose file's sigma_deg column wins over --orientation-sigma-deg: with it in every
    pose file the option was taken and weighed nothing (the same fit as without it)."""
    lines = [line for line in (work / "poses.csv").read_text().splitlines()
             if not line.startswith("#")]
    (work / "stated.csv").write_text(lines[0] + ",sigma_deg\n"
                                     + "".join(row + ",0.5\n" for row in lines[1:]))
    stated = ["calibrate", "ec66", "stated.csv", "--lambda", "0.1", "--model", "complete",
              "--out", "c.urdf"]
    line = refused(capsys, stated + ["--orientation-sigma-deg", "0.02"], work)
    assert line == ("kincal: error: --orientation-sigma-deg would weigh no row: every pose or "
                    "flush file states its orientation noise in a sigma_deg column, which is "
                    "used; leave out the option or the column")
    line = refused(capsys, ["evaluate", "ec66", "stated.csv", "--fit-frames",
                            "--orientation-sigma-deg", "0.02"], work)
    assert "--orientation-sigma-deg would weigh no row" in line
    # beside a pose file without the column, the option weighs that file's rows
    assert main(stated[:3] + ["poses.csv"] + stated[3:]
                + ["--orientation-sigma-deg", "0.02", "-q"]) == 0
