"""Orientation errors of pose data, everywhere position errors are reported (calibrate
summary, JSON and HTML report, evaluate), checked against an independent computation:
Pinocchio's forward kinematics (Robot.tip_poses) and scipy's Rotation, to 1e-9 deg."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kincal import CalibrationOptions, CalibrationProblem, Robot
from kincal.cli.main import main
from kincal.frames_file import CellFrames, SetFrames, chain_hash
from kincal.measurements.pose import FRAMES, PoseData
from kincal.rotations import base_rotation

TOL_DEG = 1e-9
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "tiago_mocap"
TIAGO = {"urdf": SHARED / "tiago_48_schunk.urdf",
         "train": SHARED / "qualisys_2021-11-30_static_postures.csv",
         "test": SHARED / "qualisys_2021-11-26_static_postures.csv"}
BASE = np.array([0.4, -0.2, 0.1, 0.05, -0.1, 0.3])   # measurement frame [m, rad]
TOOL = np.array([0.01, -0.02, 0.08, 0.2, -0.1, 0.4])  # tool frame in the tip frame


def predicted(robot, q, frames):
    """(positions (N, 3), rotations (N, 3, 3)) of the tool frame in the measurement frame,
    by Pinocchio (not kincal's chain engine)."""
    T = robot.tip_poses(q)
    Rb, Rt = base_rotation(*frames[3:6]), base_rotation(*frames[9:12])
    p = (T[:, :3, 3] + T[:, :3, :3] @ frames[6:9]) @ Rb.T + frames[:3]
    return p, Rb @ T[:, :3, :3] @ Rt


def angles_deg(R_measured, R_predicted):
    """(N,) angle of the rotation between measured and predicted [deg], by scipy."""
    return Rotation.from_matrix(R_measured @ np.transpose(R_predicted, (0, 2, 1))).magnitude() \
        * 180 / np.pi


def stats(d):
    return {"mean": d.mean(), "max": d.max(), "rms": np.sqrt(np.mean(d ** 2)),
            "median": np.median(d), "std": d.std(ddof=1)}


def check(got, d, suffix=""):
    for k, v in stats(d).items():
        value = got[k + suffix] if isinstance(got, dict) else getattr(got, k)
        assert value == pytest.approx(v, abs=TOL_DEG), k


def planted(robot, n=24, seed=0):
    """Joint values, measured positions and rotations with known orientation errors (deg,
    0.01 to 8 about random axes) and known frames; the planted angles [deg]."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, size=(n, len(robot.joint_names)))
    p, R = predicted(robot, q, np.r_[BASE, TOOL])
    angle = np.linspace(0.01, 8.0, n)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    E = Rotation.from_rotvec(axis * np.radians(angle)[:, None]).as_matrix()
    return q, p + rng.normal(scale=2e-4, size=p.shape), R @ E, angle


def write_poses(path, names, q, p, R, quat="xyzw"):
    x = Rotation.from_matrix(R).as_quat()
    if quat == "wxyz":
        x = x[:, [3, 0, 1, 2]]
    cols = list(names) + ["x", "y", "z"] + (["qx", "qy", "qz", "qw"] if quat == "xyzw"
                                            else ["qw", "qx", "qy", "qz"])
    rows = np.hstack([q, p, x])
    path.write_text(",".join(cols) + "\n" + "".join(",".join(map(repr, r.tolist())) + "\n"
                                                     for r in rows))
    return path


def test_evaluate_reports_the_planted_orientation_errors(tmp_path, capsys):
    robot = Robot.load("ec66")
    q, p, R, angle = planted(robot)
    data = write_poses(tmp_path / "poses.csv", robot.joint_names, q, p, R)
    frames = CellFrames(robot.model_name, chain_hash(robot), robot.base, robot.tip,
                        robot.joint_names, (SetFrames("pose", "", FRAMES,
                                                      tuple(np.r_[BASE, TOOL])),))
    (tmp_path / "f.json").write_text(frames.dumps())
    assert main(["evaluate", "ec66", str(data), "--frames", str(tmp_path / "f.json"),
                 "--report", str(tmp_path / "e.json")]) == 0
    out = capsys.readouterr().out
    assert "position: mean" in out and "orientation: mean" in out
    got = json.loads((tmp_path / "e.json").read_text())["orientation_errors"]
    check(got, angle, "_deg")
    assert got["n"] == len(angle)
    assert f"max {angle.max():.4f}" in out.split("orientation:")[1]


def test_calibrate_summary_before_and_after_match_pinocchio_and_scipy():
    robot = Robot.load("ec66")
    q, p, R, angle = planted(robot, n=30, seed=1)
    data = PoseData(joint_names=robot.joint_names, joint_values=q, positions=p, rotations=R,
                    orientation_sigma_deg=1.0)
    result = CalibrationProblem(robot, [data], CalibrationOptions(lam=0.1)).solve()
    s = result.sets[0]
    lay = result.layout
    start = np.asarray(lay.frames(result.x_start, 0))
    check(s.orientation_before, angles_deg(R, predicted(robot, q, start)[1]))
    after = angles_deg(R, predicted(result.corrected, q, s.frames)[1])
    check(s.orientation_after, after)
    assert s.orientation_after_deg == pytest.approx(after.mean(), abs=TOL_DEG)
    text = result.summary()
    assert f"orientation before: mean {s.orientation_before.mean:.4f}" in text
    assert f"orientation after:  mean {s.orientation_after.mean:.4f}" in text
    assert f"RMS {s.orientation_after.rms:.4f} deg" in text
    # frame parameters: start (fitted with the nominal kinematics), estimate, std. error
    assert "frames of the sets" in text or "measurement frame, tool" in text
    rows = {line.split()[0]: line.split()[1:] for line in text.splitlines()
            if line.strip().startswith(("base.", "tool."))}
    for k, name in enumerate(FRAMES):
        scale = 1e3 if name.split(".")[1] in "xyz" else 180 / np.pi
        i = lay.index(name)
        assert float(rows[name][0]) == pytest.approx(result.x_start[i] * scale, abs=1e-4)
        assert float(rows[name][1]) == pytest.approx(result.x[i] * scale, abs=1e-4)
        assert float(rows[name][2]) == pytest.approx(result.parameter(name).std_error * scale,
                                                     abs=1e-5)


def marker_poses(path):
    """(joints (N, 8), positions (N, 3), rotations (N, 3, 3)) of the TIAGo hand: marker 1,
    and the frame of markers 1, 2, 4 (x to marker 2, z normal to the marker plane)."""
    from kincal.measurements.csv_table import read_columns

    joints = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
    v = read_columns(path, joints + tuple(f"{c}{k}" for k in (1, 2, 4) for c in "xyz")).values
    m = {k: np.column_stack([v[f"{c}{k}"] for c in "xyz"]) for k in (1, 2, 4)}
    x = m[2] - m[1]
    x /= np.linalg.norm(x, axis=1)[:, None]
    z = np.cross(x, m[4] - m[1])
    z /= np.linalg.norm(z, axis=1)[:, None]
    R = np.stack([x, np.cross(z, x), z], axis=2)
    return joints, np.column_stack([v[j] for j in joints]), m[1], R


@pytest.mark.skipif(not TIAGO["urdf"].is_file(), reason="../shared/data/tiago_mocap absent")
def test_tiago_poses_calibrate_report_html_and_evaluate(tmp_path, capsys):
    names, q, p, R = marker_poses(TIAGO["train"])
    train = write_poses(tmp_path / "train.csv", names, q, p, R, quat="wxyz")
    names, q2, p2, R2 = marker_poses(TIAGO["test"])
    test = write_poses(tmp_path / "test.csv", names, q2, p2, R2)
    out = tmp_path / "cal.urdf"
    assert main(["calibrate", str(TIAGO["urdf"]), str(train), "--tip", "wrist_ft_tool_link",
                 "--orientation-columns", "qx", "qy", "qz", "qw", "--orientation-sigma-deg",
                 "0.2", "--model", "offsets", "--lambda", "0", "--out", str(out),
                 "--frames-out", str(tmp_path / "f.json"), "--report",
                 str(tmp_path / "r.json"), "--html", str(tmp_path / "r.html")]) == 0
    text = capsys.readouterr().out
    nominal = Robot.load(TIAGO["urdf"], tip="wrist_ft_tool_link")
    corrected = Robot.load(out, tip="wrist_ft_tool_link")
    frames = CellFrames.read(tmp_path / "f.json").sets[0]
    f = np.array([frames.value(n) for n in FRAMES])
    after = angles_deg(R, predicted(corrected, q, f)[1])
    report = json.loads((tmp_path / "r.json").read_text())["sets"][0]["orientation_errors"]
    check(report["after"], after, "_deg")
    # before: the nominal model with the start frames (the API gives them)
    data = PoseData(joint_names=nominal.joint_names, joint_values=q, positions=p, rotations=R,
                    orientation_sigma_deg=0.2)
    res = CalibrationProblem(nominal, [data], CalibrationOptions(model="offsets", lam=0.0)).solve()
    start = np.asarray(res.layout.frames(res.x_start, 0))
    check(report["before"], angles_deg(R, predicted(nominal, q, start)[1]), "_deg")
    assert f"orientation after:  mean {report['after']['mean_deg']:.4f}" in text
    html = (tmp_path / "r.html").read_text()
    assert "orientation before" in html and f"{report['after']['rms_deg']:.4f}" in html
    assert main(["evaluate", str(out), str(test), "--frames", str(tmp_path / "f.json"),
                 "--report", str(tmp_path / "e.json")]) == 0
    got = json.loads((tmp_path / "e.json").read_text())["orientation_errors"]
    check(got, angles_deg(R2, predicted(corrected, q2, f)[1]), "_deg")


def _frames_file(path, robot, kind_set):
    frames = CellFrames(robot.model_name, chain_hash(robot), robot.base, robot.tip,
                        robot.joint_names, (kind_set,))
    path.write_text(frames.dumps())
    return str(path)


def _write_points(path, names, q, columns, p):
    rows = np.hstack([q, p])
    path.write_text(",".join([*names, *columns]) + "\n"
                    + "".join(",".join(map(repr, r.tolist())) + "\n" for r in rows))
    return str(path)


def test_points_are_evaluated_with_a_pose_calibrations_frames(tmp_path, capsys):
    """A pose set's frames serve points: its measurement frame and the origin of its tool
    frame (the tool point). Points planted at known distances from that origin (by
    Pinocchio) come out at those distances; several points per pose are refused (one
    tool origin), nothing written."""
    robot = Robot.load("ec66")
    rng = np.random.default_rng(5)
    q = rng.uniform(-2.5, 2.5, size=(20, len(robot.joint_names)))
    p = predicted(robot, q, np.r_[BASE, TOOL])[0]
    d = np.linspace(0.01e-3, 0.4e-3, len(q))  # [m] the planted errors
    u = rng.normal(size=p.shape)
    u /= np.linalg.norm(u, axis=1)[:, None]
    frames = _frames_file(tmp_path / "f.json", robot,
                          SetFrames("pose", "poses.csv", FRAMES, tuple(np.r_[BASE, TOOL])))
    data = _write_points(tmp_path / "points.csv", robot.joint_names, q, "xyz", p + d[:, None] * u)
    report = tmp_path / "e.json"
    assert main(["evaluate", "ec66", data, "--frames", frames, "--report", str(report)]) == 0
    out = capsys.readouterr().out
    how = f"frames from {frames} (the pose set's measurement frame and tool origin)"
    assert how in out and "orientation" not in out
    got = json.loads(report.read_text())
    assert got["kind"] == "point" and got["frames"] == how
    assert got["errors"]["mean_mm"] == pytest.approx(d.mean() * 1e3, abs=1e-9)
    assert got["errors"]["max_mm"] == pytest.approx(d.max() * 1e3, abs=1e-9)
    two = _write_points(tmp_path / "two.csv", robot.joint_names, q,
                        ("x1", "y1", "z1", "x2", "y2", "z2"), np.hstack([p, p]))
    report.unlink()
    assert main(["evaluate", "ec66", two, "--frames", frames, "--position-columns", "x1",
                 "y1", "z1", "x2", "y2", "z2", "--report", str(report)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("kincal: error:")
    assert "2 measured points per pose" in err and "one origin (tool.x .y .z)" in err
    assert not report.exists()


def test_a_pose_file_on_a_point_calibration_is_refused_and_its_positions_evaluated(
        tmp_path, capsys):
    """A point calibration holds no tool orientation: a pose file against its frames is
    refused, saying so and pointing to --positions-only, which evaluates the positions
    with the point set's measurement frame and tool point."""
    robot = Robot.load("ec66")
    q, p, R, _ = planted(robot)
    exact = predicted(robot, q, np.r_[BASE, TOOL[:3], 0.0, 0.0, 0.0])[0]
    data = str(write_poses(tmp_path / "poses.csv", robot.joint_names, q, p, R))
    point = CellFrames.of_points(BASE, TOOL[:3]).sets[0]
    frames = _frames_file(tmp_path / "f.json", robot, point)
    assert main(["evaluate", "ec66", data, "--frames", frames]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("kincal: error:")
    assert "a point calibration holds no tool orientation" in err and "--positions-only" in err
    report = tmp_path / "e.json"
    assert main(["evaluate", "ec66", data, "--frames", frames, "--positions-only",
                 "--report", str(report)]) == 0
    got = json.loads(report.read_text())["errors"]
    assert got["mean_mm"] == pytest.approx(np.linalg.norm(p - exact, axis=1).mean() * 1e3,
                                           abs=1e-9)


def test_added_tool_frame_of_a_pose_calibration_has_the_tool_orientation():
    """--add-frames wrote a pose set's kincal_tool_point with the tip's axes: a tool frame
    turned by TOOL's 0.2, -0.1, 0.4 rad (26 deg) in FRAMES.json's T_tip_tool came out of the
    URDF 26 deg off the orientations measured, the positions right."""
    from kincal.export.outputs import corrected_urdf

    robot = Robot.load("ec66")
    q, p, R, _ = planted(robot, n=30, seed=1)
    R = predicted(robot, q, np.r_[BASE, TOOL])[1]  # orientations without planted errors
    data = PoseData(joint_names=robot.joint_names, joint_values=q, positions=p, rotations=R,
                    orientation_sigma_deg=1.0)
    result = CalibrationProblem(robot, [data], CalibrationOptions(lam=0.1)).solve()
    text = corrected_urdf(result, add_frames=True)[0]
    import pinocchio as pin

    model = pin.buildModelFromXML(text)
    seen = Robot(model, text, "ec66", "kincal_measurement_frame", "kincal_tool_point")
    T = seen.tip_poses(q)
    fit_p, fit_R = predicted(result.corrected, q, result.sets[0].frames)  # the calibration's
    assert angles_deg(R, T[:, :3, :3]).max() < 0.5  # the orientations measured [deg]
    assert angles_deg(fit_R, T[:, :3, :3]).max() < 1e-9  # as the calibration predicts them
    assert np.abs(T[:, :3, 3] - fit_p).max() < 1e-12  # and the positions [m]
    frames = result.frames().sets[0].derived()["T_tip_tool"]
    d = model.createData()
    pin.framesForwardKinematics(model, d, pin.neutral(model))
    at_tip = (d.oMf[model.getFrameId(result.robot.tip)].actInv(
        d.oMf[model.getFrameId("kincal_tool_point")])).homogeneous
    assert np.abs(at_tip - np.array(frames)).max() < 1e-12  # FRAMES.json's tool frame
