"""Files as they come from real tools: CSV dialects, renamed joint columns, xacro URDFs,
parameter patterns. Each variant must read to exactly the samples of the plain file."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from conftest import random_joint_values

from kincal.cli.main import main
from kincal.errors import DataError, KincalNote
from kincal.measurements.data import Measurements
from kincal.models import mdh
from kincal.planning.candidates import read_candidates
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot

JOINTS = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")


@pytest.fixture(scope="module")
def ec66():
    return Robot.load("ec66")


@pytest.fixture(scope="module")
def plain(ec66, tmp_path_factory):
    """(path, text) of a plain comma-separated file of 20 simulated EC66 samples."""
    rng = np.random.default_rng(3)
    model = mdh.extract(ec66.geometry)
    q = random_joint_values(ec66.geometry, rng, 20)
    truth = Truth(planted_table(model, rng), np.array([0.5, 0.1, 0.2, 0.0, 0.0, 0.3]),
                  np.array([0.03, 0.02, 0.12]))
    text = measure(model, truth, q, 1e-5, rng).to_csv_text()
    path = tmp_path_factory.mktemp("plain") / "plain.csv"
    path.write_text(text)
    return path, text


def _read(path, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = Measurements.from_csv(path, JOINTS, **kw)
    return data, [str(w.message) for w in caught if issubclass(w.category, KincalNote)]


def _same(a, b):
    np.testing.assert_array_equal(a.joint_values, b.joint_values)
    np.testing.assert_array_equal(a.positions, b.positions)


def _dialect(text, sep=",", eol="\n", bom=False, comments=False):
    lines = text.strip("\n").split("\n")
    if comments:  # a preamble, a comment between rows and an indented one
        lines = ["# exported by the tracker software", "#   unit: m, rad", lines[0],
                 "# first pose", *lines[1:5], "   # pause", *lines[5:]]
    out = eol.join(line.replace(",", sep) if not line.lstrip().startswith("#") else line
                   for line in lines) + eol
    return ("\ufeff" if bom else "") + out


@pytest.mark.parametrize("sep", [",", ";", "\t"])
@pytest.mark.parametrize("eol", ["\n", "\r\n", "\r"])
@pytest.mark.parametrize("bom,comments", [(False, False), (True, True)])
def test_dialects_read_like_the_plain_file(plain, tmp_path, sep, eol, bom, comments):
    path, text = plain
    reference, notes = _read(path)
    assert notes == []
    other = tmp_path / "other.csv"
    other.write_bytes(_dialect(text, sep, eol, bom, comments).encode("utf-8"))
    data, notes = _read(other)
    _same(data, reference)
    if sep == ",":
        assert notes == []
    else:  # the guess is said
        assert len(notes) == 1 and {";": "semicolon", "\t": "tab"}[sep] in notes[0]
    if comments:  # line numbers stay those of the file
        assert data.rows[0] == 5 and data.rows[4] == 10


def test_decimal_comma_is_refused_with_a_reason(plain, tmp_path):
    _, text = plain
    semicolon = _dialect(text, ";").replace(".", ",")
    bad = tmp_path / "comma.csv"
    bad.write_text(semicolon)
    with pytest.raises(DataError, match="line 2, column 'joint_1'.*decimal comma"):
        Measurements.from_csv(bad, JOINTS)
    # with comma separators a decimal comma splits cells: the count is wrong, and said why
    bad.write_text(text.split("\n")[0] + "\n" + "0,5," * 8 + "0,5\n")
    with pytest.raises(DataError, match="line 2: the header does not fit its rows: 18 cells, 9 "
                                        r"names \(columns 10-18 have no name\) .or decimal commas"):
        Measurements.from_csv(bad, JOINTS)


def test_a_header_of_separators_alone_is_named_missing(tmp_path):
    """A first line of separators alone (",,") is blank to the reader, so the first row of
    numbers was taken for the header: "duplicated column(s) 1 in the header" (or "a header
    but no samples"). Now: that line holds numbers, the header is missing."""
    bad = tmp_path / "unnamed.csv"
    bad.write_text(",,\n1,1,1\n")
    with pytest.raises(DataError, match="line 2 holds numbers, not column names: the header "
                                        "is missing"):
        Measurements.from_csv(bad, JOINTS)


def test_an_empty_data_file_says_what_it_should_hold(tmp_path, capsys):
    """The command line reads a file's header before its kind is known: an empty file said
    "the file is empty; expected a header with" and stopped there."""
    from kincal.cli.main import main

    empty = tmp_path / "empty.csv"
    empty.write_text("")
    assert main(["calibrate", "ec66", str(empty), "--out", str(tmp_path / "c.urdf")]) == 1
    line = capsys.readouterr().err.strip()
    assert line.endswith("the file is empty; expected a header naming the columns, then rows "
                         "of numbers"), line


def test_commented_out_header_is_named(plain, tmp_path):
    _, text = plain
    bad = tmp_path / "savetxt.csv"
    bad.write_text("# " + text)  # numpy.savetxt(header=...) writes the header this way
    with pytest.raises(DataError, match="holds numbers, not column names.*commented out"):
        Measurements.from_csv(bad, JOINTS)


def _renamed(text):
    header, rest = text.split("\n", 1)
    for k, j in enumerate(JOINTS, start=1):
        header = header.replace(j, f"J{k} [rad]")
    return header + "\n" + rest


def test_joint_column_mapping(plain, tmp_path):
    path, text = plain
    reference, _ = _read(path)
    renamed = tmp_path / "renamed.csv"
    renamed.write_text(_renamed(text))
    mapping = {j: f"J{k} [rad]" for k, j in enumerate(JOINTS, start=1)}
    data, _ = _read(renamed, joint_columns=mapping)
    _same(data, reference)
    assert data.joint_names == JOINTS and data.ignored_columns == ()
    # a partial mapping: the other joints keep their own names
    partial = tmp_path / "partial.csv"
    partial.write_text(text.replace("joint_3", "axis3", 1))
    _same(_read(partial, joint_columns={"joint_3": "axis3"})[0], reference)


def test_joint_column_mapping_errors(plain, tmp_path):
    path, text = plain
    renamed = tmp_path / "renamed.csv"
    renamed.write_text(_renamed(text))
    with pytest.raises(DataError, match="'joint_7', which is not a joint.*Did you mean"):
        Measurements.from_csv(path, JOINTS, joint_columns={"joint_7": "J7"})
    with pytest.raises(DataError, match=r"missing column\(s\) J3 \(for joint_3\).*Did you mean "
                                        r"'J3 \[rad\]'"):
        Measurements.from_csv(renamed, JOINTS, joint_columns={
            **{j: f"J{k} [rad]" for k, j in enumerate(JOINTS, start=1)}, "joint_3": "J3"})
    with pytest.raises(DataError, match="joint_1 and joint_2 would both be read from column"):
        Measurements.from_csv(path, JOINTS, joint_columns={"joint_2": "joint_1"})
    with pytest.raises(DataError, match="must be a mapping"):
        Measurements.from_csv(path, JOINTS, joint_columns=[("joint_1", "a")])
    # a joint mapped onto a measured column read joint_1's values from x, silently (the gate
    # refused it only after the fit, blaming the corrections); one column, one value
    with pytest.raises(DataError, match="column 'x' would be read for joint_1 and a measured"):
        Measurements.from_csv(path, JOINTS, joint_columns={"joint_1": "x"})
    with pytest.raises(DataError, match="column 'J1 \\[rad\\]' would be read for joint_1 and"):
        Measurements.from_csv(renamed, JOINTS, joint_columns={
            j: f"J{k} [rad]" for k, j in enumerate(JOINTS, start=1)},
            position_columns=("J1 [rad]", "y", "z"))


def test_candidates_read_dialects_and_mapping(ec66, plain, tmp_path):
    path, text = plain
    q0, _ = read_candidates(path, ec66)
    other = tmp_path / "cand.csv"
    other.write_text(_dialect(_renamed(text), "\t", "\r\n", comments=True))
    with pytest.warns(KincalNote, match="tab"):
        q, lines = read_candidates(other, ec66, joint_columns={
            j: f"J{k} [rad]" for k, j in enumerate(JOINTS, start=1)})
    np.testing.assert_array_equal(q, q0)
    assert lines[0] == 5


def test_cli_joint_columns_and_note(plain, tmp_path, capsys):
    _, text = plain
    data = tmp_path / "renamed.csv"
    data.write_text(_dialect(_renamed(text), ";"))
    args = [f"joint_{k}=J{k} [rad]" for k in range(1, 7)]
    assert main(["analyze", "ec66", str(data), "--joint-columns", *args]) == 0
    captured = capsys.readouterr()
    assert "kincal: note:" in captured.err and "semicolon" in captured.err
    assert "20 poses" in captured.out
    assert main(["evaluate", "ec66", str(data), "--fit-frames", "--joint-columns", *args]) == 0
    assert "(n = 20)" in capsys.readouterr().out
    # a malformed pair is a usage error (exit 2); an unknown joint one line, exit 1
    with pytest.raises(SystemExit) as exc:
        main(["analyze", "ec66", str(data), "--joint-columns", "joint_1"])
    assert exc.value.code == 2 and "expected URDF_NAME=CSV_NAME" in capsys.readouterr().err
    assert main(["analyze", "ec66", str(data), "--joint-columns", "joint_9=J1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("kincal: error:") and "joint_9" in err[0]
    assert main(["analyze", "ec66", str(data), "--joint-columns", "joint_1=J1",
                 "joint_1=J2"]) == 1
    assert "names joint joint_1 twice" in capsys.readouterr().err
    out = tmp_path / "chosen.csv"
    assert main(["plan", "ec66", str(data), "--poses", "12", "--out", str(out),
                 "--joint-columns", *args[:3], "--joint-columns", *args[3:]]) == 0  # both kept
    assert [r for r in out.read_text().splitlines() if not r.startswith("#")][0].startswith(
        "joint_1,joint_2")


def test_parameter_patterns(ec66):
    from kincal.errors import ParameterError
    from kincal.measurements.point_space import ParameterSpace

    from kincal import models

    space = ParameterSpace.of_model(models.build("mdh", ec66.geometry))
    assert space.expand(["*.d"]) == tuple(f"{j}.d" for j in JOINTS)
    assert space.expand(("joint_[456].a", "joint_4.a", "tool.*")) == (
        "joint_4.a", "joint_5.a", "joint_6.a", "tool.x", "tool.y", "tool.z")
    assert space.expand("base.r?") == ("base.rx", "base.ry", "base.rz")
    np.testing.assert_array_equal(space.indices(["joint_1.*"]), [0, 1, 2, 3])
    np.testing.assert_array_equal(space.indices(["joint_1.?"]), [0, 2])
    with pytest.raises(ParameterError, match="pattern 'joint_9.*' matches no parameter. "
                                             "Valid names: joint_1.a"):
        space.expand(["joint_9.*"])
    with pytest.raises(ParameterError, match="unknown parameter 'joint_1.b'"):
        space.expand(["joint_1.b"])


def test_fix_patterns_in_a_calibration(ec66, plain, tmp_path, capsys):
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem

    data = Measurements.from_csv(plain[0], JOINTS)
    by_name = CalibrationProblem(ec66, data, CalibrationOptions(
        method="ls", fix=tuple(f"{j}.d" for j in JOINTS))).analyze()
    by_pattern = CalibrationProblem(ec66, data, CalibrationOptions(
        method="ls", fix=("*.d",))).analyze()
    assert by_pattern.fixed == by_name.fixed == tuple(f"{j}.d" for j in JOINTS)
    assert by_pattern.kept == by_name.kept
    out = tmp_path / "cal.urdf"
    assert main(["calibrate", "ec66", str(plain[0]), "--method", "ls", "--fix", "*.d",
                 "joint_[56].theta", "--out", str(out), "--quiet"]) == 0 and out.exists()
    assert main(["calibrate", "ec66", str(plain[0]), "--fix", "*.gamma", "--out",
                 str(tmp_path / "no.urdf")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert [e for e in err if "error" in e] == [err[-1]] and "'*.gamma' matches no" in err[-1]
    assert not (tmp_path / "no.urdf").exists()


@settings(max_examples=60, deadline=None)
@given(values=st.lists(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=3, max_size=3),
                       min_size=1, max_size=8),
       sep=st.sampled_from([",", ";", "\t"]), eol=st.sampled_from(["\n", "\r\n", "\r"]),
       bom=st.booleans(), comments=st.lists(st.integers(0, 9), max_size=4),
       blank=st.lists(st.integers(0, 9), max_size=3))
def test_any_dialect_reads_the_same_numbers_and_lines(tmp_path_factory, values, sep, eol, bom,
                                                      comments, blank):
    from kincal.measurements.csv_table import read_columns

    rows = [sep.join(["a", "b c", "d"])] + [sep.join(repr(v) for v in row) for row in values]
    lines, numbers = [], []
    for k, row in enumerate(rows):  # comment and blank lines before some rows
        lines += ["# note, with; separators\tinside"] * comments.count(k) + [""] * blank.count(k)
        lines.append(row)
        numbers.append(len(lines))
    path = tmp_path_factory.mktemp("fuzz") / "f.csv"
    path.write_bytes((("\ufeff" if bom else "") + eol.join(lines) + eol).encode("utf-8"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalNote)
        table = read_columns(path, ["a", "b c", "d"])
    assert table.separator == sep
    np.testing.assert_array_equal(np.column_stack([table.values[c] for c in ("a", "b c", "d")]),
                                  np.array(values))
    np.testing.assert_array_equal(table.lines, numbers[1:])
