"""Orientation columns as loggers write them (quaternions either way round, roll/pitch/yaw
in both conventions, rotation vectors, matrices; radians or degrees), a FIGAROH-style file
calibrated with one option naming its format, the warning for the other convention, and
the refusal of orientation columns left unread."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kincal import Robot
from kincal.cli.main import main
from kincal.errors import DataError
from kincal.measurements.orientation_columns import rotations
from kincal.measurements.pose import PoseData

from test_pose_orientation import TIAGO, marker_poses, write_poses


def random_rotations(n=50, seed=0):
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=seed)
    # the nasty cases on purpose: identity, near gimbal lock (pitch +-90 deg), angle near pi
    extra = Rotation.from_euler("xyz", [[0, 0, 0], [0.3, np.pi / 2 - 1e-7, -0.2],
                                        [-1.0, -np.pi / 2 + 1e-9, 2.0]])
    near_pi = Rotation.from_rotvec(rng.normal(size=(1, 3)) * 0 + [[0, 0, np.pi - 1e-6]])
    return Rotation.concatenate([R, extra, near_pi])


@pytest.mark.parametrize("unit", ["rad", "deg"])
def test_every_format_reads_the_rotation_scipy_gives(unit):
    R = random_rotations()
    k = 1.0 if unit == "rad" else np.pi / 180
    cases = {"quat-xyzw": R.as_quat(), "quat-wxyz": R.as_quat()[:, [3, 0, 1, 2]],
             "rotvec": R.as_rotvec() / k, "matrix": R.as_matrix().reshape(-1, 9)}
    for fmt, values in cases.items():
        got = rotations(values, fmt, k)
        np.testing.assert_allclose(got, R.as_matrix(), atol=1e-12, err_msg=fmt)
    # angles to matrices (scipy's matrix-to-angles loses digits near gimbal lock)
    rng = np.random.default_rng(1)
    angles = np.vstack([rng.uniform(-np.pi, np.pi, size=(50, 3)), [[0, 0, 0]],
                        [[0.3, np.pi / 2 - 1e-7, -0.2]], [[-1.0, -np.pi / 2, 2.0]]])
    for fmt, seq in (("rpy-zyx", "xyz"), ("rpy-xyz", "XYZ")):
        np.testing.assert_allclose(rotations(angles / k, fmt, k),
                                   Rotation.from_euler(seq, angles).as_matrix(), atol=1e-12,
                                   err_msg=fmt)
    # the conventions named as documented: rpy-zyx is Rz(c) Ry(b) Rx(a), rpy-xyz Rx Ry Rz
    a, b, c = 0.3, -0.5, 1.1
    Rx, Ry, Rz = (Rotation.from_rotvec(np.eye(3)[i] * v).as_matrix()
                  for i, v in enumerate((a, b, c)))
    np.testing.assert_allclose(rotations([[a, b, c]], "rpy-zyx")[0], Rz @ Ry @ Rx, atol=1e-15)
    np.testing.assert_allclose(rotations([[a, b, c]], "rpy-xyz")[0], Rx @ Ry @ Rz, atol=1e-15)


def test_bad_quaternion_and_matrix_rows_are_refused_with_their_line():
    with pytest.raises(DataError, match=r"line 3: the quaternion \(a, b, c, d\) has norm 2"):
        rotations([[0, 0, 0, 1], [0, 0, 0, 2]], "quat-wxyz", columns="abcd")
    M = np.eye(3).ravel()
    with pytest.raises(DataError, match=r"line 2: the matrix .* off orthonormal"):
        rotations([M * 1.1, M], "matrix")
    with pytest.raises(DataError, match="line 2: the matrix"):  # a reflection
        rotations([np.diag([1.0, 1.0, -1.0]).ravel()], "matrix")


def test_angles_in_degrees_read_as_radians_are_warned():
    """Joints in radians beside roll/pitch/yaw in degrees: no --angle-unit reads both, and
    the gate's refusal named noise, tip or URDF as the cause; the reading now warns with
    the largest angle. Angles of a turn or less (radians as loggers write them) are not."""
    R = Rotation.random(20, random_state=3)  # no gimbal lock: scipy's angles warn there
    deg = R.as_euler("xyz", degrees=True)
    with pytest.warns(UserWarning, match=r"poses.csv: orientation angles \(roll, pitch, yaw\) "
                      r"reach 1\d\d(\.\d)? rad: were they degrees\?"):
        rotations(deg, "rpy-zyx", 1.0, "poses.csv", columns=("roll", "pitch", "yaw"))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for fmt, values in (("rpy-zyx", R.as_euler("xyz")), ("rotvec", R.as_rotvec()),
                            ("rpy-xyz", deg)):
            rotations(values, fmt, 1.0 if fmt != "rpy-xyz" else np.pi / 180)


def figaroh_file(path, names, q, p, R, convention="xyz", degrees=False):
    """FIGAROH's layout: x1 y1 z1 phix1 phiy1 phiz1 and the joint columns."""
    phi = Rotation.from_matrix(R).as_euler(convention, degrees=degrees)
    cols = ["x1", "y1", "z1", "phix1", "phiy1", "phiz1"] + list(names)
    rows = np.hstack([p, phi, q])
    path.write_text(",".join(cols) + "\n" + "".join(",".join(map(repr, r.tolist())) + "\n"
                                                     for r in rows))
    return path


needs_tiago = pytest.mark.skipif(not TIAGO["urdf"].is_file(),
                                 reason="../shared/data/tiago_mocap absent")


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out = capsys.readouterr()
    return code, out.out, out.err


@needs_tiago
def test_figaroh_file_calibrates_like_its_quaternion_file(tmp_path, capsys):
    names, q, p, R = marker_poses(TIAGO["train"])
    fig = figaroh_file(tmp_path / "figaroh.csv", names, q, p, R)
    quat = write_poses(tmp_path / "quat.csv", names, q, p, R)
    common = ("--tip", "wrist_ft_tool_link", "--orientation-sigma-deg", 0.2, "--model",
              "offsets", "--lambda", 0)
    code, out1, err = run(capsys, "calibrate", TIAGO["urdf"], fig, "--position-columns", "x1",
                          "y1", "z1", "--orientation-format", "rpy-zyx", *common, "--out",
                          tmp_path / "a.urdf", "--frames-out", tmp_path / "a.json")
    assert code == 0, err
    assert "convention" not in err  # the right convention: no doubt raised
    code, out2, err = run(capsys, "calibrate", TIAGO["urdf"], quat, *common, "--out",
                          tmp_path / "b.urdf", "--frames-out", tmp_path / "b.json")
    assert code == 0, err
    fa = json.loads((tmp_path / "a.json").read_text())["sets"][0]["frames"]
    fb = json.loads((tmp_path / "b.json").read_text())["sets"][0]["frames"]
    assert fa.keys() == fb.keys()
    np.testing.assert_allclose([fa[k] for k in fa], [fb[k] for k in fa], atol=1e-9)
    a, b = (Robot.load(tmp_path / f, tip="wrist_ft_tool_link") for f in ("a.urdf", "b.urdf"))
    np.testing.assert_allclose(a.tip_poses(q), b.tip_poses(q), atol=1e-9)
    after = [line for line in out1.splitlines() if "after:" in line]
    assert after == [line for line in out2.splitlines() if "after:" in line]
    # the same file in degrees (angles and revolute joints: --angle-unit is the file's)
    qd = np.hstack([q[:, :1], np.degrees(q[:, 1:])])
    deg = figaroh_file(tmp_path / "deg.csv", names, qd, p, R, degrees=True)
    outs = []
    for path, unit in ((fig, "rad"), (deg, "deg")):
        code, out, err = run(capsys, "evaluate", tmp_path / "a.urdf", path, "--position-columns",
                             "x1", "y1", "z1", "--orientation-format", "rpy-zyx",
                             "--angle-unit", unit, "--frames", tmp_path / "a.json")
        assert code == 0, err
        outs.append(out.splitlines()[1:])
    assert outs[0] == outs[1] and "orientation: mean" in outs[0][1]


@needs_tiago
def test_the_other_convention_is_warned_about_with_evidence(tmp_path, capsys):
    names, q, p, R = marker_poses(TIAGO["train"])
    fig = figaroh_file(tmp_path / "figaroh.csv", names, q, p, R)
    code, out, err = run(capsys, "analyze", TIAGO["urdf"], fig, "--tip", "wrist_ft_tool_link",
                         "--position-columns", "x1", "y1", "z1", "--orientation-format",
                         "rpy-xyz", "--model", "offsets")
    assert code == 0, err
    warning = [line for line in err.splitlines() if "is the file's convention rpy-zyx?" in line]
    assert len(warning) == 1, err
    ours = float(warning[0].split("orientation error of ")[1].split(" deg")[0])
    other = float(warning[0].split("read as rpy-zyx ")[1].split(" deg")[0])
    assert ours > 20 and other < 5  # tens of degrees against a few


@needs_tiago
def test_unread_angle_columns_are_refused_unless_positions_only(tmp_path, capsys):
    names, q, p, R = marker_poses(TIAGO["train"])
    fig = figaroh_file(tmp_path / "figaroh.csv", names, q, p, R)
    args = ("analyze", TIAGO["urdf"], fig, "--tip", "wrist_ft_tool_link", "--position-columns",
            "x1", "y1", "z1", "--model", "offsets")
    code, out, err = run(capsys, *args)
    assert code == 1 and err.count("\n") == 1 and err.startswith("kincal: error:")
    assert "phix1, phiy1, phiz1" in err and "--positions-only" in err
    code, out, err = run(capsys, *args, "--positions-only")
    assert code == 0, err
    code, out, err = run(capsys, *args, "--positions-only", "--orientation-format", "rpy-zyx")
    assert code == 1 and "cannot go with" in err and err.count("\n") == 1


def test_wrong_column_count_and_missing_columns_one_line(tmp_path, capsys):
    robot = Robot.load("ec66")
    q = np.zeros((3, 6)) + np.arange(3)[:, None] * 0.1
    T = robot.tip_poses(q)
    path = write_poses(tmp_path / "p.csv", robot.joint_names, q, T[:, :3, 3], T[:, :3, :3])
    code, out, err = run(capsys, "analyze", "ec66", path, "--orientation-format", "rpy-zyx")
    assert code == 1 and err.count("\n") == 1
    assert "no orientation columns for format rpy-zyx" in err and "roll pitch yaw" in err
    code, out, err = run(capsys, "analyze", "ec66", path, "--orientation-format", "rpy-zyx",
                         "--orientation-columns", "qx", "qy", "qz", "qw")
    assert code == 1 and "takes 3 columns, got 4" in err and err.count("\n") == 1


def test_pose_data_reads_degrees_for_angles():
    R = random_rotations(5)
    np.testing.assert_allclose(rotations(R.as_rotvec(degrees=True), "rotvec", np.pi / 180),
                               R.as_matrix(), atol=1e-12)


def test_pose_data_from_csv_reads_a_named_format(tmp_path):
    robot = Robot.load("ec66")
    q = np.random.default_rng(3).uniform(-2, 2, size=(6, 6))
    T = robot.tip_poses(q)
    path = tmp_path / "m.csv"
    cols = list(robot.joint_names) + ["x", "y", "z"] + [f"r{i}{j}" for i in (1, 2, 3)
                                                         for j in (1, 2, 3)]
    rows = np.hstack([q, T[:, :3, 3], T[:, :3, :3].reshape(-1, 9)])
    path.write_text(",".join(cols) + "\n" + "".join(",".join(map(repr, r.tolist())) + "\n" for r in rows))
    data = PoseData.from_csv(path, robot.joint_names, orientation_format="matrix")
    np.testing.assert_allclose(data.rotations, T[:, :3, :3], atol=1e-14)


@pytest.mark.parametrize("fmt", ["quat-xyzw", "quat-wxyz", "rpy-zyx", "rpy-xyz", "rotvec",
                                 "matrix"])
@pytest.mark.parametrize("unit", ["rad", "deg"])
def test_written_orientations_read_back_to_the_same_rotations(fmt, unit):
    """orientation_values is the inverse of rotations, gimbal lock and angles near pi
    included (each format as kincal writes it, read back as a user's file is read)."""
    from kincal.measurements.orientation_columns import orientation_values

    R = random_rotations().as_matrix()
    k = 1.0 if unit == "rad" else np.pi / 180
    values = orientation_values(R, fmt, k)
    assert values.shape == (len(R), {"quat-xyzw": 4, "quat-wxyz": 4, "matrix": 9}.get(fmt, 3))
    np.testing.assert_allclose(rotations(values, fmt, k), R, atol=1e-12, rtol=0)


def test_simulate_writes_poses_in_the_format_named_and_they_read_back(tmp_path, capsys):
    """kincal simulate --kind pose --orientation-format rpy-zyx: roll pitch yaw columns that,
    read with the same option, give the poses of the quaternion file to 1e-12."""
    from kincal.measurements.sets import read_set_file

    common = ["simulate", "ur10", "--kind", "pose", "--poses", "12", "--seed", "3"]
    files = {}
    for fmt in ("quat-xyzw", "rpy-zyx"):
        files[fmt] = tmp_path / f"{fmt}.csv"
        assert main([*common, "--orientation-format", fmt, "--out", str(files[fmt])]) == 0
    header = next(line for line in files["rpy-zyx"].read_text().splitlines()
                  if not line.startswith("#")).split(",")  # after the provenance lines
    assert header[-4:] == ["roll", "pitch", "yaw", "sigma"] and "qw" not in header
    robot = Robot.load("ur10")
    a = PoseData.from_csv(files["quat-xyzw"], robot.joint_names)
    b = PoseData.from_csv(files["rpy-zyx"], robot.joint_names, orientation_format="rpy-zyx")
    np.testing.assert_array_equal(a.joint_values, b.joint_values)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_allclose(b.rotations, a.rotations, atol=1e-12, rtol=0)
    # the writer's own round trip through the set reader
    from kincal.measurements.sets import to_csv_text

    again = tmp_path / "again.csv"
    again.write_text(to_csv_text(b, "rpy-zyx"))
    c = read_set_file(again, robot.joint_names, orientation_format="rpy-zyx")
    np.testing.assert_allclose(c.rotations, b.rotations, atol=1e-12, rtol=0)
    # only pose files have orientations to write: refused, nothing written
    out = tmp_path / "points.csv"
    capsys.readouterr()
    assert main(["simulate", "ur10", "--orientation-format", "rpy-zyx", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("kincal: error:") == 1 and "--kind pose" in err and not out.exists()


def test_a_calibration_of_a_convention_in_doubt_is_refused_by_the_gate(tmp_path, capsys):
    """Scalar-first quaternions under generic names read scalar-last: the warning came, and
    the URDF was written anyway (15 mm median after calibration, under the residual bound;
    3 deg corrections: a wrong model). The gate now refuses it, --accept-implausible writes
    it, the right reading calibrates, and analyze (which writes nothing) only warns."""
    sim = tmp_path / "p.csv"
    assert main(["simulate", "ec66", "--kind", "pose", "--orientation-format", "quat-wxyz",
                 "--poses", "40", "--seed", "3", "--out", str(sim), "--quiet"]) == 0
    text = sim.read_text().replace("qw,qx,qy,qz", "q1,q2,q3,q4")
    data = tmp_path / "generic.csv"
    data.write_text(text)
    cols = ["--orientation-columns", "q1", "q2", "q3", "q4"]
    out = tmp_path / "c.urdf"
    capsys.readouterr()
    code, _, err = run(capsys, "calibrate", "ec66", data, "--orientation-format", "quat-xyzw",
                       *cols, "--out", out, "--model", "mdh")
    errors = [line for line in err.splitlines() if line.startswith("kincal: error:")]
    assert code == 1 and len(errors) == 1, err
    assert "implausible" in errors[0] and "is the file's convention quat-wxyz?" in errors[0]
    assert not out.exists()
    # the diagnosis: the convention's finding has no one number (it showed value 0,
    # threshold 0); its two readings' errors are in its message
    code, _, err = run(capsys, "calibrate", "ec66", data, "--orientation-format", "quat-xyzw",
                       *cols, "--out", out, "--model", "mdh", "--report", tmp_path / "r.json",
                       "--html", tmp_path / "r.html")
    finding = [f for f in json.loads((tmp_path / "r.json").read_text())["plausibility"]
               ["findings"] if f["kind"] == "orientation_convention"][0]
    assert finding["value"] is None and finding["threshold"] is None
    html = (tmp_path / "r.html").read_text()
    row = html[html.index("is the file&#x27;s convention quat-wxyz?"):]
    assert row.split("</tr>")[0].count("<td>0</td>") == 0
    code, _, err = run(capsys, "calibrate", "ec66", data, "--orientation-format", "quat-xyzw",
                       *cols, "--out", out, "--model", "mdh", "--accept-implausible")
    assert code == 0 and out.exists() and "convention" in err
    code, _, err = run(capsys, "calibrate", "ec66", data, "--orientation-format", "quat-wxyz",
                       *cols, "--out", tmp_path / "right.urdf", "--model", "mdh")
    assert code == 0 and "convention" not in err
    code, _, err = run(capsys, "analyze", "ec66", data, "--orientation-format", "quat-xyzw",
                       *cols)
    assert code == 0 and "is the file's convention quat-wxyz?" in err


def test_the_api_checks_the_convention_too(tmp_path):
    """The convention check lived in the command line: a Python user who read the same
    file with PoseData.from_csv got no warning, and write_calibration wrote the URDF of a
    wrong reading. Now the gate checks every calibration's pose data, API or not."""
    import warnings

    from kincal import Outputs, calibrate, write_calibration
    from kincal.errors import ImplausibleResultError, KincalWarning
    from kincal.identification.orientation_convention import checked, other_reading

    sim = tmp_path / "p.csv"
    assert main(["simulate", "ec66", "--kind", "pose", "--orientation-format", "quat-wxyz",
                 "--poses", "40", "--seed", "3", "--out", str(sim), "--quiet"]) == 0
    data_file = tmp_path / "generic.csv"
    data_file.write_text(sim.read_text().replace("qw,qx,qy,qz", "q1,q2,q3,q4"))
    robot = Robot.load("ec66")
    cols = ("q1", "q2", "q3", "q4")
    wrong = PoseData.from_csv(data_file, robot.joint_names, orientation_columns=cols,
                              orientation_format="quat-xyzw")
    right = PoseData.from_csv(data_file, robot.joint_names, orientation_columns=cols,
                              orientation_format="quat-wxyz")
    assert wrong.orientation_format == "quat-xyzw" and wrong.convention_doubt is None
    # the other reading from the rotations is the file read the other way
    np.testing.assert_allclose(other_reading(wrong.rotations, "quat-xyzw"), right.rotations,
                               atol=1e-12)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = calibrate(robot, wrong, model="mdh")
    assert any("is the file's convention quat-wxyz?" in str(w.message) for w in caught
               if issubclass(w.category, KincalWarning))
    assert not result.plausibility.plausible
    assert any(f.kind == "orientation_convention" for f in result.plausibility.findings)
    out = tmp_path / "api.urdf"
    with pytest.raises(ImplausibleResultError, match="quat-wxyz"):
        write_calibration(result, Outputs(urdf=out))
    assert not out.exists()
    # the right reading: checked, no doubt, written
    from kincal import CalibrationProblem

    assert checked(CalibrationProblem, robot, right).convention_doubt == ""
    good = calibrate(robot, right, model="mdh")
    assert good.plausibility.plausible
    write_calibration(good, Outputs(urdf=out))
    assert out.exists()
    # named ROS quaternions fix their convention: not checked
    ros = tmp_path / "ros.csv"
    assert main(["simulate", "ec66", "--kind", "pose", "--poses", "10", "--seed", "3", "--out",
                 str(ros), "--quiet"]) == 0
    assert PoseData.from_csv(ros, robot.joint_names).orientation_format == ""


def test_the_gate_names_orientation_angles_in_degrees_as_the_cause(tmp_path, capsys):
    """Joints in radians, roll/pitch/yaw in degrees: the gate refused, but its likely cause
    was noise, a tip or another URDF (the 'were they degrees?' warning came after the line).
    The reader's largest angle is now a unit clue of the gate: the cause it names."""
    src, bad = tmp_path / "p.csv", tmp_path / "deg.csv"
    assert main(["simulate", "ec66", "--kind", "pose", "--orientation-format", "rpy-zyx",
                 "--poses", "30", "--seed", "3", "--out", str(src), "--quiet"]) == 0
    rows = [r.split(",") for r in src.read_text().splitlines() if not r.startswith("#")]
    turned = [rows[0].index(c) for c in ("roll", "pitch", "yaw")]
    bad.write_text("\n".join(",".join(
        repr(float(np.degrees(float(c)))) if k and i in turned else c for i, c in enumerate(r))
        for k, r in enumerate(rows)) + "\n")
    capsys.readouterr()
    argv = ["calibrate", "ec66", "--orientation-format", "rpy-zyx", "--out",
            str(tmp_path / "o.urdf")]
    assert main([*argv[:2], str(bad), *argv[2:]]) == 1
    err = capsys.readouterr().err.splitlines()
    line = next(e for e in err if e.startswith("kincal: error:"))
    assert "orientation angles reach 1" in line and "Likely cause: orientation angles in " \
        "degrees read as radians (they reach 1" in line, line
    assert not (tmp_path / "o.urdf").exists()
    assert main([*argv[:2], str(src), *argv[2:]]) == 0  # the same file in radians: plausible
    assert PoseData.from_csv(src, Robot.load("ec66").joint_names,
                             orientation_format="rpy-zyx").angles_read_max < np.pi + 1e-9


@pytest.mark.parametrize("names", [("Roll", "Pitch", "Yaw"), ("quat_x", "quat_y", "quat_z", "quat_w"),
                                   ("pose.orientation.x", "pose.orientation.y",
                                    "pose.orientation.z", "pose.orientation.w"),
                                   ("qx", "qy", "qz"), ("Rotation X", "Rotation Y", "Rotation Z"),
                                   ("yaw_deg", "pitch_deg", "roll_deg")])
def test_orientation_columns_under_other_names_are_never_dropped(tmp_path, capsys, names):
    """A logger's names for orientation components (not the usual qx .. qw, roll pitch yaw,
    phix ..): read as positions they were dropped without a word and the file calibrated as
    points. Refused as the usual names are, naming the columns; read with
    --orientation-columns, or as positions with --positions-only; compensate alike."""
    robot = Robot.load("ec66")
    q = np.random.default_rng(3).uniform(-1, 1, (12, 6))
    T = robot.tip_poses(q)
    R = Rotation.from_matrix(T[:, :3, :3])
    values = (R.as_quat() if len(names) == 4 else R.as_quat()[:, :3] if names[0] == "qx"
              else R.as_euler("xyz"))
    cols = list(robot.joint_names) + ["x", "y", "z", *names]
    rows = np.hstack([q, T[:, :3, 3], values])
    path = tmp_path / "log.csv"
    path.write_text(",".join(f'"{c}"' if " " in c else c for c in cols) + "\n"
                    + "".join(",".join(map(repr, r.tolist())) + "\n" for r in rows))
    args = ("calibrate", "ec66", path, "--model", "offsets", "--method", "ls")
    code, out, err = run(capsys, *args, "--out", tmp_path / "a.urdf")
    assert code == 1 and err.count("\n") == 1 and err.startswith("kincal: error:"), err
    assert ", ".join(names) in err and "--orientation-columns" in err and "--positions-only" in err
    assert not (tmp_path / "a.urdf").exists()
    code, out, err = run(capsys, *args, "--positions-only", "--out", tmp_path / "b.urdf")
    assert code == 0, err
    if len(names) == 4:  # a quaternion, scalar last, under its own names: read as poses
        code, out, err = run(capsys, *args, "--orientation-columns", *names,
                             "--out", tmp_path / "c.urdf")
        assert code == 0 and "orientation after:" in out, err
    frames = tmp_path / "frames.json"
    assert main(["calibrate", "ec66", str(path), "--positions-only", "--model", "offsets",
                 "--method", "ls", "--out", str(tmp_path / "d.urdf"), "--frames-out",
                 str(frames), "-q"]) == 0
    capsys.readouterr()
    code, out, err = run(capsys, "compensate", tmp_path / "d.urdf", path, "--tip", "flange",
                         "--frames", frames, "--out", tmp_path / "j.csv")
    assert code == 1 and err.count("\n") == 1 and ", ".join(names) in err, err
