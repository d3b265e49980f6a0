"""Run a few hundred generated bad inputs through the kincal CLI and count the promises kept.

The promise, for every case: the exit code expected (1 for a KincalError, 2 for an
argparse usage error, 130/143 for SIGINT/SIGTERM); exactly one line ``kincal: error:
...`` on stderr (file descriptor 2, so C++ output from urdfdom would be caught) and no
traceback; and the folder of the run exactly as before (names, bytes, mtimes): nothing
written, nothing replaced.

    python scripts/bad_input_sweep.py            # every case (~2 min alone on this machine)
    python scripts/bad_input_sweep.py --sample 20  # every k-th case, for a quick check

The command line's own cases (issue 24: options that would be ignored, outputs checked
before the work, path, OS and console failures, foreign stderr lines) are generated in
bad_input_cli_cases.py; the console cases run in a child process.

Prints how many cases held the promise and lists any that did not; exit code 1 if any.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bad_input_audit_cases import audit_cases
from bad_input_bound_cases import bound_cases
from bad_input_cli_cases import (CaseSkipped, chain_cases, console_cases,
                                  ignored_option_cases, message_cases, output_first_cases,
                                  run_console_case, snapshot, tree_inputs,
                                  unit_and_kind_cases, undo_read_only)

REPO = Path(__file__).resolve().parents[1]
EC66 = REPO / "urdf" / "ec66.urdf"


# ------------------------------------------------------------------ inputs
def make_inputs(d: Path) -> dict:
    """The good inputs the cases damage: data CSV, URDF text, frames JSON."""
    from kincal.cli.main import main

    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "ec66", "--out", str(d / "good.csv"), "--poses", "30",
                     "--tool-m", "0.03", "0.02", "0.12"]) == 0
        assert main(["calibrate", "ec66", str(d / "good.csv"), "--method", "ls", "--quiet",
                     "--out", str(d / "good.urdf"), "--frames-out", str(d / "frames.json")]) == 0
        assert main(["simulate", "ec66", "--out", str(d / "poses.csv"), "--poses", "30",
                     "--kind", "pose", "--seed", "1"]) == 0
    return {"csv": (d / "good.csv").read_text(), "urdf": EC66.read_text(),
            "frames": (d / "frames.json").read_text(),
            "tree": {k: str(v) for k, v in tree_inputs(d).items()}}


def csv_cases(good: str):
    """(label, text or bytes) of damaged data files."""
    lines = [line for line in good.splitlines() if not line.startswith("#")]  # no provenance
    header, rows = lines[0], lines[1:]
    for r in (0, 7, 29):
        for c in (0, 3, 6, 8):
            for cell in ("nan", "inf", "-inf", "", "abc", "1e999", "1e300", "0x1p3", " "):
                cells = rows[r].split(",")
                cells[c] = cell
                yield (f"csv cell r{r} c{c} {cell!r}",
                       "\n".join([header] + rows[:r] + [",".join(cells)] + rows[r + 1:]))
        yield f"csv extra cell r{r}", "\n".join([header] + rows[:r] + [rows[r] + ",1"] + rows[r + 1:])
        yield f"csv short row r{r}", "\n".join([header] + rows[:r] + [rows[r].rsplit(",", 1)[0]]
                                               + rows[r + 1:])
    cols = header.split(",")
    for k, col in enumerate(cols):
        yield f"csv missing column {col}", "\n".join(
            ",".join(v for i, v in enumerate(line.split(",")) if i != k) for line in lines)
        yield f"csv misspelled column {col}", "\n".join([header.replace(col, col + "x", 1)] + rows)
    yield "csv duplicated column", "\n".join([header.replace("joint_5", "joint_4")] + rows)
    yield "csv empty", ""
    yield "csv header only", header + "\n"
    yield "csv blank lines only", "\n\n\n"
    yield "csv one pose", "\n".join([header] + rows[:1])
    yield "csv identical poses", "\n".join([header] + [rows[0]] * 12)
    yield "csv binary", bytes(range(256)) * 8
    yield "csv latin-1", ("\n".join([header] + rows) + "\n\xe9\xe9").encode("latin-1")
    yield "csv NUL bytes", "\n".join([header] + rows).replace(",", "\x00", 3)
    yield "csv huge field", header + "\n" + "1" * 200_000
    yield "csv quote never closed", header + '\n"' + rows[0]
    yield "csv positions 1e7", "\n".join([header] + [",".join(r.split(",")[:6] + ["1e7"] * 3)
                                                     for r in rows])


def urdf_cases(good: str):
    """(label, text or bytes) of damaged URDF files."""
    yield "urdf unclosed tag", good.replace("</joint>", "", 1)
    yield "urdf mismatched tag", good.replace("</joint>", "</jiont>", 1)
    yield "urdf root not robot", good.replace("<robot", "<robit", 1).replace("</robot>", "</robit>")
    yield "urdf empty", ""
    yield "urdf not xml", "hello"
    yield "urdf binary", bytes(range(256))
    yield "urdf latin-1 declared", good.replace('encoding="utf-8"', 'encoding="latin-1"', 1)
    yield "urdf entity", ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "b">]><robot name="&a;">'
                          '<link name="l"/></robot>')
    yield "urdf external dtd", '<!DOCTYPE robot SYSTEM "http://x/y.dtd"><robot name="r"/>'
    # xacro is expanded (a valid xacro file is good input); a substitution that cannot be
    # evaluated is not (``${e}`` would be Euler's number: xacro knows the math constants)
    yield "urdf xacro substitution", good.replace('effort="150"', 'effort="${no_such_name}"', 1)
    for k in range(6):
        joint = f'<joint name="joint_{k + 1}"'
        head, tail = good.split(joint, 1)
        yield f"urdf zero axis joint_{k + 1}", head + joint + tail.replace(
            '<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1)
        yield f"urdf axis nan joint_{k + 1}", head + joint + tail.replace(
            '<axis xyz="0 0 1"/>', '<axis xyz="0 nan 1"/>', 1)
        yield f"urdf axis 2 numbers joint_{k + 1}", head + joint + tail.replace(
            '<axis xyz="0 0 1"/>', '<axis xyz="0 1"/>', 1)
        yield f"urdf lower above upper joint_{k + 1}", head + joint + tail.replace(
            'lower="-', 'lower="9', 1)
        yield f"urdf limit not a number joint_{k + 1}", head + joint + tail.replace(
            'upper="', 'upper="x', 1)
        # the audit a22's: numbers whose squares overflow (a traceback in the fit before)
        yield f"urdf axis overflows joint_{k + 1}", head + joint + tail.replace(
            '<axis xyz="0 0 1"/>', '<axis xyz="1e200 0 1e200"/>', 1)
        yield f"urdf origin 1e160 m joint_{k + 1}", head + joint + re.sub(
            r'<origin xyz="\S+', '<origin xyz="1e160', tail, count=1)
        yield f"urdf second origin joint_{k + 1}", head + joint + re.sub(
            r'(<origin [^>]*/>)', r'\1<origin xyz="0 0 0"/>', tail, count=1)
    yield "urdf link with two parent joints", re.sub(
        r'(<joint name="joint_3".*?<child link=")[^"]*', r'\1link_2', good, count=1,
        flags=re.S)
    yield "urdf missing parent link", good.replace('<parent link="base_link"/>',
                                                   '<parent link="nolink"/>', 1)
    yield "urdf duplicate link", good.replace("</robot>", '<link name="link_1"/></robot>')
    yield "urdf unknown joint type", good.replace('type="revolute"', 'type="weird"', 1)
    yield "urdf two roots", good.replace("</robot>", '<link name="other_root"/></robot>')
    chain = ['<link name="l0"/>'] + [
        f'<link name="l{i}"/><joint name="j{i}" type="revolute"><parent link="l{i - 1}"/>'
        f'<child link="l{i}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" '
        'velocity="1"/></joint>' for i in range(1, 3000)]
    yield "urdf 3000 links (Pinocchio would crash)", '<robot name="d">' + "".join(chain) + "</robot>"


def option_cases():
    """(label, argv with {csv} {urdf} {d} placeholders, expected codes)."""
    cal = ["calibrate", "ec66", "{csv}", "--out", "{d}/out.urdf"]
    sim = ["simulate", "ec66", "--out", "{d}/s.csv", "--poses", "5"]
    plan = ["plan", "ec66", "--random", "40", "--poses", "10", "--out", "{d}/p.csv"]
    ev = ["evaluate", "ec66", "{csv}", "--fit-frames", "--report", "{d}/e.json"]
    an = ["analyze", "ec66", "{csv}", "--report", "{d}/a.json"]
    bad = ["nan", "inf", "-inf", "-1", "1e308"]  # 1e308: beyond the bound of a size or an sd
    nonfinite = ["nan", "inf", "-inf", "-1", "x"]  # for values with no natural upper bound
    table = [
        (cal, "--lambda", nonfinite), (cal, "--folds", ["0", "1", "-2", "x", "1.5"]),
        (cal, "--seed", ["-1", "x"]),
        (cal + ["--robust", "huber"], "--robust-scale-mm", nonfinite + ["0"]),
        (sim, "--size-mm", bad + ["0"]), (sim, "--tilt-deg", bad), (sim, "--noise-mm", bad),
        (sim, "--length-error-mm", bad), (sim, "--angle-error-deg", bad),
        (sim, "--seed", ["-1", "x"]), (sim, "--truth-seed", ["-1"]),
        (["simulate", "ec66", "--out", "{d}/s.csv"], "--poses", ["0", "-5", "10000000000", "x"]),
        (plan, "--noise-mm", nonfinite + ["0"]), (plan, "--seed", ["-1"]),
        (["plan", "ec66", "--poses", "10", "--out", "{d}/p.csv"], "--random",
         ["0", "-1", "100000000"]),
        (["plan", "ec66", "--random", "40", "--out", "{d}/p.csv"], "--poses", ["0", "-1", "41"]),
    ]
    for base, option, values in table:
        for v in values:
            yield f"{base[0]} {option} {v}", base + [option, v]
    for cmd in (cal, plan, ev, an):
        for v in ("nan", "inf", "1e308"):
            yield f"{cmd[0]} --tool-offset {v}", cmd + ["--tool-offset", "0", v, "0"]
    yield "simulate --tool-offset", sim + ["--tool-offset", "0", "0", "0.1"]
    yield "simulate --center-m nan", sim + ["--center-m", "0", "nan", "0"]
    yield "simulate --tool-m inf", sim + ["--tool-m", "0", "inf", "0"]
    yield "simulate --base-frame nan", sim + ["--base-frame", "0", "0", "0", "0", "nan", "0"]
    conflicts = [
        ["--method", "ls", "--lambda", "5"], ["--method", "frames", "--lambda", "cv"],
        ["--lambda", "2", "--folds", "3"], ["--lambda", "2", "--seed", "3"],
        ["--method", "ls", "--folds", "3"], ["--robust-scale-mm", "2"],
        ["--method", "ls", "--free", "joint_2.d"], ["--model", "complete", "--order-column", "t"],
        ["--backlash", "joint_6", "--order-column", "x"],
        ["--method", "frames", "--backlash", "joint_6"], ["--fix", "joint_9.a"],
        ["--free", "nope"], ["--backlash", "joint_9"], ["--tip", "flang"], ["--base", "nolink"],
        ["--tip", "base_link", "--base", "flange"], ["--position-columns", "x", "y"],
        ["--position-columns", "a", "b", "c"], ["--folds", "1000"],
        ["--method", "frames", "--fix", "base.x", "base.y", "base.z", "base.rx", "base.ry",
         "base.rz", "tool.x", "tool.y", "tool.z"],
    ]
    for extra in conflicts:
        yield "calibrate " + " ".join(extra), cal + extra
    yield "plan --seed with candidates", ["plan", "ec66", "{csv}", "--seed", "2", "--poses", "5",
                                          "--out", "{d}/p.csv"]
    yield "plan both candidates and random", ["plan", "ec66", "{csv}", "--random", "20",
                                              "--poses", "5", "--out", "{d}/p.csv"]
    yield "evaluate --tool-offset with --frames", ["evaluate", "ec66", "{csv}", "--frames",
                                                   "{frames}", "--tool-offset", "0", "0", "0.1"]
    yield "evaluate neither frames nor fit", ["evaluate", "ec66", "{csv}"]
    yield "evaluate --order-column without backlash", ["evaluate", "ec66", "{csv}", "--frames",
                                                        "{frames}", "--order-column", "t"]
    yield "unknown robot", ["calibrate", "ec77", "{csv}", "--out", "{d}/o.urdf"]
    yield "unknown command", ["calibrat", "ec66"]
    yield "unknown option", cal + ["--lamda", "1"]
    yield "length unit cm", cal + ["--length-unit", "cm"]


def output_cases():
    """(label, argv, setup(folder)) for outputs that must be refused before any work."""
    cal = ["calibrate", "ec66", "{csv}", "--method", "ls"]

    def existing(d):
        (d / "out.urdf").write_text("keep")

    def folder(d):
        (d / "out.urdf").mkdir()

    def fifo(d):
        os.mkfifo(d / "out.urdf")

    def sock(d):
        import socket

        s = socket.socket(socket.AF_UNIX)
        s.bind(str(d / "out.urdf"))
        s.close()  # the socket file stays

    def dangling(d):
        (d / "out.urdf").symlink_to(d / "nowhere")

    def afile(d):
        (d / "afile").write_text("a file")

    def old_demo(d):
        (d / "demo").mkdir()
        (d / "demo" / "tables.md").write_text("an earlier demo")

    def fleet_named(d):
        (d / "FLEET.json.csv").write_text("joint_1,x\n1,2\n")

    def bad_unit(d):
        (d / "bad.csv").write_text("joint_1,x\n1,2\n")

    nothing = None
    yield "out exists", cal + ["--out", "{d}/out.urdf"], existing
    yield "out is a directory", cal + ["--out", "{d}/out.urdf", "--overwrite"], folder
    yield "out is a FIFO", cal + ["--out", "{d}/out.urdf"], fifo
    yield "out is a FIFO with --overwrite", cal + ["--out", "{d}/out.urdf", "--overwrite"], fifo
    # never a real /dev node as an output: a broken kincal would replace it machine-wide
    yield "out is a socket", cal + ["--out", "{d}/out.urdf", "--overwrite"], sock
    yield "out dangling symlink", cal + ["--out", "{d}/out.urdf"], dangling
    yield "out missing folder", cal + ["--out", "{d}/no/out.urdf"], nothing
    yield "out under a file", cal + ["--out", "{d}/afile/out.urdf"], afile
    yield "out twice", cal + ["--out", "{d}/o.urdf", "--report", "{d}/o.urdf"], nothing
    yield "out is the data", cal + ["--out", "{csv}"], nothing
    yield "report exists, plots asked", cal + ["--out", "{d}/o.urdf", "--report", "{d}/out.urdf",
                                               "--plots", "{d}/plots"], existing
    yield "plots under a file", cal + ["--out", "{d}/o.urdf", "--plots", "{d}/afile/p"], afile
    yield "plots is a file", cal + ["--out", "{d}/o.urdf", "--plots", "{d}/afile"], afile
    yield "frames-out is a FIFO", cal + ["--out", "{d}/o.urdf", "--frames-out", "{d}/out.urdf"], fifo
    yield "simulate out exists", ["simulate", "ec66", "--poses", "5", "--out", "{d}/out.urdf"], existing
    yield "simulate truth-out FIFO", ["simulate", "ec66", "--poses", "5", "--out", "{d}/s.csv",
                                      "--truth-out", "{d}/out.urdf"], fifo
    yield "plan out is the candidates", ["plan", "ec66", "{csv}", "--poses", "5", "--out", "{csv}"], nothing
    # an input is never replaced, --overwrite or not (but the corrected URDF over its robot)
    yield "out is the data, --overwrite", cal + ["--out", "{csv}", "--overwrite"], nothing
    yield "report is the robot, --overwrite", ["calibrate", "{urdf}", "{csv}", "--tip", "flange",
                                               "--out", "{d}/o.urdf", "--report", "{urdf}",
                                               "--overwrite"], nothing
    yield "evaluate report is the data, --overwrite", [
        "evaluate", "ec66", "{csv}", "--fit-frames", "--report", "{csv}", "--overwrite"], nothing
    yield "evaluate report is the frames, --overwrite", [
        "evaluate", "ec66", "{csv}", "--frames", "{frames}", "--report", "{frames}",
        "--overwrite"], nothing
    for out in ("{csv}", "{frames}", "{urdf}"):
        yield f"compensate out is an input ({out}), --overwrite", [
            "compensate", "{urdf}", "{csv}", "--tip", "flange", "--frames", "{frames}",
            "--out", out, "--overwrite"], nothing
    yield "simulate out is its poses file, --overwrite", [
        "simulate", "ec66", "--poses-file", "{csv}", "--out", "{csv}", "--overwrite"], nothing
    yield "plan out is the measured data, --overwrite", [
        "plan", "ec66", "--random", "50", "--measured", "{csv}", "--poses", "5", "--out",
        "{csv}", "--overwrite"], nothing
    yield "analyze report is the data, --overwrite", [
        "analyze", "ec66", "{csv}", "--report", "{csv}", "--overwrite"], nothing
    yield "ur yaml of a URDF in another layout", cal[:1] + ["ur10", "{d}/../inputs/good.csv",
                                                           "--out", "{d}/o.urdf", "--yaml-out",
                                                           "{d}/k.yaml", "--yaml-format", "ur",
                                                           "--ur-hash", "calib_1"], nothing
    yield "joint mapped onto a position column", cal + ["--out", "{d}/o.urdf", "--joint-columns",
                                                       "joint_1=x"], nothing
    yield "fleet unit named as the fleet's own file", [
        "fleet", "ec66", "{csv}", "{d}/FLEET.json.csv", "--out-dir", "{d}/D"], fleet_named
    # one unit calibrated, one failed: the fleet fails, and writes no unit's files either
    yield "fleet with fewer than 2 units calibrated", [
        "fleet", "ec66", "{csv}", "{d}/bad.csv", "--out-dir", "{d}/D", "--quiet"], bad_unit
    yield "analyze report exists", ["analyze", "ec66", "{csv}", "--report", "{d}/out.urdf"], existing
    yield "evaluate report is a dir", ["evaluate", "ec66", "{csv}", "--fit-frames", "--report",
                                       "{d}/out.urdf", "--overwrite"], folder
    yield "demo over an earlier demo", ["demo", "--out", "{d}/demo"], old_demo
    yield "demo into a file", ["demo", "--out", "{d}/afile"], afile


def special_file_cases():
    """(label, argv, setup) for special and missing input files."""
    def fifo(d):
        os.mkfifo(d / "pipe")

    def huge(d):
        with open(d / "huge.csv", "wb") as f:
            f.truncate(300 * 2**20)

    def adir(d):
        (d / "adir").mkdir()

    for what, argv in (("data", ["calibrate", "ec66", "{x}", "--out", "{d}/o.urdf"]),
                       ("urdf", ["calibrate", "{x}", "{csv}", "--tip", "flange", "--out",
                                 "{d}/o.urdf"]),
                       ("frames", ["evaluate", "ec66", "{csv}", "--frames", "{x}"]),
                       ("candidates", ["plan", "ec66", "{x}", "--poses", "5", "--out",
                                       "{d}/p.csv"])):
        for label, x, setup in (("/dev/zero", "/dev/zero", None), ("FIFO", "{d}/pipe", fifo),
                                ("missing", "{d}/missing", None), ("directory", "{d}/adir", adir),
                                ("300 MB", "{d}/huge.csv", huge)):
            yield f"{what} is {label}", [a.replace("{x}", x) for a in argv], setup


# ---------------------------------------------------------------- running
CASE_TIMEOUT_S = 60


class CaseTimeout(BaseException):
    """A case ran longer than CASE_TIMEOUT_S."""


def _on_alarm(signum, frame):
    raise CaseTimeout(f"still running after {CASE_TIMEOUT_S} s")


def run_case(argv, folder: Path, codes=(1, 2), expect: str | None = None) -> str | None:
    """Run main(argv) in-process, fd 2 captured; None if the promise held, else why not.
    expect: a piece of the error line (the case is refused for the reason it names)."""
    from kincal.cli.main import main

    before = snapshot(folder)
    sys.stderr.flush()
    signal.signal(signal.SIGALRM, _on_alarm)
    signal.alarm(CASE_TIMEOUT_S)  # a case that hangs (a FIFO read, say) is reported, not waited on
    saved = os.dup(2)
    with tempfile.TemporaryFile() as cap, contextlib.redirect_stdout(io.StringIO()):
        os.dup2(cap.fileno(), 2)
        err_py = io.StringIO()
        try:
            with contextlib.redirect_stderr(err_py):
                try:
                    code = main(argv)
                except SystemExit as exc:
                    code = exc.code
                except BaseException as exc:  # the promise is broken: report, keep sweeping
                    import traceback

                    code = f"raised {type(exc).__name__}: {exc}"
                    err_py.write("Traceback\n" + traceback.format_exc())
        finally:
            signal.alarm(0)
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        cap.seek(0)
        err = (err_py.getvalue() + cap.read().decode("utf-8", "replace")).strip().splitlines()
    problems = []
    if code not in codes:
        problems.append(f"exit code {code}, expected {' or '.join(map(str, codes))}")
    if any("Traceback" in e for e in err):
        problems.append("traceback")
    if code == 1 and len([e for e in err if e.startswith("kincal: error:")]) != 1:
        problems.append("not exactly one 'kincal: error:' line")
    if code == 1 and any(not e.startswith(("kincal: error:", "kincal: warning:")) for e in err):
        problems.append("other output on stderr")
    if code == 2 and not (err and "error:" in err[-1]):
        problems.append("usage error without a message")
    if expect is not None and not any(expect in e for e in err if "error:" in e):
        problems.append(f"the error line does not say {expect!r}")
    if snapshot(folder) != before:
        problems.append("the folder changed")
    if problems:
        return "; ".join(problems) + " | stderr: " + " / ".join(err[-3:])
    return None


SIGNAL_CHILD = """
import sys
from kincal.cli.main import main
sys.stderr.write("ready\\n"); sys.stderr.flush()
sys.exit(main(sys.argv[1:]))
"""


def run_signal_case(sig, code, data: Path, folder: Path) -> str | None:
    before = snapshot(folder)
    child = subprocess.Popen(
        [sys.executable, "-c", SIGNAL_CHILD, "calibrate", "ec66", str(data), "--out",
         str(folder / "o.urdf"), "--report", str(folder / "r.json"), "--plots",
         str(folder / "plots")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    child.stderr.readline()
    time.sleep(1.0)
    if child.poll() is not None:
        return "the run ended before the signal"
    child.send_signal(sig)
    _, err = child.communicate(timeout=120)
    lines = err.strip().splitlines()
    problems = []
    if child.returncode != code:
        problems.append(f"exit code {child.returncode}, expected {code}")
    if len(lines) != 1 or not lines[0].startswith("kincal: error: interrupted"):
        problems.append(f"stderr {lines[-3:]}")
    if snapshot(folder) != before:
        problems.append("the folder changed")
    return "; ".join(problems) or None


def cases(inputs_dir: Path, inputs: dict):
    """Every case as (label, runner(folder) -> problem or None)."""
    fill = {"csv": str(inputs_dir / "good.csv"), "frames": str(inputs_dir / "frames.json"),
            "poses": str(inputs_dir / "poses.csv"), "urdf": str(inputs_dir / "good.urdf")}

    def cli(argv, setup=None, codes=(1, 2), expect=None):
        def runner(folder):
            try:
                if setup is not None:
                    setup(folder)
                args = [a.format(d=folder, **fill) if "{" in a else a for a in argv]
                return run_case(args, folder, codes, expect)
            except CaseSkipped:
                return None
            finally:
                undo_read_only(folder)
        return runner

    def console(argv, how, code):
        def runner(folder):
            if how == "full" and not Path("/dev/full").exists():
                return None
            try:
                args = [a.format(d=folder, **fill) if "{" in a else a for a in argv]
                return run_console_case(args, how, code, folder)
            except CaseSkipped:
                return None
        return runner

    def with_file(name, content, argv_of):
        def setup(folder):
            mode = "wb" if isinstance(content, bytes) else "w"
            with open(folder / name, mode, **({} if mode == "wb" else {"encoding": "utf-8"})) as f:
                f.write(content)
        return lambda path: cli(argv_of(path), setup)

    for label, text in csv_cases(inputs["csv"]):
        yield label, with_file("data.csv", text, lambda p: [
            "calibrate", "ec66", "{d}/data.csv", "--method", "ls", "--out", "{d}/o.urdf",
            "--report", "{d}/r.json"])(None)
    for label, text in urdf_cases(inputs["urdf"]):
        yield label, with_file("robot.urdf", text, lambda p: [
            "calibrate", "{d}/robot.urdf", "{csv}", "--tip", "flange", "--method", "ls",
            "--out", "{d}/o.urdf"])(None)
    mesh = ('<link name="link_1"><collision><geometry><mesh filename="package://no_such_pkg/'
            'link_1.stl"/></geometry></collision>')  # a description without its meshes
    meshless = inputs["urdf"].replace('<link name="link_1">', mesh, 1)
    for cmd in ("plan", "simulate"):  # refused naming where it looked and --no-collision
        yield f"{cmd} in a volume, collision mesh missing", with_file(
            "robot.urdf", meshless, lambda p, c=cmd: [
                c, "{d}/robot.urdf", "--tip", "flange", "--in-cube", "0.4", "0", "0.25", "0.02",
                "--poses", "12", "--out", "{d}/o.csv"])(None)
    frames_bad = {"frames garbage": "not json", "frames nan": inputs["frames"].replace(
        '"x": ', '"x": NaN, "xx": ', 1), "frames empty object": "{}",
                  "frames no tool": '{"base": {"x": 0, "y": 0, "z": 0, "rx": 0, "ry": 0, "rz": 0}}'}
    for label, text in frames_bad.items():
        yield label, with_file("f.json", text, lambda p: [
            "evaluate", "ec66", "{csv}", "--frames", "{d}/f.json"])(None)
    for label, argv in option_cases():
        yield label, cli(argv)
    for label, argv, setup in output_cases():
        yield label, cli(argv, setup, codes=(1,))
    for label, argv, setup in special_file_cases():
        yield label, cli(argv, setup, codes=(1,))
    for label, argv in chain_cases():  # tree paths, several chains, mimic joints
        yield label, cli([a.replace("{d}", "{{d}}").format(**inputs["tree"]).replace(
            "{{d}}", "{d}") if "{" in a else a for a in argv], codes=(1,))
    for label, argv in ignored_option_cases():  # 2: "-inf" reads as an option to argparse
        yield label, cli(argv, codes=(1, 2))
    for label, argv in bound_cases():  # numeric options beyond their range
        yield label, cli(argv, codes=(1,))
    for label, argv, setup in output_first_cases():
        yield label, cli(argv, setup, codes=(1,))
    for label, argv, setup, expect in message_cases():  # the line must name the cause
        yield label, cli(argv, setup, codes=(1,), expect=expect)
    for label, argv, setup in unit_and_kind_cases():  # newer paths' units, files' kinds
        yield label, cli(argv, setup, codes=(1,))
    for label, argv, how, code in console_cases():
        yield label, console(argv, how, code)
    for label, argv, setup, expect in audit_cases():  # the audit of issues 22 and 24
        yield label, cli(argv, setup and (lambda folder, s=setup: s(folder, fill)),
                         codes=(1,), expect=expect)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", type=int, default=1, help="run every k-th case only")
    ap.add_argument("--no-signals", action="store_true", help="skip the two signal cases")
    ap.add_argument("--only", metavar="TEXT", help="run only the cases whose label contains TEXT")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    failed, n = [], 0
    with tempfile.TemporaryDirectory(prefix="kincal-sweep-") as tmp:
        root = Path(tmp)
        inputs_dir = root / "inputs"
        inputs_dir.mkdir()
        inputs = make_inputs(inputs_dir)
        inputs_before = snapshot(inputs_dir)
        import warnings

        warnings.simplefilter("ignore")  # non-kincal warnings of libraries: not the point here
        for k, (label, runner) in enumerate(cases(inputs_dir, inputs)):
            if k % args.sample or (args.only and args.only not in label):
                continue
            folder = root / f"case{k}"
            folder.mkdir()
            n += 1
            problem = runner(folder)
            if problem:
                failed.append((label, problem))
        if snapshot(inputs_dir) != inputs_before:  # before the signal cases' own input
            failed.append(("inputs", "an input file changed"))
        if not args.no_signals:
            with contextlib.redirect_stdout(io.StringIO()):
                from kincal.cli.main import main as kincal

                kincal(["simulate", "ec66", "--out", str(inputs_dir / "p200.csv"), "--poses",
                        "200", "--seed", "2", "--tool-m", "0.03", "0.02", "0.12"])
            inputs_before = snapshot(inputs_dir)
            for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
                folder = root / f"signal{code}"
                folder.mkdir()
                n += 1
                problem = run_signal_case(sig, code, inputs_dir / "p200.csv", folder)
                if problem:
                    failed.append((f"signal {sig.name} during cross-validation", problem))
            if snapshot(inputs_dir) != inputs_before:
                failed.append(("inputs", "an input file changed in a signal case"))
    print(f"bad-input sweep: {n - len(failed)} of {n} cases held the promise (one line, "
          f"right exit code, nothing written) in {time.perf_counter() - t0:.0f} s")
    for label, problem in failed:
        print(f"  FAILED {label}: {problem}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
