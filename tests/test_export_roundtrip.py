"""Corrected URDF export: the written file is the corrected model, and nothing else changed."""

import io
import json
import re

import numpy as np
import pytest
import yourdfpy
from chains import random_chain
from conftest import random_joint_values, tiago_urdf

from kincal.export.urdf_export import edit_joint_origins
from kincal.models import mdh
from kincal.robot import Robot

ROBOTS = [("ec66", "flange"), ("ur5", "tool0"), ("ur10", "tool0"), ("panda", "panda_link8"),
          ("tiago", "arm_tool_link"), ("tiago_file", "wrist_ft_tool_link")]


def _load(name, tip):
    return Robot.load(tiago_urdf() if name == "tiago_file" else name, tip=tip)


def _corrected(robot, rng):
    model = mdh.extract(robot.geometry)
    err = rng.normal(size=model.table.shape)
    err[:, [0, 2]] *= 2e-3   # a, d [m]
    err[:, [1, 3]] *= 5e-3   # alpha, theta [rad]
    return robot.with_joint_frames(model.joint_frames(model.table + err))


def _yourdfpy_tip_poses(text, robot, q):
    u = yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), load_meshes=False, build_collision_scene_graph=False,
                           load_collision_meshes=False)
    out = np.empty((len(q), 4, 4))
    for k, qk in enumerate(q):
        u.update_cfg(dict(zip(robot.joint_names, qk)))
        out[k] = u.get_transform(frame_to=robot.tip, frame_from=robot.base)
    return out


def _check_roundtrip(robot, corrected, tmp_path, rng, n):
    text = edit_joint_origins(robot.urdf_text, robot.changed_origins(corrected)).text
    path = tmp_path / "corrected.urdf"
    path.write_text(text)
    reloaded = Robot.load(path, tip=robot.tip, base=robot.base)
    q = random_joint_values(robot.geometry, rng, n)
    T_mem = corrected.tip_poses(q)
    T_pin = reloaded.tip_poses(q)
    assert np.abs(T_pin - T_mem).max() < 1e-12
    T_urdfpy = _yourdfpy_tip_poses(text, robot, q)
    assert np.abs(T_urdfpy - T_mem).max() < 1e-12
    return text


@pytest.mark.parametrize("name,tip", ROBOTS)
def test_export_reloads_to_the_corrected_model(name, tip, tmp_path, rng):
    robot = _load(name, tip)
    _check_roundtrip(robot, _corrected(robot, rng), tmp_path, rng, 1000)


@pytest.mark.parametrize("name,tip", ROBOTS)
def test_zero_errors_export_the_input_unchanged(name, tip):
    robot = _load(name, tip)
    model = mdh.extract(robot.geometry)
    same = robot.with_joint_frames(model.joint_frames(model.table))
    assert robot.changed_origins(same) == {}
    assert edit_joint_origins(robot.urdf_text, robot.changed_origins(same)).text == robot.urdf_text


@pytest.mark.parametrize("seed", range(15))
def test_random_chains_round_trip(seed, tmp_path):
    rng = np.random.default_rng(100 + seed)
    text, _ = random_chain(rng)
    src = tmp_path / "chain.urdf"
    src.write_text(text)
    robot = Robot.load(src, tip="tip")
    _check_roundtrip(robot, _corrected(robot, rng), tmp_path, rng, 200)


@pytest.mark.parametrize("name,tip", [("ec66", "flange"), ("ur10", "tool0"),
                                      ("tiago_file", "wrist_ft_tool_link")])
def test_export_changes_only_chain_origins(name, tip, rng):
    robot = _load(name, tip)
    text = edit_joint_origins(robot.urdf_text, robot.changed_origins(_corrected(robot, rng))).text
    assert text.count("<!--") == robot.urdf_text.count("<!--")
    old, new = robot.urdf_text.splitlines(), text.splitlines()
    assert len(old) == len(new)
    changed = [(a, b) for a, b in zip(old, new) if a != b]
    assert changed  # the corrections did land
    strip = re.compile(r'\s(xyz|rpy)="[^"]*"')
    for a, b in changed:
        assert "<origin" in a and "<origin" in b
        assert strip.sub("", a) == strip.sub("", b)


def test_joint_offset_next_to_gimbal_lock_keeps_rpy_readable(tmp_path, rng):
    from kincal.export.readable_export import corrected_text

    robot = _load("tiago_file", "wrist_ft_tool_link")  # arm_6 origin: rpy 0 -pi/2 -pi/2
    model = mdh.extract(robot.geometry)
    err = np.zeros_like(model.table)
    err[:, 3] = 1e-3  # a joint offset on every joint
    corrected = robot.with_joint_frames(model.joint_frames(model.table + err))
    plain, _ = corrected_text(robot, corrected, readable=False)
    assert np.max(np.abs(plain.for_joint("arm_6_joint").rpy_change)) > 1.0  # rpy alone swings
    result, moved = corrected_text(robot, corrected)
    assert [m.joint for m in moved] == ["arm_6_joint"] and moved[0].children == ("arm_7_joint",)
    assert result.for_joint("arm_6_joint").new_rpy == "0.0 -1.57079632679 -1.57079632679"
    assert np.max(np.abs(result.for_joint("arm_7_joint").rpy_change)) < 0.01
    path = tmp_path / "c.urdf"
    path.write_text(result.text)
    q = random_joint_values(robot.geometry, rng, 500)
    assert np.abs(Robot.load(path, tip=robot.tip).tip_poses(q) - corrected.tip_poses(q)).max() < 1e-12


def test_a_tilt_next_to_gimbal_lock_is_exact_and_reported(tmp_path, rng):
    from kincal.export.readable_export import RpySwing, corrected_text

    robot = _load("tiago_file", "wrist_ft_tool_link")  # arm_4 origin: rpy -pi/2 -pi/2 0
    model = mdh.extract(robot.geometry)
    err = np.zeros_like(model.table)
    err[robot.joint_names.index("arm_4_joint"), 1] = np.radians(0.2)  # alpha_3: a tilt
    corrected = robot.with_joint_frames(model.joint_frames(model.table + err))
    result, notes = corrected_text(robot, corrected)
    swings = [n for n in notes if isinstance(n, RpySwing)]
    assert [s.joint for s in swings] == ["arm_4_joint"]
    assert swings[0].rotation == pytest.approx(np.radians(0.2), rel=1e-6)
    assert swings[0].largest_change > np.radians(5)
    assert "no edit of joint origins alone avoids it" in swings[0].describe()
    path = tmp_path / "c.urdf"
    path.write_text(result.text)
    q = random_joint_values(robot.geometry, rng, 200)
    assert np.abs(Robot.load(path, tip=robot.tip).tip_poses(q) - corrected.tip_poses(q)).max() < 1e-12


def test_offset_moved_into_children_that_are_off_the_chain(tmp_path, rng):
    """The regauged joint's link also carries joints off the chain (a sensor's fixed frame, a
    mimic finger): their origins take the offset too, the written URDF keeps every one of
    their frames where the plain corrected URDF has them (a KeyError before: the lookup of
    their nominal origins knew only the chain's joints)."""
    from kincal.export.readable_export import Regauged, corrected_text

    base = _load("tiago_file", "wrist_ft_tool_link")
    extra = (
        '<joint name="hunt_sensor_joint" type="fixed"><parent link="arm_6_link"/>'
        '<child link="hunt_sensor"/><origin xyz="0.01 0.02 0.03" rpy="0.1 0.2 0.3"/></joint>'
        '<link name="hunt_sensor"/>'
        '<joint name="hunt_finger_joint" type="revolute"><parent link="arm_6_link"/>'
        '<child link="hunt_finger"/><origin xyz="0.0 0.04 0.0" rpy="0 0 0.2"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
        '<mimic joint="arm_6_joint" multiplier="0.5" offset="0.1"/></joint>'
        '<link name="hunt_finger"/></robot>')
    src = tmp_path / "tiago_extra.urdf"
    src.write_text(base.urdf_text.replace("</robot>", extra))
    robot = Robot.load(src, tip="wrist_ft_tool_link")
    model = mdh.extract(robot.geometry)
    err = np.zeros_like(model.table)
    err[:, 3] = 1e-3  # a joint offset on every joint: arm_6's is moved into its children
    corrected = robot.with_joint_frames(model.joint_frames(model.table + err))
    plain, _ = corrected_text(robot, corrected, readable=False)
    result, moved = corrected_text(robot, corrected)
    regauged = [m for m in moved if isinstance(m, Regauged)]
    assert [m.joint for m in regauged] == ["arm_6_joint"]
    assert set(regauged[0].children) == {"arm_7_joint", "hunt_sensor_joint", "hunt_finger_joint"}
    for text, name in ((plain.text, "plain.urdf"), (result.text, "readable.urdf")):
        (tmp_path / name).write_text(text)
    for tip in ("hunt_sensor", "hunt_finger", "wrist_ft_tool_link"):
        a, b = (Robot.load(tmp_path / name, tip=tip) for name in ("plain.urdf", "readable.urdf"))
        q = random_joint_values(a.geometry, rng, 50)
        assert np.abs(a.tip_poses(q) - b.tip_poses(q)).max() < 1e-12


def test_calibration_writes_a_regauged_joint_whose_link_carries_a_fixed_frame(tmp_path, rng,
                                                                              capsys):
    """kincal calibrate end to end where the readable export moves arm_6's offset into its
    children and one child is a fixed joint off the chain: the read-back check of the
    written URDF looked for that fixed joint's own children and crashed (StopIteration)."""
    from kincal.cli.main import main

    base = _load("tiago_file", "wrist_ft_tool_link")
    src = tmp_path / "tiago_sensor.urdf"
    src.write_text(base.urdf_text.replace("</robot>", (
        '<joint name="hunt_sensor_joint" type="fixed"><parent link="arm_6_link"/>'
        '<child link="hunt_sensor"/><origin xyz="0.01 0.02 0.03" rpy="0.1 0.2 0.3"/></joint>'
        '<link name="hunt_sensor"/></robot>')))
    robot = Robot.load(src, tip="wrist_ft_tool_link")
    model = mdh.extract(robot.geometry)
    err = np.zeros_like(model.table)
    err[:, 3] = 2e-3  # joint offsets: arm_6's (pitch -90 deg in its origin) is regauged
    truth = robot.with_joint_frames(model.joint_frames(model.table + err))
    q = random_joint_values(robot.geometry, rng, 40)
    T = truth.tip_poses(q)
    P = T[:, :3, 3] + T[:, :3, :3] @ np.array([0.05, 0.02, 0.1])
    rows = [",".join(robot.joint_names) + ",x,y,z"]
    rows += [",".join(repr(float(v)) for v in (*qi, *p)) for qi, p in zip(q, P)]
    (tmp_path / "d.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "c.urdf"
    assert main(["calibrate", str(src), str(tmp_path / "d.csv"), "--tip", "wrist_ft_tool_link",
                 "--model", "offsets", "--tool-offset", "0.05", "0.02", "0.1",
                 "--out", str(out), "--frames-out", str(tmp_path / "f.json"), "-q"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out), str(tmp_path / "d.csv"), "--frames",
                 str(tmp_path / "f.json"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["errors"]["max_mm"] < 1e-3  # noise-free data


def test_no_regauge_turns_a_link_a_chain_ends_at(tmp_path, rng, capsys):
    """Two chains, one to the wrist, one ending at arm_6_link, whose joint's offset (pitch -90
    deg in its origin) the readable export moved into its children: that turned arm_6_link's
    frame, the second chain's tip, and the read-back check refused the whole calibration
    ('differs from the calibrated model of base_footprint -> arm_6_link ... please report
    this').
    A joint whose child link is a chain's base or tip now keeps its offset."""
    from kincal.cli.main import main

    src = _load("tiago_file", "wrist_ft_tool_link").source
    tool = np.array([0.05, 0.02, 0.1])
    files = []
    for tip in ("wrist_ft_tool_link", "arm_6_link"):
        robot = Robot.load(src, tip=tip)
        model = mdh.extract(robot.geometry)
        err = np.zeros_like(model.table)
        err[:, 3] = 2e-3  # joint offsets: arm_6's is the one the export would regauge
        truth = robot.with_joint_frames(model.joint_frames(model.table + err))
        q = random_joint_values(robot.geometry, rng, 40)
        T = truth.tip_poses(q)
        P = T[:, :3, 3] + T[:, :3, :3] @ tool
        rows = [",".join(robot.joint_names) + ",x,y,z"]
        rows += [",".join(repr(float(v)) for v in (*qi, *p)) for qi, p in zip(q, P)]
        files.append(tmp_path / f"{tip}.csv")
        files[-1].write_text("\n".join(rows) + "\n")
    out = tmp_path / "c.urdf"
    assert main(["calibrate", str(src), *map(str, files), "--tip", "wrist_ft_tool_link",
                 "arm_6_link", "--model", "offsets", "--tool-offset", *map(str, tool),
                 "--out", str(out), "--frames-out", str(tmp_path / "f.json"), "-q"]) == 0
    capsys.readouterr()
    for tip, f in zip(("wrist_ft_tool_link", "arm_6_link"), files):
        assert main(["evaluate", str(out), str(f), "--tip", tip, "--frames",
                     str(tmp_path / "f.json"), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["errors"]["max_mm"] < 1e-3
