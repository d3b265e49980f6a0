"""Corrected URDF export: the written file is the corrected model, and nothing else changed."""

import io
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
