"""Compliance terms: gravity torques, the Jacobian column, identification, FRAMES.json,
evaluate and compensate, and the model choice."""

import json
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_joint_values

from kincal.cli.main import main
from kincal.errors import KincalWarning, OptionError
from kincal.frames_file import CellFrames
from kincal.identification.problem import calibrate
from kincal.identification.diagnosis import ALPHA
from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.planning.simulation import Truth, cube_poses, measure, true_positions
from kincal.robot import Robot

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import model_auto  # noqa: E402  (the study's simulated cases, reduced to a few seeds)

REPO = Path(__file__).resolve().parents[1]
EC66 = REPO / "urdf" / "ec66.urdf"
BASE = np.array([0.9, -0.4, 0.2, 0.05, -0.1, 2.0])
TOOL = np.array([0.03, -0.02, 0.10])


def _potential(robot, qs, gravity=9.81):
    """Potential energy [J] of every link, in the base frame with gravity along its -z."""
    m, d = robot.model, robot.model.createData()
    pin.forwardKinematics(m, d, robot.configuration(qs))
    pin.updateFramePlacement(m, d, robot.base_id)
    oMb = d.oMf[robot.base_id]
    return sum(gravity * I.mass * oMb.actInv(d.oMi[b].act(I.lever))[2]
               for b, I in enumerate(m.inertias))


@pytest.mark.parametrize("base,tip", [(None, "tool0"), ("wrist_3_link", "upper_arm_link")])
def test_gravity_torques_are_minus_the_gradient_of_the_potential(base, tip, rng):
    # the second chain climbs from the wrist (held fixed) to the upper arm: reversed joints,
    # whose far side is the rest of the robot, not their URDF subtree
    robot = Robot.load("ur10", tip=tip, base=base)
    q = random_joint_values(robot.geometry, rng, 4)
    tau = robot.gravity_torques(q)
    h = 1e-6
    for s, qs in enumerate(q):
        for j in range(robot.geometry.n):
            e = np.zeros(robot.geometry.n)
            e[j] = h
            fd = -(_potential(robot, qs + e) - _potential(robot, qs - e)) / (2 * h)
            assert tau[s, j] == pytest.approx(fd, abs=1e-5 * max(1.0, abs(fd)))
    assert np.abs(tau).max() > 10  # [N m] the test sees real torques


def test_compliance_columns_match_central_differences(rng):
    robot = Robot.load(EC66, tip="flange")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, 25)
    g = rng.choice([-1.0, 1.0], size=q.shape)
    tau = robot.gravity_torques(q)
    soft = ("joint_2", "joint_3", "joint_5")
    mm = MeasurementModel(model, q, g, ("joint_3",), torque=tau, compliance=soft)
    assert mm.space.names[-4:] == ("joint_3.backlash", "joint_2.compliance",
                                   "joint_3.compliance", "joint_5.compliance")
    x = mm.space.join(model.table, BASE, TOOL, [1e-3, 2e-5, -3e-5, 1e-4])
    x = x + np.where(mm.space.is_kinematic, rng.normal(size=x.size) * 1e-3, 0.0)
    _, J = mm.jacobian(x)
    for c in np.flatnonzero(mm.space.is_backlash | mm.space.is_kinematic):
        h = 1e-8 if mm.space.names[c].endswith(".compliance") else 1e-6
        e = np.zeros_like(x)
        e[c] = h
        fd = (mm.predict(x + e) - mm.predict(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        assert np.abs(J[:, :, c] - fd).max() / scale < 1e-6, mm.space.names[c]
    # a compliance term moves the joint by c tau: equal to moving the joint values
    q_eff = q.copy()
    q_eff[:, 2] += 1e-3 * g[:, 2]
    for c, j in zip([2e-5, -3e-5, 1e-4], (1, 2, 4)):
        q_eff[:, j] += c * tau[:, j]
    plain = MeasurementModel(model, q_eff)
    assert np.abs(mm.predict(x) - plain.predict(x[:plain.space.size])).max() < 1e-15


def _ec66_with_compliance(noise=0.0, seed=4):
    rng = np.random.default_rng(seed)
    robot = Robot.load(EC66, tip="flange")
    model = mdh.extract(robot.geometry)
    q = cube_poses(robot, 60, [0.4, 0.0, 0.25], 0.4, TOOL, rng)
    truth = Truth(model.table, BASE, TOOL, joint_compliance={"joint_2": 3e-5, "joint_3": -5e-5},
                  robot=robot)
    return robot, model, q, truth, measure(model, truth, q, noise, rng)


def test_planted_compliance_is_recovered_and_the_frames_carry_it(tmp_path):
    robot, model, q, truth, data = _ec66_with_compliance()
    res = calibrate(robot, data, method="ls", compliance=("joint_3", "joint_2"))
    assert res.layout.compliance == ("joint_2", "joint_3")  # chain order
    assert res.compliance["joint_2"] == pytest.approx(3e-5, rel=1e-6)
    assert res.compliance["joint_3"] == pytest.approx(-5e-5, rel=1e-6)
    assert res.after.max < 1e-9
    assert np.abs(res.predict(q) - true_positions(model, truth, q)).max() < 1e-10
    frames = res.frames_dict()
    assert set(frames["compliance"]) == {"joint_2", "joint_3"}
    assert "gravity torque" in frames["compliance_convention"]
    back = CellFrames.from_dict(json.loads(json.dumps(frames)))
    assert back.compliance == pytest.approx(res.compliance)
    text = res.summary()
    assert "compliance terms: joint_2" in text and "deg/(N m)" in text
    from kincal.export.report import result_dict  # REPORT.json: SI keys name its unit too

    row = next(p for p in result_dict(res)["parameters"] if p["name"] == "joint_2.compliance")
    assert row["estimate_rad/(N m)"] == pytest.approx(3e-5, rel=1e-6)  # was "estimate_rad"
    assert row["deviation_deg/(N m)"] == pytest.approx(np.degrees(3e-5), rel=1e-6)
    assert not {"nominal_rad", "estimate_rad", "deviation_rad", "std_error_rad"} & set(row)
    from kincal.planning.accuracy_map import point_view  # the map: geometry and frames

    space, idx = point_view(res.layout, res.error_model, 0, 1)
    assert space.size == idx.size == res.layout.size - 2
    # without the term the deflection stays in the residuals
    assert calibrate(robot, data, method="ls").after.rms > 0.02  # [mm], exact data


def test_evaluate_and_compensate_apply_the_compliance(tmp_path, capsys):
    robot, model, q, truth, data = _ec66_with_compliance(noise=1e-6)
    csv = tmp_path / "d.csv"
    csv.write_text("joint_1,joint_2,joint_3,joint_4,joint_5,joint_6,x,y,z\n" + "".join(
        ",".join(f"{v:.12g}" for v in row) + "\n"
        for row in np.hstack([data.joint_values, data.positions])))
    out, frames = tmp_path / "c.urdf", tmp_path / "f.json"
    assert main(["calibrate", str(EC66), str(csv), "--tip", "flange", "--out", str(out),
                 "--frames-out", str(frames), "--compliance", "joint_2", "joint_3",
                 "--quiet", "--accept-implausible"]) == 0
    saved = json.loads(frames.read_text())
    assert saved["compliance"]["joint_3"] == pytest.approx(-5e-5, rel=0.02)
    capsys.readouterr()
    assert main(["evaluate", str(out), str(csv), "--tip", "flange", "--frames", str(frames)]) == 0
    text = capsys.readouterr().out
    assert "with compliance of joint_2, joint_3" in text
    rms = float(re.search(r"RMS ([0-9.]+) mm", text).group(1))
    assert rms < 0.01  # [mm] the deflection applied: what is left is the 0.001 mm noise
    # compensate: the commanded joints, deflected by the gravity torques there, are the
    # joints the corrected model needs to reach the target
    from kincal.compensation.compensate import compensate
    from kincal.compensation.targets import Targets
    from kincal.rotations import base_rotation

    corrected = Robot.load(out, tip="flange")
    cell = CellFrames.read(frames)
    want = true_positions(model, truth, q[:5])
    q_eff = q[:5] + np.array([0, 3e-5, -5e-5, 0, 0, 0]) * robot.gravity_torques(q[:5])
    R_tip, _ = MeasurementModel(model, q_eff).tip_poses(model.table)
    comp = compensate(corrected, cell, Targets(q[:5], want, base_rotation(*BASE[3:]) @ R_tip,
                                               np.arange(2, 7), "<t>"))
    cmd = comp.joint_values
    c = np.array([0, cell.compliance["joint_2"], cell.compliance["joint_3"], 0, 0, 0])
    q_real = cmd + c * corrected.gravity_torques(cmd)
    assert "compliance compensated" in " ".join(comp.notes)
    assert np.abs(q_real - comp.joint_values).max() > 1e-4  # [rad] a visible correction
    # [rad] the truth's commands, found again to what the fit's estimate allows (2.6e-5 on
    # the draws of OpenBLAS's Prescott kernels, whose simulated poses differ)
    assert np.abs(cmd - q[:5]).max() < 5e-5


def test_position_targets_keep_the_orientation_the_deflected_robot_has_at_the_seed():
    """A position target keeps the tool's orientation at the seed: where the real robot is
    when the seed is commanded, deflected by gravity. Targets where the true robot's tool
    point is at the commands q, seeds q: the compensated commands are q again. Before, the
    kept orientation was the undeflected seed's, so the commands turned the tool by the
    deflection (here up to 0.039 deg; 1.46 deg on the TIAGo's arm_6) away from the seed's."""
    from kincal.compensation.compensate import compensate
    from kincal.compensation.targets import Targets

    robot, model, q, truth, data = _ec66_with_compliance()
    res = calibrate(robot, data, method="ls", compliance=("joint_2", "joint_3"))
    want = true_positions(model, truth, q[:5])
    comp = compensate(res.corrected, res.frames(), Targets(q[:5], want, None, np.arange(2, 7)))
    assert comp.reached.all()
    assert np.abs(comp.joint_values - q[:5]).max() < 1e-8  # [rad] exact data: the truth's


def test_a_urdf_without_inertials_has_no_compliance_term(tmp_path):
    text = re.sub(r"<inertial>.*?</inertial>", "", EC66.read_text(), flags=re.S)
    bare = tmp_path / "bare.urdf"
    bare.write_text(text)
    robot = Robot.load(bare, tip="flange")
    assert not robot.gravity_torques(np.zeros((1, 6))).any()
    _, model, q, truth, data = _ec66_with_compliance(noise=1e-5)
    with pytest.raises(OptionError, match="joint_2.compliance: the joint carries no gravity"):
        calibrate(robot, data, compliance=("joint_2",))
    warnings.simplefilter("ignore", KincalWarning)
    res = calibrate(robot, data, model="auto")
    assert res.model_choice.compliance == ()
    assert any("compliance terms unavailable: the URDF has no inertials" in line
               for line in res.model_choice.lines())


def test_a_prismatic_joint_has_no_compliance_term(tmp_path):
    """Compliance turns a revolute joint by its torque; a prismatic joint is refused by name
    (its sag would be a force over a stiffness in m/N, which kincal does not model)."""
    from kincal.errors import ParameterError

    text = EC66.read_text().replace('<joint name="joint_3" type="revolute">',
                                    '<joint name="joint_3" type="prismatic">')
    assert 'name="joint_3" type="prismatic"' in text
    slide = tmp_path / "slide.urdf"
    slide.write_text(text)
    robot = Robot.load(slide, tip="flange")
    _, model, q, truth, data = _ec66_with_compliance(noise=1e-5)
    with pytest.raises(ParameterError, match="joint_3 is prismatic: a compliance term turns"):
        calibrate(robot, data, compliance=("joint_3",))


@pytest.mark.parametrize("name,seed", [("EC66", 1), ("UR10", 2)])
def test_auto_finds_a_planted_compliance_on_its_joint(name, seed):
    warnings.simplefilter("ignore", KincalWarning)
    robot, data, joint = model_auto.case(name, seed, planted=True, term="compliance")
    mc = calibrate(robot, data, model="auto").model_choice
    assert mc.compliance == (joint,) and mc.backlash == ()


@pytest.mark.parametrize("name,seed", [("EC66", 3), ("UR10", 4)])
def test_auto_chooses_no_term_when_none_is_planted(name, seed):
    warnings.simplefilter("ignore", KincalWarning)
    robot, data, _ = model_auto.case(name, seed, planted=False, term="compliance")
    mc = calibrate(robot, data, model="auto").model_choice
    assert mc.compliance == () and mc.backlash == ()
    # compliance terms were tested (the score test), none significant, none CV-scored
    note = next(n for n in mc.notes if n.startswith("no further joint term significant"))
    assert re.search(r"\(\d backlash, [1-9] compliance\)", note), note
    assert len(mc.step_p) == 1 and mc.step_p[0] >= ALPHA
    assert not any(c.compliance or c.backlash for c in mc.candidates)
    # nothing significant was left out of the scoring: no note says so (it counted every
    # candidate the score test rejected as "not CV-scored")
    assert not any("not CV-scored" in n for n in mc.notes), mc.notes
