"""Numeric columns of a CSV file, with errors that name the file, line and column.

The one CSV reader behind :class:`kincal.measurements.Measurements` and the candidate
poses of :mod:`kincal.candidates`. A header row names the columns; blank lines are
skipped (line numbers stay those of the file); a byte-order mark is accepted. Every cell
of a wanted column must be a finite number.
"""

from __future__ import annotations

import csv
import math
import os
from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kincal.errors import DataError, InputFileError, listing, suggest
from kincal.input_files import MAX_DATA_BYTES, check_regular_file


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

    def ignored(self) -> tuple[str, ...]:
        """The columns of the file that were not read."""
        return tuple(h for h in self.header if h not in self.values)


def read_columns(path, required, optional=(), kind: str = "data", expected: str = "",
                 rows_name: str = "samples") -> Columns:
    """Read the ``required`` (and any ``optional``) columns of the CSV file ``path``.

    kind: what the file is, for "<kind> file not found". expected: what the required
    columns are, for the message on missing ones. rows_name: what a row is.
    """
    if not isinstance(path, (str, os.PathLike)) or str(path) == "":
        raise InputFileError(f"the {kind} file must be a path (str or Path), got {path!r}")
    path = Path(path)
    required, optional = list(required), list(optional)
    if not path.exists():
        raise InputFileError(f"{kind} file not found: {path}")
    if path.is_dir():
        raise InputFileError(f"expected a CSV file, got a directory: {path}")
    check_regular_file(path, f"{kind} CSV", MAX_DATA_BYTES)  # no FIFO, /dev/zero, 10 GB file
    # Streamed: each row is converted as it is read (8 bytes per wanted cell kept), and the
    # first bad cell stops the reading, however long the file.
    flat, lines = array("d"), array("q")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            rows = ((reader.line_num, row) for row in reader if any(c.strip() for c in row))
            first = next(rows, None)
            if first is None:
                raise DataError(f"{path}: the file is empty; expected a header with "
                                f"{', '.join(required)}")
            header = [h.strip() for h in first[1]]
            dupes = sorted({h for h in header if header.count(h) > 1})
            if dupes:
                raise DataError(f"{path}: duplicated column(s) {', '.join(dupes)} in the header")
            missing = [c for c in required if c not in header]
            if missing:
                extra = [h for h in header if h not in required]
                hints = "".join(suggest(m, extra) for m in missing)
                raise DataError(f"{path}: missing column(s) {', '.join(missing)}.{hints} Expected "
                                f"{expected + ': ' if expected else ''}{', '.join(required)}; the "
                                f"header has {listing(header)}")
            wanted = required + [c for c in optional if c in header and c not in required]
            cols = [header.index(c) for c in wanted]
            for line, row in rows:
                if len(row) != len(header):
                    raise DataError(f"{path}, line {line}: {len(row)} cells, the header has "
                                    f"{len(header)}")
                for c in cols:
                    cell = row[c].strip()
                    try:
                        v = float(cell)
                    except ValueError:
                        v = math.nan
                    if not math.isfinite(v):
                        what = "an empty cell" if cell == "" else repr(cell)
                        raise DataError(f"{path}, line {line}, column {header[c]!r}: {what}; "
                                        "expected a finite number")
                    flat.append(v)
                lines.append(line)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputFileError(f"cannot read {path}: {exc}") from exc
    if not lines:
        raise DataError(f"{path}: a header but no {rows_name}")
    values = np.frombuffer(flat, dtype=float).reshape(len(lines), len(cols)).copy()
    return Columns(path, {c: values[:, k] for k, c in enumerate(wanted)},
                   np.array(lines, dtype=int), tuple(header))
