"""--joint-value NAME=VALUE: a chain joint absent from the data file, held during the
measurements; the same result as a file with its constant column, recorded in FRAMES.json
and the report, refused when the file has the column or the joint is not on the chain."""

import json

import numpy as np

from kincal.cli.main import main
from kincal.frames_file import CellFrames


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out = capsys.readouterr()
    return code, out.out, out.err


def write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(repr, r.tolist())) + "\n"
                                                       for r in rows))
    return path


def test_held_joint_gives_the_same_calibration_and_is_recorded(tmp_path, capsys):
    full = tmp_path / "full.csv"
    assert main(["simulate", "ec66", "--poses", "30", "--out", str(full), "--seed", "4"]) == 0
    capsys.readouterr()
    lines = [r for r in full.read_text().splitlines() if not r.startswith("#")]
    header = lines[0].split(",")
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    k = header.index("joint_6")
    rows[:, k] = 30.0 * np.pi / 180  # the wrist held at 30 deg
    with_column = write(tmp_path / "with.csv", header, rows)
    in_deg = rows.copy()
    joints = [i for i, h in enumerate(header) if h.startswith("joint_")]
    in_deg[:, joints] = np.degrees(rows[:, joints])  # the file in degrees, as --angle-unit says
    without = write(tmp_path / "without.csv", header[:k] + header[k + 1:],
                    np.delete(in_deg, k, axis=1))
    common = ("--model", "offsets", "--fix", "joint_6.theta", "--lambda", 0)
    code, out1, err = run(capsys, "calibrate", "ec66", with_column, *common, "--out",
                          tmp_path / "a.urdf", "--frames-out", tmp_path / "a.json")
    assert code == 0, err
    code, out2, err = run(capsys, "calibrate", "ec66", without, *common, "--joint-value",
                          "joint_6=30", "--angle-unit", "deg", "--out", tmp_path / "b.urdf",
                          "--frames-out", tmp_path / "b.json", "--report", tmp_path / "r.json")
    assert code == 0, err
    assert "joints held during the measurements (not in the file): joint_6 = 30 deg" in out2
    a, b = (json.loads((tmp_path / f).read_text())["sets"][0] for f in ("a.json", "b.json"))
    np.testing.assert_allclose(list(a["frames"].values()), list(b["frames"].values()),
                               atol=1e-9)
    assert "fixed_joints" not in a
    assert b["fixed_joints"] == {"joint_6": np.radians(30.0)}
    assert CellFrames.read(tmp_path / "b.json").sets[0].fixed_joints == (
        ("joint_6", np.radians(30.0)),)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["sets"][0]["fixed_joints"] == {"joint_6": np.radians(30.0)}
    # evaluate and analyze read the file the same way
    code, out, err = run(capsys, "evaluate", tmp_path / "b.urdf", without, "--frames",
                         tmp_path / "b.json", "--joint-value", "joint_6=30", "--angle-unit",
                         "deg")
    assert code == 0, err
    code, ref, err = run(capsys, "evaluate", tmp_path / "b.urdf", with_column, "--frames",
                         tmp_path / "b.json")
    assert out.splitlines()[1] == ref.splitlines()[1]
    code, out, err = run(capsys, "analyze", "ec66", without, "--joint-value", "joint_6=5",
                         "--angle-unit", "deg")
    assert code == 0, err


def test_joint_value_refusals_are_one_line(tmp_path, capsys):
    data = tmp_path / "d.csv"
    assert main(["simulate", "ec66", "--poses", "10", "--out", str(data), "--seed", "1"]) == 0
    capsys.readouterr()
    for argv, says in ((("--joint-value", "joint_6=0"), "has a column for joint_6"),
                       (("--joint-value", "joint_9=0"), "not a joint of the chain"),
                       (("--joint-value", "joint_6"), "expects NAME=VALUE"),
                       (("--joint-value", "joint_6=nan"), "expects NAME=VALUE"),
                       (("--joint-value", "joint_6=1", "--joint-value", "joint_6=2"),
                        "given twice")):
        code, out, err = run(capsys, "analyze", "ec66", data, *argv)
        assert code == 1 and err.count("\n") == 1 and says in err, err
