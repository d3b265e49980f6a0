"""Numeric options, bounded: a value far beyond a robot cell (a kilometre cube, a tolerance or
a penalty no data set can answer, 10^9 rounds) is refused with one ``kincal: error:`` line
naming the option, the value and the accepted range in the option's unit, and nothing is
written. Each bound has one home (the API's constant the command line reads): the line
quotes it. A value that has a meaning keeps it (a tilt direction of any finite length).

Each case was accepted before: ``compensate --tolerance-mm 1e308`` counted every seed as
reached, ``--accuracy-map`` over a 10,000 km cube wrote its result, a 1e308 tilt direction
overflowed into "the arm cannot reach the centre"."""

import math
import shutil

import numpy as np
import pytest

from kincal.cli.main import main
from kincal.compensation.ik import POSITION_TOLERANCE_RANGE, IkOptions
from kincal.errors import OptionError
from kincal.fleet.fleet import MAX_ROUNDS
from kincal.frames_file import MAX_LENGTH
from kincal.identification.options import MAX_LAMBDA, CalibrationOptions

from test_cli_refusals import refused


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    for seed, name in (("0", "points.csv"), ("5", "unit2.csv")):
        assert main(["simulate", "ec66", "--out", str(d / name), "--poses", "30", "--seed",
                     seed, "--tool-m", "0.03", "0.02", "0.12", "-q"]) == 0
    assert main(["calibrate", "ec66", str(d / "points.csv"), "--method", "ls", "--quiet",
                 "--out", str(d / "cal.urdf"), "--frames-out", str(d / "frames.json")]) == 0
    return d


@pytest.fixture
def work(inputs, tmp_path, monkeypatch):
    for name in ("points.csv", "unit2.csv", "cal.urdf", "frames.json"):
        shutil.copy2(inputs / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


CAL = ["calibrate", "ec66", "points.csv", "--out", "c.urdf"]
AN = ["analyze", "ec66", "points.csv", "--report", "a.json"]
PLAN = ["plan", "ec66", "--random", "60", "--poses", "10", "--out", "p.csv"]
VOLUME = PLAN + ["--in-cube", "0.5", "0", "0.3", "0.3"]
SIM = ["simulate", "ec66", "--out", "s.csv", "--poses", "5"]
COMP = ["compensate", "cal.urdf", "points.csv", "--tip", "flange", "--frames", "frames.json",
        "--out", "j.csv", "--flag-unreachable"]
FLEET = ["fleet", "ec66", "points.csv", "unit2.csv", "--out-dir", "D"]
KM = f"{MAX_LENGTH:g} m"  # the one bound of a length in the cell

# (argv, the option as the line names it, the value as printed, the range as printed)
CASES = [
    (COMP + ["--tolerance-mm", "1e308"], "--tolerance-mm", "1e+308",
     f"<= {POSITION_TOLERANCE_RANGE[1] * 1e3:g} mm"),
    (COMP + ["--tolerance-mm", "1e-300"], "--tolerance-mm", "1e-300",
     f">= {POSITION_TOLERANCE_RANGE[0] * 1e3:g}"),
    (CAL + ["--lambda", "1e308"], "--lambda", "1e+308", f"<= {MAX_LAMBDA:g}"),
    (FLEET + ["--lambda", "1e13"], "--lambda", "1e+13", f"<= {MAX_LAMBDA:g}"),
    (CAL + ["--robust", "huber", "--robust-scale-mm", "1e7"], "--robust-scale-mm", "1e+07",
     "<= 1000 mm"),
    (CAL + ["--accuracy-map", "0.5", "0", "0.3", "1e7"], "--accuracy-map EDGE", "1e+07",
     f"<= {MAX_LENGTH:g} m"),
    (AN + ["--accuracy-map", "0.5", "0", "0.3", "2e6", "--length-unit", "mm"],
     "--accuracy-map EDGE", "2e+06", f"<= {MAX_LENGTH * 1e3:g} mm"),
    (AN + ["--accuracy-map", "1e308", "0", "0.3", "0.2"], "--accuracy-map CX CY CZ", "1e+308",
     f"<= {MAX_LENGTH:g} m"),
    (PLAN + ["--in-cube", "0.5", "0", "0.3", "2000"], "--in-cube EDGE", "2000", KM),
    (PLAN + ["--in-sphere", "0.5", "0", "0.3", "1e7"], "--in-sphere R", "1e+07", KM),
    (PLAN + ["--in-cube", "0.5", "5000", "0.3", "0.3"], "--in-cube CX CY CZ", "5000", KM),
    (VOLUME + ["--target-cube", "0.5", "0", "0.3", "1e308"], "--target-cube EDGE", "1e+308", KM),
    (VOLUME + ["--floor", "-1500"], "--floor", "-1500", KM),
    (PLAN + ["--kind", "distance", "--pivot", "0", "1e308", "0"], "--pivot", "1e+308", KM),
    (SIM + ["--in-sphere", "0.5", "0", "0.3", "1e308"], "--in-sphere R", "1e+308", KM),
    (SIM + ["--base-frame", "0.8", "0.3", "-0.2", "1", "900", "60"], "--base-frame RX RY RZ",
     "900", "<= 360 deg"),
    (FLEET + ["--hierarchical", "1000000000"], "--hierarchical", "1000000000",
     f"<= {MAX_ROUNDS}"),
    (COMP + ["--point", "0"], "--point", "0", ">= 1"),
]


@pytest.mark.parametrize("argv, option, value, bound", CASES,
                         ids=[" ".join(c[0][:1] + c[0][-4:]) for c in CASES])
def test_a_value_beyond_its_range_is_one_line_naming_option_value_and_range(
        work, capsys, argv, option, value, bound):
    line = refused(capsys, argv, work)
    assert f"{option} must be" in line and f"got {value}" in line and bound in line, line


def test_folds_beyond_the_cross_validations_poses_name_both_options(work, capsys):
    """--folds 1e9 was refused as "cv_max_poses must be an integer >= the number of folds
    (1000000000), got 2000": the option given was not named, the one named was not given."""
    line = refused(capsys, CAL + ["--folds", "3000"], work)
    assert "--folds" in line and "3000" in line and "--cv-max-poses" in line, line
    assert "at most 2000 folds" in line, line


def test_a_tilt_direction_counts_by_its_direction_alone(work, capsys):
    """(0, 0, -1e308) is the direction (0, 0, -1): its norm overflowed to inf, the direction
    became zero and the plan said the arm could not reach the volume."""
    chosen = []
    for z in ("-1", "-1" + "0" * 308):  # -1e308, written as argparse takes a negative number
        out = work / f"p{len(chosen)}.csv"
        argv = [a if a != "p.csv" else str(out) for a in VOLUME]
        assert main(argv + ["--tilt-direction", "0", "0", z, "-q"]) == 0
        chosen.append([line for line in out.read_text().splitlines()
                       if not line.startswith("#")])
    assert chosen[0] == chosen[1]


def test_the_api_holds_the_same_bounds():
    """The command line reads these constants; the API refuses beyond them too."""
    from kincal.fleet import calibrate_fleet
    from kincal.planning.accuracy_map import cube_grid
    from kincal.planning.volume_candidates import Volume

    with pytest.raises(OptionError, match="position_tolerance"):
        IkOptions(position_tolerance=POSITION_TOLERANCE_RANGE[1] * 10)
    IkOptions(position_tolerance=POSITION_TOLERANCE_RANGE[1])  # the bound itself is in
    with pytest.raises(OptionError, match="lambda"):
        CalibrationOptions(lam=MAX_LAMBDA * 10).validated()
    CalibrationOptions(lam=MAX_LAMBDA).validated()
    with pytest.raises(OptionError, match="robust_scale_mm"):
        CalibrationOptions(robust="huber", robust_scale_mm=1e7).validated()
    with pytest.raises(OptionError, match="edge"):
        cube_grid([0.5, 0, 0.3], MAX_LENGTH * 2)
    with pytest.raises(OptionError, match="centre"):
        Volume.sphere([MAX_LENGTH * 2, 0, 0], 0.1)
    with pytest.raises(OptionError, match="rounds"):
        calibrate_fleet(None, [], rounds=MAX_ROUNDS + 1)  # before any engine starts


CONTINUOUS = """<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
<origin xyz="0 0 0.3"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="continuous"><parent link="b"/><child link="c"/><axis xyz="0 1 0"/>
<origin xyz="0.4 0 0"/></joint></robot>"""


def test_a_joint_without_limits_is_held_within_a_data_files_magnitudes(tmp_path):
    """--joint-value of a continuous joint had no bound at all (its URDF limits are
    infinite): 1e308 rad went on as a constant column."""
    from kincal.measurements.data import MAX_ABS_VALUE
    from kincal.measurements.fixed_joints import held_values
    from kincal.robot import Robot

    (tmp_path / "r.urdf").write_text(CONTINUOUS)
    robot = Robot.load(str(tmp_path / "r.urdf"), tip="c")
    assert math.isinf(robot.geometry.upper[1])
    assert held_values(["j2=100"], [robot]) == {"j2": 100.0}  # a meaning: turns and more
    with pytest.raises(OptionError, match=r"j2=1e308.*accepted range.*1e\+06"):
        held_values(["j2=1e308"], [robot])
    assert np.isfinite(MAX_ABS_VALUE)
