"""Run a few hundred generated bad inputs through the kincal CLI and count the promises kept.

The promise, for every case: the exit code expected (1 for a KincalError, 2 for an
argparse usage error, 130/143 for SIGINT/SIGTERM); exactly one line ``kincal: error:
...`` on stderr (file descriptor 2, so C++ output from urdfdom would be caught) and no
traceback; and the folder of the run exactly as before (names, bytes, mtimes): nothing
written, nothing replaced.

    python scripts/bad_input_sweep.py            # every case (~2 min alone on this machine)
    python scripts/bad_input_sweep.py --sample 20  # every k-th case, for a quick check

Prints how many cases held the promise and lists any that did not; exit code 1 if any.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EC66 = REPO / "urdf" / "ec66.urdf"


def snapshot(folder: Path) -> dict:
    out = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        data = p.read_bytes() if stat.S_ISREG(st.st_mode) else None
        out[str(p.relative_to(folder))] = (stat.S_IFMT(st.st_mode), data, st.st_mtime_ns)
    return out


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
            "frames": (d / "frames.json").read_text()}


def csv_cases(good: str):
    """(label, text or bytes) of damaged data files."""
    lines = good.splitlines()
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
        ["--method", "ls", "--free", "joint_2.d"], ["--order-column", "x"],
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


def ignored_option_cases():
    """(label, argv) of options the run would silently ignore, or out of their range
    (issue 24, class 3): each refused with one line, exit code 1."""
    sim = ["simulate", "ec66", "--out", "{d}/s.csv", "--poses", "5"]
    plan = ["plan", "ec66", "--random", "40", "--poses", "10", "--out", "{d}/p.csv"]
    cube = ["--in-cube", "0.4", "0", "0.3", "0.3"]
    sphere = ["--in-sphere", "0.4", "0", "0.3", "0.2"]
    for cmd in (["calibrate", "ec66", "{csv}", "--method", "ls", "--out", "{d}/o.urdf"],
                ["analyze", "ec66", "{csv}"], ["evaluate", "ec66", "{csv}", "--fit-frames"]):
        for v in ("0.001", "0.01", "1", "10"):  # points only: no pose file to weigh
            yield f"{cmd[0]} --orientation-sigma-deg {v} on points", cmd + [
                "--orientation-sigma-deg", v]
        for v in ("nan", "inf", "-1", "0"):
            yield f"{cmd[0]} --orientation-sigma-deg {v}", cmd + ["--orientation-sigma-deg", v]
        if cmd[0] != "evaluate":
            for v in ("2", "5", "9"):
                yield f"{cmd[0]} --grid {v} without a map", cmd + ["--grid", v]
    for v in ("nan", "inf", "-inf", "-1", "0"):
        yield f"analyze --noise-mm {v}", ["analyze", "ec66", "{csv}", "--noise-mm", v]
    for v in ("0", "0.1", "-0.5"):
        for base, name in ((plan, "plan"), (sim, "simulate")):
            yield f"{name} --floor {v} without a volume", base + ["--floor", v]
            yield f"{name} --floor {v} with --no-floor", base + cube + ["--floor", v, "--no-floor"]
    for v in ("nan", "inf"):
        for base, name in ((plan, "plan"), (sim, "simulate")):
            yield f"{name} --floor {v}", base + cube + ["--floor", v]
            yield f"{name} --in-cube {v}", base + ["--in-cube", "0.4", v, "0.3", "0.3"]
            yield f"{name} --tilt-direction {v}", base + cube + ["--tilt-direction", "0", v, "-1"]
            yield f"{name} --max-tilt {v}", base + cube + ["--max-tilt", v]
        yield f"plan --home {v}", plan + cube + ["--home", "0", "0", v, "0", "0", "0"]
        yield f"plan --kind distance --pivot {v}", plan + ["--kind", "distance", "--pivot", "0",
                                                           "0", v]
    for kind in ("point", "pose", "plane"):
        yield f"plan --kind {kind} --pivot", plan + ["--kind", kind, "--pivot", "0", "0", "0.2"]
    for v in ("1", "200", "1000"):
        yield f"plan --target-poses {v} without --criterion i", plan + ["--target-poses", v]
    for volume, vname in ((cube, "cube"), (sphere, "sphere")):
        yield f"simulate --size-mm with --in-{vname}", sim + volume + ["--size-mm", "400"]
        yield f"simulate --center-m with --in-{vname}", sim + volume + ["--center-m", "0.4", "0",
                                                                         "0.3"]
    pf = ["simulate", "ec66", "--out", "{d}/s.csv", "--poses-file", "{csv}"]
    for extra in (["--poses", "5"], ["--poses", "60"], ["--center-m", "0.4", "0", "0.3"],
                  ["--size-mm", "100"], ["--tilt-deg", "10"]):
        yield f"simulate --poses-file with {extra[0]} {extra[1]}", pf + extra
    for kind in ("point", "distance", "plane"):
        for v in ("0", "0.01", "1"):
            yield f"simulate --kind {kind} --orientation-noise-deg {v}", sim + [
                "--kind", kind, "--orientation-noise-deg", v]
    for v in ("-1", "nan", "inf", "1e300"):
        yield f"simulate --kind pose --orientation-noise-deg {v}", sim + [
            "--kind", "pose", "--orientation-noise-deg", v]


OUTPUT_OPTIONS = {  # command: (argv without outputs, {output option: file name})
    "calibrate": (["calibrate", "ec66", "{csv}", "--method", "ls"],
                  {"--out": "o.urdf", "--frames-out": "f.json", "--report": "r.json",
                   "--yaml-out": "k.yaml", "--mdh-out": "m.csv", "--html": "r.html",
                   "--plots": "plots"}),
    "calibrate-sets": (["calibrate", "ec66", "{csv}", "{poses}", "--method", "ls"],
                       {"--out": "o.urdf", "--frames-out": "f.json", "--yaml-out": "k.yaml",
                        "--mdh-out": "m.csv"}),
    "simulate": (["simulate", "ec66", "--poses", "5"], {"--out": "s.csv", "--truth-out": "t.json"}),
    "plan": (["plan", "ec66", "--random", "40", "--poses", "5"], {"--out": "p.csv"}),
    "analyze": (["analyze", "ec66", "{csv}"], {"--report": "a.json"}),
    "evaluate": (["evaluate", "ec66", "{csv}", "--fit-frames"], {"--report": "e.json"}),
    "compensate": (["compensate", "{urdf}", "--program", "{csv}", "--nominal", "ec66",
                    "--tip", "flange"], {"--out": "j.csv"}),
    "demo": (["demo"], {"--out": "demo"}),
}
REQUIRED_OUT = ("calibrate", "calibrate-sets", "simulate", "plan", "compensate")


def _outputs_argv(command: str, option: str, path: str) -> list[str]:
    """argv of ``command`` with ``option`` at ``path`` (and a fine --out when it needs one)."""
    argv, _ = OUTPUT_OPTIONS[command]
    argv = list(argv) + [option, path]
    if option != "--out" and command in REQUIRED_OUT:
        argv += ["--out", "{d}/fine.out"]
    return argv


_MOUNTS: list[Path] = []


def _read_only(folder: Path) -> None:
    """folder/ro: no file can be made in it (a read-only mount when running as root)."""
    ro = folder / "ro"
    ro.mkdir()
    if os.geteuid() != 0:
        ro.chmod(0o555)
    elif subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(ro)],
                        capture_output=True).returncode == 0:
        _MOUNTS.append(ro)
    else:
        raise CaseSkipped("running as root without a way to make a read-only folder")


def _undo_read_only(folder: Path) -> None:
    ro = folder / "ro"
    if ro in _MOUNTS:
        subprocess.run(["umount", str(ro)], check=True)
        _MOUNTS.remove(ro)
    elif ro.exists():
        ro.chmod(0o755)


class CaseSkipped(Exception):
    """The case cannot be set up here (say, root without mount)."""


def output_first_cases():
    """(label, argv, setup) of outputs the run must refuse before any work (issue 24, class
    4: read-only folders, existing files, two outputs on one file, several-file runs) and
    of paths the OS refuses (class 5: names over 255 bytes, paths over PATH_MAX, symlink
    loops)."""
    def existing(name):
        def setup(d):
            if name in ("plots", "demo"):  # a folder holding a file the run would write
                (d / name).mkdir()
                (d / name / ("tables.md" if name == "demo" else "residuals.png")).write_text("keep")
            else:
                (d / name).write_text("keep")
        return setup

    def loop(name):
        return lambda d: (d / name).symlink_to(name)

    long_dir = "/".join(["d" * 250] * 18)  # 4,500 characters: over PATH_MAX
    for command, (_, outputs) in OUTPUT_OPTIONS.items():
        for option, name in outputs.items():
            yield (f"{command} {option} in a read-only folder",
                   _outputs_argv(command, option, "{d}/ro/" + name), _read_only)
            if command == "demo":
                yield ("demo --out below a read-only folder",
                       _outputs_argv(command, option, "{d}/ro/a/b"), _read_only)
            yield (f"{command} {option} exists", _outputs_argv(command, option, "{d}/" + name),
                   existing(name))
            for n in (256, 300, 1000):
                yield (f"{command} {option} name of {n} bytes",
                       _outputs_argv(command, option, "{d}/" + "n" * (n - 4) + ".out"), None)
            yield (f"{command} {option} path over PATH_MAX",
                   _outputs_argv(command, option, "{d}/" + long_dir + "/" + name), None)
            yield (f"{command} {option} a symlink loop",
                   _outputs_argv(command, option, "{d}/" + name), loop(name))
    for other in ("--frames-out", "--yaml-out", "--mdh-out"):
        yield (f"calibrate-sets --out equal to {other}",
               OUTPUT_OPTIONS["calibrate-sets"][0] + ["--out", "{d}/x", other, "{d}/x"], None)
    yield ("calibrate-sets --out is an input", OUTPUT_OPTIONS["calibrate-sets"][0]
           + ["--out", "{poses}"], None)
    for what, argv in (("data", ["calibrate", "ec66", "{x}", "--out", "{d}/o.urdf"]),
                       ("urdf", ["calibrate", "{x}", "{csv}", "--out", "{d}/o.urdf"]),
                       ("frames", ["evaluate", "ec66", "{csv}", "--frames", "{x}"]),
                       ("candidates", ["plan", "ec66", "{x}", "--poses", "5", "--out",
                                       "{d}/p.csv"])):
        for label, x in (("a name of 300 bytes", "{d}/" + "n" * 300),
                         ("a path over PATH_MAX", "{d}/" + long_dir + "/x")):
            yield f"{what} is {label}", [a.replace("{x}", x) for a in argv], None
        yield f"{what} is a symlink loop", [a.replace("{x}", "{d}/in") for a in argv], loop("in")


def message_cases():
    """(label, argv, setup) of inputs whose one line used to name another problem (class 8)."""
    def write(name, text):
        return lambda d: (d / name).write_text(text)

    for text, what in (("", "empty"), ("  \n\n", "blank"), ("[1, 2]", "a list"),
                       ("[" * 10_000, "10,000 deep")):
        for argv in (["evaluate", "ec66", "{csv}", "--frames", "{d}/f.json"],
                     ["compensate", "{urdf}", "{csv}", "--frames", "{d}/f.json", "--out",
                      "{d}/j.csv"]):
            yield f"{argv[0]} frames {what}", argv, write("f.json", text)
    for header in ("joint_1,,,x", ",,", "joint_1,joint_2,,y,,z"):
        yield (f"csv unnamed columns {header!r}",
               ["calibrate", "ec66", "{d}/u.csv", "--out", "{d}/o.urdf"],
               write("u.csv", header + "\n" + ",".join("1" * max(1, header.count(",") + 1))
                     + "\n"))


CONSOLE_CHILD = [sys.executable, "-m", "kincal"]


def console_cases():
    """(label, argv, how, code) run in a child process (class 6 and 9): how is "full"
    (stdout on /dev/full), "noerr" (stderr closed), "ascii" (an ASCII stdout) or "rohome"
    (a read-only HOME)."""
    cal = ["calibrate", "ec66", "{csv}", "--method", "ls", "--out", "{d}/o.urdf"]
    for argv in (cal, cal + ["--plots", "{d}/plots", "--report", "{d}/r.json"],
                 ["simulate", "ec66", "--poses", "5", "--out", "{d}/s.csv"],
                 ["plan", "ec66", "--random", "40", "--poses", "5", "--out", "{d}/p.csv"],
                 ["analyze", "ec66", "{csv}"],
                 ["evaluate", "ec66", "{csv}", "--fit-frames", "--report", "{d}/e.json"]):
        yield f"{argv[0]} stdout on a full disk {len(argv)}", argv, "full", 1
    yield "calibrate with stderr closed", cal, "noerr", 0
    yield "calibrate refused with stderr closed", cal + ["--out", "{csv}"], "noerr", 1
    yield "calibrate to a non-ASCII path on an ASCII stdout", cal[:-1] + ["{d}/\u00e9.urdf"], \
        "ascii", 0
    yield "calibrate --plots with a read-only HOME", cal + ["--plots", "{d}/plots"], "rohome", 0
    yield "calibrate refused with a read-only HOME", cal + ["--plots", "{d}/plots",
                                                            "--out", "{csv}"], "rohome", 1


def run_console_case(argv, how: str, code: int, folder: Path) -> str | None:
    """The promise in a child: exit code ``code``; every stderr line kincal's, one error
    line for a refusal; after a refusal the folder as before; no traceback."""
    import shlex

    env = dict(os.environ)
    if how == "ascii":
        env["PYTHONIOENCODING"] = "ascii"
    if how == "rohome":
        _read_only(folder)
        env["HOME"] = str(folder / "ro")
        for k in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME"):
            env.pop(k, None)
    before = snapshot(folder)
    try:
        if how == "noerr":
            command = " ".join(shlex.quote(a) for a in CONSOLE_CHILD + argv) + " 2>&-"
            run = subprocess.run(["sh", "-c", command], capture_output=True, text=True,
                                 timeout=300, env=env)
        else:
            out = open("/dev/full", "w") if how == "full" else subprocess.PIPE
            try:
                run = subprocess.run(CONSOLE_CHILD + argv, stdout=out, stderr=subprocess.PIPE,
                                     text=True, timeout=300, env=env)
            finally:
                if how == "full":
                    out.close()
        after = snapshot(folder)  # before the read-only HOME is undone
    finally:
        if how == "rohome":
            _undo_read_only(folder)
    err = [e for e in run.stderr.splitlines() if e.strip()]
    problems = []
    if run.returncode != code:
        problems.append(f"exit code {run.returncode}, expected {code}")
    if any(not e.startswith("kincal: ") for e in err) or any("Traceback" in e for e in err):
        problems.append("a foreign line or a traceback on stderr")
    if how != "noerr" and code == 1 and len([e for e in err if e.startswith("kincal: error:")]) != 1:
        problems.append("not exactly one 'kincal: error:' line")
    if code == 1 and after != before:
        problems.append("the folder changed")
    if problems:
        return "; ".join(problems) + " | stderr: " + " / ".join(err[-3:])
    return None


# ---------------------------------------------------------------- running
CASE_TIMEOUT_S = 60


class CaseTimeout(BaseException):
    """A case ran longer than CASE_TIMEOUT_S."""


def _on_alarm(signum, frame):
    raise CaseTimeout(f"still running after {CASE_TIMEOUT_S} s")


def run_case(argv, folder: Path, codes=(1, 2)) -> str | None:
    """Run main(argv) in-process, fd 2 captured; None if the promise held, else why not."""
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

    def cli(argv, setup=None, codes=(1, 2)):
        def runner(folder):
            try:
                if setup is not None:
                    setup(folder)
                args = [a.format(d=folder, **fill) if "{" in a else a for a in argv]
                return run_case(args, folder, codes)
            except CaseSkipped:
                return None
            finally:
                _undo_read_only(folder)
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
    for label, argv in ignored_option_cases():  # 2: "-inf" reads as an option to argparse
        yield label, cli(argv, codes=(1, 2))
    for label, argv, setup in output_first_cases():
        yield label, cli(argv, setup, codes=(1,))
    for label, argv, setup in message_cases():
        yield label, cli(argv, setup, codes=(1,))
    for label, argv, how, code in console_cases():
        yield label, console(argv, how, code)


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
            failed.append(("inputs", "an input file changed"))
    print(f"bad-input sweep: {n - len(failed)} of {n} cases held the promise (one line, "
          f"right exit code, nothing written) in {time.perf_counter() - t0:.0f} s")
    for label, problem in failed:
        print(f"  FAILED {label}: {problem}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
