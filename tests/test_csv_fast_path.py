"""The CSV reader's fast path (one numpy parse of a plain file) against the careful
row-by-row reading it stands in for: the same values, line numbers, header and separator
wherever it is taken, and declined (the careful reading runs, with its message) wherever
a file is not plain. The messages themselves are those of tests/test_bad_input.py,
test_cli_refusals.py and test_csv_header_fit.py, which run through the fast path."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from kincal.errors import DataError
from kincal.measurements import csv_table
from kincal.measurements.csv_table import read_columns

SHARED = sorted(Path("/work/shared/data").glob("*/*.csv"))


def _careful(monkeypatch, *args, **kwargs):
    with monkeypatch.context() as m:
        m.setattr(csv_table, "_read_fast", lambda *a: None)
        return read_columns(*args, **kwargs)


def _same(a, b):
    assert a.header == b.header and a.separator == b.separator
    assert np.array_equal(a.lines, b.lines) and list(a.values) == list(b.values)
    for c in a.values:
        assert np.array_equal(a.values[c], b.values[c]), c  # bit for bit


def _numeric_columns(path):
    """The named columns of a file whose every cell parses as a finite number."""
    with open(path, encoding="utf-8-sig") as fh:
        rows = [line.rstrip("\r\n").split(",") for line in fh if line.strip()]
    out = []
    for k, name in enumerate(rows[0]):
        try:
            if name and all(np.isfinite(float(r[k])) for r in rows[1:]):
                out.append(name)
        except (ValueError, IndexError):
            pass
    return out


@pytest.mark.skipif(not SHARED, reason="the shared data files are not on this machine")
@pytest.mark.parametrize("path", SHARED, ids=lambda p: p.name)
def test_shared_data_files_read_the_same_both_ways(path, monkeypatch):
    names = _numeric_columns(path)
    assert names
    try:
        careful = _careful(monkeypatch, path, names)
    except DataError as exc:  # e.g. unnamed columns holding numbers: the same refusal
        with pytest.raises(DataError) as fast_exc:
            read_columns(path, names)
        assert str(fast_exc.value) == str(exc)
        return
    _same(read_columns(path, names), careful)


def _plain(tmp_path, rng, name="plain.csv", separator=",", newline="\n", bom=False,
           comments=0, index=False, fmt=repr, rows=300):
    values = rng.normal(size=(rows, 4)) * 10.0 ** rng.integers(-6, 6, size=(rows, 4))
    values[:5, 0] = [0.0, -0.0, 1.0, -3.0, 1e-300][:rows]
    head = ([""] if index else []) + ["a", "b", "sigma", "c"]
    values[:, 2] = np.abs(values[:, 2]) % 100 + 1e-3  # within the range of a sigma
    lines = [f"# comment {k}" for k in range(comments)] + [separator.join(head)]
    for k, row in enumerate(values):
        lines.append(separator.join(([str(k)] if index else []) + [fmt(float(v)) for v in row]))
    path = tmp_path / name
    path.write_bytes(((b"\xef\xbb\xbf" if bom else b"")
                      + (newline.join(lines) + newline).encode()))
    return path, values


@pytest.mark.parametrize("case", [
    {}, {"separator": ";"}, {"separator": "\t"}, {"newline": "\r\n"}, {"bom": True},
    {"comments": 2}, {"index": True}, {"fmt": lambda v: f"{v:.17g}"},
    {"fmt": lambda v: f" {v:+.6e} "}, {"fmt": lambda v: f"{v:.3f}"}, {"rows": 1},
])
def test_plain_files_take_the_fast_path_with_the_careful_values(case, tmp_path, monkeypatch):
    path, _ = _plain(tmp_path, np.random.default_rng(len(str(case))), **case)
    names = ["a", "b", "c"]
    with warnings.catch_warnings(record=True):
        assert csv_table._read_fast(path, names, ["sigma"], csv_table.COLUMN_RANGES) is not None
    with warnings.catch_warnings(record=True) as fast_notes:
        warnings.simplefilter("always")
        fast = read_columns(path, names, optional=["sigma"])
    with warnings.catch_warnings(record=True) as careful_notes:
        warnings.simplefilter("always")
        careful = _careful(monkeypatch, path, names, optional=["sigma"])
    _same(fast, careful)
    assert [str(w.message) for w in fast_notes] == [str(w.message) for w in careful_notes]


def test_repr_of_random_doubles_reads_back_bit_for_bit(tmp_path):
    rng = np.random.default_rng(1)
    bits = rng.integers(0, 2**63 - 1, size=20000, dtype=np.int64) & ~np.int64(0x7ff << 52)
    values = bits.view(np.float64).reshape(-1, 4) * rng.choice([-1.0, 1.0], (5000, 4))
    path = tmp_path / "doubles.csv"
    path.write_text("a,b,c,d\n" + "\n".join(",".join(repr(float(v)) for v in row)
                                            for row in values) + "\n")
    got = read_columns(path, list("abcd"))
    assert np.array_equal(np.column_stack([got.values[c] for c in "abcd"]), values)


@pytest.mark.parametrize("body, message", [
    ('"1.0",2\n3,4\n', None),                      # quoted cells: careful, same values
    ("1,2\n\n3,4\n", None),                         # a blank line among the rows
    ("1,2\n# note\n3,4\n", None),                   # a comment line among the rows
    ("1,2\n3,nan\n", "line 3, column 'b': 'nan'; expected a finite number"),
    ("1,2\n3,1e999\n", "line 3, column 'b': '1e999'; expected a finite number"),
    ("1,2\n3,\n", "line 3, column 'b': an empty cell; expected a finite number"),
    ("1,2\n3,x\n", "line 3, column 'b': 'x'; expected a finite number"),
    ("1,2\n3\n", "line 3: 1 cells, the header has 2"),
    ("1,2\n3,4,5\n", "line 3: 3 cells, the header has 2"),
    # float() reads these (as 10, 1.0 and 2.0), numpy and other CSV readers do not: refused
    ("1,2\n3,1_0\n", r"line 3, column 'b': '1_0'; expected a finite number written with the "
                     r"digits 0-9 \(no '_' digit separators"),
    ("1,2\n\uff11,4\n", "line 3, column 'a': '\uff11'; expected a finite number written with"),
    ("1,2\n3,\u0662\n", "line 3, column 'b': '\u0662'; expected a finite number written with"),
    ("1,2\n3,joint_states\n", "line 3, column 'b': 'joint_states'; expected a finite number$"),
    ("1,2\r3,4\r", None),                           # old Mac line ends
])
def test_files_the_fast_path_declines_read_or_fail_as_before(body, message, tmp_path,
                                                             monkeypatch):
    path = tmp_path / "t.csv"
    path.write_bytes(("a,b\n" + body).encode())
    assert csv_table._read_fast(path, ["a", "b"], [], csv_table.COLUMN_RANGES) is None
    if message is None:
        _same(read_columns(path, ["a", "b"]), _careful(monkeypatch, path, ["a", "b"]))
    else:
        with pytest.raises(DataError, match=message):
            read_columns(path, ["a", "b"])


def test_a_sigma_out_of_range_is_refused_with_its_line(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("a,sigma\n1,0.5\n2,5000\n")
    assert csv_table._read_fast(path, ["a", "sigma"], [], csv_table.COLUMN_RANGES) is None
    with pytest.raises(DataError, match="line 3, column 'sigma': 5000 is outside"):
        read_columns(path, ["a", "sigma"])


def test_measurements_files_take_the_fast_path(tmp_path, monkeypatch):
    """What kincal writes (Measurements.to_csv_text) is plain: the fast path reads it."""
    from kincal.measurements.data import Measurements

    rng = np.random.default_rng(2)
    data = Measurements(("j1", "j2"), rng.normal(size=(50, 2)), rng.normal(size=(50, 3)))
    path = tmp_path / "m.csv"
    path.write_text(data.to_csv_text())
    names = ["j1", "j2", "x", "y", "z"]
    assert csv_table._read_fast(path, names, [], csv_table.COLUMN_RANGES) is not None
    _same(read_columns(path, names), _careful(monkeypatch, path, names))
