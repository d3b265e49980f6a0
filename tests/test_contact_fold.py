"""A flush contact face's tilt goes into the URDF written beside FRAMES.json
(kincal.export.contact_fold): a reader of the URDF's tip frame and the contact point alone
sees the identified contact frame."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import random_joint_values

import kincal
from kincal import models
from kincal.errors import ExportError
from kincal.export import Outputs, write_calibration
from kincal.export.contact_fold import MAX_FOLD_DEG, folds
from kincal.export.outputs import _corrected
from kincal.export.readback import check_readback
from kincal.frames_file import CellFrames
from kincal.planning.kind_simulation import simulate_flush
from kincal.robot import Robot
from kincal.rotations import base_rotation, transform

TABLE = np.array([[0.1, -0.15, 0.25]])  # rx, ry [rad], d [m]


def _result(rng, tip="flange", contact=(0.01, -0.02, 0.1, 0.03, -0.02)):
    robot = Robot.load("ec66", tip=tip)
    em = models.build("complete", robot.geometry)
    contact = np.array(contact)
    truth = em.nominal + np.where(em.is_length, 0.3e-3, np.radians(0.03)) * rng.normal(size=em.size)
    data = simulate_flush(em, truth, contact, TABLE, random_joint_values(robot.geometry, rng, 3000),
                          40, 2e-5, 0.01, rng,
                          limits=(robot.geometry.lower, robot.geometry.upper))
    return kincal.calibrate(robot, [data], method="l2", lam=1e-3, tool_guess=tuple(contact[:3]))


def _contact(robot, q, frames):
    """(N, 4, 4) the contact frame: the tip turned by the tilts, at the contact point."""
    R = base_rotation(frames["tool.rx"], frames["tool.ry"], 0.0)
    return robot.tip_poses(q) @ transform(R, [frames["tool." + c] for c in "xyz"])


def test_the_urdf_alone_gives_the_identified_contact_frame(tmp_path, rng):
    result = _result(rng)
    identified = dict(zip(result.sets[0].frame_names, result.sets[0].frames))
    assert abs(identified["tool.rx"]) > 0.01  # a tilt to carry
    written = write_calibration(result, Outputs(urdf=tmp_path / "cal.urdf",
                                                frames=tmp_path / "frames.json",
                                                yaml=tmp_path / "k.yaml"))
    assert any("flange_joint" in n and "turned about the contact point" in n
               for n in written.notes)
    data = json.loads((tmp_path / "frames.json").read_text())
    frames = data["sets"][0]["frames"]
    assert frames["tool.rx"] == 0.0 and frames["tool.ry"] == 0.0
    assert [frames["tool." + c] for c in "xyz"] == [identified["tool." + c] for c in "xyz"]
    read_back = CellFrames.read(tmp_path / "frames.json")  # the record is read past
    assert read_back.sets[0].value("tool.ry") == 0.0
    (fold,) = data["tilts_in_urdf"]
    assert fold["joint"] == "flange_joint" and fold["tool.rx"] == identified["tool.rx"]
    # what a URDF reader composes: the written tip frame with the file's contact point
    read = Robot.load(tmp_path / "cal.urdf", tip="flange")
    q = random_joint_values(read.geometry, rng, 50)
    want = _contact(result.corrected, q, identified)
    got = _contact(read, q, frames)
    assert np.abs(got - want).max() < 1e-9
    # the other joints' origins are the calibration's, untouched by the fold
    joints = tuple(result.error_model.joint_names)
    for name, T in result.corrected.urdf_origins(joints).items():
        assert np.abs(read.urdf_origins((name,))[name] - T).max() < 1e-12
    # the YAML of corrected origins holds the folded joint as the URDF does (it listed the
    # chain joints alone: a reader of it and FRAMES.json lost the tilt)
    from kincal.export.cell_exports import read_kinematics_yaml
    from kincal.rotations import rpy_to_matrix

    yaml = read_kinematics_yaml((tmp_path / "k.yaml").read_text())
    assert list(yaml) == [*joints, "flange_joint"]
    origin = ET.fromstring((tmp_path / "cal.urdf").read_bytes()).find(
        "joint[@name='flange_joint']/origin")
    xyz, rpy = (np.array(origin.get(k).split(), float) for k in ("xyz", "rpy"))
    np.testing.assert_allclose(yaml["flange_joint"], transform(rpy_to_matrix(rpy), xyz),
                               rtol=0, atol=1e-15)


def test_the_readback_checks_the_folded_joint(rng):
    result = _result(rng)
    text, _, made = _corrected(result)
    assert [f.joint for f in made] == ["flange_joint"]
    check_readback(result, text, False, made)  # as written: accepted
    with pytest.raises(ExportError, match="flange_joint"):  # the fold's origin not written
        check_readback(result, _without_fold(result), False, made)
    with pytest.raises(ExportError):  # a fold written but not declared
        check_readback(result, text, False, ())


def _without_fold(result):
    from kincal.export.readable_export import corrected_text

    edits, _ = corrected_text(result.robot, result.corrected, True,
                              joints=tuple(result.error_model.joint_names))
    return edits.text


@pytest.mark.parametrize("tip, contact, why", [
    ("link_6", (0.01, -0.02, 0.2, 0.03, -0.02), "hangs on a moving joint"),
    ("flange", (0.01, -0.02, 0.1, np.radians(MAX_FOLD_DEG + 3), -0.02), "the face's design"),
])
def test_a_tilt_no_urdf_joint_should_carry_stays_in_frames_json(tip, contact, why, tmp_path, rng):
    result = _result(rng, tip, contact)
    made, notes = folds(result)
    assert made == () and any(why in n for n in notes), notes
    written = write_calibration(result, Outputs(urdf=tmp_path / "cal.urdf",
                                                frames=tmp_path / "frames.json"))
    assert any(why in n for n in written.notes)
    frames = json.loads((tmp_path / "frames.json").read_text())["sets"][0]["frames"]
    identified = dict(zip(result.sets[0].frame_names, result.sets[0].frames))
    assert frames["tool.rx"] == identified["tool.rx"] != 0.0


def test_frames_json_alone_keeps_the_tilts(tmp_path, rng):
    """Without a URDF written beside it, FRAMES.json is the only carrier."""
    result = _result(rng)
    write_calibration(result, Outputs(frames=tmp_path / "frames.json"))
    data = json.loads((tmp_path / "frames.json").read_text())
    identified = dict(zip(result.sets[0].frame_names, result.sets[0].frames))
    assert data["sets"][0]["frames"]["tool.ry"] == identified["tool.ry"]
    assert "tilts_in_urdf" not in data


def test_added_frames_leave_the_tilt_in_frames_json_and_say_so(rng):
    result = _result(rng)
    text, notes, made = _corrected(result, add_frames=True)
    assert made == () and any("--add-frames" in n for n in notes), notes
    check_readback(result, text, True, made)


def test_no_fold_where_another_chain_passes_through_the_joint(tmp_path, rng):
    """A second set's chain through the fixed joint above the flush tip (its tip below it)
    would be turned by the fold: the tilt stays in FRAMES.json with a note, and the files
    are written (the read-back check refused the whole calibration before)."""
    from kincal.identification.chains import Chains

    text = Robot.load("ec66").urdf_text.replace("</robot>", (
        '<link name="probe"/><joint name="probe_joint" type="revolute"><parent link="flange"/>'
        '<child link="probe"/><origin xyz="0 0.02 0.05" rpy="0 0 0"/><axis xyz="1 0 0"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'))
    path = tmp_path / "ec66_probe.urdf"
    path.write_text(text)
    robots = [Robot.load(path, tip="flange"), Robot.load(path, tip="probe")]
    ch = Chains(robots, 2, "placement")
    kin = ch.model.nominal + np.where(ch.model.is_length, 0.3e-3, np.radians(0.03)) * rng.normal(
        size=ch.model.size)
    contact = np.array([0.01, -0.02, 0.1, 0.03, -0.02])
    flush = simulate_flush(ch.models[0], kin[ch.idx[0]], contact, TABLE,
                           random_joint_values(robots[0].geometry, rng, 3000), 40, 2e-5, 0.01,
                           rng, limits=(robots[0].geometry.lower, robots[0].geometry.upper))
    q = random_joint_values(robots[1].geometry, rng, 60)
    T = robots[1].with_origins(ch.origins(kin - ch.model.nominal)).tip_poses(q)
    points = kincal.Measurements(joint_names=robots[1].joint_names, joint_values=q,
                                 positions=T[:, :3, 3] + T[:, :3, :3] @ [0.0, 0.0, 0.03],
                                 source="probe points")
    result = kincal.calibrate(robots, [flush, points], method="l2", lam=1e-3, model="placement",
                              tool_guess=tuple(contact[:3]))
    assert abs(dict(zip(result.sets[0].frame_names, result.sets[0].frames))["tool.rx"]) > 0.01
    made, notes = folds(result)
    assert made == () and any("flange_joint is also on the chain base_link -> probe" in n
                              for n in notes), notes
    written = write_calibration(result, Outputs(urdf=tmp_path / "cal.urdf",
                                                frames=tmp_path / "frames.json"))
    assert any("also on the chain" in n for n in written.notes)
    frames = json.loads((tmp_path / "frames.json").read_text())
    assert frames["sets"][0]["frames"]["tool.rx"] != 0.0 and "tilts_in_urdf" not in frames


def test_the_mdh_table_carries_the_folded_tilt(tmp_path, rng):
    """The MD-H table written beside the URDF describes the same tip frame: its T_n_tip has
    the face's tilt the URDF's fixed joint carries (FRAMES.json then holds zero tilts)."""
    from test_cell_exports import _mdh_product

    result = _result(rng)
    write_calibration(result, Outputs(urdf=tmp_path / "cal.urdf", mdh=tmp_path / "mdh.csv"))
    read = Robot.load(tmp_path / "cal.urdf", tip="flange")
    q = random_joint_values(read.geometry, rng, 20)
    got = _mdh_product((tmp_path / "mdh.csv").read_text(), q)
    assert np.abs(got - read.tip_poses(q)).max() < 1e-9
    assert np.abs(got - result.corrected.tip_poses(q)).max() > 1e-5  # the tilt, not nothing
