"""The bad-input sweep's cases of the audit of issues 22 and 24 (2026-11-25): faults tried
as a new user and a hostile environment would, outside the earlier classes' generators.

Each case is (label, argv, setup, expect): ``expect`` is a piece of the one error line, so
a case refused for another reason than the one its label names fails (the earlier cases
check the line's shape only). Classes: data given twice and held-out files that are not
held out; pose files in degrees read as radians and candidates that identify nothing;
CSV, JSON and URDF files damaged or in another's place; wrong robots, tips and units
through the command line; outputs on a full disk (a 4-64 kB tmpfs, root only), in
read-only folders, behind symlinks and hard links, already there; fleet and simulate
misuse; non-finite options not covered before.

Used by scripts/bad_input_sweep.py; argv use its placeholders {d} (the case's folder),
{csv} (a good point file), {poses} (a good pose file), {urdf} (a corrected URDF) and
{frames} (its FRAMES.json).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
from pathlib import Path

from bad_input_cli_cases import _MOUNTS, TREE_URDF, CaseSkipped, _read_only

GIVEN_TWICE = "a data file given twice counts each sample twice"
NOT_HELD_OUT = "held-out errors judge a calibration on samples it did not see"
DEGREES = "were the joint values degrees? Read them with --angle-unit deg"
INPUT = "refusing to overwrite the input file"
FULL = "No space left on device"


def _rows(path) -> list[str]:
    return [r for r in Path(path).read_text().splitlines() if not r.startswith("#")]


def _write(name, text_of):
    """setup: d/name holding text_of(fill) (fill: the sweep's good input paths)."""
    return lambda d, fill: (d / name).write_text(text_of(fill))


def _degrees(fill) -> str:
    rows = _rows(fill["csv"])
    return "\n".join([rows[0]] + [",".join(repr(math.degrees(float(c))) if i < 6 else c
                                           for i, c in enumerate(r.split(",")))
                                  for r in rows[1:]]) + "\n"


def _cell(fill, row: int, col: int, value: str) -> str:
    rows = _rows(fill["csv"])
    cells = rows[row].split(",")
    cells[col] = value
    rows[row] = ",".join(cells)
    return "\n".join(rows) + "\n"


def _column(fill, name: str, value) -> str:
    rows = _rows(fill["csv"])
    return "\n".join([rows[0] + "," + name] + [r + "," + str(value(k))
                                              for k, r in enumerate(rows[1:])]) + "\n"


def _frames_with(fill, key: str, value) -> str:
    frames = json.loads(Path(fill["frames"]).read_text())
    frames[key] = value
    return json.dumps(frames)  # a NaN as JSON's NaN token


def _full_disk(size: str):
    """setup: a tmpfs of ``size`` mounted on the case's folder itself (so no folder the
    snapshot sees changes its time when a staged file is made and removed); root only."""
    def setup(d, fill):
        if os.geteuid() != 0 or subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)],
                capture_output=True).returncode != 0:
            raise CaseSkipped("no way to mount a small file system here")
        _MOUNTS.append(d)
    return setup


def _link(name: str, target_of):
    return lambda d, fill: (d / name).symlink_to(target_of(d, fill))


def _both(*setups):
    def setup(d, fill):
        for s in setups:
            s(d, fill)
    return setup


def _ro(d, fill):
    _read_only(d)


def _prior_file(d, fill) -> None:
    """d/p.json: a fleet prior of the EC66 design (tip flange, model complete), two units of
    0.1 mm and 0.01 deg scatter about nominal, written as kincal fleet writes it."""
    import numpy as np

    from kincal.export.report import dumps
    from kincal.identification.prior import FleetPrior
    from kincal.models import build
    from kincal.robot import Robot

    robot = Robot.load("ec66", tip="flange")
    m = build("complete", robot.geometry)
    sd = np.where(np.asarray(m.is_length, bool), 1e-4, 1.7e-4)
    prior = FleetPrior.estimate(robot, "complete", m.names, m.is_length, m.nominal,
                                np.array([sd, -sd]), ["u1", "u2"])
    (d / "p.json").write_text(dumps(prior.as_dict()))


def audit_cases():
    """(label, argv, setup(folder, fill) or None, expect) of the audit's faults: each
    refused with one line holding ``expect``, exit code 1, nothing written."""
    cal = ["calibrate", "ec66", "{csv}", "--method", "ls"]
    data = ["calibrate", "ec66", "{d}/x.csv", "--out", "{d}/o.urdf"]
    ev = ["evaluate", "ec66", "{csv}", "--frames", "{d}/f.json"]
    fleet = ["fleet", "ec66", "{csv}", "{poses}", "--quiet"]  # two units
    comp = ["compensate", "{urdf}", "{csv}", "--frames", "{frames}", "--tip", "flange"]
    mapped = ["--joint-columns"] + [f"{u}=joint_{k + 1}" for k, u in enumerate(
        ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
         "wrist_2_joint", "wrist_3_joint"))]
    copy = _write("copy.csv", lambda f: Path(f["csv"]).read_text())
    other = _write("other.csv", lambda f: "\n".join(_rows(f["csv"])) + "\n")
    deg = _write("deg.csv", _degrees)
    yield from [
        # data given twice, held-out files that are not held out
        ("calibrate: a data file given twice", ["calibrate", "ec66", "{csv}", "{csv}", "--out",
                                                "{d}/o.urdf"], None, GIVEN_TWICE),
        ("calibrate: a copy of the data file's bytes", ["calibrate", "ec66", "{csv}",
                                                        "{d}/copy.csv", "--out", "{d}/o.urdf"],
         copy, "has the same bytes as"),
        ("analyze: a data file given twice", ["analyze", "ec66", "{csv}", "{csv}"], None,
         GIVEN_TWICE),
        ("calibrate: --validate is the data file", cal + ["--validate", "{csv}", "--out",
                                                          "{d}/o.urdf"], None, NOT_HELD_OUT),
        ("calibrate: --validate holds the training samples", cal + [
            "--validate", "{d}/other.csv", "--out", "{d}/o.urdf"], other, NOT_HELD_OUT),
        # pose files in degrees read as radians; candidates that identify nothing
        ("plan: candidates in degrees", ["plan", "ec66", "{d}/deg.csv", "--poses", "12",
                                         "--out", "{d}/p.csv"], deg, DEGREES),
        ("plan: --measured in degrees", ["plan", "ec66", "--random", "50", "--measured",
                                         "{d}/deg.csv", "--poses", "5", "--out", "{d}/p.csv"],
         deg, DEGREES),
        ("simulate: --poses-file in degrees", ["simulate", "ec66", "--poses-file",
                                               "{d}/deg.csv", "--out", "{d}/s.csv"], deg,
         DEGREES),
        ("analyze: --accuracy-poses in degrees", ["analyze", "ec66", "{csv}", "--accuracy-poses",
                                                  "{d}/deg.csv"], deg, DEGREES),
        ("plan: twenty copies of one pose as candidates", [
            "plan", "ec66", "{d}/x.csv", "--poses", "5", "--out", "{d}/p.csv"],
         _write("x.csv", lambda f: "\n".join([_rows(f["csv"])[0]] + [_rows(f["csv"])[1]] * 20)),
         "identify no parameter of the chain's joints"),
        # CSV, JSON and URDF files damaged or in another's place
        ("csv: a header line of separators alone", data, _write("x.csv", lambda f: ",,\n1,1,1\n"),
         "holds numbers, not column names"),
        ("csv: an empty data file", data, _write("x.csv", lambda f: ""),
         "the file is empty; expected a header naming"),
        ("csv: truncated mid-row", data, _write("x.csv", lambda f: "\n".join(
            _rows(f["csv"]))[:1500]), "cells, the header has"),
        ("csv: a sigma column of zeros", data, _write("x.csv", lambda f: _column(
            f, "sigma", lambda k: 0)), "is outside the accepted range"),
        ("csv: a sigma of nan", data, _write("x.csv", lambda f: _column(
            f, "sigma", lambda k: "nan" if k == 3 else 1e-4)), "'nan'; expected a finite number"),
        ("csv: an order column with nan", data + ["--order-column", "t", "--backlash",
                                                  "joint_5"],
         _write("x.csv", lambda f: _column(f, "t", lambda k: "nan" if k == 3 else k)),
         "column 't': 'nan'"),
        ("csv: an order column repeating a value", data + ["--order-column", "t", "--backlash",
                                                           "joint_5"],
         _write("x.csv", lambda f: _column(f, "t", lambda k: min(k, 5))), "the same order value"),
        ("csv: two joints mapped onto one column", cal + ["--joint-columns", "joint_1=joint_2",
                                                          "--out", "{d}/o.urdf"], None,
         "would both be read from column"),
        ("csv: CR line ends and a nan", data, _write("x.csv", lambda f: "\r".join(
            _rows(f["csv"])).replace(_rows(f["csv"])[3].split(",")[0], "nan", 1)),
         "'nan'; expected a finite number"),
        ("csv: a position of nan for evaluate", ["evaluate", "ec66", "{d}/x.csv", "--frames",
                                                 "{frames}"],
         _write("x.csv", lambda f: _cell(f, 5, 7, "nan")), "'nan'; expected a finite number"),
        ("csv: a digit separator (float() reads 1_5 as 15)", data,
         _write("x.csv", lambda f: _cell(f, 5, 7, "1_5")),
         "'1_5'; expected a finite number written with the digits 0-9"),
        ("csv: a fullwidth digit (float() reads it as 1)", data,
         _write("x.csv", lambda f: _cell(f, 4, 2, "\uff11")),
         "expected a finite number written with the digits 0-9"),
        ("json: FRAMES.json is a URDF", ["evaluate", "ec66", "{csv}", "--frames", "{urdf}"],
         None, "is XML (a URDF or xacro file?), not a kincal frames file"),
        ("json: --prior is a data file", cal + ["--prior", "{csv}", "--out", "{d}/o.urdf"],
         None, "is a CSV file (a data file?), not a kincal fleet prior"),
        ("json: --prior truncated", cal + ["--prior", "{d}/p.json", "--out", "{d}/o.urdf"],
         _write("p.json", lambda f: '{"format": "kincal-fleet-prior", "version": 1, "units": ['),
         "not a kincal fleet prior (invalid JSON"),
        ("json: --prior of the design on a corrected URDF", [
            "calibrate", "{urdf}", "{csv}", "--tip", "flange", "--model", "complete", "--prior",
            "{d}/p.json", "--out", "{d}/o.urdf"], _prior_file,
         "learned on a robot of another design"),
        ("json: --prior with --lambda 0", ["calibrate", "ec66", "{csv}", "--model", "complete",
                                           "--prior", "{d}/p.json", "--lambda", "0", "--out",
                                           "{d}/o.urdf"], _prior_file,
         "lambda 0 (--lambda 0) switches off"),
        ("json: FRAMES.json truncated", ev, _write("f.json", lambda f: Path(
            f["frames"]).read_text()[:200]), "not a kincal frames file (invalid JSON"),
        ("json: a backlash of 1e300", ev, _write("f.json", lambda f: _frames_with(
            f, "backlash", {"joint_5": 1e300})), "is not a plausible half play"),
        ("json: a compliance of NaN", ev, _write("f.json", lambda f: _frames_with(
            f, "compliance", {"joint_2": float("nan")})), "compliance.joint_2 is not a finite"),
        ("urdf: truncated in half", ["calibrate", "{d}/r.urdf", "{csv}", "--tip", "flange",
                                     "--out", "{d}/o.urdf"],
         _write("r.urdf", lambda f: Path(f["urdf"]).read_text()[:3000]), "malformed XML"),
        # wrong robots, tips and units through the command line
        ("robot: UR10 for EC66 data", ["calibrate", "ur10", "{csv}", *mapped, "--out",
                                       "{d}/o.urdf"], None, "implausible calibration"),
        ("tip: link_4 for flange data", ["calibrate", "ec66", "{csv}", "--tip", "link_4",
                                         "--out", "{d}/o.urdf"], None, "implausible calibration"),
        ("units: metres read as millimetres", ["calibrate", "ec66", "{csv}", "--length-unit",
                                               "mm", "--out", "{d}/o.urdf"], None,
         "positions in metres read as millimetres"),
        ("tip: evaluate flange frames at link_6", ["evaluate", "ec66", "{csv}", "--frames",
                                                   "{frames}", "--tip", "link_6"], None,
         "does not match the tip frame 'flange' recorded"),
        ("robot: evaluate EC66 frames on UR10", ["evaluate", "ur10", "{csv}", "--tip", "tool0",
                                                 *mapped, "--frames", "{frames}"], None,
         "does not match the tip frame 'flange' recorded"),
        ("robot: compensate with UR10 as the nominal", ["compensate", "{urdf}", "--program",
                                                        "{csv}", "--nominal", "ur10", "--tip",
                                                        "flange", "--out", "{d}/j.csv"], None,
         "unknown tip frame 'flange' in robot 'ur10'"),
        # outputs on a full disk
        ("disk full: calibrate's four outputs", cal + [
            "--out", "{d}/o.urdf", "--report", "{d}/r.json", "--html", "{d}/r.html", "--plots",
            "{d}/p"], _full_disk("48k"), FULL),
        ("disk full: simulate 3000 poses", ["simulate", "ec66", "--poses", "3000", "--out",
                                            "{d}/s.csv"], _full_disk("64k"), FULL),
        ("disk full: plan 200 poses", ["plan", "ec66", "--random", "3000", "--poses", "200",
                                       "--out", "{d}/p.csv"], _full_disk("8k"), FULL),
        ("disk full: compensate", comp + ["--out", "{d}/j.csv"], _full_disk("4k"), FULL),
        ("disk full: analyze --accuracy-plot", ["analyze", "ec66", "{csv}", "--accuracy-map",
                                                "0.4", "0", "0.25", "0.2", "--accuracy-plot",
                                                "{d}/m.png"], _full_disk("8k"), FULL),
        ("disk full: demo", ["demo", "--out", "{d}/demo"], _full_disk("64k"), FULL),
        ("disk full: fleet", fleet + ["--out-dir", "{d}/D"], _full_disk("64k"), FULL),
        # read-only folders
        ("read-only: fleet --out-dir", fleet + ["--out-dir", "{d}/ro/D"], _ro, "cannot write in"),
        ("read-only: analyze --accuracy-plot", ["analyze", "ec66", "{csv}", "--accuracy-map",
                                                "0.4", "0", "0.25", "0.2", "--accuracy-plot",
                                                "{d}/ro/m.png"], _ro, "cannot write in"),
        ("read-only: calibrate --residuals-out", cal + ["--out", "{d}/o.urdf", "--residuals-out",
                                                        "{d}/ro/r.csv"], _ro, "cannot write in"),
        # symlinks and hard links
        ("symlink: --out into a read-only folder", cal + ["--out", "{d}/o.urdf"],
         _both(_ro, _link("o.urdf", lambda d, f: d / "ro" / "o.urdf")), "a dangling symlink"),
        ("symlink: --out to a folder", cal + ["--out", "{d}/o.urdf", "--overwrite"],
         _both(lambda d, f: (d / "dir").mkdir(), _link("o.urdf", lambda d, f: d / "dir")),
         "is a directory"),
        ("symlink: --plots to a file", cal + ["--out", "{d}/o.urdf", "--plots", "{d}/p"],
         _both(_write("f", lambda f: "keep"), _link("p", lambda d, f: d / "f")),
         "exists and is not a directory"),
        ("symlink: fleet --out-dir to a file", fleet + ["--out-dir", "{d}/D"],
         _both(_write("f", lambda f: "keep"), _link("D", lambda d, f: d / "f")),
         "exists and is not a directory"),
        ("symlink: fleet --out-dir a loop", fleet + ["--out-dir", "{d}/D"],
         _link("D", lambda d, f: d / "D"), "symlink loop"),
        ("symlink: data to a folder", data, _both(lambda d, f: (d / "dir").mkdir(),
                                                  _link("x.csv", lambda d, f: d / "dir")),
         "got a directory"),
        ("symlink: data dangling", data, _link("x.csv", lambda d, f: d / "nowhere"),
         "data file not found"),
        ("symlink: --out to the robot, no --overwrite", [
            "calibrate", "{urdf}", "{csv}", "--tip", "flange", "--out", "{d}/o.urdf"],
         _link("o.urdf", lambda d, f: f["urdf"]), INPUT),
        ("symlink: evaluate --report to its frames, --overwrite", [
            "evaluate", "ec66", "{csv}", "--frames", "{frames}", "--report", "{d}/r.json",
            "--overwrite"], _link("r.json", lambda d, f: f["frames"]), INPUT),
        ("symlink: simulate --out to its --poses-file", [
            "simulate", "ec66", "--poses-file", "{csv}", "--out", "{d}/s.csv", "--overwrite"],
         _link("s.csv", lambda d, f: f["csv"]), INPUT),
        ("symlink: plan --out to --measured", [
            "plan", "ec66", "--random", "50", "--measured", "{csv}", "--poses", "5", "--out",
            "{d}/p.csv", "--overwrite"], _link("p.csv", lambda d, f: f["csv"]), INPUT),
        ("symlink: compensate --out to --frames", comp + ["--out", "{d}/j.csv", "--overwrite"],
         _link("j.csv", lambda d, f: f["frames"]), INPUT),
        ("hard link: compensate --out of its targets", [
            "compensate", "{urdf}", "{d}/t.csv", "--frames", "{frames}", "--tip", "flange",
            "--out", "{d}/j.csv", "--overwrite"],
         _both(_write("t.csv", lambda f: Path(f["csv"]).read_text()),
               lambda d, f: os.link(d / "t.csv", d / "j.csv")), INPUT),
        ("hard link: calibrate --report of its data", [
            "calibrate", "ec66", "{d}/t.csv", "--out", "{d}/o.urdf", "--report", "{d}/r.json",
            "--overwrite"], _both(_write("t.csv", lambda f: Path(f["csv"]).read_text()),
                                  lambda d, f: os.link(d / "t.csv", d / "r.json")), INPUT),
        # existing outputs, two outputs on one file
        ("existing: simulate --truth-out", ["simulate", "ec66", "--poses", "5", "--out",
                                            "{d}/s.csv", "--truth-out", "{d}/t.json"],
         _write("t.json", lambda f: "keep"), "already exists"),
        ("existing: fleet FLEET.json", fleet + ["--out-dir", "{d}/D"],
         lambda d, f: ((d / "D").mkdir(), (d / "D" / "FLEET.json").write_text("keep")),
         "already exists"),
        ("existing: a stranger's folder named as a unit, --overwrite", fleet + [
            "--out-dir", "{d}/D", "--overwrite"],
         lambda d, f: ((d / "D" / "good").mkdir(parents=True),
                       (d / "D" / "good" / "notes.txt").write_text("keep")),
         "holds files a fleet unit does not write"),
        ("outputs: --report equal to --frames-out", cal + [
            "--out", "{d}/o.urdf", "--frames-out", "{d}/f.json", "--report", "{d}/f.json"],
         None, "two outputs name the same file"),
        ("outputs: --residuals-out equal to --out", cal + [
            "--out", "{d}/o.urdf", "--residuals-out", "{d}/o.urdf"], None,
         "two outputs name the same file"),
        ("outputs: simulate --truth-out equal to --out", [
            "simulate", "ec66", "--poses", "5", "--out", "{d}/s.csv", "--truth-out",
            "{d}/s.csv"], None, "two outputs name the same file"),
        # fleet and simulate misuse
        ("fleet: --out-dir empty (the current folder)", fleet + ["--out-dir", ""], None,
         "an output folder must be a non-empty str or Path, got ''"),
        ("calibrate: --plots empty", ["calibrate", "ec66", "{csv}", "--out", "{d}/o.urdf",
                                      "--plots", ""], None,
         "an output folder must be a non-empty str or Path, got ''"),
        ("fleet: --scheduler without a port", fleet + ["--out-dir", "{d}/D", "--scheduler",
                                                       "localhost"], None,
         "no Dask scheduler answers there (missing port number"),
        ("fleet: --scheduler the dashboard's http://", fleet + [
            "--out-dir", "{d}/D", "--scheduler", "http://127.0.0.1:8787"], None,
         "no Dask scheduler answers there (unknown address scheme 'http'"),
        ("fleet: --out-dir is a file", fleet + ["--out-dir", "{d}/D"],
         _write("D", lambda f: "keep"), "exists and is not a directory"),
        ("fleet: a unit that would be DIR/..", ["fleet", "ec66", "{csv}", "{d}/...csv",
                                                "--out-dir", "{d}/D"],
         _write("...csv", lambda f: Path(f["csv"]).read_text()), "its unit would be DIR/.."),
        ("simulate: an empty --poses-file", ["simulate", "ec66", "--poses-file", "{d}/x.csv",
                                             "--out", "{d}/s.csv"], _write("x.csv", lambda f: ""),
         "the file is empty"),
        ("simulate: --model mdh on a tree path", [
            "simulate", "{d}/tree.urdf", "--base", "atip", "--tip", "btip", "--center-m", "0",
            "0", "0.3", "--model", "mdh", "--out", "{d}/s.csv"],
         _write("tree.urdf", lambda f: TREE_URDF), "cannot describe a tree path"),
        ("compensate: empty targets", ["compensate", "{urdf}", "{d}/x.csv", "--frames",
                                       "{frames}", "--tip", "flange", "--out", "{d}/j.csv"],
         _write("x.csv", lambda f: ""), "the file is empty"),
        ("plan: a candidate of nan", ["plan", "ec66", "{d}/x.csv", "--poses", "5", "--out",
                                      "{d}/p.csv"], _write("x.csv", lambda f: _cell(f, 5, 1, "nan")),
         "'nan'; expected a finite number"),
        # non-finite options not covered before
        ("nan: compensate --tolerance-mm", comp + ["--out", "{d}/j.csv", "--tolerance-mm", "nan"],
         None, "--tolerance-mm must be a finite number"),
        ("nan: analyze --joint-value", ["analyze", "ec66", "{csv}", "--joint-value",
                                        "joint_1=nan"], None, "expects NAME=VALUE"),
        ("nan: plan --target-cube", ["plan", "ec66", "--random", "50", "--poses", "10",
                                     "--criterion", "i", "--in-cube", "0.4", "0", "0.25", "0.3",
                                     "--target-cube", "0.4", "nan", "0.25", "0.3", "--out",
                                     "{d}/p.csv"], None, "--target-cube CX CY CZ must be a finite"),
        ("nan: fleet --tool-offset", ["fleet", "ec66", "{csv}", "{poses}", "--tool-offset", "0",
                                      "nan", "0", "--out-dir", "{d}/D"], None,
         "--tool-offset must be a finite number"),
        # --on-plane used nowhere: a log with position or pose columns is read as its kind
        ("calibrate: --on-plane --flush, a pose file", [
            "calibrate", "ec66", "{poses}", "--on-plane", "--flush", "--out", "{d}/o.urdf"],
         None, "reads files of joint columns alone as contacts, but every data file"),
        ("evaluate: --on-plane, a point file", [
            "evaluate", "{urdf}", "{csv}", "--frames", "{frames}", "--tip", "flange",
            "--on-plane"], None, "reads files of joint columns alone as contacts"),
    ]
