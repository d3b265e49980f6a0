"""Numeric columns of a CSV file, with errors that name the file, line and column; and
:func:`csv_line`, the one way kincal writes a CSV line.

The one CSV reader behind :class:`kincal.measurements.Measurements` and the candidate
poses of :mod:`kincal.candidates`. A header row names the columns; blank lines and lines
starting with ``#`` are skipped (line numbers stay those of the file); a byte-order mark
and CRLF or CR line ends are accepted, and UTF-16 with its byte-order mark. The
separator is a comma, or a semicolon or a tab when the header has one of those and no
comma outside its double-quoted names (sniffed from the header, and said in a
:class:`KincalNote`), or the one a first line ``sep=;`` names (as Excel writes it).
Every cell of a wanted column must be a finite number with a decimal point: a decimal
comma ("0,5") is refused with a message saying so, never read as two cells or as 5; so
are digit separators and digits other than 0-9 ("1_000", "１"), which Python's ``float()``
reads and other CSV readers (numpy's, the fast path's) do not. The
columns of stated standard deviations (``sigma``, ``sigma_deg``) must lie in
:data:`COLUMN_RANGES`; a value outside is refused with its line. A column asked for twice
(a joint mapped onto a position column) is refused.

Robot logs often carry unnamed columns (empty names in the header). An unnamed column of
text (metadata) or a leading unnamed column (an index, as pandas writes it) is simply not
read; an unnamed column holding numbers elsewhere, or a row with more cells than the header
has names, means the header does not fit its rows (shifted names read the wrong values):
refused with the column positions (counted from 1) and the shift that would fit, if any.
Cells in double quotes (RFC 4180: a column name holding a comma, a quote or a line end, as
:func:`csv_line` writes it) are read as the csv module reads them.
"""

from __future__ import annotations

import csv
import math
import itertools
import os
import re
import warnings
from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kincal.errors import DataError, InputFileError, KincalNote, listing, suggest
from kincal.input_files import MAX_DATA_BYTES, check_regular_file
from kincal.measurements.checks import SIGMA_RANGE_DEG

SEPARATORS = {",": "a comma", ";": "a semicolon", "\t": "a tab"}
_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+(?:[eE][+-]?\d+)?$")
_DECIMAL_COMMA_HINT = ("kincal reads numbers with a decimal point only; if the file uses decimal "
                       "commas, export it with decimal points (e.g. LC_NUMERIC=C, or a spreadsheet "
                       "set to English)")

# accepted values of the columns of stated standard deviations (both ends included):
# (low, high, unit for the message). ``sigma`` is in the file's length unit, m or mm, so
# the range spans both (1 nm to 1 km in metres, 1 pm to 1 m in millimetres); the set's
# own check (kincal.measurements.kind.check_sigmas) narrows it in SI.
# what a column of numbers that is no joint or coordinate holds, said when a cell is not one
COLUMN_MEANING = {"plane": " (the plane's number: touches with the same number lie on one "
                           "plane; name planes 1, 2, 3, not by words)"}
COLUMN_RANGES = {"sigma": (1e-9, 1e3, "in the file's length unit"),
                 "sigma_deg": (*SIGMA_RANGE_DEG, "deg")}  # a stated orientation sigma's range


@dataclass(frozen=True)
class Columns:
    """The wanted columns of a CSV file.

    values: {column: (R,) floats}, the required columns and the optional ones present.
    lines: (R,) line numbers of the rows in the file (1 = the first line).
    header: every column of the file, in order.
    """

    path: Path
    values: dict
    lines: np.ndarray
    header: tuple[str, ...]
    separator: str = ","

    def ignored(self) -> tuple[str, ...]:
        """The columns of the file that were not read."""
        return tuple(h for h in self.header if h and h not in self.values)


_QUOTE_IF = (",", '"', "\n", "\r")  # a cell holding one of these is quoted (RFC 4180)


def csv_line(cells) -> str:
    """One CSV record, without its line end, as every CSV file kincal writes has its lines:
    the cells (str) joined by commas, a cell holding a comma, a double quote, CR or LF in
    double quotes with its quotes doubled (RFC 4180, as the csv module's QUOTE_MINIMAL
    writes it), any other cell as it is. A record without such a cell is the plain comma
    join, byte for byte; :func:`read_columns` reads a quoted one back to the same names
    (a URDF joint named ``a,b`` is one column)."""
    cells = list(cells)
    line = ",".join(cells)
    if line.count(",") == len(cells) - 1 and '"' not in line and "\n" not in line \
            and "\r" not in line:
        return line if line or len(cells) != 1 else '""'  # one empty cell: not a blank line
    return ",".join('"' + c.replace('"', '""') + '"' if any(q in c for q in _QUOTE_IF) else c
                    for c in cells)


def _content_lines(fh):
    """The lines of ``fh`` with ``#`` comment lines blanked (so line numbers stay)."""
    for line in fh:
        yield "\n" if line.lstrip().startswith("#") else line


def _column_hint(name: str, columns) -> str:
    """' Did you mean ...?' for a missing column: a close spelling, or a column that
    starts with the name (a unit or note added: 'joint_3 [deg]', 'J3 (rad)')."""
    close = suggest(name, columns)
    if close:
        return close
    key = name.lower()
    starts = [c for c in columns if c.lower().startswith(key) and not c[len(key):][:1].isalnum()]
    return (" Did you mean " + " or ".join(repr(c) for c in starts[:3]) + "?") if starts else ""


def _number(cell: str) -> float:
    """The number a cell holds, as ``float()`` reads it but for what no other CSV reader
    takes as a number (numpy's, the fast path's, refuses them): digit separators ("1_000",
    "1_5", which ``float()`` reads as 1000 and 15) and digits other than 0-9 (fullwidth,
    Arabic-Indic: ``float("１")`` is 1.0); nan when it holds none."""
    cell = cell.strip()
    if "_" in cell or not cell.isascii():
        return math.nan
    try:
        return float(cell)
    except ValueError:
        return math.nan


def _python_reads(cell: str) -> bool:
    """Whether ``float()`` reads the cell (the numbers :func:`_number` does not take)."""
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _is_number(cell: str) -> bool:
    """A number, finite or not (:func:`_number`'s rule), or one with a decimal comma."""
    cell = cell.strip()
    return (cell.isascii() and "_" not in cell and _python_reads(cell)) \
        or bool(_DECIMAL_COMMA.match(cell))


def _positions(index) -> str:
    """1-based column positions, runs written as ranges: "2, 34-37"."""
    runs: list[list[int]] = []
    out: list[str] = []
    for i in sorted(index):
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    for a, b in runs:
        out.append(f"{a + 1}" if a == b else f"{a + 1}-{b + 1}")
    return ("column " if len(index) == 1 else "columns ") + ", ".join(out)


def _verb(count: int, one: str, several: str) -> str:
    """The verb agreeing with :func:`_positions`' "column 4" or "columns 4-5"."""
    return one if count == 1 else several


def _shift_hint(header, row, cols) -> str:
    """' the named columns fit the cells k columns to their right ...' for the smallest
    shift k that puts every wanted column on a number and every number (after a leading
    index) under a name, else ''."""
    def number(i):
        try:
            return 0 <= i < len(row) and math.isfinite(_number(row[i]))
        except ValueError:
            return False

    numbers = [i for i in range(1, len(row)) if number(i)]
    for k in sorted(range(-len(row), len(row) + 1), key=abs):
        if k and cols and all(number(c + k) for c in cols) and \
                all(0 <= i - k < len(header) and header[i - k] for i in numbers):
            side = "right" if k > 0 else "left"
            return (f"; the named columns fit the cells {abs(k)} column{'s' * (abs(k) > 1)} to "
                    f"their {side} (the names look shifted)")
    return ""


def _check_fit(path, line: int, header, row, cols, separator: str) -> None:
    """Refuse a header that does not fit the first row: cells without a name, or unnamed
    columns holding numbers (other than a leading index column)."""
    if len(row) > len(header):
        commas = f" (or decimal commas? {_DECIMAL_COMMA_HINT})" if separator == "," else ""
        raise DataError(f"{path}, line {line}: the header does not fit its rows: {len(row)} cells, "
                        f"{len(header)} names ({_positions(range(len(header), len(row)))} "
                        f"{_verb(len(row) - len(header), 'has', 'have')} no name)"
                        f"{_shift_hint(header, row, cols)}{commas}")
    unnamed = [i for i, h in enumerate(header) if not h and i < len(row) and row[i].strip()
               and _is_number(row[i]) and i > 0]
    if unnamed:
        raise DataError(f"{path}, line {line}: the header does not fit its rows: "
                        f"{_positions(unnamed)} {_verb(len(unnamed), 'holds', 'hold')} numbers "
                        f"but {_verb(len(unnamed), 'has', 'have')} no name in the header"
                        f"{_shift_hint(header, row, cols)}; name every data column")


_SEP_LINE = re.compile(r"^\s*sep=(.)\s*$")  # Excel's first line naming the separator
_QUOTED = re.compile(r'"(?:[^"]|"")*(?:"|$)')  # a quoted cell (to the line end if open)


def sniff_separator(header_line: str) -> str:
    """The separator of a CSV file from its header line, outside its quoted cells (a
    quoted name may hold a comma: ``"a,b";joint_2`` is separated by semicolons): a comma
    if there is one, else a semicolon or a tab, whichever occurs (a one-column header: a
    comma)."""
    header_line = _QUOTED.sub("", header_line)
    if "," in header_line:
        return ","
    counts = {sep: header_line.count(sep) for sep in (";", "\t")}
    best = max(counts, key=lambda sep: counts[sep])
    return best if counts[best] else ","


def read_columns(path, required, optional=(), kind: str = "data", expected: str = "",
                 rows_name: str = "samples", aliases=None, ranges=None,
                 header_only: bool = False, joints=()) -> Columns:
    """Read the ``required`` (and any ``optional``) columns of the CSV file ``path``.

    kind: what the file is, for "<kind> file not found". expected: what the required
    columns are, for the message on missing ones. rows_name: what a row is. aliases:
    {column: what it stands for} (e.g. the URDF joint a renamed column holds), for
    messages. ranges: {column: (low, high, unit)} of accepted values (default
    COLUMN_RANGES). Warns a :class:`KincalNote` when the separator is not a comma.
    header_only: read the header and check that it fits the first row; no values. joints:
    the required columns that hold chain joints (a missing one may have been held still).
    """
    ranges = COLUMN_RANGES if ranges is None else ranges
    if not isinstance(path, (str, os.PathLike)) or str(path) == "":
        raise InputFileError(f"the {kind} file must be a path (str or Path), got {path!r}")
    path = Path(path)
    required, optional = list(required), list(optional)
    aliases = dict(aliases or {})
    twice = [c for c in dict.fromkeys(required) if required.count(c) > 1]
    if twice:  # one column for two things (a joint mapped onto a position column, ...)
        c = twice[0]
        what = f"{aliases[c]} and a measured value" if c in aliases else "two values"
        raise DataError(f"{path}: column {c!r} would be read for {what}; give each its own "
                        "column (--joint-columns, --position-columns, --orientation-columns)")
    if not path.exists():
        raise InputFileError(f"{kind} file not found: {path}")
    if path.is_dir():
        raise InputFileError(f"expected a CSV file, got a directory: {path}")
    check_regular_file(path, f"{kind} CSV", MAX_DATA_BYTES)  # no FIFO, /dev/zero, 10 GB file
    _refuse_other_kind(path, kind)
    if not header_only:
        fast = _read_fast(path, required, optional, ranges)
        if fast is not None:
            return fast
    # The careful reading, row by row: a file the fast path does not take (quoted cells,
    # blank or comment lines among the rows, a cell it cannot read) reads here, to the
    # same values or to the message naming the line and column of the first bad cell.
    # Streamed: each row is converted as it is read (8 bytes per wanted cell kept), and the
    # first bad cell stops the reading, however long the file; the separator is sniffed
    # from the header line.
    flat, lines = array("d"), array("q")
    try:
        with open(path, newline="", encoding=_encoding(path)) as fh:
            content = _content_lines(fh)
            pending = []
            for ln in content:  # blank and comment lines before the header
                pending.append(ln)
                if ln.strip():
                    break
            directive = _SEP_LINE.match(pending[-1] if pending else "")
            if directive:  # Excel's "sep=;" line names the separator; the header follows
                separator = directive.group(1)
                if separator not in SEPARATORS:
                    raise DataError(f"{path}: the first line names the separator "
                                    f"{separator!r}; expected a comma, a semicolon or a tab")
                pending[-1] = "\n"  # read as a blank line: the line numbers stay the file's
                for ln in content:  # blank and comment lines before the header
                    pending.append(ln)
                    if ln.strip():
                        break
            else:
                separator = sniff_separator(pending[-1] if pending else "")
            reader = csv.reader(itertools.chain(pending, content), delimiter=separator)
            rows = ((reader.line_num, row) for row in reader if any(c.strip() for c in row))
            first = next(rows, None)
            if first is None:
                raise DataError(f"{path}: the file is empty; expected a header naming "
                                f"{', '.join(required) or 'the columns'}, then rows of numbers")
            header = [h.strip() for h in first[1]]
            if all(_is_number(h) for h in header):  # numpy.savetxt writes "# a,b,c"
                raise DataError(f"{path}: line {first[0]} holds numbers, not column names: the "
                                "header is missing (or commented out with '#'); expected a "
                                f"header naming {', '.join(required) or 'the columns'}")
            dupes = sorted({h for h in header if h and header.count(h) > 1})
            if dupes:
                raise DataError(f"{path}: duplicated column(s) {', '.join(dupes)} in the header")
            missing = [c for c in required if c not in header]
            if missing:
                extra = [h for h in header if h not in required]
                hints = "".join(_column_hint(m, extra) for m in missing)
                held = [aliases.get(m, m) for m in missing
                        if m in joints and not _column_hint(m, extra)]
                if held:  # no close name: a joint not logged, held still while measuring?
                    hints += (f" A chain joint held still during the measurements needs no "
                              f"column: give its value (--joint-value {held[0]}=VALUE).")
                named = [f"{m} (for {aliases[m]})" if m in aliases else m for m in missing]
                raise DataError(f"{path}: missing column(s) {', '.join(named)}.{hints} Expected "
                                f"{expected + ': ' if expected else ''}{', '.join(required)}; "
                                f"the header has {listing(header)}")
            wanted = required + [c for c in optional if c in header and c not in required]
            cols = [header.index(c) for c in wanted]
            limits = [(c, ranges[header[c]]) for c in cols if header[c] in ranges]
            for line, row in rows:
                if not lines:  # the first row tells whether the header fits
                    _check_fit(path, line, header, row, cols, separator)
                    if header_only:  # the rows are left to the reading that follows
                        return Columns(path, {}, np.zeros(0, dtype=int), tuple(header),
                                       separator)
                if len(row) != len(header):
                    hint = (f" (decimal commas? {_DECIMAL_COMMA_HINT})"
                            if separator == "," and len(row) > len(header) else "")
                    raise DataError(f"{path}, line {line}: {len(row)} cells, the header has "
                                    f"{len(header)}{hint}")
                for c in cols:
                    cell = row[c].strip()
                    v = _number(cell)
                    if not math.isfinite(v):
                        what = "an empty cell" if cell == "" else repr(cell)
                        if ("_" in cell or not cell.isascii()) and _python_reads(cell):
                            raise DataError(f"{path}, line {line}, column {header[c]!r}: {what}"
                                            "; expected a finite number written with the "
                                            "digits 0-9 (no '_' digit separators, no other "
                                            "digits: what other CSV readers read)")
                        if _DECIMAL_COMMA.match(cell):
                            raise DataError(f"{path}, line {line}, column {header[c]!r}: {what} "
                                            f"has a decimal comma; {_DECIMAL_COMMA_HINT}")
                        hint = _shift_hint(header, row, cols) if not lines else ""
                        hint += COLUMN_MEANING.get(header[c], "")
                        raise DataError(f"{path}, line {line}, column {header[c]!r}: "
                                        f"{what}; expected a finite number{hint}")
                    flat.append(v)
                for c, (lo, hi, unit) in limits:
                    v = flat[len(flat) - len(cols) + cols.index(c)]
                    if not lo <= v <= hi:
                        raise DataError(f"{path}, line {line}, column {header[c]!r}: {v:g} is "
                                        f"outside the accepted range {lo:g} to {hi:g} ({unit}) "
                                        "of a standard deviation")
                lines.append(line)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputFileError(f"cannot read {path}: {exc}") from exc
    if not lines:
        raise DataError(f"{path}: a header but no {rows_name}")
    if separator != ",":
        warnings.warn(f"{path}: columns separated by {SEPARATORS[separator]} (read from the "
                      f"{'sep= line' if directive else 'header line'})", KincalNote)
    values = np.frombuffer(flat, dtype=float).reshape(len(lines), len(cols)).copy()
    return Columns(path, {c: values[:, k] for k, c in enumerate(wanted)},
                   np.array(lines, dtype=int), tuple(header), separator)


def _refuse_other_kind(path: Path, kind: str) -> None:
    """A URDF or a JSON file (FRAMES.json, ...) given where a CSV file is read: say so,
    rather than name its first line's text as a header without the columns."""
    try:
        with open(path, encoding=_encoding(path)) as fh:
            head = fh.read(4096)
    except (UnicodeError, OSError):
        return  # the reading names it, with its line
    first = next((ln.strip() for ln in head.splitlines()
                  if ln.strip() and not ln.lstrip().startswith("#")), "")
    if first.startswith("<"):
        what = "XML (a URDF or xacro file?)"
    elif first.startswith("{") or re.match(r"\[\s*(?:[{\[\"\d-]|$)", first):
        what = "JSON (a FRAMES.json, REPORT.json or FLEET.json?)"
    else:
        return
    raise DataError(f"{path}: is {what}, not a CSV {kind} file: expected a header line of "
                    "column names, then rows of numbers (is a file given in another's place?)")


def _encoding(path: Path) -> str:
    """UTF-16 when the file starts with its byte-order mark (a spreadsheet's "Unicode
    text"), else UTF-8 (a byte-order mark allowed)."""
    with open(path, "rb") as fh:
        head = fh.read(2)
    return "utf-16" if head in (b"\xff\xfe", b"\xfe\xff") else "utf-8-sig"


_BLANK_OR_COMMENT = re.compile(rb"\n[ \t]*(?:#|\r?\n)")


def _read_fast(path: Path, required, optional, ranges) -> Columns | None:
    """The columns of a plain file in one numpy parse, or None for the careful reading.

    Plain: UTF-8, no quotes, no blank or comment lines after the header, LF or CRLF line
    ends, every cell of every column a number numpy reads, each row as long as the
    header, no unnamed column after the first. numpy reads a subset of what ``float()``
    reads and to the same double; its values are taken only when every wanted cell is
    finite and in range and there is one row per line, so they are the values of the
    careful reading. Anything else returns None: the careful reading then gives its
    values or its message (line and column) for the first bad cell."""
    try:
        raw = path.read_bytes()
        if b'"' in raw or (b"\r" in raw and raw.count(b"\r") != raw.count(b"\r\n")):
            return None
        start, number = (3 if raw.startswith(b"\xef\xbb\xbf") else 0), 1
        while True:  # blank and comment lines before the header
            end = raw.find(b"\n", start)
            first = raw[start:len(raw) if end < 0 else end].decode("utf-8").strip()
            if first and not first.startswith("#") or end < 0:
                break
            start, number = end + 1, number + 1
        stop = len(raw)  # the rows: from the header's line end to the last non-blank
        while stop > start and raw[stop - 1] in b" \t\r\n":
            stop -= 1
        if end < 0 or end >= stop or _BLANK_OR_COMMENT.search(raw, end, stop) or \
                _SEP_LINE.match(first):
            return None
        rows = raw.count(b"\n", end, stop)
        del raw
    except (OSError, UnicodeDecodeError):  # the careful reading names an undecodable file
        return None
    separator = sniff_separator(first)
    header = [h.strip() for h in first.split(separator)]
    if any(not h for h in header[1:]) or len(set(header)) < len(header) or any(
            c not in header for c in required):
        return None
    wanted = list(required) + [c for c in optional if c in header and c not in required]
    cols = [header.index(c) for c in wanted]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy's "empty input" warning: None below
            table = np.loadtxt(path, delimiter=separator, comments=None, skiprows=number,
                               ndmin=2, encoding="utf-8-sig")
    except (ValueError, OSError):
        return None
    if table.shape != (rows, len(header)):
        return None
    values = table if cols == list(range(len(header))) else table[:, cols]  # all: no copy
    if not np.isfinite(values).all():
        return None
    for k, c in enumerate(wanted):
        if c in ranges and not ((ranges[c][0] <= values[:, k]) & (values[:, k] <= ranges[c][1])).all():
            return None
    if separator != ",":
        warnings.warn(f"{path}: columns separated by {SEPARATORS[separator]} (read from the "
                      "header line)", KincalNote)
    values = np.ascontiguousarray(values)
    return Columns(path, {c: values[:, k] for k, c in enumerate(wanted)},
                   np.arange(number + 1, number + 1 + rows), tuple(header), separator)
