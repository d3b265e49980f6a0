"""Foundation: URDF loading, chain choice, MD-H extraction and the corrected model."""

import math

import numpy as np
import pytest
from conftest import EC66, random_joint_values, tiago_urdf

from kincal.errors import ChainError, FrameError, InputFileError, KincalError
from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.robot import Robot

D = math.pi / 180
# Table 1 of the paper (minus signs restored): a_{i-1} [mm], d_i [mm], alpha_{i-1} [deg], theta_oi [deg]
TABLE1 = [(0, 95.5, 0, 0), (0, 138.0, -90, 0), (418, -114.0, 0, 0),
          (398, 98.0, 0, 0), (0, 98.0, -90, 0), (0, 89.0, -90, 0)]

ROBOTS = [("ec66", "flange"), ("ur5", "tool0"), ("ur10", "tool0"), ("panda", "panda_link8"),
          ("tiago", "arm_tool_link")]


def _craig(a, alpha, d, theta):
    """Independent MD-H transform, written out from the definition Rx Tx Rz Tz."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    Rx = np.array([[1, 0, 0, 0], [0, ca, -sa, 0], [0, sa, ca, 0], [0, 0, 0, 1]])
    Tx = np.eye(4); Tx[0, 3] = a
    Rz = np.array([[ct, -st, 0, 0], [st, ct, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    Tz = np.eye(4); Tz[2, 3] = d
    return Rx @ Tx @ Rz @ Tz


def test_ec66_urdf_is_table1(rng):
    robot = Robot.load(EC66, tip="flange")
    q = random_joint_values(robot.geometry, rng, 1000)
    T = robot.tip_poses(q)
    for k in range(len(q)):
        F = np.eye(4)
        for (a, d, al, th), qi in zip(TABLE1, q[k]):
            F = F @ _craig(a * 1e-3, al * D, d * 1e-3, th * D + qi)
        assert np.abs(F[:3, 3] - T[k, :3, 3]).max() < 1e-12
        assert np.abs(F[:3, :3] - T[k, :3, :3]).max() < 1e-12


def test_ec66_extraction_gives_table1():
    model = mdh.extract(Robot.load("ec66").geometry)
    expected = np.array([(a * 1e-3, al * D, d * 1e-3, th * D) for a, d, al, th in TABLE1])
    assert np.abs(model.table - expected).max() < 1e-12
    assert np.abs(model.T_base_0 - np.eye(4)).max() < 1e-15
    assert "parallel" in model.notes[1] and "parallel" in model.notes[2]
    assert "intersect" in model.notes[0]


@pytest.mark.parametrize("name,tip", ROBOTS)
def test_zero_errors_reproduce_nominal_placements(name, tip):
    robot = Robot.load(name, tip=tip)
    model = mdh.extract(robot.geometry)
    corrected = robot.with_joint_frames(model.joint_frames(model.table))
    for j in robot._chain:
        A = robot.model.jointPlacements[j].homogeneous
        B = corrected.model.jointPlacements[j].homogeneous
        assert np.abs(A - B).max() < 1e-15
    origins, origins_c = robot.urdf_origins(), corrected.urdf_origins()
    for k in origins:
        assert np.abs(origins[k] - origins_c[k]).max() < 1e-15


def _random_table(model, rng, scale=1.0):
    err = rng.normal(size=model.table.shape) * scale
    err[:, [0, 2]] *= 2e-3   # lengths [m]
    err[:, [1, 3]] *= 5e-3   # angles [rad]
    return model.table + err


@pytest.mark.parametrize("name,tip", ROBOTS)
def test_corrected_pinocchio_model_equals_mdh_model(name, tip, rng):
    robot = Robot.load(name, tip=tip)
    model = mdh.extract(robot.geometry)
    table = _random_table(model, rng)
    corrected = robot.with_joint_frames(model.joint_frames(table))
    q = random_joint_values(robot.geometry, rng, 1000)
    R, p = MeasurementModel(model, q).tip_poses(table)
    T = corrected.tip_poses(q)
    assert np.abs(T[:, :3, 3] - p).max() < 1e-12
    assert np.abs(T[:, :3, :3] - R).max() < 1e-12
    # the nominal robot is untouched
    R0, p0 = MeasurementModel(model, q[:20]).tip_poses(model.table)
    assert np.abs(robot.tip_poses(q[:20])[:, :3, 3] - p0).max() < 1e-12


def test_tiago_file_has_prismatic_torso():
    robot = Robot.load(tiago_urdf(), tip="wrist_ft_tool_link")
    assert robot.joint_names[0] == "torso_lift_joint"
    assert robot.geometry.kinds[0] == "prismatic"
    assert robot.joint_names[1:] == tuple(f"arm_{i}_joint" for i in range(1, 8))
    assert robot.geometry.lower[0] == 0.0 and robot.geometry.upper[0] == pytest.approx(0.35)


def test_unknown_tip_lists_valid_frames():
    with pytest.raises(FrameError) as exc:
        Robot.load("ec66", tip="flang")
    assert "flange" in str(exc.value) and "Did you mean" in str(exc.value)
    assert "link_6" in exc.value.valid


def test_a_link_named_as_a_joint_is_the_frame_meant(rng):
    """example-robot-data's so100 has a link and a joint both named "gripper": --tip gripper
    crashed in Pinocchio ("ValueError: Several frames match the filter"), a traceback in
    every command. The link is the frame meant: its chain ends at wrist_roll, and its pose
    is Pinocchio's of the link."""
    import pinocchio as pin

    robot = Robot.load("so100", tip="gripper")
    assert robot.joint_names == ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex",
                                 "wrist_roll")
    q = random_joint_values(robot.geometry, rng, 3)
    m, d = robot.model, robot.model.createData()
    link = m.getFrameId("gripper", pin.FrameType.BODY)
    for qk, T in zip(q, robot.tip_poses(q)):
        pin.framesForwardKinematics(m, d, robot.configuration(qk))
        assert np.abs(T - (d.oMf[robot.base_id].inverse() * d.oMf[link]).homogeneous).max() < 1e-12
    assert Robot.load("so100", tip="jaw", base="gripper").joint_names == ("gripper",)


def test_tip_above_base_climbs_the_chain():
    """A tip above the base is a tree path: the joints between them, reversed."""
    robot = Robot.load("ec66", base="link_3", tip="link_1")
    assert robot.joint_names == ("joint_3", "joint_2")
    assert list(robot.geometry.is_reversed) == [True, True]
    q = np.array([[0.3, -0.7]])
    T = Robot.load("ec66", base="link_1", tip="link_3").tip_poses(q[:, ::-1])[0]  # joint_2, joint_3
    assert np.abs(robot.tip_poses(q)[0] - np.linalg.inv(T)).max() < 1e-12


def test_base_and_tip_on_one_body_is_rejected():
    with pytest.raises(ChainError, match="no movable joint"):
        Robot.load("ec66", base="link_6", tip="flange")


def test_floating_joint_on_chain_is_rejected(tmp_path):
    text = EC66.read_text().replace('<joint name="joint_3" type="revolute">',
                                    '<joint name="joint_3" type="floating">')
    path = tmp_path / "floating.urdf"
    path.write_text(text)
    with pytest.raises(ChainError, match="joint_3") as exc:
        Robot.load(path, tip="flange")
    assert "link_3" in str(exc.value)  # the valid base below it
    robot = Robot.load(path, base="link_3", tip="flange")  # below the floating joint it is fine
    assert robot.joint_names == ("joint_4", "joint_5", "joint_6")


def test_unknown_robot_name_and_missing_file():
    with pytest.raises(InputFileError, match="ur10"):
        Robot.load("ur11")
    with pytest.raises(InputFileError, match="not found"):
        Robot.load("/nonexistent/robot.urdf", tip="x")
    assert issubclass(FrameError, KincalError)


def test_no_tip_lists_leaf_links(tmp_path):
    path = tmp_path / "r.urdf"
    path.write_text(EC66.read_text())
    with pytest.raises(FrameError, match="flange"):
        Robot.load(path)


def test_off_chain_joint_values(rng):
    robot = Robot.load("tiago", tip="arm_tool_link", joint_values={"head_1_joint": 0.3})
    assert robot.off_chain == {"head_1_joint": 0.3}
    q = robot.configuration(np.zeros(robot.geometry.n))
    assert q[robot.model.joints[robot.model.getJointId("head_1_joint")].idx_q] == 0.3
    plain = Robot.load("tiago", tip="arm_tool_link")
    qs = random_joint_values(robot.geometry, rng, 5)
    assert np.abs(robot.tip_poses(qs) - plain.tip_poses(qs)).max() < 1e-15
    with pytest.raises(FrameError, match="head_1_joint"):
        Robot.load("tiago", tip="arm_tool_link", joint_values={"head_1_jiont": 0.3})
    with pytest.raises(FrameError, match="on the chain"):
        Robot.load("tiago", tip="arm_tool_link", joint_values={"arm_1_joint": 0.3})
