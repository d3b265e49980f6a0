"""The bad-input sweep's cases for the command line's own promises (issue 24): options
that would be ignored (class 3), outputs checked before the work (4), path and OS errors
(5), console failures (6), misleading messages (8) and foreign stderr lines (9).

Used by scripts/bad_input_sweep.py; argv use the placeholders {d} (the case's folder),
{csv} (a good point file), {poses} (a good pose file) and {urdf} (a corrected URDF).
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path


def snapshot(folder: Path) -> dict:
    out = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        data = p.read_bytes() if stat.S_ISREG(st.st_mode) else None
        out[str(p.relative_to(folder))] = (stat.S_IFMT(st.st_mode), data, st.st_mtime_ns)
    return out


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
    for base, name in ((plan, "plan"), (sim, "simulate")):
        yield f"{name} --no-collision without a volume", base + ["--no-collision"]
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


def undo_read_only(folder: Path) -> None:
    """Undo _read_only, and a file system mounted on the folder itself (a full disk)."""
    ro = folder / "ro"
    if ro in _MOUNTS:
        subprocess.run(["umount", str(ro)], check=True)
        _MOUNTS.remove(ro)
    elif ro.exists():
        ro.chmod(0o755)
    if folder in _MOUNTS:
        subprocess.run(["umount", str(folder)], check=True)
        _MOUNTS.remove(folder)


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
    """(label, argv, setup, expect) of inputs whose one line used to name another problem
    (class 8); expect: what the line must say."""
    def write(name, text):
        return lambda d: (d / name).write_text(text)

    for text, what, expect in (("", "empty", "the frames file is empty"),
                               ("  \n\n", "blank", "the frames file is empty"),
                               ("[1, 2]", "a list", "a JSON object was expected"),
                               ("[" * 10_000, "10,000 deep", "JSON nested too deeply")):
        for argv in (["evaluate", "ec66", "{csv}", "--frames", "{d}/f.json"],
                     ["compensate", "{urdf}", "{csv}", "--frames", "{d}/f.json", "--out",
                      "{d}/j.csv"]):
            yield f"{argv[0]} frames {what}", argv, write("f.json", text), expect
    for header, expect in (("joint_1,,,x", "columns 2-3 hold numbers but have no name"),
                           (",,", "line 2 holds numbers, not column names"),
                           ("joint_1,joint_2,,y,,z", "columns 3, 5 hold numbers but have no")):
        yield (f"csv unnamed columns {header!r}",
               ["calibrate", "ec66", "{d}/u.csv", "--out", "{d}/o.urdf"],
               write("u.csv", header + "\n" + ",".join("1" * max(1, header.count(",") + 1))
                     + "\n"), expect)


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
            undo_read_only(folder)
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


# ------------------------------------------------ chains: tree paths, several, mimic
TREE_URDF = """<?xml version="1.0"?>
<robot name="sweep_tree">
  <link name="base_link"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"/>
  <joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0.2" rpy="0.2 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.2" upper="0.2" effort="1" velocity="1"/></joint>
  <link name="l2"/>
  <joint name="atip_joint" type="fixed"><parent link="l2"/><child link="atip"/>
    <origin xyz="0 0.1 0" rpy="0 0.3 0"/></joint>
  <link name="atip"/>
  <joint name="k1" type="revolute"><parent link="base_link"/><child link="m1"/>
    <origin xyz="0 0.2 0.3" rpy="0 0 0.4"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="m1"/>
  <joint name="k2" type="continuous"><parent link="m1"/><child link="m2"/>
    <origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 1 0"/></joint>
  <link name="m2"/>
  <joint name="finger" type="revolute"><parent link="m2"/><child link="f"/>
    <origin xyz="0.2 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="k2" multiplier="0.5" offset="0"/></joint>
  <link name="f"/>
  <joint name="btip_joint" type="fixed"><parent link="f"/><child link="btip"/>
    <origin xyz="0.05 0 0" rpy="0 0 0"/></joint>
  <link name="btip"/>
  <joint name="p1" type="planar"><parent link="base_link"/><child link="pl"/>
    <origin xyz="0 -0.3 0" rpy="0 0 0"/><axis xyz="0 0 1"/></joint>
  <link name="pl"/>
</robot>
"""


def tree_inputs(d: Path) -> dict:
    """The tree URDF and its data files (good columns, arbitrary numbers: every case is
    refused before a fit) written into ``d``; {name: path}."""
    import numpy as np

    rng = np.random.default_rng(0)
    out = {"tree": d / "tree.urdf"}
    out["tree"].write_text(TREE_URDF)
    for name, cols in (("up", ["j2", "j1", "k1", "k2", "finger", "x", "y", "z"]),
                       ("down", ["k1", "k2", "finger", "x", "y", "z"]),
                       ("nofinger", ["k1", "k2", "x", "y", "z"]),
                       ("touch_up", ["j2", "j1", "k1", "k2", "finger"]),
                       ("touch_down", ["k1", "k2", "finger"])):
        rows = rng.uniform(-0.1, 0.1, (12, len(cols)))
        out[name] = d / f"tree_{name}.csv"
        out[name].write_text(",".join(cols) + "\n" + "".join(
            ",".join(repr(float(v)) for v in r) + "\n" for r in rows))
    return out


def chain_cases():
    """(label, argv) of bad chains, several chains and mimic joints ({tree}, {up}, ...:
    tree_inputs' paths; {d}: the case's folder)."""
    cal = ["calibrate", "{tree}"]
    out = ["--out", "{d}/o.urdf", "--frames-out", "{d}/f.json"]
    two = cal + ["{up}", "{down}"]
    yield "chains: 3 --base for 2 files", two + ["--base", "atip", "base_link", "atip",
                                                  "--tip", "btip"] + out
    yield "chains: 3 --tip for 2 files", two + ["--base", "atip", "base_link", "--tip", "btip",
                                                 "btip", "atip"] + out
    yield "chains: complete on two chains", two + ["--base", "atip", "base_link", "--tip",
                                                   "btip", "--model", "complete"] + out
    # held-out files that are not data files (a data file as --validate is refused first)
    yield "chains: --validate with two chains", two + ["--base", "atip", "base_link", "--tip",
                                                       "btip", "--validate", "{nofinger}"] + out
    yield "chains: 3 --validate files for 2 data files", two + [
        "--base", "atip", "base_link", "--tip", "btip", "--validate", "{nofinger}",
        "{touch_up}", "{touch_down}"] + out
    yield "tree: --mdh-out on a tree path", cal + ["{up}", "--base", "atip", "--tip", "btip",
                                                   "--mdh-out", "{d}/m.csv"] + out
    yield "contacts: --accuracy-map on flush touches", cal + [
        "{touch_up}", "--base", "atip", "--tip", "btip", "--on-plane", "--flush",
        "--accuracy-map", "0", "0", "0.3", "0.2"] + out
    yield "chains: --shared-plane, two bases", cal + [
        "{touch_up}", "{touch_down}", "--base", "atip", "base_link", "--tip", "btip",
        "--on-plane", "--flush", "--shared-plane"] + out
    yield "chains: --shared-plane without --on-plane", two + [
        "--base", "atip", "base_link", "--tip", "btip", "--shared-plane"] + out
    yield "chains: base is the tip", cal + ["{up}", "--base", "btip", "--tip", "btip"] + out
    yield "chains: unknown tip on a tree", cal + ["{up}", "--base", "atip", "--tip", "btipp"] + out
    yield "chains: a planar joint on the path", cal + ["{up}", "--base", "pl", "--tip",
                                                       "btip"] + out
    yield "chains: file of the other chain", cal + ["{down}", "--base", "atip", "--tip",
                                                    "btip"] + out
    yield "chains: --backlash on no chain's joint", cal + ["{up}", "--base", "atip", "--tip",
                                                           "btip", "--backlash", "p1"] + out
    yield "chains: --joint-value on no chain's joint", cal + [
        "{nofinger}", "--base", "base_link", "--tip", "btip", "--joint-value", "j1=0.1"] + out
    yield "mimic: held while its master moves", cal + [
        "{nofinger}", "--base", "base_link", "--tip", "btip", "--joint-value",
        "finger=0.1"] + out
    yield "mimic: its master off the chain", ["analyze", "{tree}", "{nofinger}", "--base", "m2",
                                             "--tip", "btip"]
    yield "mimic: evaluate, held while its master moves", [
        "evaluate", "{tree}", "{nofinger}", "--base", "base_link", "--tip", "btip",
        "--fit-frames", "--joint-value", "finger=0.1"]


# ------------------------------- units and file kinds on the newer paths (audit, issue 6/11)
def _simulated(d: Path, name: str, *argv: str, degrees=(), millimetres=()) -> None:
    """d/name: a simulated EC66 file (``argv`` after ``simulate ec66``), its ``degrees``
    columns (a prefix: "joint_" for all joints) in degrees, ``millimetres`` columns in mm."""
    import contextlib
    import io
    import math

    from kincal.cli.main import main

    src = d / ("src-" + name)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["simulate", "ec66", "--out", str(src), "--poses", "40", *argv]) == 0
    rows = [r for r in src.read_text().splitlines() if not r.startswith("#")]
    src.unlink()
    header = rows[0].split(",")
    scale = [180 / math.pi if h.startswith(tuple(degrees)) and degrees else
             1e3 if h in millimetres else 1.0 for h in header]
    (d / name).write_text("\n".join([rows[0]] + [",".join(
        repr(float(c) * s) if s != 1.0 else c for c, s in zip(r.split(","), scale))
        for r in rows[1:]]) + "\n")


def unit_and_kind_cases():
    """(label, argv, setup) of wrong units on the newer paths (flush and plane contacts,
    poses with --orientation-format, compensate's program and targets), files of the wrong
    kind in another's place, malformed --joint-value and --xacro-arg, one fleet unit's data
    given twice, and outputs over inputs: each refused, one line, nothing written."""
    J = ("joint_",)

    def sim(name, *argv, **units):
        return lambda d: _simulated(d, name, *argv, **units)

    cal = ["calibrate", "ec66", "{d}/bad.csv", "--out", "{d}/o.urdf", "--frames-out",
           "{d}/f.json"]
    yield ("flush contacts in degrees read as radians", cal + ["--on-plane", "--flush"],
           sim("bad.csv", "--kind", "flush", degrees=J))
    yield ("plane contacts in degrees read as radians", cal + ["--on-plane"],
           sim("bad.csv", "--kind", "plane", degrees=J))
    rpy = ["--kind", "pose", "--orientation-format", "rpy-zyx"]
    yield ("pose rpy angles in degrees read as radians", cal + ["--orientation-format", "rpy-zyx"],
           sim("bad.csv", *rpy, degrees=("roll", "pitch", "yaw")))
    yield ("pose positions in mm read as m", cal + ["--orientation-format", "rpy-zyx"],
           sim("bad.csv", *rpy, millimetres=("x", "y", "z")))
    comp = ["compensate", "{urdf}", "--tip", "flange", "--out", "{d}/j.csv"]
    targets = ["compensate", "{urdf}", "{x}", "--tip", "flange", "--out", "{d}/j.csv",
               "--frames", "{frames}"]  # TARGETS right after the robot (argparse: nargs ?)

    def on(x, argv):
        return [a.replace("{x}", x) for a in argv]

    def renamed(d):  # a pose file whose quaternion a logger named otherwise
        _simulated(d, "bad.csv", "--kind", "pose")
        text = (d / "bad.csv").read_text()
        (d / "bad.csv").write_text(text.replace("qx,qy,qz,qw", "quat_x,quat_y,quat_z,quat_w", 1))
    for what, argv in (("calibrate", cal), ("evaluate", ["evaluate", "ec66", "{d}/bad.csv",
                                                         "--fit-frames"]),
                       ("compensate", on("{d}/bad.csv", targets))):
        yield f"{what}: orientation columns under a logger's names", argv, renamed
    for flag in ([], ["--flag-unreachable"]):
        yield (f"compensate --program in degrees {' '.join(flag)}",
               comp + ["--program", "{d}/bad.csv", "--nominal", "ec66", *flag],
               sim("bad.csv", degrees=J))
        yield (f"compensate targets' seeds in degrees {' '.join(flag)}",
               on("{d}/bad.csv", targets) + flag, sim("bad.csv", degrees=J))
    yield ("compensate targets in mm read as m", on("{d}/bad.csv", targets),
           sim("bad.csv", millimetres=("x", "y", "z")))
    # files of another kind in a file's place
    for what, argv in (("data", ["calibrate", "ec66", "{x}", "--out", "{d}/o.urdf"]),
                       ("--validate", ["calibrate", "ec66", "{csv}", "--validate", "{x}",
                                       "--out", "{d}/o.urdf"]),
                       ("--program", comp + ["--program", "{x}", "--nominal", "ec66"]),
                       ("targets", targets),
                       ("candidates", ["plan", "ec66", "{x}", "--poses", "5", "--out",
                                       "{d}/p.csv"]),
                       ("evaluate data", ["evaluate", "ec66", "{x}", "--fit-frames"])):
        for kind, x in (("a URDF", "{urdf}"), ("a FRAMES.json", "{frames}")):
            yield f"{what} is {kind}", on(x, argv), None
    for what, argv in (("robot", ["calibrate", "{x}", "{csv}", "--tip", "flange", "--out",
                                  "{d}/o.urdf"]),
                       ("--nominal", comp + ["--program", "{csv}", "--nominal", "{x}"]),
                       ("--frames", ["evaluate", "ec66", "{csv}", "--frames", "{x}"]),
                       ("--prior", ["calibrate", "ec66", "{csv}", "--prior", "{x}", "--out",
                                    "{d}/o.urdf"])):
        for kind, x in (("a CSV", "{csv}"), ("a FRAMES.json", "{frames}"), ("a URDF", "{urdf}")):
            if not (what == "robot" and kind == "a URDF") and not (
                    what == "--nominal" and kind == "a URDF") and not (
                    what == "--frames" and kind == "a FRAMES.json"):
                yield f"{what} is {kind}", on(x, argv), None
    for v in ("joint_1=abc", "joint_1=nan", "joint_1=inf", "=0.1", "joint_1", "joint_1=1e300",
              "nojoint=0.1"):
        yield f"--joint-value {v}", ["calibrate", "ec66", "{csv}", "--joint-value", v,
                                     "--out", "{d}/o.urdf"], None
    for v in ("foo", ":=1", "foo=1"):
        yield f"--xacro-arg {v}", ["calibrate", "ec66", "{csv}", "--xacro-arg", v, "--out",
                                   "{d}/o.urdf"], None
    for extra in (["--method", "ls"], ["--lambda", "0.1"], ["--lambda", "evidence"]):
        yield (f"--cv-max-poses with {' '.join(extra)} (no CV)", [
            "calibrate", "ec66", "{csv}", *extra, "--cv-max-poses", "10", "--out",
            "{d}/o.urdf"], None)
    for v in ("0", "100000"):  # 100,000 worker processes hung the machine starting them
        yield f"fleet --workers {v}", ["fleet", "ec66", "{csv}", "{poses}", "--workers", v,
                                       "--out-dir", "{d}/D"], None
    yield ("--xacro-arg on a plain URDF", ["calibrate", "ec66", "{csv}", "--xacro-arg",
                                           "ur_type:=ur5e", "--out", "{d}/o.urdf"], None)
    # outputs over inputs, --overwrite or not
    yield ("FRAMES.json over the robot", ["calibrate", "{urdf}", "{csv}", "--tip", "flange",
                                          "--out", "{d}/o.urdf", "--frames-out", "{urdf}",
                                          "--overwrite"], None)
    yield ("--residuals-out over the data", ["calibrate", "ec66", "{csv}", "--out", "{d}/o.urdf",
                                             "--residuals-out", "{csv}", "--overwrite"], None)
    yield ("--out over the --validate file", ["calibrate", "ec66", "{csv}", "--validate",
                                              "{poses}", "--out", "{poses}", "--overwrite"], None)
    yield ("compensate --out over its --program", comp[:-1] + [
        "{csv}", "--program", "{csv}", "--nominal", "ec66", "--overwrite"], None)
    # one fleet unit's data twice: two units of one
    fleet = ["fleet", "ec66", "--tip", "flange", "--out-dir", "{d}/D"]

    def copy(d):
        (d / "copy.csv").write_bytes(Path(d / "bad.csv").read_bytes())

    yield "fleet: one file twice", fleet + ["{csv}", "{csv}"], None
    yield ("fleet: a copy of a unit's file", fleet + ["{d}/bad.csv", "{csv}", "{d}/copy.csv"],
           lambda d: (sim("bad.csv")(d), copy(d)))
