"""kincal evaluate --fit-frames measurement: the measurement frame refitted, the tool and
kinematics of FRAMES.json kept (another day, same tool), beside the full refit."""

import json

import numpy as np
import pytest

from kincal import Robot
from kincal.cli.main import main
from kincal.frames_file import CellFrames, SetFrames, chain_hash
from kincal.measurements.pose import FRAMES

from test_pose_orientation import BASE, TOOL, predicted, write_poses

DAY2 = BASE + np.array([0.006, -0.002, 0.001, 0.004, -0.002, 0.003])  # the frame moved


def frames_file(path, robot, base, tool):
    f = CellFrames(robot.model_name, chain_hash(robot), robot.base, robot.tip, robot.joint_names,
                   (SetFrames("pose", "", FRAMES, tuple(np.r_[base, tool])),))
    path.write_text(f.dumps())
    return path


def evaluate(capsys, tmp_path, *argv):
    report = tmp_path / "e.json"
    assert main(["evaluate", "ec66", *map(str, argv), "--report", str(report),
                 "--overwrite"]) == 0
    out = capsys.readouterr().out
    return out, json.loads(report.read_text())


def test_measurement_refit_recovers_the_moved_frame_and_keeps_the_tool(tmp_path, capsys):
    robot = Robot.load("ec66")
    q = np.random.default_rng(5).uniform(-2.5, 2.5, size=(30, 6))
    p, R = predicted(robot, q, np.r_[DAY2, TOOL])  # day 2: same tool, moved frame
    data = write_poses(tmp_path / "day2.csv", robot.joint_names, q, p, R)
    right = frames_file(tmp_path / "right.json", robot, BASE, TOOL)
    out, rep = evaluate(capsys, tmp_path, data, "--frames", right)
    assert rep["errors"]["mean_mm"] > 1.0  # the day-1 frame is off by millimetres
    out, rep = evaluate(capsys, tmp_path, data, "--frames", right, "--fit-frames", "measurement")
    assert rep["errors"]["max_mm"] < 1e-6 and rep["orientation_errors"]["max_deg"] < 1e-6
    from kincal.rotations import base_rotation

    R = base_rotation(*BASE[3:]).T @ base_rotation(*DAY2[3:])
    deg = np.degrees(np.arccos((np.trace(R) - 1) / 2))
    mm = np.linalg.norm(DAY2[:3] - BASE[:3]) * 1e3
    assert f"moved {mm:.2f} mm, {deg:.3f} deg" in out
    # a wrong tool in the file stays wrong: only the full refit absorbs it
    wrong = frames_file(tmp_path / "wrong.json", robot, BASE, TOOL + [0.005, 0, 0, 0, 0, 0.02])
    out, rep = evaluate(capsys, tmp_path, data, "--frames", wrong, "--fit-frames", "measurement")
    assert rep["errors"]["mean_mm"] > 0.5
    out, rep = evaluate(capsys, tmp_path, data, "--fit-frames")
    assert rep["errors"]["max_mm"] < 1e-6


def test_measurement_refit_needs_frames_and_a_measurement_frame(tmp_path, capsys):
    robot = Robot.load("ec66")
    q = np.random.default_rng(6).uniform(-2, 2, size=(8, 6))
    p, R = predicted(robot, q, np.r_[BASE, TOOL])
    data = write_poses(tmp_path / "d.csv", robot.joint_names, q, p, R)
    assert main(["evaluate", "ec66", str(data), "--fit-frames", "measurement"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "keeps the tool of --frames" in err


def test_frame_move_is_the_rotation_angle_also_for_small_turns():
    """The frame's move is rotations.rotation_angle of the relative rotation: its former own
    arccos of the trace read a turn of 1e-8 rad as 0 and one of 1e-7 rad 1 % short."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from kincal.identification.frame_refit import moved

    km = SimpleNamespace(frame_names=FRAMES)
    for a in (1e-9, 1e-8, 1e-7, 1e-3, 3.0):
        after = np.r_[0.001, 0.0, 0.0, np.array([a, -a, 2 * a]) / 3 ** 0.5, np.zeros(6)]
        mm, deg = moved(np.zeros(12), after, km)
        angle = np.degrees(Rotation.from_euler("XYZ", after[3:6]).magnitude())  # Rx Ry Rz
        assert abs(mm - 1.0) < 1e-12 and abs(deg - angle) < 1e-12 * angle


def test_evaluate_warns_of_joint_columns_beyond_the_chain(tmp_path, capsys):
    """A chain of a FRAMES.json of several chains (or a --tip) that ends before the data's:
    the file's column of a joint below the tip was ignored without a word and the errors
    (hundreds of mm) read as the model's. calibrate's gate says so; evaluate now warns."""
    data = tmp_path / "d.csv"
    assert main(["simulate", "ec66", "--out", str(data), "--poses", "30", "--tool-m", "0.03",
                 "0.02", "0.12", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["evaluate", "ec66", str(data), "--tip", "link_5", "--fit-frames"]) == 0
    err = [e for e in capsys.readouterr().err.splitlines() if e.startswith("kincal: warning:")]
    assert any(f"{data}: the columns of joint_6, URDF joints beyond the chain's ends "
               "(base_link -> link_5), are ignored" in e and "check --tip" in e for e in err), err
    assert main(["evaluate", "ec66", str(data), "--fit-frames"]) == 0  # its own chain: no word
    assert "beyond the chain" not in capsys.readouterr().err
