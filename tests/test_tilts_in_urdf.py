"""A contact face's tilt written into the calibrated URDF (kincal.export.contact_fold) is put
back by a reader given another URDF (kincal.tilts_in_urdf): the nominal URDF with the
calibrated FRAMES.json judges the contact frame the calibration identified, not the URDF's
tip frame without its tilt."""

from __future__ import annotations

import json
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import random_joint_values
from test_contact_fold import TABLE

import kincal
from kincal import models
from kincal.cli.main import main
from kincal.errors import DataError, KincalWarning
from kincal.export import Outputs, write_calibration
from kincal.frames_file import CellFrames
from kincal.planning.kind_simulation import simulate_flush
from kincal.robot import Robot
from kincal.tilts_in_urdf import Origin, joint_origin, on_urdf

CONTACT = np.array([0.01, -0.02, 0.1, 0.03, -0.02])  # x, y, z [m], rx, ry [rad] on flange


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A flush calibration of the EC66 written twice: with its URDF (the tilt folded into
    flange_joint, FRAMES.json with zero tilts and the record) and FRAMES.json alone (the
    tilts in it), and a held-out file of touches of the same robot."""
    rng = np.random.default_rng(7)
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    truth = em.nominal + np.where(em.is_length, 0.3e-3, np.radians(0.03)) * rng.normal(
        size=em.size)
    limits = (robot.geometry.lower, robot.geometry.upper)
    train, held = (simulate_flush(em, truth, CONTACT, TABLE,
                                  random_joint_values(robot.geometry, rng, 3000), n, 2e-5, 0.01,
                                  rng, limits=limits) for n in (40, 15))
    result = kincal.calibrate(robot, [train], method="l2", lam=1e-3,
                              tool_guess=tuple(CONTACT[:3]))
    d = tmp_path_factory.mktemp("cell")
    write_calibration(result, Outputs(urdf=d / "cal.urdf", frames=d / "folded.json"))
    write_calibration(result, Outputs(frames=d / "tilts.json"))
    (d / "held.csv").write_text(held.to_csv_text())
    (d / "nominal.urdf").write_text(robot.urdf_text)
    return d, result


def _tilts(frames):
    return [s.value(n) for s in frames.sets for n in ("tool.rx", "tool.ry")]


def test_the_record_holds_the_joint_origin_as_written_and_before(cell):
    d, result = cell
    (record,) = CellFrames.read(d / "folded.json").tilts_in_urdf
    assert record.joint == "flange_joint" and record.tip_frame == "flange"
    assert record.written == joint_origin((d / "cal.urdf").read_text(), "flange_joint")
    assert record.before == joint_origin((d / "nominal.urdf").read_text(), "flange_joint")
    assert not record.written.equals(record.before)
    identified = dict(zip(result.sets[0].frame_names, result.sets[0].frames))
    assert record.tilts == (identified["tool.rx"], identified["tool.ry"])


def test_the_nominal_urdf_gets_the_tilt_back_exactly(cell):
    """The fold undone: the nominal URDF with the folded FRAMES.json holds the frames of the
    FRAMES.json written alone (the tilts in it), value for value; the note says so."""
    d, _ = cell
    nominal = Robot.load(d / "nominal.urdf", tip="flange")
    folded, alone = CellFrames.read(d / "folded.json"), CellFrames.read(d / "tilts.json")
    assert _tilts(folded) == [0.0, 0.0] != _tilts(alone)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got, notes = on_urdf(folded, nominal)
    assert [s.values for s in got.sets] == [s.values for s in alone.sets]
    (note,) = notes
    assert "flange_joint" in note and "from before the calibration" in note
    assert got.tilts_in_urdf == () and on_urdf(got, nominal) == (got, ())  # resolved once


def test_evaluate_on_the_nominal_urdf_judges_the_identified_contact_frame(cell, capsys):
    """kincal evaluate NOMINAL.urdf --frames FRAMES.json (written beside the calibrated
    URDF) gives the held-out errors of FRAMES.json written alone, to 1e-9; before, the tilt
    was lost without a word. The calibrated URDF's own figures are unchanged by the record."""
    d, _ = cell

    def evaluate(urdf, frames):
        capsys.readouterr()
        assert main(["evaluate", str(urdf), str(d / "held.csv"), "--frames", str(frames),
                     "--tip", "flange", "--on-plane", "--flush", "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    restored, expected = (evaluate(d / "nominal.urdf", d / f) for f in ("folded.json",
                                                                        "tilts.json"))
    for key in ("errors", "orientation_errors"):
        for name, v in expected[key].items():
            assert restored[key][name] == pytest.approx(v, rel=0, abs=1e-9), (key, name)
    assert restored["notes"] and "flange_joint" in restored["notes"][0]
    assert expected["notes"] == []
    # what was read before: the frames' zero tilts on the nominal tip frame, the tilt lost
    data = json.loads((d / "folded.json").read_text())
    del data["tilts_in_urdf"]
    (d / "lost.json").write_text(json.dumps(data))
    lost = evaluate(d / "nominal.urdf", d / "lost.json")["orientation_errors"]
    assert abs(lost["rms_deg"] - expected["orientation_errors"]["rms_deg"]) > 0.01
    folded = evaluate(d / "cal.urdf", d / "folded.json")  # the URDF carries it: no note
    assert folded["notes"] == []
    assert folded["orientation_errors"]["rms_deg"] < expected["orientation_errors"]["rms_deg"]


def test_a_urdf_with_another_origin_is_warned_about_and_gets_no_tilt(cell, capsys):
    d, _ = cell
    text = (d / "nominal.urdf").read_text()
    before = joint_origin(text, "flange_joint")
    root = ET.fromstring(text)  # flange_joint 1 mm off both recorded origins
    root.find("joint[@name='flange_joint']/origin").set(
        "xyz", " ".join(repr(v + 0.001) for v in before.xyz))
    moved = d / "moved.urdf"
    moved.write_text(ET.tostring(root, encoding="unicode"))
    folded = CellFrames.read(d / "folded.json")
    with pytest.warns(KincalWarning, match=r"moved.urdf: the fixed joint flange_joint has the "
                      r"origin xyz=.*, neither the calibrated one \(xyz=.*\) nor the one before "
                      r"the calibration \(xyz=.*\).* is not applied") as seen:
        got, notes = on_urdf(folded, Robot.load(moved, tip="flange"))
    assert len(seen) == 1 and notes == () and _tilts(got) == [0.0, 0.0]
    capsys.readouterr()
    assert main(["evaluate", str(moved), str(d / "held.csv"), "--frames",
                 str(d / "folded.json"), "--tip", "flange", "--on-plane", "--flush"]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "flange_joint" in line]
    assert len(err) == 1 and err[0].startswith("kincal: warning: ") and "not applied" in err[0]


def test_an_older_record_without_origins_is_used_as_it_is_with_a_warning(cell, tmp_path):
    d, _ = cell
    data = json.loads((d / "folded.json").read_text())
    for record in data["tilts_in_urdf"]:
        del record["origin_written"], record["origin_before"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps(data))
    frames = CellFrames.read(old)
    for urdf in ("cal.urdf", "nominal.urdf"):
        with pytest.warns(KincalWarning, match="without that origin .*cannot be checked"):
            got, notes = on_urdf(frames, Robot.load(d / urdf, tip="flange"))
        assert notes == () and _tilts(got) == [0.0, 0.0]


def test_tilts_beside_the_record_are_not_replaced(cell, tmp_path):
    """A file whose sets hold tilts as well as the record (edited): its values are kept,
    with a warning, never silently replaced by the recorded ones."""
    d, _ = cell
    data = json.loads((d / "folded.json").read_text())
    data["sets"][0]["frames"]["tool.rx"] = 0.01
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(data))
    with pytest.warns(KincalWarning, match="non-zero tilts on that tip too"):
        got, _ = on_urdf(CellFrames.read(edited), Robot.load(d / "nominal.urdf", tip="flange"))
    assert _tilts(got) == [0.01, 0.0]


@pytest.mark.parametrize("record", [
    "not a list",
    [{"tip_frame": "flange", "joint": "flange_joint", "tool.rx": 0.01}],
    [{"tip_frame": "flange", "joint": "flange_joint", "tool.rx": 0.01, "tool.ry": 0.0,
      "origin_written": {"xyz": [0, 0], "rpy": [0, 0, 0]}, "origin_before": None}],
])
def test_a_malformed_record_is_refused(cell, tmp_path, record):
    d, _ = cell
    data = json.loads((d / "folded.json").read_text())
    data["tilts_in_urdf"] = record
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(DataError, match="not a kincal frames file"):
        CellFrames.read(bad)


def test_a_record_round_trips(cell):
    d, _ = cell
    frames = CellFrames.read(d / "folded.json")
    again = CellFrames.from_dict(json.loads(frames.dumps()))
    assert again.tilts_in_urdf == frames.tilts_in_urdf
    assert Origin((0.0, 0.0, 0.1), (0.0, 0.0, 0.0)).equals(Origin((0.0, 0.0, 0.1 + 1e-10),
                                                                  (0.0, 0.0, 0.0)))


def test_talos_nominal_urdf_with_the_calibrated_frames(tmp_path, capsys):
    """The real TALOS touches (../shared): the calibrated URDF with its FRAMES.json holds
    out what it did (4.212 mm, roll 0.4414, pitch 0.2633 deg); the nominal URDF with that
    FRAMES.json gets the face's tilt back (0.4 deg, lost before), as a FRAMES.json holding
    the tilts (the URDF written with --add-frames, which keeps them there) gives, to 1e-9."""
    from test_tree_paths import _talos_study

    study = _talos_study()
    names, q_valid = study.joint_rows(study.DATA / "left_validation.csv")
    valid = tmp_path / "valid.csv"
    study.write_joint_csv(valid, names, q_valid)
    urdf = study.talos_urdf()
    cal, folded = study.calibrate(tmp_path, urdf, study.DATA / "left_train.csv", "cal")
    _, kept = study.calibrate(tmp_path, urdf, study.DATA / "left_train.csv", "kept",
                              "--add-frames")
    assert "tilts_in_urdf" in json.loads(folded.read_text())
    assert "tilts_in_urdf" not in json.loads(kept.read_text())

    def evaluate(robot, frames):
        capsys.readouterr()
        assert main(["evaluate", str(robot), str(valid), "--frames", str(frames), "--base",
                     study.BASE, "--tip", study.TIP, "--on-plane", "--flush", "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    own = evaluate(cal, folded)
    assert own["errors"]["rms_mm"] == pytest.approx(4.212, abs=5e-4)
    assert own["orientation_errors"]["roll_rms_deg"] == pytest.approx(0.4414, abs=5e-5)
    assert own["orientation_errors"]["pitch_rms_deg"] == pytest.approx(0.2633, abs=5e-5)
    assert own["notes"] == []
    restored, expected = evaluate(urdf, folded), evaluate(urdf, kept)
    for key in ("errors", "orientation_errors"):
        for name, v in expected[key].items():
            assert restored[key][name] == pytest.approx(v, rel=0, abs=1e-9), (key, name)
    assert "gripper_left_base_link_joint" in restored["notes"][0]
