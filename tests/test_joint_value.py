"""--joint-value NAME=VALUE: a chain joint absent from the data file, held during the
measurements; the same result as a file with its constant column, recorded in FRAMES.json
and the report, refused when the file has the column or the joint is not on the chain."""

import json
import re

import numpy as np
import pytest

from kincal.cli.main import main
from kincal.frames_file import CellFrames


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out = capsys.readouterr()
    return code, out.out, out.err


def write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(repr, r.tolist())) + "\n"
                                                       for r in rows))
    return path


def simulated(tmp_path, capsys):
    """(header, rows) of 30 simulated EC66 points."""
    full = tmp_path / "full.csv"
    assert main(["simulate", "ec66", "--poses", "30", "--out", str(full), "--seed", "4"]) == 0
    capsys.readouterr()
    lines = [r for r in full.read_text().splitlines() if not r.startswith("#")]
    return lines[0].split(","), np.array([[float(v) for v in line.split(",")]
                                          for line in lines[1:]])


def test_held_joint_gives_the_same_calibration_and_is_recorded(tmp_path, capsys):
    header, rows = simulated(tmp_path, capsys)
    k = header.index("joint_6")
    rows[:, k] = 30.0 * np.pi / 180  # the wrist held at 30 deg
    with_column = write(tmp_path / "with.csv", header, rows)
    in_deg = rows.copy()
    joints = [i for i, h in enumerate(header) if h.startswith("joint_")]
    in_deg[:, joints] = np.degrees(rows[:, joints])  # the file in degrees, as --angle-unit says
    without = write(tmp_path / "without.csv", header[:k] + header[k + 1:],
                    np.delete(in_deg, k, axis=1))
    common = ("--model", "offsets", "--fix", "joint_6.theta", "--lambda", 0)
    code, out1, err = run(capsys, "calibrate", "ec66", with_column, *common, "--out",
                          tmp_path / "a.urdf", "--frames-out", tmp_path / "a.json")
    assert code == 0, err
    code, out2, err = run(capsys, "calibrate", "ec66", without, *common, "--joint-value",
                          "joint_6=30", "--angle-unit", "deg", "--out", tmp_path / "b.urdf",
                          "--frames-out", tmp_path / "b.json", "--report", tmp_path / "r.json")
    assert code == 0, err
    assert "joints held during the measurements (not in the file): joint_6 = 30 deg" in out2
    a, b = (json.loads((tmp_path / f).read_text())["sets"][0] for f in ("a.json", "b.json"))
    np.testing.assert_allclose(list(a["frames"].values()), list(b["frames"].values()),
                               atol=1e-9)
    assert "fixed_joints" not in a
    assert b["fixed_joints"] == {"joint_6": np.radians(30.0)}
    assert CellFrames.read(tmp_path / "b.json").sets[0].fixed_joints == (
        ("joint_6", np.radians(30.0)),)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["sets"][0]["fixed_joints"] == {"joint_6": np.radians(30.0)}
    # evaluate and analyze read the file the same way
    code, out, err = run(capsys, "evaluate", tmp_path / "b.urdf", without, "--frames",
                         tmp_path / "b.json", "--joint-value", "joint_6=30", "--angle-unit",
                         "deg")
    assert code == 0, err
    code, ref, err = run(capsys, "evaluate", tmp_path / "b.urdf", with_column, "--frames",
                         tmp_path / "b.json")
    assert out.splitlines()[1] == ref.splitlines()[1]
    code, out, err = run(capsys, "analyze", "ec66", without, "--joint-value", "joint_6=5",
                         "--angle-unit", "deg")
    assert code == 0, err


def test_joint_value_refusals_are_one_line(tmp_path, capsys):
    data = tmp_path / "d.csv"
    assert main(["simulate", "ec66", "--poses", "10", "--out", str(data), "--seed", "1"]) == 0
    capsys.readouterr()
    for argv, says in ((("--joint-value", "joint_6=0"), "has a column for joint_6"),
                       (("--joint-value", "joint_9=0"), "not a joint of the chain"),
                       (("--joint-value", "joint_6"), "expects NAME=VALUE"),
                       (("--joint-value", "joint_6=nan"), "expects NAME=VALUE"),
                       (("--joint-value", "joint_6=1", "--joint-value", "joint_6=2"),
                        "given twice")):
        code, out, err = run(capsys, "analyze", "ec66", data, *argv)
        assert code == 1 and err.count("\n") == 1 and says in err, err


def test_joint_value_outside_the_urdf_limits_is_refused_naming_the_option(tmp_path, capsys):
    """A held value outside the joint's URDF limits (degrees given with --angle-unit rad) is
    refused at the option, before any work: it used to run the calibration, then blame the
    data file ("d.csv: joint_6: 10 of 10 values outside its URDF limits (worst 100 at line
    2)", "were they degrees?") and refuse through the gate."""
    header, rows = simulated(tmp_path, capsys)
    keep = [k for k, c in enumerate(header) if c != "joint_6"]
    data = write(tmp_path / "d.csv", [header[k] for k in keep], rows[:, keep])
    for argv, says in ((("--joint-value", "joint_6=100"), "[-6.283, 6.283] rad"),
                       (("--joint-value", "joint_6=400", "--angle-unit", "deg"),
                        "[-360, 360] deg")):
        for command in (["calibrate", "ec66", data, "--out", tmp_path / "c.urdf"],
                        ["analyze", "ec66", data]):
            code, out, err = run(capsys, *command, *argv)
            assert code == 1 and err.count("\n") == 1, err
            assert f"--joint-value {argv[1]}: outside joint_6's URDF limits {says}" in err
            assert not (tmp_path / "c.urdf").exists()


MIMIC_ARM = """<?xml version="1.0"?>
<robot name="mimic_arm">
  <link name="base_link"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"/>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0 0.1" rpy="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l2"/>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0.02 0.4" rpy="0 0.2 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l3"/>
  <joint name="finger" type="revolute"><parent link="l3"/><child link="f"/>
    <origin xyz="0.3 0.05 0.02" rpy="0.1 0 0.4"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="j3" multiplier="-0.5" offset="0.1"/></joint>
  <link name="f"/>
  <joint name="ftip_joint" type="fixed"><parent link="f"/><child link="ftip"/>
    <origin xyz="0.02 0.1 0.05" rpy="0 0 0"/></joint>
  <link name="ftip"/>
  <joint name="side" type="revolute"><parent link="l2"/><child link="s"/>
    <origin xyz="0 0.1 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="s"/>
  <joint name="smimic" type="revolute"><parent link="s"/><child link="s2"/>
    <origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="side" multiplier="2" offset="0"/></joint>
  <link name="s2"/>
</robot>
"""


def _mimic_files(tmp_path):
    """The arm's URDF, and its tool points (tip ftip, through the mimic finger) measured
    at joint values where the finger follows j3 as its <mimic> says (Pinocchio with the
    finger's values filled by the rule: what the URDF means)."""
    from kincal.robot import Robot

    urdf = tmp_path / "mimic_arm.urdf"
    urdf.write_text(MIMIC_ARM)
    robot = Robot.load(urdf, tip="ftip")
    assert robot.joint_names == ("j1", "j2", "j3", "finger")
    q = np.random.default_rng(1).uniform(-1.2, 1.2, (30, 4))
    q[:, 3] = -0.5 * q[:, 2] + 0.1
    T = robot.tip_poses(q)
    P = T[:, :3, 3] + T[:, :3, :3] @ np.array([0.01, 0.02, 0.03])
    full = write(tmp_path / "full.csv", ["j1", "j2", "j3", "finger", "x", "y", "z"],
                 np.hstack([q, P]))
    short = write(tmp_path / "short.csv", ["j1", "j2", "j3", "x", "y", "z"],
                  np.hstack([q[:, :3], P]))
    return urdf, q, P, full, short


def test_mimic_joint_without_a_column_follows_its_master(tmp_path, capsys):
    """A file without the mimic finger's column: its values come from j3 by the URDF's rule
    (the same calibration as the file with the column); before, 'missing column finger'."""
    urdf, q, P, full, short = _mimic_files(tmp_path)
    common = ("--tip", "ftip", "--model", "placement", "--lambda", "0.001",
              "--tool-offset", "0.01", "0.02", "0.03")
    for name, data in (("a", full), ("b", short)):
        code, out, err = run(capsys, "calibrate", urdf, data, *common, "--out",
                             tmp_path / f"{name}.urdf", "--frames-out", tmp_path / f"{name}.json")
        assert code == 0, err
        assert "mimic" not in err  # consistent files: nothing to warn about
    a, b = (json.loads((tmp_path / f).read_text())["sets"][0] for f in ("a.json", "b.json"))
    np.testing.assert_allclose(list(a["frames"].values()), list(b["frames"].values()),
                               atol=1e-12)
    a_text, b_text = (re.sub(r"<!--.*?-->", "", (tmp_path / f).read_text(), flags=re.S)
                      for f in ("a.urdf", "b.urdf"))  # less the provenance comments
    assert a_text == b_text and a_text != re.sub(r"<!--.*?-->", "", MIMIC_ARM, flags=re.S)
    code, out, err = run(capsys, "evaluate", tmp_path / "b.urdf", short, "--frames",
                         tmp_path / "b.json", "--json")
    assert code == 0, err
    assert json.loads(out)["errors"]["max_mm"] < 1e-6  # noise-free, nominal robot


def test_mimic_column_off_its_rule_is_warned_and_bad_uses_refused(tmp_path, capsys):
    urdf, q, P, full, short = _mimic_files(tmp_path)
    off = np.hstack([q, P])
    off[4, 3] += 0.01  # the finger's column of sample 5 no longer follows j3
    bent = write(tmp_path / "bent.csv", ["j1", "j2", "j3", "finger", "x", "y", "z"], off)
    code, out, err = run(capsys, "evaluate", urdf, bent, "--tip", "ftip", "--fit-frames")
    assert code == 0, err
    assert ("column finger differs from what the URDF's <mimic> makes of j3 (finger = -0.5 j3 "
            "+ 0.1) by up to 0.01 (rad or m, sample 5)") in err
    # held while its master moves: refused, one line, nothing written
    code, out, err = run(capsys, "calibrate", urdf, short, "--tip", "ftip", "--joint-value",
                         "finger=0.3", "--out", tmp_path / "x.urdf")
    assert code == 1 and not (tmp_path / "x.urdf").exists()
    assert err.strip().splitlines() == [
        "kincal: error: --joint-value finger: finger mimics j3 in the URDF (finger = -0.5 j3 "
        f"+ 0.1), which moves in {short}: it cannot be held; drop --joint-value finger (kincal "
        "gives it its value from its master's)"]
    # a mimic joint on the chain whose master is off it, without a column: refused
    side = write(tmp_path / "side.csv", ["side", "x", "y", "z"],
                 np.random.default_rng(2).uniform(-1, 1, (10, 4)))
    code, out, err = run(capsys, "analyze", urdf, side, "--base", "s", "--tip", "s2")
    assert code == 1
    assert "no column for chain joint smimic, which mimics side in the URDF (smimic = 2 side " \
           "+ 0), a joint off the chain" in err


def test_commands_that_treat_chain_joints_as_free_refuse_a_coupled_mimic(tmp_path, capsys):
    """compensate solves for every chain joint, simulate draws them: with the finger
    mimicking j3 on the same chain, their joint values would break the URDF's rule (the
    robot moves the finger with j3), so they refuse in one line, writing nothing (compensate
    wrote joint values 'reached' whose finger was off its rule by up to 4 deg for targets
    5 mm off the seeds); simulate at given poses still runs."""
    urdf, q, P, full, short = _mimic_files(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = run(capsys, "simulate", urdf, "--tip", "ftip", "--out",
                         tmp_path / "sim.csv", "--center-m", "0.3", "0.1", "0.6")
    assert code == 1 and err.strip().splitlines() == [
        "kincal: error: finger mimics j3 in the URDF (finger = -0.5 j3 + 0.1), both on the "
        "chain base_link -> ftip: drawing simulated poses treats every chain joint as free and "
        "would break that rule; choose a chain without the mimic joint (e.g. a tip before "
        "finger)"]
    assert main(["calibrate", str(urdf), str(full), "--tip", "ftip", "--model", "placement",
                 "--lambda", "0.001", "--tool-offset", "0.01", "0.02", "0.03", "--out",
                 str(tmp_path / "c.urdf"), "--frames-out", str(tmp_path / "f.json"), "-q"]) == 0
    capsys.readouterr()
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = run(capsys, "compensate", tmp_path / "c.urdf", full, "--frames",
                         tmp_path / "f.json", "--out", tmp_path / "j.csv")
    assert code == 1 and "compensation (its joint values solved for) treats every " \
        "chain joint as free" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    code, out, err = run(capsys, "plan", urdf, "--tip", "ftip", "--random", "50", "--poses",
                         "5", "--out", tmp_path / "plan.csv")
    assert code == 1 and "drawing random candidates treats every chain joint" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    # given poses are the file's own values (calibrate checks them): simulated at them
    poses = write(tmp_path / "poses.csv", ["j1", "j2", "j3", "finger"], q)
    code, out, err = run(capsys, "simulate", urdf, "--tip", "ftip", "--poses-file", poses,
                         "--out", tmp_path / "sim.csv")
    assert code == 0, err


def test_mimic_column_off_its_rule_is_warned_through_the_python_api(tmp_path):
    """Measurements.from_csv + calibrate on a file whose mimic finger column breaks the
    URDF's rule: warned as the command line warns (the problem checks every set; before,
    only the command line's reader did, and the API calibrated the bent column without a
    word into a URDF whose reader computes the finger from j3)."""
    from kincal import Measurements, calibrate
    from kincal.errors import KincalWarning
    from kincal.robot import Robot

    urdf, q, P, full, short = _mimic_files(tmp_path)
    off = np.hstack([q, P])
    off[4, 3] += 0.05
    bent = write(tmp_path / "bent.csv", ["j1", "j2", "j3", "finger", "x", "y", "z"], off)
    robot = Robot.load(urdf, tip="ftip")
    with pytest.warns(KincalWarning, match=r"bent.csv: column finger differs from what the "
                      r"URDF's <mimic> makes of j3 .* by up to 0.05 \(rad or m, sample 5\)"):
        calibrate(robot, Measurements.from_csv(bent, robot.joint_names), model="placement",
                  lam=0.001, tool_guess=(0.01, 0.02, 0.03))


def test_compensation_api_refuses_a_coupled_mimic(tmp_path):
    """compensate() and filter_program() on the arm whose finger mimics j3 on the same
    chain: refused in one line, as kincal compensate refuses (before, the API returned joint
    values it called reached whose finger was off the URDF's rule by up to 12 deg, targets
    5 mm off the data)."""
    from kincal import Measurements, calibrate
    from kincal.compensation import compensate, filter_program, read_targets
    from kincal.errors import OptionError
    from kincal.robot import Robot

    urdf, q, P, full, short = _mimic_files(tmp_path)
    robot = Robot.load(urdf, tip="ftip")
    result = calibrate(robot, Measurements.from_csv(full, robot.joint_names),
                       model="placement", lam=0.001, tool_guess=(0.01, 0.02, 0.03))
    moved = P + np.random.default_rng(3).normal(0, 0.005, P.shape)
    targets = read_targets(write(tmp_path / "t.csv", ["j1", "j2", "j3", "finger", "x", "y",
                                                      "z"], np.hstack([q, moved])),
                           result.corrected)
    says = (r"finger mimics j3 in the URDF \(finger = -0.5 j3 \+ 0.1\), both on the chain "
            r"base_link -> ftip: compensation \(its joint values solved for\) treats every")
    with pytest.raises(OptionError, match=says):
        compensate(result.corrected, result.frames(), targets)
    with pytest.raises(OptionError, match=says):
        filter_program(robot, result.corrected, q + 0.05, result.frames())


def test_drawing_joint_values_through_the_api_refuses_a_coupled_mimic(tmp_path):
    """random_candidates, volume_candidates and cube_poses draw every chain joint
    independently: on the arm whose finger mimics j3 they refuse, as kincal plan and
    kincal simulate refused alone (before, the API drew poses that break the URDF's rule,
    which the robot follows, without a word)."""
    from kincal.errors import OptionError
    from kincal.planning.candidates import random_candidates
    from kincal.planning.simulation import cube_poses
    from kincal.planning.volume_candidates import Volume, VolumeSpec, volume_candidates
    from kincal.robot import Robot

    urdf, *_ = _mimic_files(tmp_path)
    robot = Robot.load(urdf, tip="ftip")
    says = r"finger mimics j3 in the URDF .* treats every chain joint as free"
    with pytest.raises(OptionError, match="drawing random candidates treats every chain joint"):
        random_candidates(robot, 20, 0)
    with pytest.raises(OptionError, match=says):
        volume_candidates(robot, VolumeSpec(Volume.cube((0.3, 0.1, 0.6), 0.05)), 20)
    with pytest.raises(OptionError, match=says):
        cube_poses(robot, 20, (0.3, 0.1, 0.6), 0.05, np.zeros(3), np.random.default_rng(0))
    below = Robot.load(urdf, tip="l3")  # the chain without the finger: drawn as ever
    assert random_candidates(below, 5, 0).shape == (5, 3)


def test_contact_simulation_refuses_a_coupled_mimic_even_at_given_poses(tmp_path, capsys):
    """Simulated plane contacts and flush touches move every chain joint onto the planes
    (and draw more candidates beside the given poses): on a chain holding a mimic joint and
    its master that breaks the URDF's rule, so they refuse in one line, writing nothing
    (before: written, the finger off its rule)."""
    urdf, q, P, full, short = _mimic_files(tmp_path)
    poses = write(tmp_path / "poses.csv", ["j1", "j2", "j3", "finger"], q)
    for kind in ("plane", "flush"):
        out = tmp_path / f"{kind}.csv"
        code, _, err = run(capsys, "simulate", urdf, "--tip", "ftip", "--poses-file", poses,
                           "--kind", kind, "--out", out)
        assert code == 1 and err.count("kincal: error:") == 1, err
        assert "finger mimics j3" in err and "simulating contacts" in err
        assert not out.exists()


def _held_calibration(tmp_path, capsys):
    """(without, with_column, header, rows, urdf, frames): 30 simulated EC66 points with
    joint_6 held at 30 deg, calibrated from the file without its column (--joint-value)."""
    header, rows = simulated(tmp_path, capsys)
    k = header.index("joint_6")
    rows[:, k] = np.radians(30.0)
    with_column = write(tmp_path / "with.csv", header, rows)
    without = write(tmp_path / "without.csv", header[:k] + header[k + 1:],
                    np.delete(rows, k, axis=1))
    code, out, err = run(capsys, "calibrate", "ec66", without, "--model", "offsets", "--fix",
                         "joint_6.theta", "--lambda", 0, "--joint-value",
                         f"joint_6={float(np.radians(30.0))!r}", "--out", tmp_path / "b.urdf",
                         "--frames-out", tmp_path / "b.json")
    assert code == 0, err
    return without, with_column, header, rows, tmp_path / "b.urdf", tmp_path / "b.json"


def test_evaluate_reads_a_file_without_the_held_column_at_the_recorded_value(tmp_path, capsys):
    """evaluate --frames on a file of the same logger (no joint_6 column): the value
    FRAMES.json records applies, said in the output and the report (before: refused,
    'missing column(s) joint_6', the user had to repeat the value)."""
    without, with_column, header, rows, urdf, frames = _held_calibration(tmp_path, capsys)
    code, out, err = run(capsys, "evaluate", urdf, without, "--frames", frames, "--report",
                         tmp_path / "r.json")
    assert code == 0, err
    assert (f"joints held during the measurements (not in the file): joint_6 = 30 deg (as "
            f"{frames} records)") in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["fixed_joints"] == {"joint_6": np.radians(30.0)}
    assert report["fixed_joints_source"] == {"joint_6": str(frames)}
    code, ref, err = run(capsys, "evaluate", urdf, with_column, "--frames", frames)
    assert code == 0 and "differs" not in err, err  # the column at the held value: silent
    assert out.splitlines()[1] == ref.splitlines()[1]  # the same errors as with the column


def test_evaluate_warns_where_the_held_joint_differs_from_frames_json(tmp_path, capsys):
    """An explicit --joint-value still wins, warned when it differs from the recorded value
    (both in degrees); a file with a column for the held joint is read as it is, warned
    when its values stray from the held value (before: the first silently, the second
    without a word)."""
    without, with_column, header, rows, urdf, frames = _held_calibration(tmp_path, capsys)
    code, out, err = run(capsys, "evaluate", urdf, without, "--frames", frames,
                         "--joint-value", "joint_6=32", "--angle-unit", "deg", "--json")
    assert code == 0, err
    assert ("--joint-value joint_6 = 32 deg differs from its value held during the calibration "
            f"(joint_6 = 30 deg, as {frames} records): the given value is used") in err
    report = json.loads(out)
    assert report["fixed_joints"] == {"joint_6": pytest.approx(np.radians(32.0))}
    assert report["fixed_joints_source"] == {"joint_6": "--joint-value"}
    assert report["errors"]["max_mm"] > 1  # 2 deg on the wrist: the tool point moved
    moved = rows.copy()
    moved[3:, header.index("joint_6")] = np.radians(31.0)
    off = write(tmp_path / "off.csv", header, moved)
    code, out, err = run(capsys, "evaluate", urdf, off, "--frames", frames)
    assert code == 0, err
    assert (f"{off}: column joint_6 differs from its value held during the calibration "
            f"(joint_6 = 30 deg, as {frames} records) in 27 of 30 rows, by up to 1 deg (line 5): "
            "its values are read as they are") in " ".join(err.split())


def test_calibrate_validate_reads_the_held_out_file_as_evaluate_does(tmp_path, capsys):
    """calibrate --validate judges the held-out file as evaluate --frames does (one path):
    without the held joint's column it gets the training's held value; with the column it
    is read as it is, warned where it strays (before: refused, 'has a column for joint_6,
    also given with --joint-value', although --joint-value described the training file)."""
    header, rows = simulated(tmp_path, capsys)
    k = header.index("joint_6")
    rows[:, k] = np.radians(30.0)
    train = write(tmp_path / "train.csv", header[:k] + header[k + 1:],
                  np.delete(rows[:20], k, axis=1))
    held_out = rows[20:].copy()
    held_out[:, k] = np.radians(31.0)
    off = write(tmp_path / "off.csv", header, held_out)
    code, out, err = run(capsys, "calibrate", "ec66", train, "--model", "offsets", "--fix",
                         "joint_6.theta", "--lambda", 0, "--joint-value",
                         f"joint_6={float(np.radians(30.0))!r}", "--validate", off, "--out",
                         tmp_path / "c.urdf")
    assert code == 0, err
    assert (f"{off}: column joint_6 differs from its value held during the calibration "
            "(joint_6 = 30 deg, as the calibration records) in 10 of 10 rows, by up to 1 deg "
            "(line 2): its values are read as they are") in " ".join(err.split())


def test_compensate_holds_the_joints_the_calibration_held(tmp_path, capsys):
    """kincal compensate with FRAMES.json recording joint_6 held at 30 deg: the targets file
    may leave its column out, the inverse kinematics keeps it at 30 deg and reaches the
    targets with the other joints, a note says so; a column at another value is warned
    about and the held value used; the --program path alike (before: 'missing column
    joint_6', and with the column the solver moved the held wrist)."""
    without, with_column, header, rows, urdf, frames = _held_calibration(tmp_path, capsys)
    k = header.index("joint_6")
    keep = [i for i, h in enumerate(header) if h.startswith("joint_") or h in "xyz"]
    targets = rows[:10, keep].copy()
    targets[:, -3:] += np.random.default_rng(5).normal(0, 0.002, (10, 3))  # 2 mm off the data
    out = tmp_path / "j.csv"
    names = [header[i] for i in keep]
    short = write(tmp_path / "t.csv", [h for h in names if h != "joint_6"],
                  np.delete(targets, names.index("joint_6"), axis=1))
    code, said, err = run(capsys, "compensate", urdf, short, "--frames", frames, "--out", out,
                          "--json")
    assert code == 0, err
    summary = json.loads(said)
    assert summary["reached"] == 10
    assert (f"held where the calibration held them (joint_6 = 30 deg, as {frames} records)"
            in summary["notes"][-1])
    q = np.array(summary["joint_values_si"])
    np.testing.assert_array_equal(q[:, 5], np.radians(30.0))
    assert np.abs(q[:, :5] - targets[:, :5]).max() > 1e-4  # the other joints moved
    wrong = targets.copy()
    wrong[:, names.index("joint_6")] = np.radians(40.0)
    full = write(tmp_path / "full.csv", names, wrong)
    code, said, err = run(capsys, "compensate", urdf, full, "--frames", frames, "--out", out,
                          "--json", "--overwrite")
    assert code == 0, err
    assert (f"{full}: column joint_6 differs from its value held during the calibration "
            f"(joint_6 = 30 deg, as {frames} records) in 10 of 10 rows, by up to 10 deg (line 2):"
            " the held value is used") in " ".join(err.split())
    np.testing.assert_array_equal(np.array(json.loads(said)["joint_values_si"])[:, 5],
                                  np.radians(30.0))
    program = write(tmp_path / "p.csv", [h for h in header[:k] if h.startswith("joint_")],
                    rows[:10, [i for i in range(k) if header[i].startswith("joint_")]])
    code, said, err = run(capsys, "compensate", urdf, "--program", program, "--nominal", "ec66",
                          "--frames", frames, "--out", out, "--json", "--overwrite")
    assert code == 0, err
    summary = json.loads(said)
    assert summary["reached"] == 10 and "held where the calibration held" in summary["notes"][1]
    np.testing.assert_array_equal(np.array(summary["joint_values_si"])[:, 5], np.radians(30.0))


def test_program_filter_with_a_held_joint_meets_the_positions(tmp_path, capsys):
    """--program with frames whose calibration held joint_6: five joints are free, so the
    nominal poses' orientations are kept as closely as they allow and their tool points met
    (the docstring's "required on six or more joints"). Before, the full pose was required
    because the chain has six joints: every pose of a calibration by the default model
    failed ("20 of 20 targets cannot be reached ... leave the orientation columns out", which
    a program has none of), while the tool points were met to 1e-10 mm."""
    without, with_column, header, rows, urdf, frames = _held_calibration(tmp_path, capsys)
    code, out, err = run(capsys, "calibrate", "ec66", without, "--model", "complete",
                         "--joint-value", f"joint_6={float(np.radians(30.0))!r}", "--out",
                         tmp_path / "c.urdf", "--frames-out", tmp_path / "c.json")
    assert code == 0, err
    joints = [f"joint_{i}" for i in range(1, 6)]
    q = rows[10:25, [header.index(j) for j in joints]] + 0.05
    program = write(tmp_path / "p.csv", joints, q)
    code, said, err = run(capsys, "compensate", tmp_path / "c.urdf", "--program", program,
                          "--nominal", "ec66", "--frames", tmp_path / "c.json", "--out",
                          tmp_path / "j.csv", "--json")
    assert code == 0, err
    summary = json.loads(said)
    assert summary["reached"] == 15 and summary["max_position_error_m"] < 1e-12
    assert 1e-6 < summary["max_orientation_error_rad"] < np.radians(0.5)
    np.testing.assert_array_equal(np.array(summary["joint_values_si"])[:, 5], np.radians(30.0))


def test_pose_targets_with_a_held_joint_say_why_they_fail(tmp_path, capsys):
    """Pose targets on a chain whose wrist the calibration held: five free joints cannot
    meet a full pose, and the refusal said the targets missed "within 0.001 mm" while the
    tool point was 1e-12 mm off. It names the orientation tolerance and the held joint."""
    from scipy.spatial.transform import Rotation

    from kincal import Robot

    without, with_column, header, rows, urdf, frames = _held_calibration(tmp_path, capsys)
    robot = Robot.load(urdf, tip="flange")
    q = rows[:5, [header.index(j) for j in robot.joint_names]].copy()
    f = json.loads(frames.read_text())["sets"][0]["frames"]
    R_base = Rotation.from_euler("XYZ", [f[f"base.r{a}"] for a in "xyz"]).as_matrix()
    wanted = R_base @ robot.tip_poses(q)[:, :3, :3] @ Rotation.from_rotvec(
        [0.0, 0.01, 0.0]).as_matrix()  # the measured tip, turned 0.57 deg about its y axis
    cols = [j for j in robot.joint_names if j != "joint_6"] + ["x", "y", "z", "qx", "qy",
                                                                "qz", "qw"]
    targets = write(tmp_path / "poses.csv", cols, np.hstack(
        [q[:, :5], rows[:5, [header.index(c) for c in "xyz"]],
         Rotation.from_matrix(wanted).as_quat()]))
    code, out, err = run(capsys, "compensate", urdf, targets, "--frames", frames, "--out",
                         tmp_path / "j.csv")
    assert code == 1 and err.count("\n") == 1, err
    assert "within 0.001 mm and 5.73e-05 deg; a full pose needs six free joints, this chain " \
           "has 5 (1 held where the calibration held them" in err, err
    assert not (tmp_path / "j.csv").exists()


def test_compensation_api_holds_the_joints_the_frames_record_held(tmp_path, capsys):
    """compensate() and filter_program() with the CellFrames of a calibration that held
    joint_6: the solution keeps it at its held value (seeds elsewhere warned about); before,
    the solver moved it from the seed's value without a word."""
    from kincal.compensation import Targets, compensate, filter_program
    from kincal.errors import KincalWarning
    from kincal.robot import Robot

    without, with_column, header, rows, urdf, path = _held_calibration(tmp_path, capsys)
    frames = CellFrames.read(path)
    robot = Robot.load(urdf, tip=frames.tip_frame)
    joints = [header.index(f"joint_{i}") for i in range(1, 7)]
    seeds = rows[:8, joints].copy()
    seeds[:, 5] = 0.0
    positions = rows[:8, [header.index(c) for c in "xyz"]] + 0.002
    with pytest.warns(KincalWarning, match="column joint_6 differs from its value held during "
                      r"the calibration \(joint_6 = 30 deg"):
        result = compensate(robot, frames, Targets(seeds, positions, None, np.arange(2, 10)))
    assert result.reached.all() and not result.at_limit.any()
    np.testing.assert_array_equal(result.joint_values[:, 5], np.radians(30.0))
    with pytest.warns(KincalWarning, match="column joint_6 differs"):
        result = filter_program(Robot.load("ec66", tip=frames.tip_frame), robot, seeds, frames)
    assert result.reached.all()
    np.testing.assert_array_equal(result.joint_values[:, 5], np.radians(30.0))
