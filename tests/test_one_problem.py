"""One problem, one result, one writer (issue 17): a set and a list of one are the same
calibration; the gate guards every writer; the one FRAMES.json schema is validated."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace

import numpy as np
import pytest

from kincal import Measurements, Robot, calibrate
from kincal.cli.main import main
from kincal.errors import DataError, IdentifiabilityError, ImplausibleResultError
from kincal.export.outputs import Outputs, write_calibration
from kincal.frames_file import CellFrames


@pytest.fixture(scope="module")
def rtest(tmp_path_factory):
    folder = tmp_path_factory.mktemp("one")
    path = folder / "rt.csv"
    assert main(["simulate", "ec66", "--design", "rtest", "--out", str(path), "--seed", "1"]) == 0
    robot = Robot.load("ec66")
    return robot, Measurements.from_csv(path, robot.joint_names), folder


def _quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


def test_a_set_and_a_list_of_one_are_the_same_calibration(rtest):
    robot, data, _ = rtest
    a = _quiet(calibrate, robot, data, lam="cv", n_lambdas=8)
    b = _quiet(calibrate, robot, [data], lam="cv", n_lambdas=8)
    assert type(a) is type(b) and len(a.sets) == len(b.sets) == 1
    assert np.array_equal(a.x, b.x) and np.array_equal(a.covariance, b.covariance)
    assert a.lam == b.lam and a.summary() == b.summary()
    assert a.layout.names == b.layout.names and a.plausibility.plausible


def test_the_summary_has_one_shape_for_one_set_or_several(rtest, tmp_path, capsys):
    """One set or two, the command line's summary says the same things once: the notes
    under the identifiable line, the weak parameters once, the dropped ones only with -v
    (the several-set path printed every dropped parameter and the weak list twice)."""
    _, _, folder = rtest
    data = str(folder / "rt.csv")
    copy = tmp_path / "copy.csv"  # the samples again (one file given twice is refused)
    copy.write_text("# a copy\n" + (folder / "rt.csv").read_text())
    shapes = []
    for files, verbose in (([data], []), ([data, str(copy)], []),
                           ([data, str(copy)], ["-v"])):
        out = tmp_path / f"c{len(shapes)}.urdf"
        _quiet(main, ["calibrate", "ec66", *files, "--out", str(out), "--lambda", "evidence",
                      "--accept-implausible", *verbose])
        lines = capsys.readouterr().out.splitlines()
        shapes.append((sum(line.startswith("  weak") for line in lines),
                       sum(line.startswith("  dropped ") for line in lines),
                       sum(line.startswith("  identifiable:") for line in lines)))
    assert shapes[0] == shapes[1] and shapes[0][1] == 0 and shapes[0][2] == 1
    assert shapes[0][0] <= 1 and shapes[2][1] > 0  # -v lists the dropped ones


def test_shuffled_rows_in_a_small_cube_are_refused_in_the_api_and_the_cli(rtest, capsys):
    robot, data, folder = rtest
    shuffled = replace(data, positions=data.positions[np.random.default_rng(0).permutation(
        len(data))])
    for given in (shuffled, [shuffled]):
        result = _quiet(calibrate, robot, given)
        assert not result.plausibility.plausible
        assert "unexplained" in {f.kind for f in result.plausibility.findings}
        out = folder / "c.urdf"
        with pytest.raises(ImplausibleResultError, match="explains only"):
            write_calibration(result, Outputs(urdf=out, frames=folder / "f.json"))
        assert not out.exists() and not (folder / "f.json").exists()
    path = folder / "shuffled.csv"
    path.write_text(shuffled.to_csv_text())
    capsys.readouterr()
    before = sorted(p.name for p in folder.iterdir())
    assert main(["calibrate", "ec66", str(path), "--out", str(folder / "c.urdf")]) == 1
    err = capsys.readouterr().err  # one error line, first (warnings may follow: the
    # shuffled rows' tool point may land near the last axis, as on other BLAS kernels)
    assert err.startswith("kincal: error: implausible calibration")
    assert err.count("kincal: error:") == 1 and err.splitlines()[0].count("kincal:") == 1
    assert sorted(p.name for p in folder.iterdir()) == before


def test_a_calibration_that_identifies_nothing_is_an_error(rtest):
    robot, data, _ = rtest
    # the one kinematic parameter left free, joint_1.theta, is the measurement frame's turn
    fix = ("joint_[2-6].*", "joint_1.a", "joint_1.alpha", "joint_1.d")
    with pytest.raises(IdentifiabilityError, match="identify none of the"):
        _quiet(calibrate, robot, data, fix=fix)
    assert _quiet(calibrate, robot, data, method="frames").converged  # frames alone: fine
    # every kinematic parameter held by fix: the cause is the option, not the data (it said
    # "these data identify none ... check the sets' sigmas ... measure poses that move")
    with pytest.raises(IdentifiabilityError, match=r"^--fix holds all \d+ kinematic parameters "
                       r"\(identifiable: \d+ of \d+\): nothing would be calibrated; fix fewer"):
        _quiet(calibrate, robot, data, fix=("joint_*",))


def test_fixed_tool_point_is_held_at_the_offset_the_start_fit_included(rtest):
    robot, data, _ = rtest
    result = _quiet(calibrate, robot, data, fix=("tool.x", "tool.y", "tool.z"),
                    tool_guess=(0.0, 0.0, 0.01))
    assert np.array_equal(result.tool, [0.0, 0.0, 0.01])
    assert {result.parameter(f"tool.{c}").status for c in "xyz"} == {"fixed"}


def test_frames_file_round_trip_and_older_versions(rtest, tmp_path):
    robot, data, _ = rtest
    result = _quiet(calibrate, robot, data, method="ls")
    path = tmp_path / "f.json"
    path.write_text(result.frames().dumps())
    frames = CellFrames.read(path)
    frames.check_chain(robot)
    assert np.allclose(frames.base, result.base) and np.allclose(frames.tools, result.tools)
    v1 = {"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), map(float, result.base))),
          "tool": dict(zip("xyz", map(float, result.tool))), "base_frame": "base_link",
          "tip_frame": "flange"}
    assert np.allclose(CellFrames.from_dict(v1).base, result.base)
    sets1 = {"format": "kincal-frames-sets-1", "tip": "flange", "base": "base_link",
             "sets": [{"kind": "point", "source": "x",
                       "frames": result.frames_dict()["sets"][0]["frames"]}]}
    assert np.allclose(CellFrames.from_dict(sets1).tools, result.tools)


@pytest.mark.parametrize("case,message", [
    ("huge", "beyond 1000 m"), ("nan", "not a kincal frames file"),
    ("contradiction", "contradicts its base"), ("deep", "nested"), ("empty", "is empty"),
    ("other_robot", "another robot"), ("version", "version 7")])
def test_frames_file_values_are_validated(rtest, tmp_path, case, message):
    robot, data, _ = rtest
    result = _quiet(calibrate, robot, data, method="ls")
    content = result.frames_dict()
    path = tmp_path / "f.json"
    if case == "huge":
        content["sets"][0]["frames"]["base.x"] = 1e308
        del content["sets"][0]["T_measurement_base"]
    elif case == "nan":
        content["sets"][0]["frames"]["base.x"] = "NaN-ish"
    elif case == "contradiction":
        content["sets"][0]["T_measurement_base"][0][3] += 0.5
    elif case == "version":
        content["version"] = 7
    elif case == "other_robot":
        content["robot"] = "ur10"
    if case == "deep":
        path.write_text("[" * 10000 + "]" * 10000)
    elif case == "empty":
        path.write_text("")
    else:
        path.write_text(json.dumps(content))
    with pytest.raises(DataError, match=message):
        CellFrames.read(path).check_chain(robot)


def test_a_urdf_the_second_parser_reads_otherwise_is_not_written(rtest, tmp_path, monkeypatch):
    """The one writer reads the corrected URDF back with yourdfpy and compares every chain's
    forward kinematics with the calibrated model: a text that says something else (here an
    origin nudged by 1 um after the edit) is refused and nothing is written."""
    import re

    from kincal.errors import ExportError
    from kincal.export import outputs

    robot, data, _ = rtest
    result = _quiet(calibrate, robot, data)
    honest = outputs._corrected  # what write_calibration writes (text, notes, folds)

    def nudged(result, readable=True, add_frames=False, no_fold=None):
        text, notes, made = honest(result, readable, add_frames, no_fold)
        m = re.search(r'(<joint name="joint_3".*?<origin[^>]*xyz=")([-0-9.e]+)', text, re.S)
        return text[:m.start(2)] + repr(float(m.group(2)) + 1e-6) + text[m.end(2):], notes, made

    out = tmp_path / "c.urdf"
    write_calibration(result, Outputs(urdf=out))  # the honest text passes
    assert out.is_file()
    monkeypatch.setattr(outputs, "_corrected", nudged)
    with pytest.raises(ExportError, match="read back before writing.*joint_3"):
        write_calibration(result, Outputs(urdf=tmp_path / "d.urdf", frames=tmp_path / "f.json"))
    assert not (tmp_path / "d.urdf").exists() and not (tmp_path / "f.json").exists()


def test_samples_repeated_exactly_are_named_by_the_gate(rtest, tmp_path, capsys):
    """A copied row (every joint value and reading to the last digit) weighs twice and makes
    the noise look smaller: the gate names the copies, in one set (with the lines) and
    across sets (the same file given twice), as a note of a result it lets through (a
    warning where the files are written) and as the first likely cause of a refusal (in its
    one line); a true repeat (a reading differing in its last digits) and the data as
    measured are not named. API and command line alike."""
    robot, data, _ = rtest

    def notes(sets):
        result = _quiet(calibrate, robot, sets, method="ls")
        return [n for n in result.plausibility.notes if "repeat" in n]

    copied = data.subset(np.r_[np.arange(60), np.arange(5)])  # rows 1-5 again
    (note,) = notes(copied)
    assert note.startswith(f"{data.source}: 5 sample(s) repeat earlier ones exactly (line "
                           f"{data.rows[0]} repeats line {data.rows[0]}): a copy counts as a "
                           "second measurement")
    (note,) = notes([data, data])
    assert f"60 of its 60 samples repeat samples of {data.source} exactly" in note
    nudged = replace(copied, positions=copied.positions + np.r_[np.zeros(60), np.full(5, 1e-12)
                                                                 ][:, None])
    assert notes(nudged) == [] and notes(data) == []
    path = tmp_path / "twice.csv"
    text = data.to_csv_text()
    path.write_text(text + text.splitlines()[-1] + "\n")
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(path), "--out", str(tmp_path / "c.urdf")]) == 0
    assert "kincal: warning: " + str(path) + ": 1 sample(s) repeat earlier ones exactly" in (
        capsys.readouterr().err)


def test_weak_parameters_say_their_unit(rtest):
    """The weak list's sensitivity is millimetres of the measured point per millimetre or
    per degree of the parameter, said as such (it read "mm per unit")."""
    robot, data, _ = rtest
    result = _quiet(calibrate, robot, data)
    weak = result.identifiability.weak
    assert weak
    length = dict(zip(result.layout.names, result.layout.is_length.tolist()))
    for w in weak:
        assert w.describe().split(", ")[-1].endswith("mm per mm" if length[w.name]
                                                     else "mm per deg"), w.describe()
