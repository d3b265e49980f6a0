"""Faults and misuse: every one answered by one line, the right exit code, nothing written.

Each CLI case runs in a folder whose snapshot (names, bytes, mtimes) must not change;
outputs are all-or-none (staged, committed with link-no-replace, rolled back on failure).
"""

import os
import signal
import socket
import stat
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np

from kincal.export.outputs import Outputs, write_calibration
import pytest
from conftest import EC66

from kincal.cli.main import main
from kincal.errors import ExportError, KincalError, OptionError
from kincal.export import safe_write
from kincal.export.safe_write import check_outputs, write_all, write_text_atomic
from kincal.identification.problem import CalibrationOptions, CalibrationProblem, calibrate
from kincal.measurements.data import Measurements
from kincal.robot import Robot


def snapshot(folder: Path) -> dict:
    """{relative path: (kind, bytes of a regular file, mtime)} of everything under folder."""
    out = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        data = p.read_bytes() if stat.S_ISREG(st.st_mode) else None
        out[str(p.relative_to(folder))] = (stat.S_IFMT(st.st_mode), data, st.st_mtime_ns)
    return out


def refused(argv, folder: Path, capsys, code: int = 1) -> str:
    """Run main(argv) expecting refusal; return the one error line. Nothing may change."""
    before = snapshot(folder)
    assert main([str(a) for a in argv]) == code
    err = capsys.readouterr().err.strip().splitlines()
    errors = [e for e in err if e.startswith("kincal: error:")]
    assert len(errors) == 1 and not any("Traceback" in e for e in err), err
    assert snapshot(folder) == before
    return errors[0]


@pytest.fixture(scope="module")
def data_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("data")
    assert main(["simulate", "ec66", "--out", str(d / "cal.csv"), "--poses", "30",
                 "--tool-m", "0.03", "0.02", "0.12"]) == 0
    return d / "cal.csv"


@pytest.fixture
def work(tmp_path, data_csv):
    """A folder holding a copy of the data, an existing file and the EC66 URDF."""
    (tmp_path / "cal.csv").write_bytes(data_csv.read_bytes())
    (tmp_path / "existing.json").write_text("keep me")
    (tmp_path / "robot.urdf").write_text(EC66.read_text())
    return tmp_path


# ------------------------------------------------------------------ options
CAL = ["calibrate", "ec66", "{csv}", "--out", "{d}/out.urdf"]
OPTION_CASES = {
    "lambda nan": (CAL + ["--lambda", "nan"], "--lambda must be a finite number >= 0"),
    "lambda inf": (CAL + ["--lambda", "inf"], "--lambda must be a finite number"),
    "lambda negative": (CAL + ["--lambda", "-1"], "--lambda must be a finite number >= 0"),
    "lambda with ls": (CAL + ["--method", "ls", "--lambda", "5"], "applies to method l2 only"),
    "folds with lambda": (CAL + ["--lambda", "5", "--folds", "3"], "--folds is used only"),
    "folds with ls": (CAL + ["--method", "ls", "--folds", "3"], "--folds is used only"),
    "folds 1": (CAL + ["--folds", "1"], "--folds must be an integer >= 2"),
    "seed negative": (CAL + ["--seed", "-3"], "--seed must be an integer >= 0"),
    "robust scale alone": (CAL + ["--robust-scale-mm", "2"], "needs --robust"),
    "robust scale nan": (CAL + ["--robust", "huber", "--robust-scale-mm", "nan"],
                         "--robust-scale-mm must be a finite number >= 1e-06 and <= 1000 mm"),
    "robust scale zero": (CAL + ["--robust", "huber", "--robust-scale-mm", "0"], ">= 1e-06"),
    "tool offset inf": (CAL + ["--tool-offset", "0", "inf", "0"], "--tool-offset must be a finite"),
    "free with ls": (CAL + ["--method", "ls", "--free", "joint_2.d"], "free (--free) applies to method l2"),
    # --model auto (the default) may add backlash terms: the order column is theirs there
    "order column alone": (CAL + ["--model", "complete", "--order-column", "t"],
                           "needs --backlash, or --model auto"),
    "everything fixed": (CAL + ["--method", "frames", "--fix", "base.x", "base.y", "base.z",
                                "base.rx", "base.ry", "base.rz", "tool.x", "tool.y", "tool.z"],
                         "nothing to fit"),
    "simulate tool offset": (["simulate", "ec66", "--out", "{d}/s.csv", "--tool-offset", "0", "0",
                              "0.1"], "--tool-m"),
    "simulate poses 0": (["simulate", "ec66", "--out", "{d}/s.csv", "--poses", "0"],
                         "--poses must be an integer >= 1"),
    "simulate huge poses": (["simulate", "ec66", "--out", "{d}/s.csv", "--poses", "10000000000"],
                            "<= 1,000,000"),
    "simulate noise negative": (["simulate", "ec66", "--out", "{d}/s.csv", "--noise-mm", "-1"],
                                "--noise-mm must be a finite number >= 0"),
    "simulate size nan": (["simulate", "ec66", "--out", "{d}/s.csv", "--size-mm", "nan"],
                          "--size-mm"),
    "simulate tilt": (["simulate", "ec66", "--out", "{d}/s.csv", "--tilt-deg", "400"], "<= 180"),
    "simulate seed": (["simulate", "ec66", "--out", "{d}/s.csv", "--seed", "-1"], "--seed"),
    "simulate truth seed": (["simulate", "ec66", "--out", "{d}/s.csv", "--truth-seed", "-1"],
                            "--truth-seed"),
    "simulate center": (["simulate", "ec66", "--out", "{d}/s.csv", "--center-m", "0", "nan", "0"],
                        "--center-m"),
    "simulate base frame": (["simulate", "ec66", "--out", "{d}/s.csv", "--base-frame", "0", "0",
                             "0", "0", "0", "inf"], "--base-frame"),
    "plan poses 0": (["plan", "ec66", "--random", "50", "--poses", "0", "--out", "{d}/p.csv"],
                     "--poses"),
    "plan random 0": (["plan", "ec66", "--random", "0", "--poses", "5", "--out", "{d}/p.csv"],
                      "--random"),
    "plan seed with csv": (["plan", "ec66", "{csv}", "--seed", "3", "--poses", "5", "--out",
                            "{d}/p.csv"], "--seed is the seed of --random"),
    "plan noise nan": (["plan", "ec66", "--random", "50", "--poses", "5", "--noise-mm", "nan",
                        "--out", "{d}/p.csv"], "--noise-mm"),
    "evaluate tool offset with frames": (["evaluate", "ec66", "{csv}", "--frames", "{d}/f.json",
                                          "--tool-offset", "0", "0", "0.1"], "--fit-frames"),
}


@pytest.mark.parametrize("case", sorted(OPTION_CASES))
def test_bad_option_is_one_line_and_writes_nothing(case, work, capsys):
    argv, expected = OPTION_CASES[case]
    argv = [a.format(csv=work / "cal.csv", d=work) for a in argv]
    assert expected in refused(argv, work, capsys)


# --------------------------------------------------------------- robot files
def _urdf(work, text, name="bad.urdf"):
    (work / name).write_text(text)
    return work / name


def test_zero_length_axis(work, capsys):
    text = EC66.read_text().replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1)
    line = refused(["calibrate", _urdf(work, text), work / "cal.csv", "--tip", "flange", "--out",
                    work / "o.urdf"], work, capsys)
    assert "bad.urdf:" in line and "joint_1" in line and "zero length" in line


def test_lower_limit_above_upper(work, capsys):
    text = EC66.read_text().replace('lower="-6.283185307179586"', 'lower="7"', 1)
    line = refused(["calibrate", _urdf(work, text), work / "cal.csv", "--tip", "flange", "--out",
                    work / "o.urdf"], work, capsys)
    assert "joint_1" in line and "lower=7 is above upper=6.28319" in line


def test_thousands_of_links_refused_before_pinocchio(work, capsys):
    # Pinocchio's parser crashes the process on a chain this deep: it must never see it
    links = ['<link name="l0"/>'] + [
        f'<link name="l{i}"/><joint name="j{i}" type="revolute"><parent link="l{i - 1}"/>'
        f'<child link="l{i}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" '
        'velocity="1"/></joint>' for i in range(1, 2500)]
    path = _urdf(work, '<robot name="deep">' + "\n".join(links) + "</robot>")
    line = refused(["analyze", path, work / "cal.csv", "--tip", "l2499"], work, capsys)
    assert "more than 2000 links" in line


def test_urdfdom_messages_become_one_line(work, capfd):
    text = EC66.read_text().replace('<parent link="base_link"/>', '<parent link="nolink"/>', 1)
    path = _urdf(work, text)
    before = snapshot(work)
    assert main(["calibrate", str(path), str(work / "cal.csv"), "--tip", "flange",
                 "--out", str(work / "o.urdf")]) == 1
    err = capfd.readouterr().err.strip().splitlines()  # fd 2: urdfdom's C++ output included
    assert len(err) == 1, err
    assert err[0].startswith("kincal: error: ") and "bad.urdf:16:" in err[0]
    assert "parent link [nolink] of joint [joint_1] not found" in err[0]
    assert snapshot(work) == before


# ---------------------------------------------------------------- data files
def test_device_as_data(work, capsys):
    line = refused(["calibrate", "ec66", "/dev/zero", "--out", work / "o.urdf"], work, capsys)
    assert "/dev/zero: is a device" in line


def test_fifo_as_data_or_urdf_does_not_block(work, capsys):
    os.mkfifo(work / "pipe.csv")
    line = refused(["calibrate", "ec66", work / "pipe.csv", "--out", work / "o.urdf"], work, capsys)
    assert "is a FIFO" in line
    line = refused(["calibrate", work / "pipe.csv", work / "cal.csv", "--out", work / "o.urdf"],
                   work, capsys)
    assert "is a FIFO" in line


def test_huge_data_file_refused_unread(work, capsys):
    with open(work / "huge.csv", "wb") as f:
        f.truncate(300 * 2**20)  # sparse
    line = refused(["calibrate", "ec66", work / "huge.csv", "--out", work / "o.urdf"], work, capsys)
    assert "at most 256 MB" in line


def test_device_as_frames_file(work, capsys):
    line = refused(["evaluate", "ec66", work / "cal.csv", "--frames", "/dev/zero"], work, capsys)
    assert "is a device" in line


# ------------------------------------------------------------------- outputs
def test_fifo_and_device_outputs_refused_even_with_overwrite(work, capsys):
    os.mkfifo(work / "out.urdf")
    for extra in ([], ["--overwrite"]):
        line = refused(["calibrate", "ec66", work / "cal.csv", "--method", "ls", "--out",
                        work / "out.urdf", *extra], work, capsys)
        assert "is a FIFO; kincal writes regular files only" in line
    # a socket stands for devices: a real /dev node must never be the target of a test,
    # since a regression would replace it for the whole machine
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(work / "sock.csv"))
        line = refused(["simulate", "ec66", "--out", work / "sock.csv", "--overwrite"], work,
                       capsys)
    assert "is a socket; kincal writes regular files only" in line
    assert stat.S_ISFIFO((work / "out.urdf").lstat().st_mode)


def test_refused_run_creates_no_plots_folder(work, capsys):
    line = refused(["calibrate", "ec66", work / "cal.csv", "--method", "ls", "--out",
                    work / "o.urdf", "--report", work / "existing.json", "--plots",
                    work / "plots"], work, capsys)
    assert "existing.json: already exists" in line and not (work / "plots").exists()


def test_plots_folder_under_a_file(work, capsys):
    line = refused(["calibrate", "ec66", work / "cal.csv", "--method", "ls", "--out",
                    work / "o.urdf", "--plots", work / "existing.json" / "plots"], work, capsys)
    assert "is a file, not a directory" in line


def test_plots_folder_that_is_a_file(work, capsys):
    line = refused(["calibrate", "ec66", work / "cal.csv", "--method", "ls", "--out",
                    work / "o.urdf", "--plots", work / "existing.json"], work, capsys)
    assert "not a directory" in line


def test_output_refused_before_the_work(work, capsys, monkeypatch):
    def no_solving(*args, **kwargs):
        raise AssertionError("solved although the output is refused")

    monkeypatch.setattr(CalibrationProblem, "solve", no_solving)
    line = refused(["calibrate", "ec66", work / "cal.csv", "--out", work / "existing.json"],
                   work, capsys)
    assert "already exists" in line


def test_demo_refuses_an_earlier_demo_folder(work, capsys):
    (work / "demo").mkdir()
    (work / "demo" / "tables.md").write_text("earlier demo")
    line = refused(["demo", "--out", work / "demo"], work, capsys)
    assert "already exists" in line and "--overwrite" in line
    line = refused(["demo", "--out", work / "existing.json"], work, capsys)
    assert "not a directory" in line


def test_write_all_rolls_back_every_earlier_file(tmp_path, monkeypatch):
    (tmp_path / "a.txt").write_text("old a")
    real_link, calls = os.link, []

    def failing_link(src, dst, *args, **kwargs):
        calls.append(dst)
        if str(dst).endswith("c.txt"):
            raise OSError(28, "No space left on device")
        return real_link(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "link", failing_link)
    before = snapshot(tmp_path)
    with pytest.raises(ExportError, match="c.txt: could not write .No space left"):
        write_all([(tmp_path / "a.txt", "new a"), (tmp_path / "b.txt", "new b"),
                   (tmp_path / "sub" / "c.txt", "new c")], overwrite=True, dirs=[tmp_path / "sub"])
    assert snapshot(tmp_path) == before  # a restored, b removed, sub removed, no temp or backup
    assert any(str(c).endswith("b.txt") for c in calls)


def test_target_appearing_during_the_run_is_not_replaced(tmp_path, monkeypatch):
    real_stage = safe_write._stage

    def stage_then_race(target, data, path):
        tmp = real_stage(target, data, path)
        if target.name == "out.txt" and not target.exists():
            target.write_text("the other run's")  # another process wins the name meanwhile
        return tmp

    monkeypatch.setattr(safe_write, "_stage", stage_then_race)
    with pytest.raises(ExportError, match="created while kincal was running"):
        write_all([(tmp_path / "first.txt", "mine"), (tmp_path / "out.txt", "mine")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
    assert (tmp_path / "out.txt").read_text() == "the other run's"


def test_racing_writers_exactly_one_wins(tmp_path):
    target, results, barrier = tmp_path / "out.txt", [], threading.Barrier(8)

    def writer(k):
        barrier.wait()
        try:
            write_text_atomic(target, f"writer {k}")
            results.append(k)
        except ExportError:
            results.append(None)

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    winners = [k for k in results if k is not None]
    assert len(winners) == 1 and target.read_text() == f"writer {winners[0]}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_check_outputs_names_the_refused_target(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(ExportError, match="two outputs name the same file"):
        check_outputs([tmp_path / "a", tmp_path / "." / "a"])
    with pytest.raises(ExportError, match="does not exist"):
        check_outputs([tmp_path / "no" / "deeper" / "a"], dirs=[tmp_path / "no" / "deeper"])
    assert check_outputs([tmp_path / "new" / "a"], dirs=[tmp_path / "new"]) == [
        (tmp_path / "new" / "a").resolve()]
    assert not (tmp_path / "new").exists()


# ------------------------------------------------------------------- signals
CHILD = """
import sys
from kincal.cli.main import main
sys.stderr.write("ready\\n"); sys.stderr.flush()
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("sig,code,name", [(signal.SIGINT, 130, "SIGINT"),
                                           (signal.SIGTERM, 143, "SIGTERM")])
def test_signal_during_cross_validation(sig, code, name, tmp_path):
    # 600 poses: a run of about 2.7 s on a fast machine (200 took 0.8 s, and the signal,
    # sent after 1 s, came as the files were written: the run ended with 0)
    assert main(["simulate", "ec66", "--out", str(tmp_path / "p.csv"), "--poses", "600",
                 "--seed", "2", "--tool-m", "0.03", "0.02", "0.12"]) == 0
    before = snapshot(tmp_path)
    # a shell's background job ignores SIGINT; the child gets the default, as at a terminal
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, "calibrate", "ec66", str(tmp_path / "p.csv"), "--out",
         str(tmp_path / "out.urdf"), "--report", str(tmp_path / "r.json"), "--plots",
         str(tmp_path / "plots"), "--lambda", "cv"],
        stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert child.stderr.readline() == "ready\n"
    try:
        child.wait(timeout=1.0)  # into the robot, the data and the CV sweep
    except subprocess.TimeoutExpired:
        pass
    assert child.poll() is None, "the run ended before the signal; make it longer"
    child.send_signal(sig)
    out, err = child.communicate(timeout=60)
    lines = err.strip().splitlines()
    assert child.returncode == code, err
    assert lines == [f"kincal: error: interrupted ({name}); no output was written or changed"]
    assert snapshot(tmp_path) == before


# ----------------------------------------------------------------------- API
@pytest.fixture(scope="module")
def robot_and_data(data_csv):
    robot = Robot.load("ec66")
    return robot, Measurements.from_csv(data_csv, robot.joint_names)


def test_api_accepts_sequences_where_tuples_are_documented(robot_and_data):
    robot, data = robot_and_data
    a = calibrate(robot, data, method="ls", fix=["joint_2.a"], tool_guess=[0.03, 0.02, 0.12])
    b = calibrate(robot, data, method="ls", fix=("joint_2.a",),
                  tool_guess=np.array([0.03, 0.02, 0.12]))
    assert np.allclose(a.x, b.x)
    c = calibrate(robot, data, lam=1.0, free=["joint_2.d"], backlash=["joint_6"])
    assert "joint_6.backlash" in c.space.names
    assert CalibrationOptions(fix=["joint_2.a"]).validated().fix == ("joint_2.a",)


@pytest.mark.parametrize("kwargs,expected", [
    ({"tool_guess": [0, float("nan"), 0.1]}, "tool_guess needs 3 finite numbers"),
    ({"tool_guess": "abc"}, "tool_guess"),
    ({"folds": 2.5}, "folds must be an integer"),
    ({"seed": -1}, "seed must be an integer >= 0"),
    ({"seed": "a"}, "seed"),
    ({"lam": [1]}, "lam"),
    ({"lam": float("inf")}, "lambda"),
    ({"fix": None}, "fix must be a sequence"),
    ({"fix": [1, 2]}, "fix must hold names"),
    ({"lamda": 1}, "unknown option(s) lamda"),
    ({"model": "mdh", "method": "ls", "fix": ["base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz",
                              "tool.x", "tool.y", "tool.z", *(f"joint_{i}.{p}" for i in range(1, 7)
                                                              for p in ("a", "alpha", "d", "theta"))]},
     "nothing to fit"),
])
def test_api_bad_options_raise_kincal_errors(kwargs, expected, robot_and_data):
    robot, data = robot_and_data
    with pytest.raises(OptionError) as info:
        calibrate(robot, data, **kwargs)
    assert expected in str(info.value)


def test_api_bad_arrays_and_paths_raise_kincal_errors(robot_and_data, tmp_path):
    robot, data = robot_and_data
    with pytest.raises(KincalError, match="arrays of numbers"):
        Measurements(robot.joint_names, [[0] * 6, [0] * 5], [[0, 0, 0]] * 2)
    with pytest.raises(KincalError, match="must be a CalibrationOptions"):
        CalibrationProblem(robot, data, "ls")
    result = calibrate(robot, data, method="ls")
    with pytest.raises(KincalError, match=r"\(N, 6\)"):
        result.predict([1, 2])
    with pytest.raises(KincalError, match="output path"):
        write_calibration(result, Outputs(urdf=""))


# -------------------------------------------------------------------- sweep
def test_bad_input_sweep():
    """scripts/bad_input_sweep.py, every case but the signals (about 30 s): a sample of every
    25th case let `calibrate --folds 1000` pass for days after the evidence took over from
    CV on few poses."""
    script = Path(__file__).resolve().parents[1] / "scripts" / "bad_input_sweep.py"
    run = subprocess.run([sys.executable, str(script), "--no-signals"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "cases held the promise" in run.stdout and "FAILED" not in run.stdout


def test_api_robot_and_planning_misuse_raise_kincal_errors(data_csv):
    from kincal.planning.candidates import random_candidates

    robot = Robot.load("ec66")
    with pytest.raises(KincalError, match="must be a dict"):
        Robot.load("ec66", joint_values=[1, 2])
    with pytest.raises(KincalError, match=r"must be \(6,\)"):
        robot.tip_poses([0.1, 0.2, 0.3])  # three values for six joints: never truncated
    with pytest.raises(KincalError, match="seed must be an integer >= 0"):
        random_candidates(robot, 5, -1)
    with pytest.raises(KincalError, match="must be a path"):
        Measurements.from_csv(None, robot.joint_names)


def test_data_reading_stops_at_the_first_bad_row(tmp_path, data_csv):
    """A bad cell on line 3 is reported before the rest is read: the bytes after it are not
    even UTF-8, and their decoding error would win if the whole file were read first."""
    lines = [r for r in data_csv.read_text().splitlines() if not r.startswith("#")]
    cells = lines[2].split(",")
    cells[7] = "nan"
    # 2,000 good rows after it: far more than the reader's buffer
    text = "\n".join(lines[:2] + [",".join(cells)] + lines[3:] * 70) + "\n"
    (tmp_path / "d.csv").write_bytes(text.encode() + b"\xff\xfe" * 100_000)
    robot = Robot.load("ec66")
    with pytest.raises(KincalError, match="line 3, column 'y': 'nan'"):
        Measurements.from_csv(tmp_path / "d.csv", robot.joint_names)


def test_urdf_parser_output_on_success_becomes_one_warning(monkeypatch, capfd):
    import kincal.robot as robot_module

    real = robot_module.pin.buildModelFromXML

    def chatty(text):
        os.write(2, b"Warning: something odd in this URDF\n  at line 5 in /src/model.cpp\n")
        return real(text)

    monkeypatch.setattr(robot_module.pin, "buildModelFromXML", chatty)
    with pytest.warns(Warning, match="the URDF parser says: Warning: something odd in this URDF$"):
        Robot.load("ec66")
    assert capfd.readouterr().err == ""  # nothing reached file descriptor 2


def test_missing_limits_message_is_the_first_reason(work, capsys):
    text = EC66.read_text().replace('<limit lower="-6.283185307179586" upper="6.283185307179586" '
                                    'effort="150" velocity="2.618"/>', "", 1)
    line = refused(["calibrate", _urdf(work, text), work / "cal.csv", "--tip", "flange", "--out",
                    work / "o.urdf"], work, capsys)
    assert line.endswith("bad.urdf:16: not a valid URDF model: Joint [joint_1] is of type "
                         "REVOLUTE but it does not specify limits")


def test_two_processes_racing_for_one_output(tmp_path):
    """Two kincal runs started together for one --out: exactly one writes, the other says so."""
    argv = [sys.executable, "-c", "import sys; from kincal.cli.main import main; "
            "sys.exit(main(sys.argv[1:]))", "simulate", "ec66", "--poses", "5", "--out",
            str(tmp_path / "same.csv")]
    runs = [subprocess.Popen(argv + ["--seed", str(k)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for k in range(2)]
    results = [(r.wait(timeout=120), r.stderr.read()) for r in runs]
    assert sorted(code for code, _ in results) == [0, 1], results
    loser = next(err for code, err in results if code == 1).strip().splitlines()
    assert len(loser) == 1 and "same.csv: already exists" in loser[0]
    winner = results.index(next(r for r in results if r[0] == 0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.csv"]
    text = (tmp_path / "same.csv").read_text()
    assert main(["simulate", "ec66", "--poses", "5", "--seed", str(winner), "--out",
                 str(tmp_path / "check.csv")]) == 0
    rows = [r for r in text.splitlines() if not r.startswith("#")]
    assert [r for r in (tmp_path / "check.csv").read_text().splitlines()
            if not r.startswith("#")] == rows  # the winner's file, whole
    assert f"--seed {winner}" in text.splitlines()[1]  # its provenance names its command
