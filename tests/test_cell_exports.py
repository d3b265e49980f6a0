"""Exports for cells, read back: each reproduces the corrected model's tip pose to 1e-12 m."""

import json

import numpy as np
import pytest
from chains import random_chain
from conftest import TIAGO_URDF, random_joint_values, ur10_path

from kincal.cli.main import main
from kincal.errors import ExportError
from kincal.export.cell_exports import kinematics_yaml, mdh_table_csv, read_kinematics_yaml
from kincal.export.urdf_export import edit_joint_origins
from kincal.models import mdh
from kincal.robot import Robot
from kincal.rotations import quaternion_to_matrix, xyz_rpy_to_transform


def _corrected(robot, rng):
    model = mdh.extract(robot.geometry)
    err = rng.normal(size=model.table.shape)
    err[:, [0, 2]] *= 2e-3   # a, d [m]
    err[:, [1, 3]] *= 5e-3   # alpha, theta [rad]
    return robot.with_joint_frames(model.joint_frames(model.table + err))


def _cases(tmp_path):
    yield Robot.load("ec66", tip="flange")
    yield Robot.load("ur10", tip="tool0")
    yield Robot.load("panda", tip="panda_link8")
    if TIAGO_URDF.exists():  # origins with pitch at -90 deg (gimbal lock)
        yield Robot.load(TIAGO_URDF, tip="wrist_ft_tool_link")
    for seed in range(8):
        text, _ = random_chain(np.random.default_rng(500 + seed))
        path = tmp_path / f"chain{seed}.urdf"
        path.write_text(text)
        yield Robot.load(path, tip="tip")


def _tip_error(A, B):
    """Largest difference [m] between poses, the rotation part taken at 1 m."""
    return float(np.abs(A - B).max())


def test_yaml_overlay_applied_to_the_nominal_urdf_reproduces_the_corrected_model(tmp_path, rng):
    for robot in _cases(tmp_path):
        corrected = _corrected(robot, rng)
        origins = read_kinematics_yaml(kinematics_yaml(robot, corrected))
        assert list(origins) == list(robot.joint_names)
        path = tmp_path / "overlaid.urdf"
        path.write_text(edit_joint_origins(robot.urdf_text, origins).text)
        overlaid = Robot.load(path, tip=robot.tip, base=robot.base)
        q = random_joint_values(robot.geometry, rng, 20)
        assert _tip_error(overlaid.tip_poses(q), corrected.tip_poses(q)) < 1e-12


def test_yaml_keeps_the_look_of_the_original_rpy():
    robot = Robot.load("ec66", tip="flange")
    text = kinematics_yaml(robot, robot)
    origins = read_kinematics_yaml(text)
    for name, T in robot.urdf_origins().items():
        np.testing.assert_allclose(origins[name], T, atol=1e-15)
    assert "joint_2:\n    x: 0.0" in text and "  hash" not in text


def _mdh_product(text, q):
    """Tip poses from the MD-H CSV text alone: T_base_0 A_1(q_1) ... A_n(q_n) T_n_tip."""
    fixed, rows = {}, []
    for line in text.splitlines():
        if line.startswith(("# T_base_0:", "# T_n_tip:")):
            key, _, values = line[2:].partition(":")
            v = [float(x) for x in values.split()]
            fixed[key] = xyz_rpy_to_transform(v[:3], v[3:])
        elif not line.startswith("#") and not line.startswith("joint,"):
            name, kind, *nums = line.split(",")
            rows.append((kind, [float(x) for x in nums]))
    out = []
    for qk in q:
        T = fixed["T_base_0"]
        for (kind, (a, alpha, beta, d, theta)), qi in zip(rows, qk):
            if kind == "revolute":
                theta = theta + qi
            else:
                d = d + qi
            ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
            Rx = np.array([[1, 0, 0, 0], [0, ca, -sa, 0], [0, sa, ca, 0], [0, 0, 0, 1]])
            Tx = np.eye(4)
            Tx[0, 3] = a
            Rz = np.array([[ct, -st, 0, 0], [st, ct, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
            cb, sb = np.cos(beta), np.sin(beta)
            Ry = np.array([[cb, 0, sb, 0], [0, 1, 0, 0], [-sb, 0, cb, 0], [0, 0, 0, 1]])
            Tz = np.eye(4)
            Tz[2, 3] = d
            T = T @ Rx @ Tx @ Ry @ Rz @ Tz
        out.append(T @ fixed["T_n_tip"])
    return np.array(out)


def test_mdh_table_through_an_independent_product_reproduces_the_corrected_model(tmp_path, rng):
    checked = 0
    for robot in _cases(tmp_path):
        corrected = _corrected(robot, rng)
        try:
            text = mdh_table_csv(corrected)
        except ExportError as exc:  # refused only for axes parallel to within the tolerance
            assert "parallel to the next one" in str(exc)
            continue
        q = random_joint_values(robot.geometry, rng, 20)
        scale = max(1.0, float(np.abs(corrected.geometry.joint_frames[:, :3, 3]).max()))
        assert _tip_error(_mdh_product(text, q), corrected.tip_poses(q)) < 1e-12 * scale
        checked += 1
    assert checked >= 8


def test_mdh_table_states_its_convention():
    robot = Robot.load("ec66", tip="flange")
    text = mdh_table_csv(robot)
    assert "Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i + q_i) Tz(d_i)" in text
    assert "joint,type,a_m,alpha_rad,beta_rad,d_m,theta_rad" in text


def test_mdh_table_of_a_calibrated_ur10_has_finite_lengths(rng):
    """UR10 (parallel joints 2-3-4): a calibrated chain's MD-H lengths run off to kilometres
    (1,239 m and -1,955 m were seen); with Hayati's beta every length stays within the arm,
    and the table still reproduces the corrected model (issue 19 item 3)."""
    robot = Robot.load(ur10_path(), tip="tool0")
    corrected = _corrected(robot, rng)
    text = mdh_table_csv(corrected)
    rows = [line.split(",") for line in text.splitlines()
            if not line.startswith("#") and not line.startswith("joint,")]
    lengths = np.abs([[float(r[2]), float(r[5])] for r in rows])
    assert lengths.max() < 2.0  # [m] a UR10 reaches 1.3 m
    assert any(abs(float(r[4])) > 0 for r in rows)  # a beta where the axes are parallel
    q = random_joint_values(robot.geometry, rng, 20)
    assert _tip_error(_mdh_product(text, q), corrected.tip_poses(q)) < 1e-12


def test_frames_matrices_and_quaternions_reproduce_the_predictions(tmp_path):
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.planning import simulation

    robot = Robot.load("ec66", tip="flange")
    model = mdh.extract(robot.geometry)
    rng = np.random.default_rng(4)
    tool = np.array([0.03, 0.02, 0.12])
    truth = simulation.Truth(simulation.planted_table(model, rng),
                             np.array([0.8, 0.3, -0.2, 0.4, -0.3, 2.0]), tool)
    q = simulation.cube_poses(robot, 30, (0.4, 0.0, 0.25), 0.4, tool, rng)
    result = CalibrationProblem(robot, simulation.measure(model, truth, q, 1e-5, rng),
                                CalibrationOptions(method="ls")).solve()
    d = json.loads(json.dumps(result.frames_dict()))  # as written to FRAMES.json
    assert {"base", "tool", "convention", "base_frame", "tip_frame"} <= set(d)  # old keys kept
    T_MB, T_Et = np.array(d["T_measurement_base"]), np.array(d["T_tip_tool"])
    pose = d["pose_measurement_base"]
    T_q = np.eye(4)
    T_q[:3, :3] = quaternion_to_matrix([pose[k] for k in ("qx", "qy", "qz", "qw")])
    T_q[:3, 3] = [pose[k] for k in "xyz"]
    T_tip = result.corrected.tip_poses(q)
    for T in (T_MB, T_q):
        P = (T @ T_tip @ T_Et)[:, :3, 3]
        np.testing.assert_allclose(P, result.predict(q), atol=1e-12, rtol=0)
    assert d["joints"] == list(robot.joint_names)


def test_calibrate_writes_the_cell_exports_all_or_none(tmp_path, capsys):
    data = tmp_path / "cal.csv"
    assert main(["simulate", "ec66", "--out", str(data), "--poses", "30", "--seed", "1"]) == 0
    out = {k: tmp_path / f"out.{k}" for k in ("urdf", "yaml", "csv")}
    (tmp_path / "out.csv").write_text("mine")  # an existing file: nothing else is written
    args = ["calibrate", "ec66", str(data), "--method", "ls", "--out", str(out["urdf"]),
            "--yaml-out", str(out["yaml"]), "--mdh-out", str(out["csv"]), "--quiet"]
    assert main(args) == 1
    assert not out["urdf"].exists() and not out["yaml"].exists()
    assert main(args + ["--overwrite"]) == 0
    assert out["yaml"].read_text().startswith("# kincal: corrected joint origins of ec66")
    assert "joint_6,revolute," in out["csv"].read_text()


@pytest.mark.parametrize("seed", range(3))
def test_yaml_numbers_are_exact_doubles(seed, tmp_path):
    robot = Robot.load("ec66", tip="flange")
    corrected = _corrected(robot, np.random.default_rng(seed))
    origins = read_kinematics_yaml(kinematics_yaml(robot, corrected))
    for name, T in corrected.urdf_origins().items():
        np.testing.assert_allclose(origins[name], T, atol=2e-16 * 4, rtol=0)


def test_yaml_keys_read_back_as_the_joint_names(tmp_path):
    """Joint names YAML would misread as plain keys (a colon and a hash, quotes, YAML 1.1's
    "on", which reads back as True) are written in double quotes: PyYAML and kincal's own
    reader give the same names back, and the plain names stay plain."""
    import yaml

    names = ("on", "a: b #c", 'say "hi"', "j_4.x")
    esc = [n.replace('"', "&quot;") for n in names]
    links = "".join(f'<link name="l{i}"/>' for i in range(len(names) + 1))
    joints = "".join(
        f'<joint name="{n}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        f'<origin xyz="0 0.1 0.2" rpy="0.1 0 0"/><axis xyz="0 {i % 2} {1 - i % 2}"/>'
        '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        for i, n in enumerate(esc))
    path = tmp_path / "odd.urdf"
    path.write_text(f'<robot name="odd">{links}{joints}</robot>')
    robot = Robot.load(path, tip=f"l{len(names)}")
    assert robot.joint_names == names
    text = kinematics_yaml(robot, robot)
    assert "\n  j_4.x:\n" in text and '\n  "on":\n' in text
    loaded = yaml.safe_load(text)["kinematics"]
    assert list(loaded) == list(names)
    origins = read_kinematics_yaml(text)
    assert list(origins) == list(names)
    for name, T in robot.urdf_origins().items():
        np.testing.assert_allclose(origins[name], T, atol=1e-15)
        np.testing.assert_allclose([loaded[name][k] for k in ("x", "y", "z")], T[:3, 3])


def test_ur_format_refuses_a_urdf_not_in_ur_descriptions_layout(tmp_path, capsys):
    """example-robot-data's UR10 (the ROS 1 layout: shoulder_lift about y, no
    base_link_inertia) has the six UR joint names, so --yaml-format ur --ur-hash wrote its
    joint origins under ur_description's segment keys: the xacro builds another robot from
    them (its tool0 2.2 m off the corrected URDF's, measured with ur_description 2.4.5's
    ur10 xacro and this file), without a word. Refused now, before the work and by the
    writer; nothing is written."""
    from kincal.cli import main
    from kincal.errors import ExportError
    from kincal.export.cell_exports import ur_kinematics_yaml

    ur10 = Robot.load("ur10")
    with pytest.raises(ExportError, match="not in ur_description's layout"):
        ur_kinematics_yaml(ur10, ur10, "calib_1")
    data = tmp_path / "d.csv"
    assert main(["simulate", "ur10", "--poses", "20", "--out", str(data), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "ur10", str(data), "--out", str(tmp_path / "c.urdf"),
                 "--yaml-out", str(tmp_path / "k.yaml"), "--yaml-format", "ur",
                 "--ur-hash", "calib_1"]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(err) == 1 and "shoulder_lift_joint" in err[0] and "layout" in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv"]
