"""Robot logs as they come: unnamed columns, and headers that do not fit their rows."""

from pathlib import Path

import numpy as np
import pytest

from kincal.errors import DataError
from kincal.measurements.csv_table import read_columns

JOINTS = [f"j{i}" for i in range(1, 7)]
META = ["gripper", "robot/left_gripper", "handle", "table/contact_{k}", "joint_states"]
SHARED = Path("/work/shared/data/talos_contact")


def _log(tmp_path, header, rows=3, name="log.csv"):
    """A robot log like TALOS's: 5 text fields, then the joint values, one row per touch."""
    rng = np.random.default_rng(0)
    lines = [",".join(header)]
    for k in range(rows):
        lines.append(",".join([m.format(k=k) for m in META]
                              + [repr(float(v)) for v in rng.uniform(-1, 1, len(JOINTS))]))
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_unnamed_text_columns_are_not_read(tmp_path):
    """The header names the joints over their numbers: 4 empty names over metadata fit."""
    path = _log(tmp_path, ["", "", "", "", "joint_names"] + JOINTS)
    table = read_columns(path, JOINTS)
    assert table.values["j1"].shape == (3,) and np.all(np.abs(table.values["j6"]) <= 1)
    assert table.ignored() == ("joint_names",)


def test_shifted_names_are_refused_with_positions(tmp_path):
    """The empty names at the end instead of the start: each joint name sits 4 cells left of
    its values, the last 4 values have no name."""
    path = _log(tmp_path, ["joint_names"] + JOINTS + ["", "", "", ""])
    with pytest.raises(DataError) as exc:
        read_columns(path, JOINTS)
    msg = str(exc.value)
    assert "line 2: the header does not fit its rows" in msg
    assert "columns 8-11 hold numbers but have no name" in msg
    assert "fit the cells 4 columns to their right" in msg and "\n" not in msg


def test_fewer_names_than_cells_is_refused_with_positions(tmp_path):
    path = _log(tmp_path, ["", "joint_names"] + JOINTS)
    with pytest.raises(DataError, match=r"line 2: the header does not fit its rows: 11 cells, "
                                        r"8 names \(columns 9-11 have no name\); the named "
                                        r"columns fit the cells 3 columns to their right"):
        read_columns(path, JOINTS)


def test_named_columns_over_text_say_the_shift(tmp_path):
    """No unnamed column, but every name one cell off: the bad cell's message says so."""
    path = _log(tmp_path, ["a", "b", "c", "d", "joint_names"] + JOINTS[1:] + ["j1"])
    header = ["a", "b", "c", "d"] + JOINTS + ["extra"]
    path.write_text("\n".join([",".join(header)] + path.read_text().splitlines()[1:]) + "\n")
    with pytest.raises(DataError, match=r"column 'j1': 'joint_states'; expected a finite "
                                        r"number; the named columns fit the cells 1 column to "
                                        r"their right"):
        read_columns(path, JOINTS)


def test_index_column_and_duplicated_names_still_behave(tmp_path):
    rng = np.random.default_rng(1)
    rows = [",".join([str(k)] + [repr(float(v)) for v in rng.normal(size=6)]) for k in range(4)]
    path = tmp_path / "pandas.csv"  # pandas writes its index as a first, unnamed column
    path.write_text("\n".join([",".join([""] + JOINTS)] + rows) + "\n")
    assert read_columns(path, JOINTS).values["j3"].shape == (4,)
    path.write_text("\n".join([",".join([""] + JOINTS[:5] + ["j1"])] + rows) + "\n")
    with pytest.raises(DataError, match=r"duplicated column\(s\) j1 in the header"):
        read_columns(path, JOINTS[:5])


@pytest.mark.skipif(not SHARED.exists(), reason="the shared TALOS logs are not on this machine")
def test_talos_logs_train_reads_validation_is_refused():
    joints = ["leg_left_1_joint", "torso_1_joint", "arm_left_7_joint"]
    train = read_columns(SHARED / "left_train.csv", joints)
    assert len(train.lines) == 21
    with pytest.raises(DataError, match="columns 34-37 hold numbers but have no name.*4 columns "
                                        "to their right"):
        read_columns(SHARED / "left_validation.csv", joints)


def test_the_command_lines_reading_says_the_shift_too(tmp_path, capsys):
    """TALOS's validation log (4 empty names at the end): read_columns said the shift, but
    the command line reads the header first, without the columns it wants, and said only
    'name every data column'. The header read now knows the chain joints' columns."""
    from kincal.measurements.sets import header_of, read_set_file

    path = _log(tmp_path, ["joint_names"] + JOINTS + ["", "", "", ""])
    for read in (lambda: header_of(path, JOINTS),
                 lambda: read_set_file(path, JOINTS, on_plane=True, flush=True)):
        with pytest.raises(DataError, match="columns 8-11 hold numbers but have no name.*"
                                            "fit the cells 4 columns to their right"):
            read()
    from kincal.cli.main import main

    ec66 = [f"joint_{i}" for i in range(1, 7)]
    path.write_text(path.read_text().replace(",".join(JOINTS), ",".join(ec66), 1))
    assert main(["calibrate", "ec66", str(path), "--on-plane", "--flush", "--quiet",
                 "--out", str(tmp_path / "cal.urdf")]) == 1
    assert "4 columns to their right" in capsys.readouterr().err
    assert not (tmp_path / "cal.urdf").exists()


def test_one_unnamed_column_is_named_in_the_singular(tmp_path):
    """One empty name over numbers (a robot log's header with a name lost) and one cell
    more than names: the lines say "column 3 holds ... has", not "column 3 hold ... have"."""
    path = tmp_path / "log.csv"
    rows = ["0.1,0.2,0.3,0.4", "0.5,0.6,0.7,0.8"]
    path.write_text("\n".join(["j1,j2,,j4"] + rows) + "\n")
    with pytest.raises(DataError, match=r"column 3 holds numbers but has no name in the header"):
        read_columns(path, ["j1", "j2"])
    path.write_text("\n".join(["j1,j2,j3"] + rows) + "\n")
    with pytest.raises(DataError, match=r"4 cells, 3 names \(column 4 has no name\)"):
        read_columns(path, ["j1", "j2"])
