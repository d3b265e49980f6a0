"""Error models (kincal.models): analytic Jacobians, exactness, export, continuity, and the
accuracy each reaches on an arm with full 6-D joint-placement errors."""

import math

import numpy as np
import pytest
from chains import random_chain
from conftest import random_joint_values, tiago_urdf
from test_export_roundtrip import _check_roundtrip

from kincal import models
from kincal.errors import OptionError, ParameterError
from kincal.identification.problem import CalibrationOptions, CalibrationProblem, calibrate
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.robot import Robot

ROBOTS = [("ec66", "flange"), ("ur10", "tool0"), ("panda", "panda_link8"),
          ("tiago_file", "wrist_ft_tool_link")]
ERRORS = {"length": 1e-3, "twist": 3e-3, "offset": 3e-3}  # [m], [rad] sd of random errors


def _load(name, tip):
    return Robot.load(tiago_urdf() if name == "tiago_file" else name, tip=tip)


def _perturbed(model, rng, scale=1.0):
    sd = np.array([ERRORS[c] for c in model.classes]) * scale
    return model.nominal + rng.normal(size=model.size) * sd


def _near_parallel_urdf(tmp_path, tilt: float, name="near.urdf"):
    """A 4-joint arm whose joints 2 and 3 are parallel up to ``tilt`` [rad], tilted within
    their common plane (the direction plain MD-H cannot follow)."""
    joints = [("j1", "0 0 0.1", "0 0 0", "0 0 1"), ("j2", "0 0.1 0.2", "0 0 0", "0 1 0"),
              ("j3", "0.4 0 0", f"0 0 {tilt}", "0 1 0"), ("j4", "0.35 0 0.05", "0 0 0", "1 0 0")]
    lines = ['<?xml version="1.0"?>', '<robot name="near">', '  <link name="base_link"/>']
    parent = "base_link"
    for j, xyz, rpy, axis in joints:
        lines += [f'  <link name="{j}_link"/>', f'  <joint name="{j}" type="revolute">',
                  f'    <parent link="{parent}"/>', f'    <child link="{j}_link"/>',
                  f'    <origin xyz="{xyz}" rpy="{rpy}"/>', f'    <axis xyz="{axis}"/>',
                  '    <limit lower="-3" upper="3" effort="1" velocity="1"/>', "  </joint>"]
        parent = f"{j}_link"
    lines += ['  <link name="tip"/>', '  <joint name="tip_joint" type="fixed">',
              f'    <parent link="{parent}"/>', '    <child link="tip"/>',
              '    <origin xyz="0.1 0.02 0" rpy="0 0 0"/>', "  </joint>", "</robot>"]
    path = tmp_path / name
    path.write_text("\n".join(lines))
    return Robot.load(path, tip="tip")


def _check_jacobian(model, robot, rng, backlash=(), n_points=1):
    q = random_joint_values(robot.geometry, rng, 30)
    q[0] = 0.0
    points = np.arange(len(q)) % n_points
    approach = rng.choice([-1.0, 1.0], size=q.shape)
    mm = MeasurementModel(model, q, approach, backlash, points, n_points)
    x = mm.space.join(_perturbed(model, rng, 3.0), rng.normal(size=6) * [.5, .5, .5, 1, 1, 1],
                      rng.normal(size=(n_points, 3)) * 0.1,
                      rng.normal(size=mm.space.n_backlash) * 0.01)
    P, J = mm.jacobian(x)
    assert np.array_equal(P, mm.predict(x))
    h = 1e-6
    for c in range(x.size):
        e = np.zeros_like(x)
        e[c] = h
        fd = (mm.predict(x + e) - mm.predict(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        assert np.abs(J[:, :, c] - fd).max() / scale < 1e-6, (model.name, mm.space.names[c])
    return mm, x


# ------------------------------------------------------------------ Jacobians
@pytest.mark.parametrize("model_name", models.MODELS)
@pytest.mark.parametrize("name,tip", ROBOTS)
def test_jacobian_matches_central_differences(model_name, name, tip, rng):
    robot = _load(name, tip)
    model = models.build(model_name, robot.geometry)
    backlash = (robot.joint_names[1], robot.joint_names[-1])
    _check_jacobian(model, robot, rng, backlash, n_points=2)


@pytest.mark.parametrize("model_name", models.MODELS)
@pytest.mark.parametrize("seed", range(8))
def test_jacobian_on_random_chains_with_degenerate_axes(model_name, seed, tmp_path):
    rng = np.random.default_rng(seed)
    path = tmp_path / "chain.urdf"
    path.write_text(random_chain(rng)[0])
    robot = Robot.load(path, tip="tip")
    _check_jacobian(models.build(model_name, robot.geometry), robot, rng)


@pytest.mark.parametrize("model_name", models.MODELS)
def test_jacobian_with_axes_parallel_within_1e_4(model_name, tmp_path, rng):
    robot = _near_parallel_urdf(tmp_path, 1e-4)
    _check_jacobian(models.build(model_name, robot.geometry), robot, rng)


@pytest.mark.parametrize("name,tip", ROBOTS)
def test_fast_columns_equal_the_generic_twists(name, tip, rng):
    robot = _load(name, tip)
    for model in (models.build(m, robot.geometry) for m in ("mdh", "complete", "placement")):
        mm = MeasurementModel(model, random_joint_values(robot.geometry, rng, 20))
        state = mm.chain.state(_perturbed(model, rng, 3.0))
        P = state.p_tip + state.R_tip @ np.array([0.03, -0.02, 0.1])
        fast, generic = state.point_columns(P)[0], state.point_columns(P, generic=True)[0]
        assert np.abs(fast - generic).max() < 1e-13


# ---------------------------------------------------------- exactness, export
@pytest.mark.parametrize("model_name", models.MODELS)
@pytest.mark.parametrize("name,tip", ROBOTS)
def test_zero_errors_give_the_nominal_placements_exactly(model_name, name, tip, rng):
    robot = _load(name, tip)
    model = models.build(model_name, robot.geometry)
    # to rounding (products of 4x4 transforms), and no URDF origin changes at all
    assert np.abs(model.joint_frames() - robot.geometry.joint_frames).max() < 1e-14
    assert robot.changed_origins(robot.with_joint_frames(model.joint_frames())) == {}
    q = random_joint_values(robot.geometry, rng, 200)
    mm = MeasurementModel(model, q)
    x = mm.space.join(model.nominal, np.zeros(6), np.zeros(3))
    assert np.abs(mm.predict(x) - robot.tip_poses(q)[:, :3, 3]).max() < 1e-13


@pytest.mark.parametrize("model_name", models.MODELS)
@pytest.mark.parametrize("name,tip", ROBOTS)
def test_export_of_every_model_round_trips(model_name, name, tip, tmp_path, rng):
    robot = _load(name, tip)
    model = models.build(model_name, robot.geometry)
    x = _perturbed(model, rng)
    corrected = robot.with_joint_frames(model.joint_frames(x))
    _check_roundtrip(robot, corrected, tmp_path, rng, 1000)
    # the corrected Pinocchio model is the model's own prediction
    q = random_joint_values(robot.geometry, rng, 100)
    mm = MeasurementModel(model, q)
    P = mm.predict(mm.space.join(x, np.zeros(6), np.zeros(3)))
    assert np.abs(P - corrected.tip_poses(q)[:, :3, 3]).max() < 1e-12


# -------------------------------------------------------------- the models
def test_complete_adds_beta_exactly_at_parallel_axes():
    ec66 = models.build("complete", Robot.load("ec66").geometry)
    assert [n for n in ec66.names if n.endswith(".beta")] == ["joint_3.beta", "joint_4.beta"]
    ur10 = models.build("complete", Robot.load("ur10").geometry)
    assert [n for n in ur10.names if n.endswith(".beta")] == ["elbow_joint.beta",
                                                              "wrist_1_joint.beta"]
    assert np.all(ec66.nominal[[ec66.names.index("joint_3.beta")]] == 0.0)
    offsets = models.build("offsets", Robot.load("ur10").geometry)
    assert offsets.size == 6 and all(n.endswith(".theta") for n in offsets.names)


def test_offsets_model_names_a_prismatic_joint_d():
    model = models.build("offsets", Robot.load(tiago_urdf(), tip="wrist_ft_tool_link").geometry)
    assert model.names[0] == "torso_lift_joint.d" and model.is_length[0]


@pytest.mark.parametrize("tilt", [0.0, 1e-7, 1e-5, 1e-4, 1e-3, 1e-2])
def test_complete_model_is_continuous_through_parallel(tilt, tmp_path):
    """Tilting an axis by a small angle changes the complete model's parameters by about
    that much; plain MD-H's common normal jumps far away."""
    ref = models.build("complete", _near_parallel_urdf(tmp_path, 0.0, "ref.urdf").geometry)
    robot = _near_parallel_urdf(tmp_path, tilt)
    near = models.build("complete", robot.geometry)
    assert near.names == ref.names
    change = np.abs(near.nominal - ref.nominal)
    assert change.max() <= 2 * tilt + 1e-12
    if tilt >= 1e-5:
        mdh = models.build("mdh", robot.geometry)
        ref_mdh = models.build("mdh", _near_parallel_urdf(tmp_path, 0.0, "ref.urdf").geometry)
        assert np.abs(mdh.nominal - ref_mdh.nominal).max() > 100 * tilt  # MD-H jumps


def test_unknown_model_lists_the_valid_ones():
    with pytest.raises(OptionError, match="complete, mdh, placement, offsets"):
        CalibrationOptions(model="hayati").validated()


def test_fix_name_of_another_model_says_which_model_has_it(rng):
    robot = Robot.load("ec66")
    q = random_joint_values(robot.geometry, rng, 30)
    data = Measurements(robot.joint_names, q, robot.tip_poses(q)[:, :3, 3])
    with pytest.raises(ParameterError, match=r"joint_3\.beta.*model complete"):
        CalibrationProblem(robot, data, CalibrationOptions(model="mdh", fix=("joint_3.beta",)))
    with pytest.raises(ParameterError, match=r"joint_2\.tx.*model placement"):
        CalibrationProblem(robot, data, CalibrationOptions(fix=("joint_2.tx",)))


# ------------------------------------------- accuracy with 6-D placement errors
def _placement_truth(robot, rng, length=0.3e-3, angle=math.radians(0.05)):
    """A Pinocchio copy of ``robot`` with small errors on all six components of every
    joint placement: the real robot of the simulation."""
    truth = models.build("placement", robot.geometry)
    e = rng.normal(size=truth.size) * np.where(truth.is_length, length, angle)
    return robot.with_joint_frames(truth.joint_frames(e))


def _tracker(true_robot, q, tool, base_R, base_t, noise, rng):
    T = true_robot.tip_poses(q)
    P = T[:, :3, 3] + T[:, :3, :3] @ tool
    return P @ base_R.T + base_t + rng.normal(size=P.shape) * noise


def test_complete_and_placement_reach_the_noise_floor_where_mdh_does_not():
    """EC66 with 6-D placement errors, 80 wide tracker poses, 5 um noise: the held-out mean
    error of complete and placement is at the noise floor (true model), mdh's is not."""
    rng = np.random.default_rng(3)
    robot = Robot.load("ec66")
    true_robot = _placement_truth(robot, rng)
    tool = np.array([0.03, 0.02, 0.12])
    R = Robot.load("ec66")  # noqa: F841 - nominal robot reused below
    base_R, base_t = np.eye(3), np.array([0.5, -0.2, 0.1])
    q = random_joint_values(robot.geometry, rng, 80) * 0.8
    q_val = random_joint_values(robot.geometry, rng, 100) * 0.8
    data = Measurements(robot.joint_names, q, _tracker(true_robot, q, tool, base_R, base_t, 5e-6, rng))
    P_val = _tracker(true_robot, q_val, tool, base_R, base_t, 0.0, rng)
    held = {}
    for name in ("mdh", "complete", "placement"):
        res = calibrate(robot, data, model=name, method="ls")
        held[name] = float(np.mean(np.linalg.norm(res.predict(q_val) - P_val, axis=1)))
    # the floor: noise 5 um over 80 poses leaves a few um of prediction error
    assert held["complete"] < 10e-6 and held["placement"] < 10e-6, held
    assert held["mdh"] > 5 * held["complete"], held


@pytest.mark.parametrize("name,base,tip", [("talos", "left_sole_link", "gripper_left_base_link"),
                                           ("tiago_file", None, "wrist_ft_tool_link")])
def test_placement_offset_class_is_exactly_a_joint_zero(name, base, tip, rng):
    """A placement error of class "offset" (the evidence gives it the joint offsets' prior)
    moves the tip exactly as shifting that joint's value does; no "twist" error does."""
    robot = (Robot.load(tiago_urdf(), tip=tip) if name == "tiago_file"
             else Robot.load(name, base=base, tip=tip))
    model = models.build("placement", robot.geometry)
    q = random_joint_values(robot.geometry, rng, 5)
    joints = list(robot.geometry.joint_names)

    def tip_of(x, qq):
        s = MeasurementModel(model, qq).chain.state(x)
        return np.concatenate([s.p_tip, s.R_tip.reshape(len(qq), 9)], axis=1)

    n_offsets = 0
    for i, (pname, cls) in enumerate(zip(model.names, model.classes)):
        if cls not in ("offset", "twist"):
            continue
        x = model.nominal.copy()
        x[i] = 2e-3
        moved = tip_of(x, q)
        j = joints.index(pname.rsplit(".", 1)[0])
        gaps = []
        for sign in (1.0, -1.0):
            qq = q.copy()
            qq[:, j] += sign * 2e-3
            gaps.append(np.abs(moved - tip_of(model.nominal, qq)).max())
        if cls == "offset":
            n_offsets += 1
            assert min(gaps) < 1e-12, pname
        else:
            assert min(gaps) > 1e-7, pname
    assert n_offsets >= len(joints) - 2  # a revolute joint's zero per origin with errors


def test_analyze_model_all_says_what_placement_adds_over_mdh(tmp_path, capsys):
    """Audit of issue 10: the comparison listed '+' only for complete (by name), so placement,
    whose names are others, seemed to add nothing over mdh; it now counts the directions
    (placement's span holds mdh's: the rank difference)."""
    from kincal.cli.main import main

    data = tmp_path / "poses.csv"
    assert main(["simulate", "ec66", "--out", str(data), "--seed", "1", "-q"]) == 0
    capsys.readouterr()
    assert main(["analyze", "ec66", str(data), "--model", "all"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()
             if line.startswith("  ") and "kinematic parameters identified" in line}
    assert "(+ joint_3.beta, joint_4.beta)" in lines["complete"]
    assert "(+ 2 directions mdh cannot express)" in lines["placement"]
    assert "(+" not in lines["mdh"] and "(+" not in lines["offsets"]
