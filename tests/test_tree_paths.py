"""Chains along any tree path: a base anywhere in the URDF tree (a leaf, a sibling branch),
joints on the way up reversed. Forward kinematics against Pinocchio's own frames, analytic
Jacobians against central differences, the corrected URDF as the original tree."""

import io

import numpy as np

from kincal.export.outputs import corrected_urdf_text
import pinocchio as pin
import pytest
import yourdfpy
from chains import random_tree
from conftest import random_joint_values

from kincal.descriptions import erd_robots_dir
from kincal.errors import ChainError, FrameError, OptionError
from kincal.export.readable_export import corrected_text
from kincal.export.urdf_export import edit_joint_origins
from kincal.models import build as build_model
from kincal.models import mdh, offsets, placement
from kincal.models.chain import Chain
from kincal.models.kinematics import ChainKinematics
from kincal.robot import Robot
from kincal.rotations import axis_rotation

TOOL = np.array([0.03, -0.02, 0.05])
STEP = 1e-6  # central differences: errors O(STEP^2) ~ 1e-12 plus roundoff / STEP ~ 1e-10
TOL = 1e-7


def _tree(tmp_path, seed):
    text, joints = random_tree(np.random.default_rng(seed))
    path = tmp_path / f"tree_{seed}.urdf"
    path.write_text(text)
    return path, joints


def _talos_path():
    root = erd_robots_dir()
    path = None if root is None else root / "talos_data" / "robots" / "talos_full_v2.urdf"
    if path is None or not path.exists():
        pytest.skip("example-robot-data's TALOS is not installed")
    return path


# (base, tip, joints up, joints down) of the random tree's paths
def _paths(joints):
    a, b, c, t = joints["a"], joints["b"], joints["c"], joints["t"]
    return [("atip", "btip", a[::-1], b),                 # leaf -> sibling branch's leaf
            ("atip", "base_link", a[::-1] + t[::-1], []),  # leaf -> root: all reversed
            ("ctip", "atip", c[::-1], t + a),              # branch off the root -> leaf
            ("al1", "btip", a[:1][::-1], b),               # a link inside a branch
            ("base_link", "btip", [], t + b)]              # the classic chain below its base


def _pinocchio_relative(robot, q):
    """T_B_E from Pinocchio's own frames (oMf), independent of kincal's chain code."""
    m = robot.model
    d = m.createData()
    b, e = m.getFrameId(robot.base), m.getFrameId(robot.tip)
    out = np.empty((len(q), 4, 4))
    for k, qk in enumerate(q):
        pin.framesForwardKinematics(m, d, robot.configuration(qk))
        out[k] = (d.oMf[b].inverse() * d.oMf[e]).homogeneous
    return out


def _rotation_difference(Rp, Rm):
    dR = Rp @ np.swapaxes(Rm, 1, 2)
    return np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0],
                     dR[:, 1, 0] - dR[:, 0, 1]], axis=1) / 2


def _check_columns(model, q, x, backlash):
    """Point, orientation and backlash columns of the chain against central differences."""
    approach = np.sign(np.random.default_rng(1).normal(size=q.shape))
    chain = Chain(model, q, approach, backlash)
    b0 = np.full(len(backlash), 2e-3)
    st = chain.state(x, b0)
    P = st.p_tip + st.R_tip @ TOOL
    K, B = st.point_columns(P)
    Kg, _ = st.point_columns(P, generic=True)
    KR, BR = st.rotation_columns()

    def moved(xv, bv):
        s = chain.state(xv, bv, keep=False)
        return s.p_tip + s.R_tip @ TOOL, s.R_tip

    for k in range(model.size):
        dx = np.zeros(model.size)
        dx[k] = STEP
        (pp, Rp), (pm, Rm) = moved(x + dx, b0), moved(x - dx, b0)
        assert np.abs(K[:, :, k] - (pp - pm) / (2 * STEP)).max() < TOL, model.names[k]
        assert np.abs(KR[:, :, k] - _rotation_difference(Rp, Rm) / (2 * STEP)).max() < TOL
    assert np.abs(Kg - K).max() < 1e-12
    for k in range(len(backlash)):
        db = np.zeros(len(backlash))
        db[k] = STEP
        (pp, Rp), (pm, Rm) = moved(x, b0 + db), moved(x, b0 - db)
        assert np.abs(B[:, :, k] - (pp - pm) / (2 * STEP)).max() < TOL
        assert np.abs(BR[:, :, k] - _rotation_difference(Rp, Rm) / (2 * STEP)).max() < TOL


@pytest.mark.parametrize("seed", range(6))
def test_random_tree_paths_kinematics_and_jacobians(seed, tmp_path):
    path, joints = _tree(tmp_path, seed)
    rng = np.random.default_rng(seed)
    for base, tip, up, down in _paths(joints):
        robot = Robot.load(path, base=base, tip=tip)
        g = robot.geometry
        assert robot.joint_names == tuple(up + down)
        assert list(g.is_reversed) == [True] * len(up) + [False] * len(down)
        if base == "atip":  # branch a has a prismatic joint 2, climbed against its direction
            assert g.kinds[robot.joint_names.index("aj2")] == "prismatic"
        q = random_joint_values(g, rng, 12)
        q[0] = 0.0
        T_pin = _pinocchio_relative(robot, q)
        assert np.abs(robot.tip_poses(q) - T_pin).max() < 1e-12
        # the numpy chain (offsets model at zero) and its joint Jacobians
        R, p, Jp, Jr = ChainKinematics.of(g).evaluate(q)
        assert np.abs(p - T_pin[:, :3, 3]).max() < 1e-12
        assert np.abs(R - T_pin[:, :3, :3]).max() < 1e-12
        for k in range(3):
            J = robot.tip_jacobian(q[k])
            assert np.abs(Jp[k] - J[:3]).max() < 1e-12 and np.abs(Jr[k] - J[3:]).max() < 1e-12
            for i in range(g.n):  # Pinocchio's relative Jacobian against central differences
                dq = np.zeros(g.n)
                dq[i] = STEP
                Tp, Tm = robot.tip_poses(q[k] + dq)[0], robot.tip_poses(q[k] - dq)[0]
                assert np.abs(J[:3, i] - (Tp[:3, 3] - Tm[:3, 3]) / (2 * STEP)).max() < TOL
                w = _rotation_difference(Tp[None, :3, :3], Tm[None, :3, :3])[0] / (2 * STEP)
                assert np.abs(J[3:, i] - w).max() < TOL
        for build in (offsets.build, placement.build):
            model = build(g)
            assert np.abs(model.joint_frames() - g.joint_frames).max() < 1e-13
            x = model.nominal + rng.normal(size=model.size) * 1e-2
            backlash = tuple(range(0, g.n, 2))
            _check_columns(model, q, x, backlash)


@pytest.mark.parametrize("seed", range(6))
def test_tree_paths_corrected_urdf_is_the_original_tree(seed, tmp_path):
    """Random corrections written into the ORIGINAL file; reloaded by Pinocchio and by
    yourdfpy, the base -> tip transforms are the model's prediction to 1e-12 m."""
    path, joints = _tree(tmp_path, seed)
    rng = np.random.default_rng(50 + seed)
    original = pin.buildModelFromUrdf(str(path))
    for base, tip, _, _ in _paths(joints):
        robot = Robot.load(path, base=base, tip=tip)
        q = random_joint_values(robot.geometry, rng, 50)
        for build in (offsets.build, placement.build):
            model = build(robot.geometry)
            x = model.nominal + rng.normal(size=model.size) * np.where(model.is_length, 2e-3, 5e-3)
            st = Chain(model, q).state(x, keep=False)
            corrected = robot.with_joint_frames(model.joint_frames(x))
            T = corrected.tip_poses(q)
            assert np.abs(T[:, :3, 3] - st.p_tip).max() < 1e-12
            assert np.abs(T[:, :3, :3] - st.R_tip).max() < 1e-12
            text = edit_joint_origins(robot.urdf_text, robot.changed_origins(corrected)).text
            out = tmp_path / "corrected.urdf"
            out.write_text(text)
            reloaded = Robot.load(out, base=base, tip=tip)
            assert reloaded.model.names.tolist() == original.names.tolist()  # the same tree
            assert list(reloaded.model.parents) == list(original.parents)
            assert np.abs(reloaded.tip_poses(q)[:, :3, 3] - st.p_tip).max() < 1e-12
            assert np.abs(reloaded.tip_poses(q)[:, :3, :3] - st.R_tip).max() < 1e-12
            u = yourdfpy.URDF.load(io.BytesIO(text.encode()), load_meshes=False,
                                   build_collision_scene_graph=False, load_collision_meshes=False)
            assert u.base_link == "base_link"
            for k in range(0, len(q), 5):
                u.update_cfg(dict(zip(robot.joint_names, q[k])))
                Tu = u.get_transform(frame_to=tip, frame_from=base)
                assert np.abs(Tu[:3, 3] - st.p_tip[k]).max() < 1e-12
                assert np.abs(Tu[:3, :3] - st.R_tip[k]).max() < 1e-12


def test_offset_of_a_reversed_joint_is_written_into_its_own_origin(tmp_path):
    path, joints = _tree(tmp_path, 3)
    robot = Robot.load(path, base="atip", tip="btip")
    model = offsets.build(robot.geometry)
    old = robot.urdf_origins()
    for i, name in enumerate(robot.joint_names):
        x = np.zeros(model.size)
        x[i] = 0.01
        new = robot.with_joint_frames(model.joint_frames(x)).urdf_origins()
        # the others move by roundoff only (the model's frames are products over the chain)
        changed = {k: T for k, T in new.items() if np.abs(T - old[k]).max() > 1e-12}
        assert list(changed) == [name]
        # the joint's frame turned (slid) in its parent link about (along) its URDF axis:
        # the true joint value is the reading + 0.01, whichever way the chain runs
        axis = robot.geometry.axes[i] * (-1 if robot.geometry.is_reversed[i] else 1)
        D = np.linalg.inv(old[name]) @ changed[name]
        if robot.geometry.kinds[i] == "prismatic":
            assert np.abs(D[:3, 3] - 0.01 * axis).max() < 1e-13
            assert np.abs(D[:3, :3] - np.eye(3)).max() < 1e-13
        else:
            assert np.abs(D[:3, 3]).max() < 1e-13
            assert np.abs(D[:3, :3] - axis_rotation(axis, 0.01)).max() < 1e-13


def test_placement_names_are_the_origins_it_writes(tmp_path):
    path, joints = _tree(tmp_path, 4)
    robot = Robot.load(path, base="atip", tip="btip")
    model = placement.build(robot.geometry)
    top = joints["a"][0]  # the last reversed joint: its origin and bj1's are one transform
    assert not any(n.startswith(top + ".") for n in model.names)
    assert "bj1" in model.notes[robot.joint_names.index(top)]
    old = robot.urdf_origins()
    for k, name in enumerate(model.names):
        x = np.zeros(model.size)
        x[k] = 1e-3
        new = robot.with_joint_frames(model.joint_frames(x)).urdf_origins()
        changed = [k for k, T in new.items() if np.abs(T - old[k]).max() > 1e-12]
        assert changed == [name.split(".")[0]], name


def test_mdh_models_refuse_tree_paths_in_one_line(tmp_path):
    path, _ = _tree(tmp_path, 0)
    robot = Robot.load(path, base="atip", tip="btip")
    for name in ("complete", "mdh"):
        with pytest.raises(OptionError, match="tree path") as exc:
            build_model(name, robot.geometry)
        assert "'placement'" in str(exc.value) and "\n" not in str(exc.value)
    below = Robot.load(path, base="base_link", tip="btip")  # no reversed joint: MD-H as ever
    assert mdh.extract(below.geometry).n == below.geometry.n


def _tree_points(tmp_path, n):
    """(URDF path, the atip -> btip chain of random tree 0, a file of its tip points at n
    random joint values, the nominal model's)."""
    path, _ = _tree(tmp_path, 0)
    robot = Robot.load(path, base="atip", tip="btip")
    q = random_joint_values(robot.geometry, np.random.default_rng(0), n)
    T = robot.tip_poses(q)
    data = tmp_path / "d.csv"
    data.write_text(",".join([*robot.joint_names, "x", "y", "z"]) + "\n" + "\n".join(
        ",".join(repr(float(v)) for v in [*row, *t[:3, 3]]) for row, t in zip(q, T)) + "\n")
    return path, robot, data


def test_mdh_out_on_a_tree_path_refused_before_the_fit(tmp_path, capsys):
    """--mdh-out on a chain from a base off the tip's branch: one line saying why (no MD-H
    table describes it) before any fit, nothing written (before: the error model's message
    after the fit, about a model the user had not chosen)."""
    from kincal.cli.main import main

    path, robot, data = _tree_points(tmp_path, 20)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["calibrate", str(path), str(data), "--base", "atip", "--tip", "btip",
                 "--out", str(tmp_path / "c.urdf"), "--mdh-out", str(tmp_path / "m.csv")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--mdh-out: an MD-H table describes a chain down" in err[0], err
    assert "traversed upward" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_mdh_table_of_a_tree_path_refused_through_the_api_as_the_command_line_does(tmp_path):
    """write_calibration(result, Outputs(mdh=...)) on a chain from a base off the tip's
    branch: one line saying why no MD-H table describes it, nothing written (before: the
    'complete' error model's refusal, a model the user had not chosen)."""
    from kincal import Measurements, Outputs, calibrate, write_calibration
    from kincal.errors import ExportError

    path, robot, data = _tree_points(tmp_path, 40)
    result = calibrate(robot, Measurements.from_csv(data, robot.joint_names), model="placement")
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(ExportError, match="an MD-H table describes a chain down from its base, "
                       r"which a chain from a base off the tip's branch \(atip -> btip: \d+ "
                       "joints traversed upward\\) is not") as exc:
        write_calibration(result, Outputs(urdf=tmp_path / "c.urdf", mdh=tmp_path / "m.csv"))
    assert "\n" not in str(exc.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_bad_base_and_tip_in_one_line(tmp_path):
    path, _ = _tree(tmp_path, 0)
    with pytest.raises(FrameError, match="unknown base frame 'nowhere'") as exc:
        Robot.load(path, base="nowhere", tip="btip")
    assert "atip" in str(exc.value) and "atip" in exc.value.valid
    with pytest.raises(FrameError, match="unknown tip frame"):
        Robot.load(path, base="atip", tip="btipp")
    with pytest.raises(FrameError, match="same frame 'atip'"):
        Robot.load(path, base="atip", tip="atip")
    # Pinocchio's frame 0 is no URDF frame: not offered, not taken (a FRAMES.json naming it
    # would name a base no other URDF reader finds)
    with pytest.raises(FrameError, match="unknown base frame 'universe'") as exc:
        Robot.load(path, base="universe", tip="btip")
    assert "universe" not in exc.value.valid and "base_link" in exc.value.valid
    text = path.read_text()
    for kind in ("floating", "planar"):
        bad = tmp_path / f"{kind}.urdf"
        # the trunk's first joint lies on the path ctip -> atip
        bad.write_text(text.replace('<joint name="tj1" type="revolute">', f'<joint name="tj1" type="{kind}">')
                       .replace('<joint name="tj1" type="continuous">', f'<joint name="tj1" type="{kind}">'))
        with pytest.raises(ChainError, match=f"joint 'tj1' on the chain 'ctip' -> 'atip' is a") as exc:
            Robot.load(bad, base="ctip", tip="atip")
        assert "\n" not in str(exc.value) and "avoids it" in str(exc.value)
        assert Robot.load(bad, base="atip", tip="btip").geometry.n > 0  # off the path: fine


def test_talos_left_sole_to_left_gripper():
    """TALOS standing on its left foot: 6 leg joints reversed, 2 torso, 7 arm joints."""
    path = _talos_path()
    robot = Robot.load(path, base="left_sole_link", tip="gripper_left_base_link")
    g = robot.geometry
    assert robot.joint_names == tuple([f"leg_left_{i}_joint" for i in range(6, 0, -1)]
                                      + ["torso_1_joint", "torso_2_joint"]
                                      + [f"arm_left_{i}_joint" for i in range(1, 8)])
    assert list(g.is_reversed) == [True] * 6 + [False] * 9
    rng = np.random.default_rng(7)
    q = random_joint_values(g, rng, 200)
    T_pin = _pinocchio_relative(robot, q)
    for build in (offsets.build, placement.build):
        st = Chain(build(g), q).state(build(g).nominal, keep=False)
        assert np.abs(st.p_tip - T_pin[:, :3, 3]).max() < 1e-12
        assert np.abs(st.R_tip - T_pin[:, :3, :3]).max() < 1e-12
    # the foot is where the chain starts: the sole stays put while the legs move
    assert np.abs(T_pin[:, :3, 3]).max() > 0.5


def test_talos_calibration_end_to_end(tmp_path):
    """Simulated points of TALOS's left gripper seen from its left sole, planted placement
    errors: the calibration reproduces the measurements, and the corrected URDF (the original
    tree with corrected origins) reproduces the model through Pinocchio and yourdfpy."""
    from kincal import calibrate
    from kincal.measurements.data import Measurements

    path = _talos_path()
    robot = Robot.load(path, base="left_sole_link", tip="gripper_left_base_link")
    g = robot.geometry
    rng = np.random.default_rng(3)
    q = random_joint_values(g, rng, 150) * 0.6
    model = placement.build(g)
    x_true = rng.normal(size=model.size) * np.where(model.is_length, 1e-3, 2e-3)
    st = Chain(model, q).state(x_true, keep=False)
    tool = np.array([0.0, 0.0, -0.12])
    T_mb = np.eye(4)
    T_mb[:3, 3] = (1.0, -0.3, 0.05)
    positions = (st.p_tip + st.R_tip @ tool) @ T_mb[:3, :3].T + T_mb[:3, 3]
    data = Measurements(g.joint_names, q, positions)
    result = calibrate(robot, data, model="placement")
    assert result.converged
    predicted = result.predict(q)
    assert np.abs(predicted - positions).max() < 1e-8
    text = corrected_urdf_text(result, readable=False)
    out = tmp_path / "talos_corrected.urdf"
    out.write_text(text)
    reloaded = Robot.load(out, base="left_sole_link", tip="gripper_left_base_link")
    T_corr = result.corrected.tip_poses(q)
    assert np.abs(reloaded.tip_poses(q) - T_corr).max() < 1e-12
    root_joints = [j for j in pin.buildModelFromUrdf(str(path)).names]
    assert list(reloaded.model.names) == root_joints
    # the readable export (offsets moved to child origins near gimbal lock) is exact too, and
    # changes attribute values of joint origins only
    edits, _ = corrected_text(robot, result.corrected, readable=True)
    out.write_text(edits.text)
    again = Robot.load(out, base="left_sole_link", tip="gripper_left_base_link")
    assert np.abs(again.tip_poses(q) - T_corr).max() < 1e-12
    assert len(edits.text.splitlines()) == len(robot.urdf_text.splitlines())
    assert "leg_left_1_joint" not in robot.changed_origins(result.corrected)  # see the note


def test_talos_floor_is_carried_with_the_sole():
    """Collision floor on a tree path: z <= floor_z of the base frame (the left sole) follows
    the sole, whatever the leg joints do in Pinocchio's world."""
    from kincal.collision import CollisionChecker

    robot = Robot.load(_talos_path(), base="left_sole_link", tip="gripper_left_base_link")
    checker = CollisionChecker(robot, floor_z=-0.01)
    standing = np.zeros(robot.geometry.n)
    assert checker.has_geometry and not checker.colliding(standing)[0]
    crouched = standing.copy()
    crouched[robot.joint_names.index("leg_left_4_joint")] = 2.0  # the knee folds: body falls
    assert checker.colliding(crouched)[0]
    assert not CollisionChecker(robot, floor_z=None).colliding(crouched)[0]


def test_default_model_for_a_tree_path(tmp_path):
    from kincal.models import DEFAULT, default_for

    path, _ = _tree(tmp_path, 1)
    assert default_for(Robot.load(path, base="atip", tip="btip").geometry) == "placement"
    assert default_for(Robot.load(path, base="base_link", tip="btip").geometry) == DEFAULT
    build_model(default_for(Robot.load(path, base="atip", tip="btip").geometry),
                Robot.load(path, base="atip", tip="btip").geometry)


def test_inverse_kinematics_on_a_tree_path(tmp_path):
    """Damped least squares with the relative Jacobian: the base moves too."""
    path, _ = _tree(tmp_path, 2)
    robot = Robot.load(path, base="atip", tip="btip")
    rng = np.random.default_rng(2)
    q_true = random_joint_values(robot.geometry, rng, 1)[0] * 0.5
    T = robot.tip_poses(q_true)[0]
    target = T[:3, 3] + T[:3, :3] @ TOOL
    q, ok = robot.inverse_kinematics(target, tool=TOOL, rotation=T[:3, :3],
                                     start=q_true + rng.normal(size=q_true.shape) * 0.05)
    assert ok
    T_q = robot.tip_poses(q)[0]
    assert np.abs(T_q[:3, 3] + T_q[:3, :3] @ TOOL - target).max() < 1e-9


def test_talos_study_script_improves_every_held_out_figure():
    """scripts/talos_contact.py on the shared real data: the calibration written by the
    command line improves the held-out height and both tilts over the nominal model (the
    README table's figures come from this script)."""
    import tempfile
    from pathlib import Path

    study = _talos_study()

    names, q_train = study.joint_rows(study.DATA / "left_train.csv")
    _, q_valid = study.joint_rows(study.DATA / "left_validation.csv")
    urdf = study.talos_urdf()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        nominal = study.held_out(urdf, study.nominal_frames(folder, urdf), q_train, q_valid, names)
        cal, frames = study.calibrate(folder, urdf, study.DATA / "left_train.csv", "cal")
        after = study.held_out(cal, frames, q_train, q_valid, names)
        # one tilt of the table fitted to the touches themselves: on the held-out day it
        # takes out most of the roll (the table turned between the days, docs/results.md),
        # on the training day, whose plane the calibration fitted, next to nothing
        turned = study.held_out(cal, frames, q_train, q_valid, names, table_tilt=True)
        same = study.held_out(cal, frames, q_train, q_train, names)
        same_turned = study.held_out(cal, frames, q_train, q_train, names, table_tilt=True)
    assert nominal[0] > 9.0  # the README's nominal baseline: 10.1 mm
    for before, now, what in zip(nominal, after, ("height", "roll", "pitch")):
        assert now < 0.6 * before, (what, before, now)
    assert turned[1] < 0.7 * after[1] and turned[2] < after[2]
    assert same_turned[1] > 0.98 * same[1] and same_turned[2] > 0.98 * same[2]


def test_talos_mirror_image_on_the_right_chain_gives_the_left_figures(tmp_path):
    """The real touches mirrored through the sole's xz plane, calibrated on the right chain
    (right sole -> right gripper) by the same command: the same problem mirrored, so the
    held-out height, roll and pitch and the log evidence are the left chain's (nothing in
    kincal may favour one side of the tree; the independent check uses another chain)."""
    study = _talos_study()
    names, q_train = study.joint_rows(study.DATA / "left_train.csv")
    _, q_valid = study.joint_rows(study.DATA / "left_validation.csv")
    urdf = study.talos_urdf()
    cal, frames = study.calibrate(tmp_path, urdf, study.DATA / "left_train.csv", "left")
    left = (*study.held_out(cal, frames, q_train, q_valid, names), study.LOG_EVIDENCE["left"])
    rows = {label: values for label, *values in study.mirrored(urdf, tmp_path)}
    right = rows["mirror image of the real touches, right sole -> right gripper"]
    assert np.allclose(right, left, rtol=0, atol=1e-6), (right, left)
    assert left[0] < 5.0  # a calibration, not two equal failures
    # the other chains of those touches calibrate too (rows of docs/results.md)
    assert all(np.all(np.isfinite(v[:3])) and v[0] < 6.0 for v in rows.values())
    # together, the real left touches and their mirror image are the same problem on either
    # chain: each chain gets the other's figures (the first-listed chain got 4.37 mm / 0.484
    # / 0.292 deg, the second 4.44 / 0.494 / 0.289, when a shared torso joint carried the
    # first chain's share of what it has in common with each chain's own origins)
    pair = [v[:3] for label, v in rows.items() if "together" in label]
    assert len(pair) == 2 and np.allclose(pair[0], pair[1], rtol=0, atol=1e-4), pair


def _talos_study():
    """scripts/talos_contact.py as a module (skips when the shared TALOS data is absent)."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("talos_contact", root / "scripts" / "talos_contact.py")
    study = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(study)
    if not study.DATA.is_dir():
        pytest.skip("../shared/data/talos_contact is not present")
    return study


def test_talos_study_day_planes_and_urdf_alone():
    """scripts/talos_contact.py's decomposition of the held-out error (docs/results.md,
    TALOS): both days fitted with a plane per day keep far less roll on the second day
    than with one plane for both (the table moved against the sole between the days), and
    the default's files judged on the URDF's tip frame and the contact point alone (the
    face tilt in FRAMES.json not applied) hold out as well as with it: the URDF carries the
    face tilt (kincal.export.contact_fold; before, pitch 0.490 against 0.267 deg)."""
    import tempfile
    from pathlib import Path

    study = _talos_study()
    names, q_train = study.joint_rows(study.DATA / "left_train.csv")
    _, q_valid = study.joint_rows(study.DATA / "left_validation.csv")
    q_both = np.vstack([q_train, q_valid])
    urdf = study.talos_urdf()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        one, days = folder / "one.csv", folder / "days.csv"
        study.write_joint_csv(one, names, q_both)
        study.write_joint_csv(days, names, q_both, [1] * len(q_train) + [2] * len(q_valid))
        floor = study.held_out(*study.calibrate(folder, urdf, one, "one"), q_both, q_valid, names)
        per_day = study.calibrate(folder, urdf, days, "days")
        own = study.held_out(*per_day, q_both, q_valid, names, plane="2")
        tilt, offset = study.plane_change(per_day[1])
        cal = study.calibrate(folder, urdf, study.DATA / "left_train.csv", "cal")
        with_tilt = study.held_out(*cal, q_train, q_valid, names)
        alone = study.held_out(*cal, q_train, q_valid, names, face_tilt=False)
    assert own[1] < 0.6 * floor[1], (own, floor)  # results.md: 0.178 against 0.404 deg
    assert 0.3 < tilt < 1.0 and 4.0 < abs(offset) < 12.0, (tilt, offset)
    assert alone == pytest.approx(with_tilt, abs=1e-6)  # the URDF holds the face tilt
    assert with_tilt[2] < 0.3, with_tilt  # results.md: 0.267 deg


def test_talos_log_closes_the_feet_loop_on_the_nominal_model():
    """docs/results.md, TALOS: the log's leg joint values put the right sole at one place
    seen from the left through both legs on the nominal model (to hundredths of a mm), and
    the check would see a leg that differs from its model: one hip pitch off by 1 deg moves
    the closed loop by millimetres over these postures."""
    study = _talos_study()
    urdf = study.talos_urdf()
    names, q_train = study.joint_rows(study.DATA / "left_train.csv")
    d50, dmax, t50, tmax = study.feet_closure(urdf, names, q_train)
    assert d50 < 0.05 and t50 < 0.01 and dmax < 1.0
    q = q_train.copy()
    q[:, names.index("leg_left_3_joint")] += np.radians(1.0)
    d50_off, _, t50_off, _ = study.feet_closure(urdf, names, q)
    assert d50_off > 1.0 and t50_off > 0.1


def test_evaluate_gives_roll_and_pitch_as_the_study_computes_them(tmp_path, capsys):
    """kincal evaluate on flush touches reports the RMS roll (about the contact frame's x
    axis) and pitch (about its y axis) beside the tilt; on the real TALOS held-out touches
    they equal what scripts/talos_contact.py computes from the written files on its own
    (Pinocchio tip poses, FRAMES.json's plane), and roll^2 + pitch^2 is the tilt's RMS^2."""
    import json

    from kincal.cli.main import main

    study = _talos_study()
    names, q_train = study.joint_rows(study.DATA / "left_train.csv")
    _, q_valid = study.joint_rows(study.DATA / "left_validation.csv")
    urdf = study.talos_urdf()
    cal, frames = study.calibrate(tmp_path, urdf, study.DATA / "left_train.csv", "cal")
    valid = tmp_path / "valid.csv"
    study.write_joint_csv(valid, names, q_valid)
    capsys.readouterr()
    assert main(["evaluate", str(cal), str(valid), "--frames", str(frames), "--base",
                 study.BASE, "--tip", study.TIP, "--on-plane", "--flush", "--json"]) == 0
    o = json.loads(capsys.readouterr().out)["orientation_errors"]
    _, roll, pitch = study.held_out(cal, frames, q_train, q_valid, names, plane="")
    assert o["roll_rms_deg"] == pytest.approx(roll, abs=1e-6)
    assert o["pitch_rms_deg"] == pytest.approx(pitch, abs=1e-6)
    assert o["roll_rms_deg"] ** 2 + o["pitch_rms_deg"] ** 2 == pytest.approx(o["rms_deg"] ** 2)
    assert main(["evaluate", str(cal), str(valid), "--frames", str(frames), "--base",
                 study.BASE, "--tip", study.TIP, "--on-plane", "--flush"]) == 0
    assert f"RMS roll {roll:.4f}, pitch {pitch:.4f} deg" in capsys.readouterr().out
    # calibrate --validate: the same held-out roll and pitch, before and after
    assert main(["calibrate", str(urdf), str(study.DATA / "left_train.csv"), "--base",
                 study.BASE, "--tip", study.TIP, "--on-plane", "--flush", "--tool-offset", "0",
                 "0", "-0.12", "--validate", str(valid), "--out", str(tmp_path / "v.urdf"),
                 "--json"]) == 0
    v = json.loads(capsys.readouterr().out)["validation"]["orientation_errors"]
    assert v["after"]["roll_rms_deg"] == pytest.approx(roll, abs=1e-6)
    assert v["after"]["pitch_rms_deg"] == pytest.approx(pitch, abs=1e-6)
    assert v["before"]["rms_deg"] > 3 * v["after"]["rms_deg"]


def test_plan_on_a_tree_path_uses_the_placement_model(tmp_path, capsys):
    """kincal plan on a chain from a base off the tip's branch plans for the chain's default
    model (placement), as calibrate fits it (before: the complete model's refusal)."""
    from kincal.cli.main import main
    from kincal.planning.pose_selection import select_poses

    path, _ = _tree(tmp_path, 0)
    robot = Robot.load(path, base="atip", tip="btip")
    q = random_joint_values(robot.geometry, np.random.default_rng(1), 300)
    chosen = select_poses(robot, q, 40, tool=(0.0, 0.0, 0.05))
    assert len(chosen.indices) == 40
    with pytest.raises(OptionError, match="tree path"):
        select_poses(robot, q, 40, tool=(0.0, 0.0, 0.05), model="complete")
    out = tmp_path / "plan.csv"
    assert main(["plan", str(path), "--base", "atip", "--tip", "btip", "--random", "300",
                 "--poses", "40", "--tool-offset", "0", "0", "0.05", "--out", str(out)]) == 0, \
        capsys.readouterr().err
    assert len(out.read_text().strip().splitlines()) >= 41


def test_talos_summary_and_report_say_which_kept_parameters_stand_in_amplified(tmp_path, capsys):
    """On the TALOS touches from the sole, a dropped leg translation acts like 27x a kept
    one: the calibrate summary says so under its identifiable line, and REPORT.json and the
    HTML report carry the note and each dropped parameter's amplification."""
    import json

    from kincal.cli.main import main

    study = _talos_study()
    report, html = tmp_path / "r.json", tmp_path / "r.html"
    capsys.readouterr()
    assert main(["calibrate", str(study.talos_urdf()), str(study.DATA / "left_train.csv"),
                 "--base", study.BASE, "--tip", study.TIP, "--on-plane", "--flush",
                 "--tool-offset", "0", "0", "-0.12", "--out", str(tmp_path / "c.urdf"),
                 "--report", str(report), "--html", str(html)]) == 0
    lines = capsys.readouterr().out.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("  identifiable:"))
    notes = []  # the notes under it: what the touches leave at the start, the stand-ins
    while lines[k + 1 + len(notes)].startswith("  note: "):
        notes.append(lines[k + 1 + len(notes)][len("  note: "):])
    (note,) = [n for n in notes if "amplified up to 28x" in n]
    assert "leg_left_5_joint.tx ~ +27.4 leg_left_2_joint.tx" in note
    assert any("held at their start: tool.z .x .y" in n for n in notes)
    ident = json.loads(report.read_text())["identifiability"]
    gains = {d["name"]: d["amplification"] for d in ident["dropped"]}
    assert gains["leg_left_5_joint.tx"] == pytest.approx(28, abs=0.5)
    assert ident["stand_in_note"] == note
    assert "amplified up to 28x" in html.read_text()
    # the stance leg read as a 7 deg turn of its hip: the export says how far that moves the
    # sole against the pelvis, which the touches do not see (it said nothing)
    (moved,) = [line for line in lines if line.startswith("  export: the corrections move")]
    assert ("base left_sole_link 7.14 deg and 87.9 mm against base_link (the URDF's root), "
            "where it turns toward its tip (RMS at the 21 samples' joint values, through the 6 "
            "joint(s) it climbs, leg_left_6_joint ... leg_left_1_joint)") in moved, moved
    assert "export: the corrections move the chain&#x27;s base left_sole_link 7.14 deg" in \
        html.read_text()
    assert json.loads(report.read_text())["export_notes"][-1] == moved[len("  export: "):]


def _root_pose(robot, model, frame, q):
    """(N, 4, 4) the frame's pose in the URDF's root link, from Pinocchio's own frames of
    ``model`` at the chain joint values q of ``robot`` (independent of kincal's chain code)."""
    d = model.createData()
    root = model.frames[1].name  # the root link's body frame follows "universe"
    r, f = model.getFrameId(root), model.getFrameId(frame)
    out = np.empty((len(q), 4, 4))
    for k, qk in enumerate(q):
        pin.framesForwardKinematics(model, d, robot.configuration(qk))
        out[k] = (d.oMf[r].inverse() * d.oMf[f]).homogeneous
    return out


@pytest.mark.filterwarnings("ignore")  # weak parameters of a random tree's fit
@pytest.mark.parametrize("seed", [1, 4])
def test_a_base_moved_against_the_root_is_said(tmp_path, seed):
    """A chain from a leaf off the root (ctip, up branch c, down the trunk to atip) whose
    climb carries turns of degrees: the export says how far the corrections move the base
    against the URDF's root, by the figures Pinocchio's own frames of the corrected model
    give; the same errors below a root base (base_link -> atip) move nothing of the kind,
    and small ones stay below the note's thresholds. (TALOS's flush touches from the left
    sole moved the sole 7.1 deg and 88 mm against the pelvis without a word.)"""
    from kincal import calibrate
    from kincal.export import base_motion
    from kincal.measurements.data import Measurements

    path, joints = _tree(tmp_path, seed)
    rng = np.random.default_rng(seed)
    said = {}
    for base, scale in (("ctip", 4.0), ("base_link", 4.0), ("ctip", 0.05)):
        robot = Robot.load(path, base=base, tip="atip")
        g = robot.geometry
        q = random_joint_values(g, rng, 120) * 0.7
        model = placement.build(g)
        # a turn of `scale` deg about a random axis of every origin, a few mm along one
        x_true = np.where(model.is_length, rng.normal(size=model.size) * scale * 1e-3,
                          np.radians(scale) * rng.normal(size=model.size) / np.sqrt(3))
        st = Chain(model, q).state(x_true, keep=False)
        positions = st.p_tip + st.R_tip @ TOOL
        result = calibrate(robot, Measurements(g.joint_names, q, positions),
                           model="placement", method="ls")
        notes = base_motion.notes(result)
        said[(base, scale)] = notes
        if (base, scale) != ("ctip", 4.0):
            continue
        T0 = _root_pose(robot, robot.model, base, q)
        T1 = _root_pose(robot, result.corrected.model, base, q)
        D = np.linalg.solve(T0, T1)
        turn = np.degrees(np.arccos(np.clip((np.trace(D[:, :3, :3], axis1=1, axis2=2) - 1) / 2,
                                            -1, 1)))
        move = np.linalg.norm(D[:, :3, 3], axis=1) * 1e3
        rms = float(np.sqrt(np.mean(turn ** 2))), float(np.sqrt(np.mean(move ** 2)))
        assert rms[0] > base_motion.TURN_DEG, rms  # the case is one for the note
        assert len(notes) == 1 and (f"base ctip {rms[0]:.3g} deg and {rms[1]:.3g} mm against "
                                    "base_link (the URDF's root)") in notes[0], (notes, rms)
        assert f"through the {len(joints['c'])} joint(s) it climbs" in notes[0]
    assert said[("base_link", 4.0)] == () and said[("ctip", 0.05)] == (), said


@pytest.mark.filterwarnings("ignore")  # weak parameters of the fits
def test_no_base_move_said_where_the_chain_does_not_climb(tmp_path):
    """Chains that do not climb say nothing, at no cost, and do not fail: a base below the
    URDF's root through fixed joints only (example-robot-data's UR10: root 'world', base
    base_link; the export failed with 'no movable joint between base world and tip
    base_link'), and with several chains one whose base is an ancestor of its tip while
    another chain corrects the joints above that base (the note measured those at zero
    joint values and blamed the chain's load)."""
    from kincal import calibrate
    from kincal.export import base_motion
    from kincal.measurements.data import Measurements

    robot = Robot.load("ur10", base="base_link", tip="tool0")
    g = robot.geometry
    rng = np.random.default_rng(0)
    q = random_joint_values(g, rng, 40)
    model = placement.build(g)
    x_true = np.where(model.is_length, 5e-3, np.radians(3.0)) * rng.normal(size=model.size)
    st = Chain(model, q).state(x_true, keep=False)
    result = calibrate(robot, Measurements(g.joint_names, q, st.p_tip), method="ls",
                       model="placement")
    assert base_motion.notes(result) == ()
    path, _ = _tree(tmp_path, 3)
    robots = [Robot.load(path, base=b, tip=t) for b, t in (("base_link", "atip"),
                                                           ("tl2", "btip"))]
    sets = []
    for r in robots:
        qr = random_joint_values(r.geometry, rng, 40) * 0.7
        m = placement.build(r.geometry)
        s_ = Chain(m, qr).state(np.where(m.is_length, 5e-3, np.radians(3.0))
                                * rng.normal(size=m.size), keep=False)
        sets.append(Measurements(r.joint_names, qr, s_.p_tip + s_.R_tip @ TOOL))
    result = calibrate(robots, sets, method="ls")
    assert base_motion.notes(result) == ()

