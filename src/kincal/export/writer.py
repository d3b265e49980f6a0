"""The one writer's general form: files each stamped with their run's provenance, written
as one transaction.

:func:`write_files` is how every file outside a calibration's (behind the gate,
:func:`kincal.export.outputs.write_calibration`) is written: the commands' files, the
demo's, the PNGs of the public plot functions. Each :class:`File` gets the provenance in
its format (:meth:`kincal.export.provenance.Provenance.stamp`), then all are written or
none (:func:`kincal.export.safe_write.write_all`). It sits under the figure modules so
that :mod:`kincal.export.plots` writes through it without an import cycle
(:mod:`kincal.export.outputs` draws the calibration's figures); outputs re-exports it and
is its face. :func:`printable` is how a name (a path, the command line) is written into
any of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class File:
    """One file of a command other than calibrate, for :func:`write_files`: where it goes,
    its format (the kinds of :meth:`kincal.export.provenance.Provenance.stamp`: json, csv,
    yaml, urdf, html, md, png) and its content in that kind's form."""

    path: Path | str
    kind: str
    content: object


def write_files(files, provenance, *, overwrite: bool, protect=(), dirs=(),
                before_commit=None) -> list[Path]:
    """The one writer of every file other than a calibration's: each :class:`File`
    stamped with ``provenance`` (a Provenance) in its format, then all written or none
    (:func:`kincal.export.safe_write.write_all`; before_commit as there). Returns the
    written paths."""
    from kincal.export.safe_write import write_all

    staged = [(f.path, provenance.stamp(f.kind, f.content)) for f in files]
    return write_all(staged, overwrite=overwrite, protect=protect, dirs=dirs,
                     before_commit=before_commit)


def printable(text: str) -> str:
    """``text`` as every file kincal writes can hold it (UTF-8, XML 1.0): bytes of a file
    name that did not decode (Python holds them as lone surrogates, U+DC80-U+DCFF) written
    ``\\xNN``, other lone surrogates ``\\uNNNN``, control characters but tab and line ends
    ``\\xNN`` (an XML comment cannot hold them; a UTF-8 file cannot hold a surrogate)."""
    if text.isprintable():
        return text
    out = []
    for c in text:
        n = ord(c)
        if 0xDC80 <= n <= 0xDCFF:
            out.append(f"\\x{n - 0xDC00:02x}")
        elif 0xD800 <= n <= 0xDFFF or n in (0xFFFE, 0xFFFF):
            out.append(f"\\u{n:04x}")
        elif n < 0x20 and c not in "\t\n\r" or n == 0x7F:
            out.append(f"\\x{n:02x}")
        else:
            out.append(c)
    return "".join(out)
