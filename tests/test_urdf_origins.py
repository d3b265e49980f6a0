"""FRAMES.json's record of the calibrated URDF's joint origins (kincal.urdf_origins): a
compensation with the nominal URDF and the calibrated frames is refused, an evaluation
says so, a re-saved calibrated URDF is still the calibrated one."""

import json
import re

import numpy as np
import pytest

from kincal.cli.main import main
from kincal.compensation import CellFrames, compensate, filter_program, read_targets
from kincal.errors import DataError
from kincal.robot import Robot


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """(folder, data, corrected URDF, FRAMES.json, targets) of a simulated EC66 calibration."""
    d = tmp_path_factory.mktemp("origins")
    data, urdf, frames, targets = (d / n for n in ("d.csv", "c.urdf", "f.json", "t.csv"))
    assert main(["simulate", "ec66", "--poses", "40", "--seed", "2", "--out", str(data),
                 "-q"]) == 0
    assert main(["calibrate", "ec66", str(data), "--tip", "flange", "--out", str(urdf),
                 "--frames-out", str(frames), "-q"]) == 0
    assert main(["simulate", "ec66", "--poses", "8", "--seed", "9", "--out", str(targets),
                 "-q"]) == 0
    return d, data, urdf, frames, targets


def test_frames_json_records_the_origins_as_the_urdf_beside_has_them(calibrated):
    _, _, urdf, frames, _ = calibrated
    record = json.loads(frames.read_text())["urdf_origins"]
    robot = Robot.load(urdf, tip="flange")
    assert list(record) == list(robot.joint_names)
    text = urdf.read_text()
    for joint, origin in record.items():  # the numbers of the file, as written
        tag = re.search(rf'<joint name="{joint}".*?<origin ([^>]*)/>', text, re.S).group(1)
        xyz = [float(v) for v in re.search(r'xyz="([^"]*)"', tag).group(1).split()]
        assert xyz == origin["xyz"], joint
    assert len(CellFrames.read(frames).urdf_origins) == 6


def test_compensating_with_the_nominal_urdf_is_refused(calibrated, capsys):
    """`kincal compensate ec66 targets.csv --frames F.json` (the robot named as for
    calibrate) gave joint values for the nominal kinematics with the calibrated frames,
    exit 0, without a word."""
    d, _, urdf, frames, targets = calibrated
    out = d / "j.csv"
    capsys.readouterr()
    assert main(["compensate", "ec66", str(targets), "--tip", "flange", "--frames",
                 str(frames), "--out", str(out)]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("kincal: error: ") and f"ec66.urdf is not the calibrated URDF " \
        f"{frames} was written with: 5 of its chain's joint origins differ" in line, line
    assert "joint_2 " in line and " mm, " in line and "give the URDF written beside" in line
    assert not out.exists()
    assert main(["compensate", str(urdf), str(targets), "--tip", "flange", "--frames",
                 str(frames), "--out", str(out), "-q"]) == 0
    assert out.exists()


def test_the_api_refuses_it_too(calibrated):
    _, _, urdf, frames, targets = calibrated
    nominal, cal = Robot.load("ec66", tip="flange"), Robot.load(urdf, tip="flange")
    f = CellFrames.read(frames)
    t = read_targets(targets, nominal)
    with pytest.raises(DataError, match="is not the calibrated URDF"):
        compensate(nominal, f, t)
    assert compensate(cal, f, t).reached.all()
    q = np.zeros((3, 6)) + 0.3
    with pytest.raises(DataError, match="is not the calibrated URDF"):
        filter_program(nominal, nominal, q, f)
    assert filter_program(nominal, cal, q, f).reached.all()


def test_evaluating_the_nominal_urdf_with_calibrated_frames_says_so(calibrated, capsys):
    _, data, urdf, frames, _ = calibrated
    capsys.readouterr()
    assert main(["evaluate", "ec66", str(data), "--frames", str(frames)]) == 0
    out = capsys.readouterr().out
    assert "note: " in out and f"is not the calibrated URDF {frames} was written with (5 joint " \
        "origins differ" in out and "the figures are this URDF's kinematics with the " \
        "calibration's frames" in out, out
    assert main(["evaluate", str(urdf), str(data), "--frames", str(frames)]) == 0
    assert "is not the calibrated URDF" not in capsys.readouterr().out


def test_a_calibrated_urdf_resaved_with_fewer_digits_is_still_it(calibrated, capsys):
    """A tool that re-saves the URDF printing 7 decimals keeps it the calibrated one (1 um
    tolerance); one origin moved by 0.1 mm does not."""
    d, _, urdf, frames, targets = calibrated
    text = re.sub(r"-?\d+\.\d+(e-?\d+)?", lambda m: f"{float(m.group(0)):.7f}",
                  urdf.read_text())
    resaved = d / "resaved.urdf"
    resaved.write_text(text)
    assert main(["compensate", str(resaved), str(targets), "--tip", "flange", "--frames",
                 str(frames), "--out", str(d / "j2.csv"), "-q"]) == 0
    moved = re.sub(r'(<joint name="joint_4".*?<origin xyz=")(-?[\d.]+)',
                   lambda m: m.group(1) + f"{float(m.group(2)) + 1e-4:.7f}", text, count=1,
                   flags=re.S)
    assert moved != text
    (d / "moved.urdf").write_text(moved)
    capsys.readouterr()
    assert main(["compensate", str(d / "moved.urdf"), str(targets), "--tip", "flange",
                 "--frames", str(frames), "--out", str(d / "j3.csv")]) == 1
    err = capsys.readouterr().err
    assert "1 of its chain's joint origins differ from the calibrated ones (joint_4 0.100 mm" \
        in err, err


def test_frames_written_without_a_urdf_record_nothing(calibrated, tmp_path):
    """FRAMES.json alone (the API's Outputs(frames=...)): no URDF beside, nothing recorded,
    nothing checked."""
    from kincal import CalibrationProblem, Outputs, write_calibration
    from kincal.measurements.data import Measurements

    _, data, _, _, targets = calibrated
    robot = Robot.load("ec66", tip="flange")
    result = CalibrationProblem(robot, Measurements.from_csv(data, robot.joint_names)).solve()
    frames = tmp_path / "f.json"
    write_calibration(result, Outputs(frames=frames))
    assert "urdf_origins" not in json.loads(frames.read_text())
    assert main(["compensate", "ec66", str(targets), "--tip", "flange", "--frames",
                 str(frames), "--out", str(tmp_path / "j.csv"), "-q"]) == 0


def test_a_malformed_record_is_refused_in_one_line(calibrated, tmp_path, capsys):
    _, data, _, frames, _ = calibrated
    d = json.loads(frames.read_text())
    d["urdf_origins"] = {"joint_2": {"xyz": [0, 0]}}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    capsys.readouterr()
    assert main(["evaluate", "ec66", str(data), "--frames", str(bad)]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == (f"kincal: error: {bad}: not a kincal frames file (TypeError: urdf_origins, "
                    "joint joint_2: an origin is {\"xyz\": [3 numbers], \"rpy\": [3 numbers]})")
