"""A joint held still (no column, --joint-value) in two of a calibration's data sets at two
different values is not taken as held by evaluate and compensate (HeldJoints): the
calibration holds at neither value alone. That was silent: evaluate then failed on the
missing column, compensate moved the joint as a free one, and nothing said why. Now one
warning names the joint, both values and the sets, and what to do."""

import json
import math
import warnings

import numpy as np
import pytest

from kincal.cli.main import main
from kincal.errors import KincalWarning
from kincal.frames_file import CellFrames
from kincal.measurements.fixed_joints import HeldJoints
from kincal.robot import Robot

JOINTS = [f"joint_{k}" for k in range(1, 7)]
HELD = (0.3, 0.5)  # joint_6 [rad] in set 1 and set 2


def _poses(path, rng, n=40):
    q = rng.uniform(-1.2, 1.2, size=(n, 6))
    q[:, 5] = HELD[0]
    path.write_text(",".join(JOINTS) + "\n" + "\n".join(",".join(f"{v:.9f}" for v in row)
                                                       for row in q) + "\n")


def _without_joint_6(src, dst):
    lines = [line for line in src.read_text().splitlines() if not line.startswith("#")]
    k = lines[0].split(",").index("joint_6")
    dst.write_text("\n".join(",".join(c for i, c in enumerate(line.split(",")) if i != k)
                             for line in lines) + "\n")


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """Two sets holding joint_6, FRAMES.json recording them at 0.3 and 0.5 rad (as a
    calibration through the API, each set with its own with_fixed_joints, records them;
    the command line's --joint-value gives every file one value)."""
    d = tmp_path_factory.mktemp("held")
    rng = np.random.default_rng(3)
    for name, seed in (("a", "1"), ("b", "2"), ("val", "3")):
        _poses(d / f"q_{name}.csv", rng)
        assert main(["simulate", "ec66", "--poses-file", str(d / f"q_{name}.csv"), "--seed", seed,
                     "--tool-m", "0.03", "0.02", "0.12", "--out", str(d / f"full_{name}.csv"),
                     "-q"]) == 0
        _without_joint_6(d / f"full_{name}.csv", d / f"{name}.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(["calibrate", "ec66", str(d / "a.csv"), str(d / "b.csv"), "--method", "ls",
                     "--joint-value", f"joint_6={HELD[0]}", "--tool-offset", "0.03", "0.02",
                     "0.12", "--out", str(d / "cal.urdf"), "--frames-out",
                     str(d / "frames.json"), "-q"]) == 0
    frames = json.loads((d / "frames.json").read_text())
    assert [s["fixed_joints"] for s in frames["sets"]] == [{"joint_6": HELD[0]}] * 2
    frames["sets"][1]["fixed_joints"] = {"joint_6": HELD[1]}
    (d / "two.json").write_text(json.dumps(frames))
    return d


def _said(text: str) -> None:
    for words in ("joint_6", f"{math.degrees(HELD[0]):g} deg in set 1 (",
                  f"{math.degrees(HELD[1]):g} deg in set 2 (", "a.csv", "b.csv",
                  "holds at neither", "--joint-value joint_6=VALUE"):
        assert words in text, (words, text)


def test_two_held_values_are_warned_and_not_taken(cell):
    robot = Robot.load("ec66")
    with pytest.warns(KincalWarning) as caught:
        held = HeldJoints.of(CellFrames.read(cell / "two.json"), robot)
    assert held.values == ()
    (w,) = [w for w in caught if "held still at different values" in str(w.message)]
    _said(str(w.message))
    with warnings.catch_warnings():  # one value in every set: held, nothing said
        warnings.simplefilter("error", KincalWarning)
        assert HeldJoints.of(CellFrames.read(cell / "frames.json"), robot).values == (
            ("joint_6", HELD[0]),)


def test_evaluate_says_why_the_joint_is_not_held(cell, capsys):
    capsys.readouterr()
    argv = ["evaluate", "ec66", str(cell / "val.csv"), "--frames", str(cell / "two.json")]
    assert main(argv) == 1  # no column, and no one value to take: refused, after the why
    err = capsys.readouterr().err.splitlines()
    (line,) = [e for e in err if "held still at different values" in e]
    assert line.startswith("kincal: warning:")
    _said(line)
    (error,) = [e for e in err if e.startswith("kincal: error:")]
    assert "joint_6" in error, error
    # its value given: evaluated, the warning still says the calibration holds at neither
    assert main([*argv, "--joint-value", f"joint_6={HELD[0]}"]) == 0
    assert sum("held still at different values" in e
               for e in capsys.readouterr().err.splitlines()) == 1


def test_compensate_says_why_the_joint_moves(cell, capsys):
    capsys.readouterr()
    assert main(["compensate", str(cell / "cal.urdf"), str(cell / "full_val.csv"), "--tip",
                 "flange", "--frames", str(cell / "two.json"), "--out",
                 str(cell / "joints.csv"), "--flag-unreachable"]) == 0
    err = capsys.readouterr().err.splitlines()
    (line,) = [e for e in err if "held still at different values" in e]
    _said(line)
