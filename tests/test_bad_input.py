"""Shop-floor input: every failure clear, every output safe (one test per bad input)."""

import time
import warnings

import numpy as np
import pytest
from conftest import EC66, random_joint_values

from kincal.cli.main import main
from kincal.errors import IdentifiabilityError, KincalWarning
from kincal.identification.problem import calibrate
from kincal.measurements.data import Measurements
from kincal.models import mdh
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot

HEADER = "joint_1,joint_2,joint_3,joint_4,joint_5,joint_6,x,y,z"


def _simulated_ec66(seed, n, noise):
    """(robot, measurements, rng) of a simulated EC66 with planted errors, n random poses."""
    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, n)
    truth = Truth(planted_table(model, rng), np.array([0.5, 0.1, 0.2, 0.0, 0.0, 0.3]),
                  np.array([0.03, 0.02, 0.12]))
    return robot, measure(model, truth, q, noise, rng), rng


@pytest.fixture(scope="module")
def good_csv(tmp_path_factory):
    _, data, _ = _simulated_ec66(0, 30, 1e-5)
    path = tmp_path_factory.mktemp("data") / "good.csv"
    path.write_text(data.to_csv_text())
    return path


def _run(args, tmp_path, capsys):
    """Run 'kincal calibrate' expecting failure; return the one error line."""
    out = tmp_path / "out.urdf"
    code = main(["calibrate", *args, "--out", str(out), "--report", str(tmp_path / "r.json")])
    err = capsys.readouterr().err.strip().splitlines()
    lines = [e for e in err if e.startswith("kincal: error:")]
    assert code == 1 and len(lines) == 1, err
    assert not any("Traceback" in e for e in err)
    assert not out.exists() and not (tmp_path / "r.json").exists()
    return lines[0]


def _csv(tmp_path, text, name="bad.csv"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _rows(good_csv, n=None):
    return good_csv.read_text().splitlines()[1:n]


# --------------------------------------------------------------------- files
def test_missing_urdf(tmp_path, capsys, good_csv):
    assert "not found" in _run([str(tmp_path / "robot.urdf"), str(good_csv), "--tip", "flange"],
                               tmp_path, capsys)


def test_unreadable_urdf_is_a_directory(tmp_path, capsys, good_csv):
    d = tmp_path / "robot.urdf"
    d.mkdir()
    assert "directory" in _run([str(d), str(good_csv), "--tip", "flange"], tmp_path, capsys)


def test_malformed_urdf(tmp_path, capsys, good_csv):
    bad = _csv(tmp_path, EC66.read_text().replace("</joint>", "</jiont>", 1), "bad.urdf")
    line = _run([bad, str(good_csv), "--tip", "flange"], tmp_path, capsys)
    assert "bad.urdf:23:5" in line and "mismatched tag" in line


def test_entity_bomb_is_rejected_fast(tmp_path, capsys, good_csv):
    lol = "".join(f'<!ENTITY l{i} "{"&l%d;" % (i - 1) * 10}">' for i in range(1, 10))
    bomb = ('<?xml version="1.0"?><!DOCTYPE robot [<!ENTITY l0 "lol">' + lol + ']>'
            '<robot name="&l9;"><link name="a"/></robot>')
    t = time.perf_counter()
    line = _run([_csv(tmp_path, bomb, "bomb.urdf"), str(good_csv), "--tip", "a"], tmp_path, capsys)
    assert time.perf_counter() - t < 5.0
    assert "entit" in line.lower() or "doctype" in line.lower()


def test_xacro_that_does_not_expand(tmp_path, capsys, good_csv):
    # xacro is expanded (tests/test_xacro.py); one that cannot be is one line naming why
    text = EC66.read_text().replace('<robot name="ec66">',
                                    '<robot name="ec66" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                                    '<xacro:property name="d1" value="${d0 * 2}"/>'
                                    '<link name="x${d1}"/>')
    line = _run([_csv(tmp_path, text, "x.urdf"), str(good_csv), "--tip", "flange"], tmp_path, capsys)
    assert "xacro expansion failed" in line and "d0" in line


def test_missing_csv(tmp_path, capsys):
    assert "not found" in _run(["ec66", str(tmp_path / "none.csv")], tmp_path, capsys)


# ------------------------------------------------------------------- columns
def test_missing_column(tmp_path, capsys, good_csv):
    text = good_csv.read_text().replace(",z\n", "\n", 1)
    text = "\n".join([text.splitlines()[0]] + [",".join(r.split(",")[:-1]) for r in text.splitlines()[1:]])
    assert "missing column(s) z" in _run(["ec66", _csv(tmp_path, text)], tmp_path, capsys)


def test_misspelled_column_suggests(tmp_path, capsys, good_csv):
    text = good_csv.read_text().replace("joint_4", "jiont_4", 1)
    line = _run(["ec66", _csv(tmp_path, text)], tmp_path, capsys)
    assert "joint_4" in line and "Did you mean 'jiont_4'" in line
    assert "--joint-value" not in line  # a misspelt column, not a joint held still


def test_a_joint_not_logged_points_to_joint_value(tmp_path, capsys, good_csv):
    """A chain joint without a column (held still, so the logger left it out): the refusal
    names the option that gives its value (issue 23: it said 'missing column' alone)."""
    rows = [r.split(",") for r in good_csv.read_text().splitlines() if not r.startswith("#")]
    k = rows[0].index("joint_6")
    text = "\n".join(",".join(c for i, c in enumerate(r) if i != k) for r in rows) + "\n"
    line = _run(["ec66", _csv(tmp_path, text)], tmp_path, capsys)
    assert "missing column(s) joint_6" in line and "(--joint-value joint_6=VALUE)" in line
    for kind in (["--on-plane"], ["--on-plane", "--flush"]):  # the other kinds' reader
        plane = "\n".join(",".join(c for i, c in enumerate(r) if i != k)
                           for r in (r[:6] for r in rows)) + "\n"
        line = _run(["ec66", _csv(tmp_path, plane, "p.csv"), *kind], tmp_path, capsys)
        assert "(--joint-value joint_6=VALUE)" in line, line


def test_duplicated_column(tmp_path, capsys, good_csv):
    text = good_csv.read_text().replace("joint_5", "joint_4", 1)
    assert "duplicated column(s) joint_4" in _run(["ec66", _csv(tmp_path, text)], tmp_path, capsys)


def test_extra_columns_are_ignored_and_reported(good_csv, tmp_path):
    lines = good_csv.read_text().splitlines()
    text = "\n".join([lines[0] + ",temperature"] + [r + ",21.5" for r in lines[1:]])
    data = Measurements.from_csv(_csv(tmp_path, text), tuple(HEADER.split(",")[:6]))
    assert data.ignored_columns == ("temperature",) and len(data) == 30


@pytest.mark.parametrize("cell,expected", [("nan", "'nan'"), ("inf", "'inf'"), ("", "empty cell"),
                                           ("12,5", "cells"), ("abc", "'abc'")])
def test_bad_cells_name_line_and_column(cell, expected, tmp_path, capsys, good_csv):
    rows = _rows(good_csv)
    parts = rows[4].split(",")
    parts[7] = cell  # column y of the 5th sample, line 6 of the file
    rows[4] = ",".join(parts)
    line = _run(["ec66", _csv(tmp_path, "\n".join([HEADER] + rows))], tmp_path, capsys)
    assert "line 6" in line and expected in line


def test_empty_file(tmp_path, capsys):
    assert "empty" in _run(["ec66", _csv(tmp_path, "")], tmp_path, capsys)


# --------------------------------------------------------------------- poses
def test_too_few_poses_says_how_many(tmp_path, capsys, good_csv):
    text = "\n".join([HEADER] + _rows(good_csv, 6))
    line = _run(["ec66", _csv(tmp_path, text), "--method", "ls"], tmp_path, capsys)
    assert "needs at least 10 poses" in line and "27 parameters" in line  # complete model


def test_identical_poses_name_what_cannot_be_identified(tmp_path, capsys, good_csv):
    row = _rows(good_csv, 2)[0]
    text = "\n".join([HEADER] + [row] * 12)
    line = _run(["ec66", _csv(tmp_path, text), "--method", "ls"], tmp_path, capsys)
    assert "cannot even locate the measurement frame" in line and "1 distinct poses of 12" in line
    assert "tool." in line


def test_nearly_identical_poses_via_api():
    rng = np.random.default_rng(1)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = np.tile(random_joint_values(robot.geometry, rng, 1), (20, 1)) + rng.normal(size=(20, 6)) * 1e-9
    data = measure(model, Truth(model.table, np.zeros(6), np.array([0.05, 0, 0.1])), q, 1e-5, rng)
    with pytest.raises(IdentifiabilityError, match="base"):
        calibrate(robot, data, method="ls")


# --------------------------------------------------------------------- units
def _warnings_of(fn):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            fn()
        except Exception:
            pass
    return [str(w.message) for w in caught if issubclass(w.category, KincalWarning)]


def test_millimetres_read_as_metres_warn(good_csv, tmp_path):
    lines = good_csv.read_text().splitlines()
    rows = []
    for r in lines[1:]:
        v = r.split(",")
        rows.append(",".join(v[:6] + [repr(float(x) * 1000) for x in v[6:]]))
    path = _csv(tmp_path, "\n".join([lines[0]] + rows))
    robot = Robot.load("ec66")
    data = Measurements.from_csv(path, robot.joint_names)
    msgs = _warnings_of(lambda: calibrate(robot, data, method="ls"))
    assert any("were they millimetres" in m for m in msgs)
    data_mm = Measurements.from_csv(path, robot.joint_names, length_unit="mm")
    assert not any("millimetres" in m for m in _warnings_of(lambda: calibrate(robot, data_mm, method="ls")))


def test_metres_read_as_millimetres_warn(good_csv):
    robot = Robot.load("ec66")
    data = Measurements.from_csv(good_csv, robot.joint_names, length_unit="mm")
    msgs = _warnings_of(lambda: calibrate(robot, data, method="ls"))
    assert any("metres read as millimetres" in m for m in msgs)


def test_degrees_read_as_radians_warn(good_csv, tmp_path):
    lines = good_csv.read_text().splitlines()
    rows = [",".join([repr(float(np.degrees(float(x)))) for x in r.split(",")[:6]] + r.split(",")[6:])
            for r in lines[1:]]
    path = _csv(tmp_path, "\n".join([lines[0]] + rows))
    robot = Robot.load("ec66")
    data = Measurements.from_csv(path, robot.joint_names)
    assert any("were they degrees" in m for m in _warnings_of(lambda: calibrate(robot, data, method="ls")))


def test_joint_values_outside_limits_warn(good_csv, tmp_path):
    lines = good_csv.read_text().splitlines()
    v = lines[3].split(",")
    v[2] = "3.0"  # joint_3 is limited to +-2.827 rad
    lines[3] = ",".join(v)
    robot = Robot.load("ec66")
    data = Measurements.from_csv(_csv(tmp_path, "\n".join(lines)), robot.joint_names)
    msgs = _warnings_of(lambda: calibrate(robot, data, method="ls"))
    assert any("joint_3: 1 of 30 values outside its URDF limits" in m and "line 4" in m for m in msgs)



def test_degrees_everywhere_give_one_limits_warning_after_the_unit_hint(good_csv, tmp_path):
    """A whole file in degrees puts every joint outside its limits: one warning naming the
    worst three (not one per joint), after the hint that names the cause."""
    lines = good_csv.read_text().splitlines()
    rows = [",".join([repr(float(np.degrees(float(x)))) for x in r.split(",")[:6]] + r.split(",")[6:])
            for r in lines[1:]]
    robot = Robot.load("ec66")
    data = Measurements.from_csv(_csv(tmp_path, "\n".join([lines[0]] + rows)), robot.joint_names)
    msgs = [m for m in _warnings_of(lambda: calibrate(robot, data, method="ls"))
            if "URDF limits" in m or "were they degrees" in m]
    assert len(msgs) == 2 and "were they degrees" in msgs[0], msgs
    assert msgs[1].count("values outside its URDF limits") == 3 and "more joints" in msgs[1]

# ------------------------------------------------------------------ outliers
def test_robust_loss_lists_and_resists_outliers():
    robot, data, rng = _simulated_ec66(2, 60, 2e-5)
    q = data.joint_values
    P = np.array(data.positions)
    bad = [3, 17, 40]
    P[bad] += rng.normal(size=(3, 3)) * 3e-3  # lost tracker lock: mm-size errors
    dirty = Measurements(data.joint_names, q, P)
    plain = calibrate(robot, dirty, method="ls")
    robust = calibrate(robot, dirty, method="ls", robust="cauchy")
    assert plain.downweighted == ()
    assert sorted(d.row for d in robust.downweighted) == [k + 2 for k in bad]  # file lines
    clean = calibrate(robot, data, method="ls")
    k = plain.space.index("joint_4.a")
    assert abs(robust.x[k] - clean.x[k]) < 0.2 * abs(plain.x[k] - clean.x[k])
    assert "robust loss cauchy: 3 samples down-weighted below 0.5: line 19 (" in robust.summary()
    assert len(dirty) == 60  # nothing dropped from the user's data
    # clean data: no sample down-weighted, said so (the line ended "below 0.5: " and nothing)
    quiet = calibrate(robot, data, method="ls", robust="huber")
    assert quiet.downweighted == ()
    assert "robust loss huber: no sample down-weighted below 0.5\n" in quiet.summary()


@pytest.mark.parametrize("kind", ["flush", "plane", "point"])
def test_radians_read_as_degrees_are_named_for_every_kind(kind, tmp_path):
    """Joint values in radians read with --angle-unit deg: every value within +-6.8 'deg' of
    zero. The hint was given for point files only (the other kinds did not keep the unit
    the file was read in), and only when the values spanned under 3 deg."""
    from kincal.measurements.checks import set_warnings
    from kincal.measurements.sets import read_set_file

    robot = Robot.load("ec66")
    rng = np.random.default_rng(0)
    lo, hi = robot.geometry.ranges()
    q = rng.uniform(np.maximum(lo, -2.5), np.minimum(hi, 2.5), (20, robot.geometry.n))
    cols = list(robot.joint_names) + (["x", "y", "z"] if kind == "point" else [])
    rows = np.hstack([q, rng.normal(size=(20, 3))]) if kind == "point" else q
    path = _csv(tmp_path, "\n".join([",".join(cols)] + [",".join(map(repr, r.tolist()))
                                                        for r in rows]))
    data = read_set_file(path, robot.joint_names, angle_unit="deg", on_plane=kind != "point",
                         flush=kind == "flush")
    said = set_warnings(data, robot.geometry)
    assert any("were they radians? Drop --angle-unit deg" in m for m in said), said
    assert not any("radians" in m for m in set_warnings(
        read_set_file(path, robot.joint_names, on_plane=kind != "point", flush=kind == "flush"),
        robot.geometry))
