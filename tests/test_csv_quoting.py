"""Every CSV file kincal writes quotes a cell as RFC 4180 and the csv module do
(:func:`kincal.measurements.csv_table.csv_line`), so a URDF joint named ``a,b`` is one
column that kincal's own reader reads back to the same name; a file without such a name is
written byte for byte as before (no quotes where none are needed)."""

from __future__ import annotations

import csv
import io
import warnings

import numpy as np
from hypothesis import given, strategies as st

from kincal.cli import main
from kincal.compensation.compensate import filter_program
from kincal.errors import KincalWarning
from kincal.export.cell_exports import mdh_table_csv
from kincal.measurements.csv_table import csv_line
from kincal.measurements.data import Measurements
from kincal.measurements.sets import to_csv_text
from kincal.planning.candidates import candidates_csv_text, read_candidates
from kincal.robot import Robot

NAMES = ("a,b", 'say "hi"', "j3")  # a comma, quotes, and a plain name
URDF = """<robot name="odd">
  <link name="base_link"/><link name="l1"/><link name="l2"/><link name="l3"/>
  <link name="flange"/>
  <joint name="a,b" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="say &quot;hi&quot;" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.05 0.4"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="flange_joint" type="fixed"><parent link="l3"/><child link="flange"/>
    <origin xyz="0.25 0 0"/></joint>
</robot>
"""


def _robot(tmp_path) -> Robot:
    path = tmp_path / "odd.urdf"
    path.write_text(URDF)
    robot = Robot.load(path, tip="flange")
    assert robot.joint_names == NAMES
    return robot


def _records(text: str) -> list[list[str]]:
    """The csv module's reading of ``text`` without its ``#`` lines."""
    return list(csv.reader(io.StringIO(
        "".join(s for s in text.splitlines(True) if not s.startswith("#")))))


@given(st.lists(st.text(alphabet='ab ,"\n\r;#0.', max_size=6), min_size=1, max_size=5))
def test_csv_line_is_the_csv_modules_record(cells):
    out = io.StringIO()
    csv.writer(out).writerow(cells)  # QUOTE_MINIMAL, line end CRLF: CR and LF are quoted
    assert csv_line(cells) + "\r\n" == out.getvalue()


def test_the_reader_reads_quoted_names_back(tmp_path):
    """Names with a comma, a quote, LF and CR (which an XML attribute can hold as &#10;
    and &#13;) read back to themselves, after provenance-like # lines."""
    from kincal.measurements.csv_table import read_columns

    names = ["a,b", 'q"t', "line\nbreak", "cr\rx", "plain"]
    path = tmp_path / "f.csv"
    path.write_text("# made by kincal\n" + csv_line(names) + "\n"
                    + csv_line(["1.0", "2.0", "3.0", "4.0", "5.0"]) + "\n", newline="")
    got = read_columns(path, names)
    assert got.header == tuple(names)
    assert [float(got.values[n][0]) for n in names] == [1.0, 2.0, 3.0, 4.0, 5.0]


def test_joint_names_with_commas_and_quotes_round_trip(tmp_path):
    robot = _robot(tmp_path)
    q = np.random.default_rng(0).uniform(-1.0, 1.0, size=(12, 3))
    data = Measurements(robot.joint_names, q, robot.tip_poses(q)[:, :3, 3])
    path = tmp_path / "data.csv"
    path.write_text(data.to_csv_text())
    assert path.read_text().splitlines()[0] == '"a,b","say ""hi""",j3,x,y,z'
    back = Measurements.from_csv(path, robot.joint_names)
    assert back.joint_names == NAMES
    np.testing.assert_array_equal(back.joint_values, data.joint_values)
    np.testing.assert_array_equal(back.positions, data.positions)
    # the other writers: plan's candidates (read back by the candidates' reader), the
    # kinds' writer, compensate's joints, the MD-H table (one cell per joint name)
    path.write_text(candidates_csv_text(robot.joint_names, q, np.arange(12) + 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        got, lines = read_candidates(path, robot)
    np.testing.assert_array_equal(got, q)
    assert _records(to_csv_text(data, "quat-xyzw"))[0] == [*NAMES, "x", "y", "z"]
    header = _records(filter_program(robot, robot, q[:2], None).to_csv_text())[0]
    assert header[:4] == ["target_line", *NAMES]
    table = _records(mdh_table_csv(robot))
    assert [r[0] for r in table[1:]] == list(NAMES) and {len(r) for r in table} == {7}


def test_commands_write_and_read_the_quoted_header(tmp_path):
    """Through the commands: simulate reads poses written by the candidates' writer and
    writes its data file (provenance lines first), analyze reads that to the URDF's joint
    names."""
    robot = _robot(tmp_path)
    poses, data = tmp_path / "poses.csv", tmp_path / "sim.csv"
    q = np.random.default_rng(1).uniform(-1.5, 1.5, size=(30, 3))
    poses.write_text(candidates_csv_text(robot.joint_names, q))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(["simulate", str(robot.source), "--tip", "flange", "--poses-file",
                     str(poses), "--out", str(data), "--quiet"]) == 0
        assert main(["analyze", str(robot.source), str(data), "--tip", "flange",
                     "--quiet"]) == 0
    assert _records(data.read_text())[0][:3] == list(NAMES)


def test_ordinary_files_are_written_as_before():
    """No quotes where none are needed: the plain comma join, byte for byte."""
    assert candidates_csv_text(["j1", "j2"], [[0.5, -1.0]], [3]) == (
        "j1,j2,candidate_line\n0.5,-1.0,3\n")
    data = Measurements(("j1", "j2"), np.array([[0.25, -0.5]]), np.array([[1.0, 2.0, 0.1]]))
    assert data.to_csv_text() == "j1,j2,x,y,z\n0.25,-0.5,1.0,2.0,0.1\n"
    assert csv_line(["joint_1", "", "0.1"]) == "joint_1,,0.1"


def test_a_semicolon_file_with_a_quoted_comma_name_is_read_as_semicolons(tmp_path):
    """The separator is sniffed outside the header's quoted names: a semicolon file (a
    European spreadsheet's export) whose first name is ``"a,b"`` was read as a comma file
    (the comma inside the quotes counted): one column ``a,b;say...`` and a missing-column
    error, or with other names the wrong cells. A tab file likewise, and a quoted ';'
    inside a comma file does not make it a semicolon file."""
    import pytest

    from kincal.errors import KincalNote
    from kincal.measurements.csv_table import read_columns, sniff_separator

    assert sniff_separator('"a,b";j2;x') == ";"
    assert sniff_separator('"a,b"\tj2\tx') == "\t"
    assert sniff_separator('"a;b",j2,x') == ","
    assert sniff_separator('"say ""x,y""";j2') == ";"  # doubled quotes inside
    assert sniff_separator("j1;j2") == ";" and sniff_separator("j1,j2;x") == ","
    robot = _robot(tmp_path)
    q = np.random.default_rng(2).uniform(-1.0, 1.0, size=(12, 3))
    data = Measurements(robot.joint_names, q, robot.tip_poses(q)[:, :3, 3])
    for sep in (";", "\t"):
        records = _records(data.to_csv_text())
        path = tmp_path / "semi.csv"
        path.write_text("\n".join(sep.join('"' + c.replace('"', '""') + '"' if ("," in c or
                                           '"' in c) else c for c in r) for r in records)
                        + "\n")
        assert path.read_text().startswith('"a,b"' + sep)
        with pytest.warns(KincalNote, match="separated by a (semicolon|tab)"):
            back = Measurements.from_csv(path, robot.joint_names)
        np.testing.assert_array_equal(back.joint_values, data.joint_values)
        np.testing.assert_array_equal(back.positions, data.positions)
        with pytest.warns(KincalNote):
            cols = read_columns(path, ["a,b", "x"])
        assert cols.separator == sep and cols.header[:3] == NAMES


def test_excels_sep_line_names_the_separator(tmp_path):
    """Excel writes (and reads) a first line ``sep=;`` naming the separator; it was read as
    the header (a missing-column error, or 'the header does not fit its rows'). Now it sets
    the separator and the header follows, line numbers as in the file; a separator other
    than a comma, semicolon or tab is refused."""
    import pytest

    from kincal.errors import DataError, KincalNote
    from kincal.measurements.csv_table import read_columns

    path = tmp_path / "excel.csv"
    path.write_text("sep=;\nj1;j2;x\n0.5;1.5;2.5\n# a note\n1;2;3e-3\n")
    with pytest.warns(KincalNote, match="semicolon"):
        got = read_columns(path, ["j1", "x"])
    assert got.header == ("j1", "j2", "x") and list(got.lines) == [3, 5]
    assert got.values["x"].tolist() == [2.5, 3e-3]
    path.write_text("sep=,\r\nj1,x\r\n0.5,1\r\n")
    assert read_columns(path, ["j1", "x"]).values["j1"].tolist() == [0.5]
    path.write_text("sep=|\nj1|x\n0.5|1\n")
    with pytest.raises(DataError, match="names the separator '\\|'"):
        read_columns(path, ["j1", "x"])


def test_a_utf16_file_with_its_mark_is_read(tmp_path):
    """A spreadsheet's "Unicode text" export (UTF-16 with a byte-order mark, tab-separated)
    was refused ("'utf-8' codec can't decode byte 0xff"); it is read as UTF-16."""
    import pytest

    from kincal.errors import KincalNote
    from kincal.measurements.csv_table import read_columns

    path = tmp_path / "u16.csv"
    for encoding in ("utf-16", "utf-16-be"):
        data = "j1\tx\r\n0.5\t2.5\r\n1\t3\r\n".encode(encoding)
        path.write_bytes(data if encoding == "utf-16" else b"\xfe\xff" + data)
        with pytest.warns(KincalNote, match="tab"):
            got = read_columns(path, ["j1", "x"])
        assert got.values["x"].tolist() == [2.5, 3.0] and list(got.lines) == [2, 3]
