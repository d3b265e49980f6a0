"""The plausibility gate: silently wrong calibrations are refused, good ones pass.

CLI cases assert exit 1, one error line naming the likely cause, and that no file in the
working folder was written or changed (names, bytes and mtimes before and after).
"""

import csv
import json
import math
import warnings
from pathlib import Path

import numpy as np

from kincal.export.outputs import Outputs, write_calibration
import pytest

from kincal import Measurements, Robot, calibrate
from kincal.cli.main import main
from kincal.errors import ImplausibleResultError, NotConvergedError
from kincal.identification.plausibility import Evidence, Thresholds, judge
from kincal.models.workspace import reach
from kincal.models.geometry import chain_length
from kincal.rotations import aligned_distances as _aligned_distances
from kincal.rotations import rotx, rotz


# ------------------------------------------------------------------ helpers
def _snapshot(folder):
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.iterdir())}


def _error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("kincal: error:")]
    assert len(errors) == 1, err
    assert not any("Traceback" in line for line in err)
    return errors[0]


def _rewrite(src, dst, change):
    """Copy the CSV ``src`` to ``dst`` with ``change(header, rows)`` applied to its numbers."""
    with open(src, newline="") as f:  # without the provenance's # lines
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    header, values = rows[0], np.array(rows[1:], dtype=float)
    change(header, values)
    with open(dst, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows([[repr(float(v)) for v in row] for row in values])


UR10_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
               "wrist_2_joint", "wrist_3_joint")


@pytest.fixture(scope="module")
def ur10_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("ur10")
    assert main(["simulate", "ur10", "--out", str(d / "d.csv"), "--seed", "0"]) == 0
    return d / "d.csv"


def _positions(header):
    return [header.index(c) for c in "xyz"]


def _mm_as_m(header, v):
    v[:, _positions(header)] *= 1000.0


def _deg_as_rad(header, v):
    v[:, [header.index(j) for j in UR10_JOINTS]] *= 180.0 / math.pi


def _shuffled(header, v):
    p = _positions(header)
    v[:, p] = v[np.random.default_rng(1).permutation(len(v))][:, p]


def _noise_100mm(header, v):
    v[:, _positions(header)] += np.random.default_rng(2).normal(0.0, 0.1, (len(v), 3))


def _unchanged(header, v):
    pass


# -------------------------------------------------------- the silently wrong
@pytest.mark.parametrize("change, extra, cause", [
    (_mm_as_m, [], "millimetres read as metres"),
    (_deg_as_rad, [], "degrees read as radians"),
    (_shuffled, [], "rows shuffled"),
    (_unchanged, ["--tip", "forearm_link"], "tip"),
    (_noise_100mm, [], "noise far above"),
], ids=["mm-as-m", "deg-as-rad", "shuffled", "wrong-tip", "noise-100mm"])
def test_calibrate_refuses_and_writes_nothing(ur10_csv, tmp_path, capsys, change, extra, cause):
    data = tmp_path / "data.csv"
    _rewrite(ur10_csv, data, change)
    (tmp_path / "frames.json").write_text("earlier run\n")  # an earlier output, untouched
    before = _snapshot(tmp_path)
    code = main(["calibrate", "ur10", str(data), "--out", str(tmp_path / "c.urdf"),
                 "--frames-out", str(tmp_path / "frames.json"), "--overwrite",
                 "--report", str(tmp_path / "r.json"), "--plots", str(tmp_path / "plots"),
                 "--lambda", "1", *extra])
    assert code == 1
    line = _error_line(capsys)
    # the diagnosis asked for is written (report, plots), marked REFUSED; nothing else
    assert "implausible calibration, no URDF, frames or cell file is written" in line
    assert "the diagnosis (marked REFUSED) is in" in line
    assert cause in line, line
    if "read as" in cause:  # a sure unit clue is named alone, once
        assert line.count("Likely cause") == 1 and line.count(cause) == 1
    assert "--accept-implausible" in line
    assert json.loads((tmp_path / "r.json").read_text())["refused"]["verdict"] == "REFUSED"
    assert list((tmp_path / "plots").glob("*.png"))
    (tmp_path / "r.json").unlink()
    for png in (tmp_path / "plots").iterdir():
        png.unlink()
    (tmp_path / "plots").rmdir()
    assert _snapshot(tmp_path) == before  # no URDF; the earlier frames.json untouched


def test_good_data_pass_the_gate(ur10_csv, tmp_path, capsys):
    out = tmp_path / "c.urdf"
    assert main(["calibrate", "ur10", str(ur10_csv), "--out", str(out), "--lambda", "1"]) == 0
    assert out.is_file() and "IMPLAUSIBLE" not in capsys.readouterr().out


def test_accept_implausible_writes_with_a_warning(ur10_csv, tmp_path, capsys):
    data = tmp_path / "data.csv"
    _rewrite(ur10_csv, data, _shuffled)
    out = tmp_path / "c.urdf"
    assert main(["calibrate", "ur10", str(data), "--out", str(out), "--lambda", "1",
                 "--accept-implausible", "--report", str(tmp_path / "r.json")]) == 0
    captured = capsys.readouterr()
    assert out.is_file()
    gate = json.loads((tmp_path / "r.json").read_text())["plausibility"]
    assert gate["plausible"] is False and gate["findings"][0]["kind"] == "residual"
    assert gate["evidence"]["residual_median_mm"] > 20 * gate["evidence"]["reach_m"]
    assert "plausibility gate: IMPLAUSIBLE (residual" in captured.out
    assert "kincal: warning: accepted an implausible calibration as asked" in captured.err


def test_unconverged_is_refused_unless_accepted(ur10_csv, tmp_path, capsys):
    out = tmp_path / "c.urdf"
    # an iteration limit of 1 cannot converge: the gate refuses, then accepts on request
    args = ["calibrate", "ur10", str(ur10_csv), "--out", str(out), "--lambda", "1"]
    from dataclasses import replace

    import importlib

    cli = importlib.import_module("kincal.cli.calibrate")
    from kincal.identification.solver import SolverOptions

    options = cli.calibration_options
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cli, "calibration_options", lambda c: replace(
            options(c), solver=SolverOptions(max_iterations=1)))
        before = _snapshot(tmp_path)
        assert main(args) == 1
        line = _error_line(capsys)
        assert "did not converge" in line and "--accept-unconverged" in line
        assert _snapshot(tmp_path) == before
        assert main(args + ["--accept-unconverged"]) == 0
        assert "accepted an unconverged calibration" in capsys.readouterr().err
    assert out.is_file()


# ---------------------------------------------------------------- evaluate
def test_evaluate_refuses_a_tip_other_than_the_frames(ur10_csv, tmp_path, capsys):
    frames = tmp_path / "frames.json"
    assert main(["calibrate", "ur10", str(ur10_csv), "--out", str(tmp_path / "c.urdf"),
                 "--lambda", "1", "--frames-out", str(frames)]) == 0
    assert json.loads(frames.read_text())["tip_frame"] == "tool0"
    capsys.readouterr()
    before = _snapshot(tmp_path)
    code = main(["evaluate", str(tmp_path / "c.urdf"), str(ur10_csv), "--frames", str(frames),
                 "--tip", "wrist_2_link", "--report", str(tmp_path / "e.json")])
    assert code == 1
    line = _error_line(capsys)
    assert "--tip 'wrist_2_link' does not match the tip frame 'tool0' recorded in" in line
    assert _snapshot(tmp_path) == before
    # without --tip, the recorded chain is used
    assert main(["evaluate", str(tmp_path / "c.urdf"), str(ur10_csv), "--frames",
                 str(frames)]) == 0
    out = capsys.readouterr().out
    assert "-> tool0)" in out


def test_evaluate_refuses_a_base_other_than_the_frames(ur10_csv, tmp_path, capsys):
    frames = tmp_path / "frames.json"
    assert main(["calibrate", "ur10", str(ur10_csv), "--out", str(tmp_path / "c.urdf"),
                 "--lambda", "1", "--frames-out", str(frames)]) == 0
    capsys.readouterr()
    assert main(["evaluate", "ur10", str(ur10_csv), "--frames", str(frames),
                 "--base", "base_link"]) == 1
    assert "--base 'base_link' does not match the base frame" in _error_line(capsys)


# --------------------------------------------------------------------- API
def test_export_urdf_refuses_an_implausible_result(ur10_csv, tmp_path):
    data_path = tmp_path / "data.csv"
    _rewrite(ur10_csv, data_path, _mm_as_m)
    robot = Robot.load("ur10")
    data = Measurements.from_csv(data_path, robot.joint_names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate(robot, data, method="l2", lam=1.0)
    p = result.plausibility
    assert not p.plausible
    assert {"length_unit", "residual", "corrections"} <= {f.kind for f in p.findings}
    assert "millimetres read as metres" in p.causes[0]
    out = tmp_path / "c.urdf"
    with pytest.raises(ImplausibleResultError) as exc:
        write_calibration(result, Outputs(urdf=out))
    assert exc.value.plausibility is p
    assert not out.exists()
    with pytest.warns(UserWarning, match="accepted an implausible"):
        write_calibration(result, Outputs(urdf=out), accept_implausible=True,
                          accept_unconverged=True)
    assert out.is_file()


def test_gather_on_good_data(ur10_csv):
    robot = Robot.load("ur10")
    data = Measurements.from_csv(ur10_csv, robot.joint_names)
    result = calibrate(robot, data, method="l2", lam=1.0, fix=("elbow_joint.a",))
    p = result.plausibility
    assert p.plausible and p.converged and p.findings == ()
    ev = p.evidence
    # only identified kinematic parameters are corrections
    status = {q.name: q.status for q in result.parameters}
    assert ev.corrections and all(status[n] == "identified" for n, _, _ in ev.corrections)
    assert "elbow_joint.a" not in [n for n, _, _ in ev.corrections]
    # UR10 at zero: 1.18 m of chain from the shoulder to tool0, plus the 120 mm tool
    assert 1.7 < ev.reach_m < 2.0
    assert ev.residual_median_mm < 0.2 and ev.change_rms_mm < 5.0
    assert 0.8 < ev.length_ratio < 1.2 and ev.explained > 0.999


def test_noise_free_nominal_data_move_nothing():
    from kincal.planning.simulation import Truth, measure
    from kincal.models import mdh

    robot = Robot.load("ur10")
    model = mdh.extract(robot.geometry)
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (40, 6))
    truth = Truth(model.table, np.array([0.5, 0.2, -0.1, 0.1, 0.2, 0.3]),
                  np.array([0.03, 0.02, 0.12]))
    data = measure(model, truth, q, 0.0, rng)
    result = calibrate(robot, data, method="ls")
    ev = result.plausibility.evidence
    assert ev.change_rms_mm < 1e-6 and ev.residual_median_mm < 1e-6


# ------------------------------------------------------- criteria, in isolation
def _evidence(**kw):
    base = dict(reach_m=1.0, residual_median_mm=0.1, residual_rms_mm=0.12, before_rms_mm=0.5,
                spread_mm=200.0, change_rms_mm=1.0, change_max_mm=2.0,
                corrections=(("j2.a", 0.5, "mm"), ("j3.alpha", 0.05, "deg")),
                length_ratio=1.0)
    base.update(kw)
    return Evidence(**base)


def test_good_evidence_has_no_finding():
    assert judge(_evidence()).findings == ()


@pytest.mark.parametrize("field, below, above, kind", [
    ("residual_median_mm", 19.9, 20.1, "residual"),       # 2 % of 1000 mm
    ("change_rms_mm", 99.0, 101.0, "corrections"),        # 10 % of 1000 mm
    ("length_ratio", 299.0, 301.0, "length_unit"),
    ("length_ratio", 1 / 299.0, 1 / 301.0, "length_unit"),
    ("angle_max", 4 * math.pi - 0.01, 4 * math.pi + 0.01, "angle_unit"),
])
def test_each_threshold(field, below, above, kind):
    assert kind not in {f.kind for f in judge(_evidence(**{field: below})).findings}
    found = [f for f in judge(_evidence(**{field: above})).findings if f.kind == kind]
    assert len(found) == 1
    f = found[0]
    assert f.value == pytest.approx(above) and f.causes
    assert not judge(_evidence(**{field: above})).plausible


def test_angle_beyond_a_turn_counts_only_outside_the_limits():
    assert not judge(_evidence(angle_max=7.0, angle_outside=False)).findings
    found = judge(_evidence(angle_max=7.0, angle_outside=True)).findings
    assert [f.kind for f in found] == ["angle_unit"]
    assert "degrees read as radians" in found[0].causes[0]
    # read as degrees on purpose: no angle clue at all
    assert not judge(_evidence(angle_max=90.0, angle_unit="deg")).findings


def test_one_huge_length_correction():
    ev = _evidence(corrections=(("j2.a", 600.0, "mm"),))
    found = judge(ev).findings
    assert [f.kind for f in found] == ["length_correction"] and found[0].parameters == ("j2.a",)


def test_causes_follow_the_evidence():
    # the model explains little of the motion: rows not matching the positions
    shuffled = judge(_evidence(residual_median_mm=180, residual_rms_mm=185, spread_mm=200))
    assert "rows shuffled" in shuffled.causes[0]
    # the model follows the motion, with large errors: noise first
    noisy = judge(_evidence(residual_median_mm=140, residual_rms_mm=160, spread_mm=240))
    assert "noise far above" in noisy.causes[0]
    # joint columns off the chain in the file: the tip first
    tip = judge(_evidence(residual_median_mm=50, residual_rms_mm=70,
                          off_chain_columns=("wrist_1_joint",)))
    assert "tip" in tip.causes[0] and "wrist_1_joint" in tip.causes[0]
    # a unit clue below the confident level still leads
    units = judge(_evidence(residual_median_mm=50, residual_rms_mm=70, length_ratio=40.0))
    assert [f.kind for f in units.findings] == ["residual"]
    assert "millimetres read as metres" in units.causes[0]


def test_not_converged_is_apart_from_plausible():
    p = judge(_evidence(converged=False, iterations=100, method="ls"))
    assert p.plausible and not p.converged
    with pytest.raises(NotConvergedError, match="--method l2"):
        p.check()
    assert p.check(accept_unconverged=True) == [
        "accepted an unconverged calibration as asked: the solver did not converge in 100 "
        "iterations"]
    with pytest.raises(ImplausibleResultError):  # implausible is checked first
        judge(_evidence(converged=False, residual_median_mm=50)).check(accept_unconverged=True)


def test_thresholds_are_options():
    strict = Thresholds(residual=0.00005)  # 0.05 mm of 1 m
    assert [f.kind for f in judge(_evidence(), strict).findings] == ["residual"]


def test_reach_and_alignment_helpers():
    frames = np.tile(np.eye(4), (3, 1, 1))
    frames[1, :3, 3] = [0.0, 0.0, 0.3]
    frames[2, :3, 3] = [0.4, 0.0, 0.3]
    tip = np.eye(4)
    tip[:3, 3] = [0.4, 0.0, 0.0]
    assert chain_length(frames, tip) == pytest.approx(1.0)
    assert reach(1.0, 0.2) == pytest.approx(1.2)
    assert reach(1.0, 500.0) == pytest.approx(2.0)  # a tool from wrong units is capped
    A = np.random.default_rng(0).normal(size=(50, 3))
    R = rotz(0.4) @ rotx(-1.1)
    assert np.max(_aligned_distances(A, A @ R.T + [1.0, 2.0, 3.0])) < 1e-12
    assert np.max(_aligned_distances(A, A * 1.1)) > 0.01


def test_joint_columns_off_the_chain_are_pointed_out(ur10_csv, tmp_path, capsys):
    # UR10 data (tool on the last axis) with the tip one link short fit well: turning the
    # last joint does not move the point. Written, with a warning naming the columns.
    out = tmp_path / "c.urdf"
    assert main(["calibrate", "ur10", str(ur10_csv), "--tip", "wrist_2_link", "--out",
                 str(out), "--lambda", "1"]) == 0
    assert out.is_file()
    assert ("columns for 1 URDF joint off the chain are ignored: wrist_3_joint beyond the "
            "chain's ends: if it moves the measured point" in capsys.readouterr().err)
    assert not judge(_evidence(off_chain_columns=("j7",))).findings
    assert judge(_evidence(off_chain_columns=("j7",))).notes
    assert not judge(_evidence(off_chain_columns=("j7",), residual_median_mm=50)).notes
    # joints on other branches (a whole robot's log) are said to move nothing measured,
    # also when the fit is bad; the names beyond six are counted, not dropped silently
    many = tuple(f"b{k}" for k in range(8))
    (note,) = judge(_evidence(other_branch_columns=many, residual_median_mm=50)).notes
    assert "8 URDF joints off the chain" in note and "b5 and 2 more" in note
    assert "move neither the tip nor the base" in note and "check --tip" not in note


def test_off_chain_movers_are_the_joints_beyond_the_tip_or_above_the_base():
    """Of a log's joints off the chain, only those below the tip's link or above the base
    can move the measured point; a sibling branch's cannot (TALOS: the right arm and leg
    and the head against the left sole -> left gripper chain; the left gripper's finger
    hangs below the tip's link)."""
    from kincal.descriptions import erd_robots_dir

    root = erd_robots_dir()
    path = None if root is None else root / "talos_data" / "robots" / "talos_full_v2.urdf"
    if path is None or not path.exists():
        pytest.skip("example-robot-data's TALOS is not installed")
    from kincal import Robot

    talos = Robot.load(path, base="left_sole_link", tip="gripper_left_base_link")
    names = ("arm_right_1_joint", "head_1_joint", "leg_right_3_joint", "gripper_left_joint",
             "torso_1_joint", "not_a_joint")
    assert talos.off_chain_movers(names) == ("gripper_left_joint",)
    # from the torso, the torso joints lie above the base (the data's frame beyond it);
    # the legs hang on another branch of the URDF tree (from its root, the pelvis)
    torso = Robot.load(path, base="torso_2_link", tip="gripper_left_base_link")
    assert torso.off_chain_movers(("leg_left_3_joint", "torso_1_joint", "head_1_joint",
                                   "arm_right_1_joint")) == ("torso_1_joint",)


def test_branches_hanging_from_the_base_name_a_moving_base():
    """Logged joints of other branches that hang from the base's own link (a standing
    humanoid's legs from its pelvis) make a refusal name a base that moves against the
    instrument, with those joints and the base; branches further along the chain do not
    (they cannot carry the base unseen by the chain's joints), nor a refusal without them."""
    legs = ("leg_l1", "leg_r1", "arm_r1")
    bad = dict(change_rms_mm=300.0, change_max_mm=500.0, bases=("base_link",))
    causes = judge(_evidence(other_branch_columns=legs, at_base=2, **bad)).causes
    (moving,) = [c for c in causes if c.startswith("a base frame that moves")]
    assert "hang from base_link (leg_l1, leg_r1)" in moving and "arm_r1" not in moving
    assert "give as --base the link that stays fixed to the instrument" in moving
    assert causes.index(moving) < causes.index(
        "a URDF that does not describe the measured robot or a tip frame that does not match "
        "the data")
    for quiet in (judge(_evidence(other_branch_columns=legs, at_base=0, **bad)),
                  judge(_evidence(**bad))):
        assert not any("base frame that moves" in c for c in quiet.causes)
    # the residual's causes too (points measured from a base that moved)
    far = judge(_evidence(other_branch_columns=legs, at_base=1, residual_median_mm=50,
                          residual_rms_mm=70, bases=("pelvis",)))
    assert any("hang from pelvis (leg_l1)" in c for c in far.causes)



def test_orientation_left_far_off_after_calibration_is_a_finding():
    """A flush face far from flush after calibration (or a pose's orientation far off): the
    model does not describe the data, whatever the heights say; half a degree is real
    data's, and sets without orientations have none to judge."""
    tilt = dict(orientation_what="tilt against the plane", orientation_rms_deg=45.9)
    assert not judge(_evidence(orientation_median_deg=0.49, **tilt)).findings
    assert not judge(_evidence()).findings  # points: no orientation (None)
    found = judge(_evidence(orientation_median_deg=36.5, off_chain_columns=(
        "arm_left_6_joint", "arm_left_7_joint"), **tilt)).findings
    assert [f.kind for f in found] == ["orientation"] and found[0].threshold == 5.0
    assert "tilt against the plane after calibration is 36.5 deg" in found[0].message
    assert found[0].causes[0].startswith("a tip frame that does not match the data: the file "
                                         "has columns for URDF joints beyond")



def test_a_tool_point_chain_lengths_from_its_tip_is_a_finding():
    """A tool point identified several chain lengths from the tip: the data did not fix it
    (for plane contacts the first cause: a flat face's touches without --flush)."""
    assert not judge(_evidence(tool_far=(0.12, 2.1, "t.csv", "flush"))).findings
    found = judge(_evidence(tool_far=(10.1, 2.1, "t.csv", "plane"))).findings
    assert [f.kind for f in found] == ["tool_point"] and found[0].threshold == pytest.approx(6.3)
    assert "identified 10.1 m from the tip frame, 5 times the chain's length" in found[0].message
    assert "with --flush each touch also gives the face's two tilts" in found[0].causes[0]
    points = judge(_evidence(tool_far=(10.1, 2.1, "p.csv", "point"))).findings
    assert "--fix tool.x tool.y tool.z" in points[0].causes[0]

def test_talos_touches_on_a_tip_two_joints_short_are_refused(tmp_path, capsys):
    """TALOS's flush touches calibrated to arm_left_5_link instead of the gripper: the
    heights pass the residual criterion (9 mm of a 2.2 m reach), the tilts stay 36 deg off
    (median): refused in one line naming the tip, nothing written; the right tip calibrates."""
    from test_tree_paths import _talos_study

    study = _talos_study()
    urdf, train = study.talos_urdf(), str(study.DATA / "left_train.csv")
    argv = ["calibrate", str(urdf), train, "--base", "left_sole_link", "--on-plane", "--flush",
            "--tool-offset", "0", "0", "-0.12", "--out", str(tmp_path / "cal.urdf")]
    capsys.readouterr()
    assert main(argv + ["--tip", "arm_left_5_link"]) != 0
    err = [line for line in capsys.readouterr().err.splitlines()
           if line.startswith("kincal: error:")]
    assert len(err) == 1 and "the tilt against the plane after calibration is 36" in err[0]
    assert "Likely cause: a tip frame that does not match the data" in err[0]
    assert not (tmp_path / "cal.urdf").exists()
    assert main(argv + ["--tip", "gripper_left_base_link"]) == 0
    # the same touches without --flush, as plane contacts: a 10 m tool point, refused
    capsys.readouterr()
    plane = [a for a in argv if a != "--flush"] + ["--tip", "gripper_left_base_link",
                                                  "--overwrite"]
    (tmp_path / "cal.urdf").unlink()
    assert main(plane) != 0 and not (tmp_path / "cal.urdf").exists()
    captured = capsys.readouterr()
    said = captured.err.splitlines()
    err = [line for line in said if line.startswith("kincal: error:")]
    assert len(err) == 1 and "Likely cause: contacts of a flat face read as plane" in err[0]
    # the kept set there is a basis as good as the data's (before the selection's
    # near-duplicates waited: condition number 4.3e5, a dropped parameter acting through
    # kept ones amplified 61397x, and the evidence did not settle; now 3.7e3, 353x)
    note = [line for line in captured.out.splitlines()
            if "dropped parameters act through kept ones" in line]
    assert note and int(note[0].split("amplified up to ")[1].split("x")[0]) < 1000


def test_evidence_that_does_not_settle_says_so(monkeypatch):
    """The evidence's hyperparameters still moving after its last round: a warning (the
    summary alone said it before), the fit the last round's."""
    import functools

    from kincal.identification import evidence
    from kincal.models import mdh
    from kincal.planning.simulation import Truth, cube_poses, measure, planted_table

    robot = Robot.load("ec66", tip="flange")
    rng = np.random.default_rng(4)
    model = mdh.extract(robot.geometry)
    q = cube_poses(robot, 40, [0.4, 0.0, 0.25], 0.02, np.array([0.02, 0.0, 0.1]), rng)
    data = measure(model, Truth(planted_table(model, rng), np.zeros(6),
                                np.array([0.02, 0.0, 0.1])), q, 5e-5, rng)
    monkeypatch.setattr(evidence, "estimate", functools.partial(evidence.estimate, max_outer=1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = calibrate(robot, data, method="l2", lam="evidence")
    assert not res.evidence.converged and res.evidence.iterations == 1
    assert any("the evidence's prior scales and noise did not settle in 1 rounds" in
               str(w.message) for w in caught)

def test_talos_from_the_urdf_root_names_the_moving_base(tmp_path, capsys):
    """The TALOS touches calibrated from the URDF's root (the default base, the pelvis,
    which moves with the legs the robot stands on): refused in one line, nothing written,
    the first likely cause the base that moves with the logged legs (not only a wrong URDF
    or tip); the same log from the left sole names no such cause (the right leg hangs
    from the pelvis, six chain joints away), and its note lists the right leg first."""
    from test_tree_paths import _talos_study

    from kincal.identification.chains import Chains
    from kincal.measurements.flush import FlushData
    from kincal.robot import Robot

    study = _talos_study()
    urdf, train = study.talos_urdf(), str(study.DATA / "left_train.csv")
    out = tmp_path / "cal.urdf"
    code = main(["calibrate", str(urdf), train, "--tip", "gripper_left_base_link",
                 "--on-plane", "--flush", "--tool-offset", "0", "0", "-0.12", "--out", str(out)])
    err = capsys.readouterr().err
    assert code != 0 and not out.exists() and err.count("\n") == 1
    assert ("Likely cause: a base frame that moves against the instrument: the file logs "
            "joints of other branches that hang from base_link (leg_left_1_joint, "
            "leg_left_2_joint, leg_left_3_joint and 9 more); if the robot stands or rolls on "
            "them, base_link moves with them") in err
    ignored = ("arm_right_1_joint", "head_1_joint", "leg_right_3_joint", "leg_left_2_joint")
    data = FlushData(joint_names=(), joint_values=np.zeros((1, 0)), ignored_columns=ignored)
    root = Chains([Robot.load(urdf, tip="gripper_left_base_link")], 1)
    assert root.off_chain_columns([data]) == (
        (), ("leg_right_3_joint", "leg_left_2_joint", "arm_right_1_joint", "head_1_joint"), 2)
    sole = Chains([Robot.load(urdf, base="left_sole_link", tip="gripper_left_base_link")], 1)
    ignored = ignored[:3]
    data = FlushData(joint_names=(), joint_values=np.zeros((1, 0)), ignored_columns=ignored)
    assert sole.off_chain_columns([data]) == (
        (), ("leg_right_3_joint", "arm_right_1_joint", "head_1_joint"), 0)


def test_several_data_sets_go_through_the_gate(tmp_path, capsys):
    """A calibration from several files writes nothing when one of them is in mm read as m."""
    from kincal.cli.main import main as kmain

    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert kmain(["simulate", "ec66", "--out", str(a), "--seed", "1", "--poses", "40"]) == 0
    assert kmain(["simulate", "ec66", "--out", str(b), "--seed", "2", "--poses", "40"]) == 0
    out = tmp_path / "c.urdf"
    assert kmain(["calibrate", "ec66", str(a), str(b), "--out", str(out)]) == 0  # both good
    out.unlink()
    lines = [r for r in b.read_text().splitlines() if not r.startswith("#")]
    head, rows = lines[0], [r.split(",") for r in lines[1:]]
    b.write_text("\n".join([head] + [",".join(r[:6] + [repr(float(v) * 1e3) for v in r[6:9]])
                                     for r in rows]) + "\n")
    capsys.readouterr()
    before = sorted(p.name for p in tmp_path.iterdir())
    assert kmain(["calibrate", "ec66", str(a), str(b), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "implausible" in err and "nothing is written" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_every_output_for_several_sets_of_other_kinds_and_the_frames_serve_the_cell(tmp_path,
                                                                                   capsys):
    """Issue 17's acceptance: points and poses in one calibration with a robust loss write
    the URDF, frames, report, HTML and plots; evaluate takes the chain from the frames and
    refuses another tip; compensate works with those frames."""
    from kincal.cli.main import main as kmain

    pts, poses = tmp_path / "points.csv", tmp_path / "poses.csv"
    assert kmain(["simulate", "ec66", "--out", str(pts), "--seed", "1", "--poses", "30"]) == 0
    assert kmain(["simulate", "ec66", "--kind", "pose", "--out", str(poses), "--seed", "2",
                  "--poses", "30"]) == 0
    capsys.readouterr()
    c, f, r, h, p = (tmp_path / n for n in ("C.urdf", "F.json", "R.json", "R.html", "P"))
    assert kmain(["calibrate", "ec66", str(pts), str(poses), "--robust", "huber", "--out", str(c),
                  "--frames-out", str(f), "--report", str(r), "--html", str(h), "--plots",
                  str(p)]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "2 measurement set(s)" in out and "robust loss huber" in out
    for path in (c, f, r, h):
        assert path.is_file() and path.stat().st_size > 0, path
    assert {"residuals.png", "residuals_set2.png"} <= {q.name for q in p.iterdir()}
    saved = json.loads(f.read_text())
    assert saved["format"] == "kincal-frames" and [s["kind"] for s in saved["sets"]] == [
        "point", "pose"]
    report = json.loads(r.read_text())
    assert [s["kind"] for s in report["sets"]] == ["point", "pose"]
    assert kmain(["evaluate", str(c), str(pts), "--frames", str(f)]) == 0
    assert "mean" in capsys.readouterr().out
    before = sorted(q.name for q in tmp_path.iterdir())
    assert kmain(["evaluate", str(c), str(pts), "--frames", str(f), "--tip", "joint_5"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("kincal: error:") and err.count("\n") == 1 and "flange" in err
    assert sorted(q.name for q in tmp_path.iterdir()) == before
    joints = tmp_path / "joints.csv"
    assert kmain(["compensate", str(c), str(pts), "--frames", str(f), "--tip", "flange",
                  "--out", str(joints)]) == 0, capsys.readouterr().err
    assert joints.is_file()




@pytest.mark.parametrize("method, equations, identified, named", [
    ("ls", 51, 48, True), ("ls", 143, 48, True), ("ls", 144, 48, False),
    ("l2", 51, 48, False), ("ls", 0, 48, False)])
def test_plain_least_squares_on_few_equations_is_named_first(method, equations, identified,
                                                             named):
    """Corrections far off with method ls and fewer than 3 equations per identified
    parameter: the likely cause named first is the over-fit, with both counts."""
    f = next(f for f in judge(_evidence(change_rms_mm=500.0, method=method, equations=equations,
                                        identified=identified)).findings
             if f.kind == "corrections")
    assert ("plain least squares on" in f.causes[0]) is named
    if named:
        assert f"{equations} equations for {identified} identified" in f.causes[0]


def test_talos_least_squares_on_few_touches_names_the_over_fit(tmp_path, capsys):
    """Seventeen real TALOS touches with --method ls: refused, nothing written, the over-fit
    named with the numbers of equations and identified parameters."""
    from test_tree_paths import _talos_study

    study = _talos_study()
    lines = (study.DATA / "left_train.csv").read_text().splitlines()
    part = tmp_path / "few.csv"
    part.write_text("\n".join(lines[:18]) + "\n")
    out = tmp_path / "cal.urdf"
    code = main(["calibrate", str(study.talos_urdf()), str(part), "--base", "left_sole_link",
                 "--tip", "gripper_left_base_link", "--on-plane", "--flush", "--tool-offset",
                 "0", "0", "-0.12", "--method", "ls", "--out", str(out)])
    assert code != 0 and not out.exists()
    assert "Likely cause: plain least squares on 51 equations for" in _error_line(capsys)


WHEEL_ARM = """<?xml version="1.0"?>
<robot name="wheel_arm">
  <link name="base_link"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"/>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0 0.1" rpy="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l2"/>
  <joint name="spin" type="continuous"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0.02 0.4" rpy="0 0.2 0"/><axis xyz="0 0 1"/></joint>
  <link name="l3"/>
  <joint name="tip_joint" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="0.1 0.05 0.02" rpy="0 0 0"/></joint>
  <link name="tip"/>
</robot>
"""


def test_a_continuous_joint_turning_many_times_is_no_unit_mistake(tmp_path, capsys):
    """A continuous joint logged as its cumulative angle (three turns and more): the same
    calibration as its values within one turn, no 'were they degrees?' warning; before, the
    gate refused it (values beyond 4 pi). The same file in degrees read as radians is still
    refused."""
    urdf = tmp_path / "wheel_arm.urdf"
    urdf.write_text(WHEEL_ARM)
    robot = Robot.load(urdf, tip="tip")
    q = np.random.default_rng(3).uniform(-1.5, 1.5, (30, 3))
    T = robot.tip_poses(q)
    P = T[:, :3, 3] + T[:, :3, :3] @ np.array([0.02, 0.01, 0.03])
    turned = q.copy()
    turned[:, 2] += 6 * np.pi
    common = ["--tip", "tip", "--model", "offsets", "--lambda", "0.001", "--tool-offset",
              "0.02", "0.01", "0.03", "-q"]
    for name, values in (("within.csv", q), ("turned.csv", turned),
                         ("degrees.csv", np.degrees(q))):
        _write_rows(tmp_path / name, ["j1", "j2", "spin", "x", "y", "z"], np.hstack([values, P]))
    for name in ("within", "turned"):
        assert main(["calibrate", str(urdf), str(tmp_path / f"{name}.csv"), *common, "--out",
                     str(tmp_path / f"{name}.urdf"), "--frames-out",
                     str(tmp_path / f"{name}.json")]) == 0
        assert "degrees" not in capsys.readouterr().err
    a, b = (json.loads((tmp_path / f"{n}.json").read_text())["sets"][0]["frames"]
            for n in ("within", "turned"))
    assert max(abs(a[k] - b[k]) for k in a) < 1e-9
    before = _snapshot(tmp_path)
    assert main(["calibrate", str(urdf), str(tmp_path / "degrees.csv"), *common, "--out",
                 str(tmp_path / "degrees.urdf")]) == 1
    assert "degrees" in _error_line(capsys)
    assert _snapshot(tmp_path) == before


def _write_rows(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(
        ",".join(repr(float(v)) for v in r) + "\n" for r in rows))


@pytest.mark.parametrize("method, weak, named", [
    ("l2", ("arm_7.ry",), True), ("l2", (), False), ("ls", ("arm_7.ry",), False)])
def test_a_weak_parameter_that_moved_most_names_the_penalty(method, weak, named):
    """Corrections far off whose largest is a weak parameter, with the penalty: the likely
    cause names the penalty too weak for it, with the evidence's scale, before the URDF."""
    f = next(f for f in judge(_evidence(
        change_rms_mm=500.0, method=method, corrections=(("arm_7.ry", -78.7, "deg"),),
        weak_corrections=weak, weak_scales="offset 45.8 deg" if weak else "")).findings
        if f.kind == "corrections")
    assert any("a penalty too weak" in c for c in f.causes) is named
    if named:
        assert "(arm_7.ry)" in f.causes[0] and "offset 45.8 deg" in f.causes[0]
        assert "a URDF that does not describe" in f.causes[-1]



def test_a_weak_parameter_under_one_lambda_names_that_lambda():
    """With CV's one lambda (no evidence scales) the cause names the lambda and the remedy
    that applies to it (the evidence or a larger lambda), not prior scales."""
    f = next(f for f in judge(_evidence(
        change_rms_mm=500.0, method="l2", corrections=(("joint_6.alpha", 62.6, "deg"),),
        weak_corrections=("joint_6.alpha",),
        weak_scales="lambda 1e-06 chosen by cross-validation")).findings
        if f.kind == "corrections")
    assert "(lambda 1e-06 chosen by cross-validation)" in f.causes[0]
    assert "--lambda evidence" in f.causes[0] and "--prior-mm" not in f.causes[0]


def test_talos_three_copies_of_a_day_name_the_penalty(tmp_path, capsys):
    """The real TALOS touches read three times (three files of one day, each with its own
    table plane; copies with a comment line of their own, since one file given twice is
    refused before the work): the evidence's offset scale runs away and a wrist turn trades
    against the contact face's tilt; refused in one line, nothing written, the copies named
    as the first likely cause, then the weak penalty with the scale the evidence estimated
    (not only a wrong URDF or tip)."""
    from test_tree_paths import _talos_study

    study = _talos_study()
    train = str(study.DATA / "left_train.csv")
    copies = [tmp_path / f"copy{k}.csv" for k in (1, 2)]
    for k, copy in enumerate(copies):
        copy.write_text(f"# copy {k + 1}\n" + Path(train).read_text())
    out = tmp_path / "cal.urdf"
    code = main(["calibrate", str(study.talos_urdf()), train, *map(str, copies), "--base",
                 "left_sole_link", "--tip", "gripper_left_base_link", "--on-plane", "--flush",
                 "--tool-offset", "0", "0", "-0.12", "--out", str(out)])
    err = capsys.readouterr().err
    assert code != 0 and not out.exists() and err.count("\n") == 1  # one line, no warning
    line = err.strip()
    assert line.startswith("kincal: error: implausible calibration")
    assert ("Likely cause: the same samples given more than once (" + str(copies[0]) + ": 21 "
            "of its 21 samples repeat samples of " + train + " exactly (line ") in line
    assert "or a penalty too weak for what the data barely tell apart" in line
    assert "whose scale the evidence estimated at" in line and "--prior-deg" in line


def test_a_second_file_in_millimetres_is_the_unit_clue(tmp_path, capsys):
    """Two point files, the second's positions in mm: the unit clue was the first positioned
    set's alone, so the gate named noise, a tip or another URDF as the likely cause. Every
    set's spread is judged now; the clue names the file that is off."""
    for seed in ("1", "7"):
        assert main(["simulate", "ec66", "--out", str(tmp_path / f"s{seed}.csv"), "--poses",
                     "40", "--seed", seed, "--tool-m", "0.03", "0.02", "0.12", "--quiet"]) == 0

    def to_mm(header, values):
        values[:, [header.index(c) for c in "xyz"]] *= 1e3

    _rewrite(tmp_path / "s7.csv", tmp_path / "mm.csv", to_mm)
    out = tmp_path / "o.urdf"
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(tmp_path / "s1.csv"), str(tmp_path / "mm.csv"),
                 "--out", str(out)]) == 1
    line = _error_line(capsys)
    assert f"the measured positions of {tmp_path / 'mm.csv'} spread" in line, line
    assert "Likely cause: positions in millimetres read as metres" in line, line
    assert not out.exists()
    assert main(["calibrate", "ec66", str(tmp_path / "s1.csv"), str(tmp_path / "s7.csv"),
                 "--out", str(out), "--quiet"]) == 0  # both in metres: plausible


def test_a_pose_file_logged_in_millimetres_and_degrees_names_the_length_unit(tmp_path, capsys):
    """TIAGo poses logged in mm and deg (its torso a prismatic joint, in mm too), read with
    --angle-unit deg alone: the positions' spread grows with the torso's, so their ratio gave
    no clue and the gate named noise, a tip or another URDF. The torso far beyond its limits
    is the clue now: warned, and the refusal's likely cause; --length-unit mm calibrates."""
    assert main(["simulate", "tiago", "--tip", "arm_tool_link", "--center-m", "0.6", "0", "0.8",
                 "--size-mm", "300", "--tilt-deg", "180", "--kind", "pose", "--poses", "40",
                 "--orientation-format", "rpy-zyx", "--out", str(tmp_path / "si.csv"),
                 "--quiet"]) == 0

    def to_mm_deg(header, values):
        values[:, [header.index(c) for c in ("torso_lift_joint", "x", "y", "z")]] *= 1e3
        angles = [c for c in header if c.startswith("arm_") or c in ("roll", "pitch", "yaw")]
        values[:, [header.index(c) for c in angles]] = np.degrees(
            values[:, [header.index(c) for c in angles]])

    _rewrite(tmp_path / "si.csv", tmp_path / "mm.csv", to_mm_deg)
    out = tmp_path / "o.urdf"
    args = ["calibrate", "tiago", str(tmp_path / "mm.csv"), "--tip", "arm_tool_link",
            "--orientation-format", "rpy-zyx", "--angle-unit", "deg", "--model", "complete",
            "--out", str(out)]
    capsys.readouterr()
    assert main(args) == 1
    err = capsys.readouterr().err
    line = [t for t in err.splitlines() if t.startswith("kincal: error:")][0]
    assert "Likely cause: lengths in millimetres read as metres (" in line, line
    assert "torso_lift_joint is" in line and "--length-unit mm" in line
    assert "were the lengths millimetres? Read them with --length-unit mm" in err
    assert not out.exists()
    assert main(args + ["--length-unit", "mm", "--quiet"]) == 0
    assert "were the lengths millimetres" not in capsys.readouterr().err


def test_validate_contacts_repeating_some_training_touches_is_warned(tmp_path, capsys):
    """A contact sample is its joint values alone: a touch program run again with commanded
    joints repeats some exactly, and its touches are measured anew. --validate with one
    training touch among the other day's 9 is judged, with a warning naming the repeat; a
    file of training touches alone is still refused (nothing written)."""
    from test_tree_paths import _talos_study

    study = _talos_study()
    names, train = study.joint_rows(study.DATA / "left_train.csv")
    _, valid = study.joint_rows(study.DATA / "left_validation.csv")
    t, mixed, same = (tmp_path / n for n in ("t.csv", "mixed.csv", "same.csv"))
    study.write_joint_csv(t, names, train)
    study.write_joint_csv(mixed, names, np.vstack([valid, train[2:3]]))
    study.write_joint_csv(same, names, train[:5])
    args = ["calibrate", str(study.talos_urdf()), str(t), "--base", "left_sole_link", "--tip",
            "gripper_left_base_link", "--on-plane", "--flush", "--tool-offset", "0", "0",
            "-0.12", "--quiet"]
    out = tmp_path / "cal.urdf"
    assert main([*args, "--out", str(out), "--validate", str(mixed)]) == 0 and out.exists()
    err = capsys.readouterr().err
    assert "1 of its 10 samples repeat samples of" in err and "judged as held out" in err
    out2 = tmp_path / "cal2.urdf"
    assert main([*args, "--out", str(out2), "--validate", str(same)]) == 1
    err = capsys.readouterr().err.strip()
    assert not out2.exists() and err.startswith("kincal: error: --validate")
    assert "5 of its 5 samples repeat samples of" in err


def test_the_residual_line_names_what_the_set_measures(tmp_path):
    """Shuffled rows of a distance file: the gate's line said "the position error after
    calibration" of data that hold no position (contacts: their distance to the plane)."""
    from dataclasses import replace

    from kincal.measurements.sets import read_set_file

    kind, what = "distance", "distance"

    path = tmp_path / "d.csv"
    assert main(["simulate", "ec66", "--kind", kind, "--poses", "60", "--seed", "1",
                 "--out", str(path), "-q"]) == 0
    robot = Robot.load("ec66", tip="flange")
    data = read_set_file(path, robot.joint_names, on_plane=kind == "plane")
    q = data.joint_values[np.random.default_rng(0).permutation(len(data))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate(robot, replace(data, joint_values=q), method="l2", lam=0.1,
                           model="complete")
    with pytest.raises(ImplausibleResultError) as exc:
        write_calibration(result, Outputs(urdf=tmp_path / "c.urdf"))
    assert f"the {what} error after calibration is " in str(exc.value)
    assert "position error" not in str(exc.value)
    assert not (tmp_path / "c.urdf").exists()
    from kincal.identification.statistics import error_label

    assert [error_label(k) for k in ("point", "pose", "distance", "plane", "flush")] == [
        "position", "position", "distance", "distance to the plane", "height above the plane"]


def test_distances_in_millimetres_read_as_metres_are_named_as_the_cause(tmp_path):
    """A distance file in mm read as m was refused with every cause but the unit (the unit
    clue looked at positions only). Distances to a fixed pivot range no wider than the tool
    point moves: 590x wider names the unit; the file in metres calibrates."""
    from dataclasses import replace

    from kincal.measurements.checks import distance_ratio
    from kincal.measurements.sets import read_set_file

    path = tmp_path / "d.csv"
    assert main(["simulate", "ec66", "--kind", "distance", "--poses", "60", "--seed", "3",
                 "--out", str(path), "-q"]) == 0
    robot = Robot.load("ec66", tip="flange")
    data = read_set_file(path, robot.joint_names)
    mm = replace(data, distances=data.distances * 1e3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate(robot, mm, method="l2", lam=0.1, model="complete")
        good = calibrate(robot, data, method="l2", lam=0.1, model="complete")
    with pytest.raises(ImplausibleResultError) as exc:
        write_calibration(result, Outputs(urdf=tmp_path / "c.urdf"))
    text = str(exc.value)
    assert "the measured distances spread " in text and "Likely cause: distances in " \
        "millimetres read as metres (they spread " in text and "--length-unit mm" in text, text
    assert good.plausibility.plausible and math.isnan(good.plausibility.evidence.length_ratio)
    rng = np.random.default_rng(0)  # a point on a sphere about the pivot: one distance
    u = rng.normal(size=(50, 3))
    sphere = 0.3 * u / np.linalg.norm(u, axis=1)[:, None]
    assert math.isnan(distance_ratio(np.full(50, 0.3), sphere))
    line = rng.uniform(-0.2, 0.2, (50, 1)) * np.array([[1.0, 0.0, 0.0]])  # along a line
    assert distance_ratio(1e3 * np.abs(line[:, 0] + 0.5), line) == pytest.approx(
        1e3 * np.ptp(line[:, 0]) / (2 * np.abs(line[:, 0] - line[:, 0].mean()).max()))
