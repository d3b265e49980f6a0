"""Checks on a file the user gives as input, before a byte of it is read, and on the JSON
value read from it (nesting depth, non-finite numbers).

A path to a FIFO, a device (``/dev/zero``, ``/dev/stdin``) or a socket would block or
never end; a file far larger than any real input would fill the memory. Both are
refused here with a message that says what was expected, so that readers can trust
that what they open is a regular file of bounded size.
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

from kincal.errors import InputFileError

MAX_DATA_BYTES = 256 * 2**20
"""Largest data or candidates CSV accepted [bytes]: about 1.5 million rows of 9 columns."""

MAX_JSON_BYTES = 16 * 2**20
"""Largest FRAMES.json accepted [bytes]; a real one is under 10 kB."""


def check_regular_file(path, kind: str, max_bytes: int) -> int:
    """The size [bytes] of ``path``; raise :class:`InputFileError` unless it is a regular file
    of at most ``max_bytes``. kind: what the file is, for the message ("data", "URDF")."""
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise InputFileError(f"{kind} file not found: {p}") from None
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputFileError(f"expected a {kind} file, got a directory: {p}")
    if not stat.S_ISREG(st.st_mode):
        what = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else
                "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
        raise InputFileError(f"{p}: is {what}; expected a regular {kind} file (save the "
                             "stream to a file first)")
    if st.st_size > max_bytes:
        raise InputFileError(f"{p}: {st.st_size / 2**20:.0f} MB; kincal reads {kind} files of "
                             f"at most {max_bytes // 2**20} MB")
    return st.st_size


def read_json(path, kind: str, what: str, error=InputFileError, expected: str = "",
              max_bytes: int = MAX_JSON_BYTES):
    """The JSON value of the file ``path``, read as every JSON input of kincal is read.

    kind: what the file is, for "<kind> file not found" ("frames", "fleet prior"); what:
    the file it should be, for "<path>: not <what> (...)" ("a kincal frames file");
    expected: what an empty file should have held. Refused as :func:`check_regular_file`
    refuses (a FIFO, a device, a directory, over ``max_bytes``), then with ``error``: text
    that is not UTF-8 (a byte-order mark is accepted, as in a CSV file), an empty file,
    invalid JSON, JSON nested too deeply to parse."""
    import json

    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{kind} file not found: {p}")
    check_regular_file(p, kind, max_bytes)  # no FIFO, device or huge file
    try:
        text = p.read_text(encoding="utf-8-sig")  # a byte-order mark, as CSV files may have
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{p}: not {what} ({exc})") from None
    if not text.strip():
        raise error(f"{p}: the {kind} file is empty; expected {expected or what}")
    try:
        return json.loads(text)
    except RecursionError:
        raise error(f"{p}: not {what} (JSON nested too deeply)") from None
    except ValueError as exc:
        first = next((ln.strip() for ln in text.splitlines()
                      if ln.strip() and not ln.lstrip().startswith("#")), "")
        if first.startswith("<"):  # as a CSV reader names a URDF given in a data file's place
            other = "XML (a URDF or xacro file?)"
        elif not first.startswith(("{", "[")) and any(c in first for c in ",;\t"):
            other = "a CSV file (a data file?)"
        else:
            raise error(f"{p}: not {what} (invalid JSON: {exc})") from None
        raise error(f"{p}: is {other}, not {what} (is a file given in another's place?)") \
            from None


def non_finite_path(value, where: str = "") -> str:
    """The key path of the first NaN or infinite number in a JSON value, or ""."""
    stack = [(where, value)]
    while stack:
        path, v = stack.pop()
        if isinstance(v, float) and not math.isfinite(v):
            return path or "a value"
        if isinstance(v, dict):
            stack.extend((f"{path}.{k}" if path else str(k), x) for k, x in v.items())
        elif isinstance(v, list):
            stack.extend((f"{path}[{i}]", x) for i, x in enumerate(v))
    return ""


def json_depth(value, limit: int) -> int:
    """Nesting depth of a JSON value, counted up to ``limit`` (iteratively)."""
    depth, level = 0, [value]
    while level and depth <= limit:
        nxt: list = []
        for v in level:
            nxt.extend(v.values() if isinstance(v, dict) else v if isinstance(v, list) else ())
        if nxt:
            depth += 1
        level = nxt
    return depth


def file_sha256(path) -> str:
    """SHA-256 of a file's bytes (hex), read in pieces: a large data file is never held
    whole (``hashlib.file_digest`` is Python 3.11's; kincal runs on 3.10)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for piece in iter(lambda: fh.read(1 << 20), b""):
            h.update(piece)
    return h.hexdigest()


def same_files(files) -> tuple[str, str, str] | None:
    """(first, second, how) for the first two of ``files`` that are one file (a path given
    twice, a link to it: one inode) or hold the same bytes, else None; how: "is given
    twice", "is FIRST" or "has the same bytes as FIRST". Files that cannot be read are left
    to their reader."""
    import contextlib

    stats = []
    for f in files:
        with contextlib.suppress(OSError):
            if os.path.isfile(f):
                stats.append((str(f), os.stat(f)))
    keys: dict = {}
    for f, st in stats:  # the same file: one inode
        keys.setdefault((st.st_dev, st.st_ino), []).append(f)
    sizes = [st.st_size for _, st in stats]
    for f, st in stats:  # the same bytes: hashed only where two files share a size
        if sizes.count(st.st_size) > 1 and len(keys[(st.st_dev, st.st_ino)]) == 1:
            keys.setdefault(file_sha256(f), []).append(f)
    for key, same in keys.items():
        if len(same) > 1:
            how = ("is given twice" if same[0] == same[1] else f"is {same[0]}"
                   if isinstance(key, tuple) else f"has the same bytes as {same[0]}")
            return same[0], same[1], how
    return None
