"""Provenance: which kincal, inputs and command made a file, and what the gate said.

Every file kincal writes carries one :class:`Provenance`, built here and only here
(:meth:`Provenance.of` for a calibration, :meth:`Provenance.of_run` for the other
commands), in the form its format allows (:meth:`Provenance.stamp`): a comment in the
URDF and Markdown, ``#`` lines in the YAML and CSV files, a ``"provenance"`` object in the
JSON files, a section of the HTML pages, text fields of the PNG plots. The writers
(:mod:`kincal.export.outputs`) put it in.

The time is the UTC time of the run, or ``SOURCE_DATE_EPOCH`` when it is set (the
reproducible-builds convention: the same inputs, command and epoch give byte-identical
files). Checksums are SHA-256 of the bytes on disk when the file is stamped; the robot
description's text as kincal parsed it (a xacro expanded with its arguments) has its own.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from kincal.errors import ExportError
from kincal.export.writer import printable


@dataclass(frozen=True)
class FileHash:
    """A file read by the run: its path as given and SHA-256 of its bytes (None: no file
    on disk, e.g. data made in code)."""

    path: str
    sha256: str | None

    @classmethod
    def of(cls, path) -> "FileHash":
        p = str(path)
        if p.startswith("<") or not Path(p).is_file():
            return cls(printable(p), None)
        from kincal.input_files import file_sha256

        return cls(printable(p), file_sha256(p))


@dataclass(frozen=True)
class Provenance:
    """Where a file kincal writes comes from.

    kincal_version: the package version. created_utc: ISO 8601 time [UTC] of the run
    (SOURCE_DATE_EPOCH when set). command: the command line, shell-quoted (None: the
    Python API). robot: the robot description file (URDF or xacro); robot_text_sha256:
    SHA-256 of the URDF text parsed (the xacro's expansion); xacro_args: (name, value)
    pairs it was expanded with. data: every data file. verdict: the gate's verdict,
    "plausible", "accepted" (implausible or unconverged, accepted as asked) or "REFUSED",
    "no gate" where none stands in front of the file (simulate, plan, ...); gate: its findings in one line ("no finding" when plausible and converged).
    """

    kincal_version: str
    created_utc: str
    command: str | None
    robot: FileHash
    robot_text_sha256: str
    xacro_args: tuple[tuple[str, str], ...]
    data: tuple[FileHash, ...]
    verdict: str
    gate: str

    @classmethod
    def of(cls, result, *, command=None, xacro_args=None, refused: str | None = None,
           more_data=()) -> "Provenance":
        """The provenance of ``result`` (a CalibrationResult) written now.

        command: the command line (a list of arguments or one string; None: the Python
        API). xacro_args: {name: value} of a xacro description. refused: the gate's
        refusal message when the files are a refused run's diagnosis. more_data: further
        files read (the held-out data).
        """
        p = result.plausibility
        if refused is not None:
            verdict, gate = "REFUSED", refused
        elif p is None:
            verdict, gate = "unchecked", "no plausibility verdict in the result"
        elif p.findings:
            verdict = "accepted"
            gate = "; ".join(f.message for f in p.findings) + " (accepted as asked)"
        else:
            verdict, gate = "plausible", "no finding"
        return cls.of_run(result.robot, (*(s.source for s in result.sets), *more_data),
                          command=command, xacro_args=xacro_args, verdict=verdict, gate=gate)

    @classmethod
    def of_run(cls, robot=None, data=(), *, command=None, xacro_args=None,
               verdict: str = "no gate",
               gate: str = "no plausibility gate applies to this output") -> "Provenance":
        """The provenance of a command's files written now: ``robot`` the Robot it loaded
        (None: none), ``data`` every file it read (paths; None entries are skipped),
        command / xacro_args as in :meth:`of` (None: those the robot was loaded with),
        verdict / gate what a gate said."""
        from kincal import __version__

        if command is not None and not isinstance(command, str):
            import shlex

            command = shlex.join(str(a) for a in command)
        if command is not None:
            command = printable(command)
        files = tuple(FileHash.of(p) for p in data if p is not None)
        if robot is None:
            robot_file, text_sha = FileHash("(no robot)", None), "(no robot)"
        else:
            robot_file = FileHash.of(robot.source or "<robot>")
            text_sha = _sha256(robot.urdf_text.encode("utf-8"))
        if xacro_args is None:
            xacro_args = dict(getattr(robot, "xacro_args", ()))
        return cls(__version__, utc_now(), command, robot_file, text_sha,
                   tuple(sorted((printable(str(k)), printable(str(v)))
                                for k, v in xacro_args.items())),
                   files, verdict, printable(gate))

    def _stamped_pieces(self, kind: str, pieces):
        """The pieces of a text file, its first stamped (it holds the title or header)."""
        yield self.stamp(kind, next(pieces, ""))
        yield from pieces

    def stamp(self, kind: str, content):
        """``content`` of a file of format ``kind`` with this provenance in it: "json" (a
        dict, given a "provenance" key, returned as JSON text), "csv" / "yaml" (text: ``#``
        lines after a ``#`` title line, else first), "urdf" (:func:`stamp_urdf`), "html"
        (a section before ``</body>``), "md" (an HTML comment first), "png" (a function of
        the PNG text fields returning the PNG bytes, :meth:`png_text`)."""
        if kind == "json":
            from kincal.export.report import dumps

            if not isinstance(content, dict):
                raise ExportError(f"a JSON output is given as a dict, got {type(content).__name__}")
            return dumps({**content, "provenance": self.as_dict()})
        if kind == "png":
            return content(self.png_text())
        if kind in ("csv", "yaml"):
            if not isinstance(content, str):  # text in pieces, written as they come
                return self._stamped_pieces(kind, iter(content))
            return (self.under_title(content) if content.startswith("#")
                    else self.hash_comment() + content)
        if kind == "urdf":
            return stamp_urdf(content, self)
        if kind == "md":
            return self.xml_comment() + "\n" + content
        if kind == "html":
            from kincal.export.html_run import provenance_section

            section = ('<section id="provenance">\n<h2>Provenance</h2>\n'
                       f"{provenance_section(self)}\n</section>\n")
            head, body_end, tail = content.rpartition("</body>")
            if not body_end:
                raise ExportError("an HTML output without </body>: no place for its provenance")
            return head + section + body_end + tail
        raise ExportError(f"no provenance stamp for a {kind!r} file; expected json, csv, yaml, "
                          "urdf, html, md or png")

    def as_dict(self) -> dict:
        """For the JSON files."""
        return {"kincal_version": self.kincal_version, "created_utc": self.created_utc,
                "command": self.command,
                "robot": {"path": self.robot.path, "sha256": self.robot.sha256,
                          "urdf_text_sha256": self.robot_text_sha256,
                          "xacro_args": dict(self.xacro_args)},
                "data": [{"path": d.path, "sha256": d.sha256} for d in self.data],
                "gate": {"verdict": self.verdict, "findings": self.gate}}

    def lines(self) -> list[str]:
        """The provenance as ``key: value`` lines (for comments and headers)."""
        out = [f"made by kincal {self.kincal_version} at {self.created_utc}",
               "command: " + (self.command if self.command is not None else "(Python API)"),
               f"robot: {self.robot.path} sha256 {self.robot.sha256 or '(no file)'}",
               f"robot URDF text parsed: sha256 {self.robot_text_sha256}"]
        if self.xacro_args:
            out.append("xacro args: " + " ".join(f"{k}:={v}" for k, v in self.xacro_args))
        out += [f"data: {d.path} sha256 {d.sha256 or '(no file)'}" for d in self.data]
        out.append(f"plausibility gate: {self.verdict} ({self.gate})")
        return [" ".join(line.split()) for line in out]  # each one line, whatever was given

    def hash_comment(self) -> str:
        """``# ``-comment lines (YAML, CSV), newline-terminated."""
        return "".join(f"# {line}\n" for line in self.lines())

    def under_title(self, text: str) -> str:
        """A ``#``-commented text (YAML, CSV) with the provenance lines after its first
        line, the file's title."""
        title, newline, rest = text.partition("\n")
        return title + newline + self.hash_comment() + rest

    def xml_comment(self) -> str:
        """One XML comment. XML forbids "--" inside a comment: the command line's "--"
        are written "-\\-" there (said in the comment)."""
        body = "\n     ".join(map(_no_double_hyphen, self.lines()))
        return (f"<!-- {body}\n     (in this comment \"-\\-\" stands for two hyphens, which "
                "XML comments cannot hold) -->")

    def png_text(self) -> dict[str, str]:
        """Text fields of a PNG (matplotlib's savefig metadata; tEXt chunks, iTXt where a
        value is not Latin-1): the PNG keywords Software (kincal and its version), Source
        (the command line), Creation Time, Description (one line: the robot, the data
        files, the verdict) and Comment (:meth:`lines`), and "kincal-provenance": the
        JSON object the JSON files carry (:meth:`as_dict`), for programs."""
        import json

        robot = ("no robot description" if self.robot.path == "(no robot)"
                 else f"robot {self.robot.path}")
        data = ("data " + ", ".join(d.path for d in self.data)) if self.data else "no data file"
        return {"Software": f"kincal {self.kincal_version}",
                "Source": self.command if self.command is not None else "kincal (Python API)",
                "Creation Time": self.created_utc,
                "Description": " ".join(f"made by kincal {self.kincal_version} from {robot} and "
                                        f"{data}; plausibility gate: {self.verdict}".split()),
                "Comment": "\n".join(self.lines()),
                "kincal-provenance": json.dumps(self.as_dict())}


def utc_now() -> str:
    """The time of the run [UTC], ISO 8601 to the second: SOURCE_DATE_EPOCH if set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch is not None and epoch.strip():
        try:
            t = datetime.fromtimestamp(int(epoch), tz=timezone.utc)
        except (ValueError, OverflowError, OSError):
            raise ExportError(f"SOURCE_DATE_EPOCH={epoch!r} is not a time; expected whole "
                              "seconds since 1970-01-01 UTC (e.g. 1700000000)") from None
    else:
        t = datetime.now(timezone.utc)
    return t.replace(microsecond=0).strftime("%Y-%m-%dT%H:%M:%SZ")


def _no_double_hyphen(line: str) -> str:
    while "--" in line:  # "---" needs two passes
        line = line.replace("--", "-\\-")
    return line


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# ------------------------------------------------------------ the corrected URDF's header
_BANNER_WORDS = ("autogenerated", "auto-generated", "generated by", "generated from",
                 "editing this file by hand")


def stamp_urdf(text: str, provenance: Provenance) -> str:
    """The URDF text with a foreign generator banner removed and kincal's provenance
    comment put before the root element.

    The comment goes after the XML declaration and the processing instructions that
    precede the root element (urdfdom's XML reader, TinyXML-2, refuses a declaration or
    processing instruction after a comment), on a line of its own where the last of them
    ends its line, else just before the root element; a byte-order mark stays first.
    A banner is the run of whole-line comments that follows there, before the root
    element, and says the file was generated (xacro's "This document was autogenerated by
    xacro ... EDITING THIS FILE BY HAND IS NOT RECOMMENDED" box): it no longer holds once
    kincal has changed the origins. Any other comment, or a banner anywhere else, is kept
    byte for byte.
    """
    newline = "\r\n" if "\r\n" in text else "\n"
    comment = provenance.xml_comment().replace("\n", newline) + newline
    after, root = _prolog(text)
    eol = text.find("\n", after)
    if text[after - 1:after] == "\n" or text[:after] in ("", "\ufeff"):
        at = after  # at a line start already: the start of the file, say
    elif eol != -1 and eol < root and not text[after:eol].strip():
        at = eol + 1  # the declaration (or instruction) ends its line: the next line
    else:  # other content shares the line: before the root element, on its own line
        at = text.rfind("\n", after, root) + 1
        if at == 0 or text[at:root].strip():
            return text[:root] + comment + text[root:]
    end = at
    for line in text[at:root].split(newline)[:-1]:  # whole lines only, before the root
        if not _whole_comment(line):
            break
        end += len(line) + len(newline)
    if end > at and any(w in text[at:end].lower() for w in _BANNER_WORDS):
        return text[:at] + comment + text[end:]
    return text[:at] + comment + text[at:]


class _Root(Exception):
    """Raised to stop the prolog's parse at the root element."""


def _prolog(text: str) -> tuple[int, int]:
    """(offset just after the last XML declaration or processing instruction before the
    root element, 0 if none (1 after a byte-order mark), offset of the root element's
    start tag), in characters of ``text``, a URDF that has been read."""
    from xml.parsers import expat

    data = text.encode("utf-8")
    parser = expat.ParserCreate(encoding="UTF-8")
    after = 3 if data.startswith(b"\xef\xbb\xbf") else 0

    def instruction(*_):
        nonlocal after
        after = data.index(b"?>", parser.CurrentByteIndex) + 2

    def start(*_):
        raise _Root(parser.CurrentByteIndex)

    parser.XmlDeclHandler = instruction
    parser.ProcessingInstructionHandler = instruction
    parser.StartElementHandler = start
    try:
        parser.Parse(data, True)
    except _Root as found:
        root = found.args[0]
    else:  # pragma: no cover - a URDF that was read has a root element
        raise ExportError("the URDF text has no root element: no place for its provenance")
    return len(data[:after].decode("utf-8")), len(data[:root].decode("utf-8"))


def _whole_comment(line: str) -> bool:
    s = line.strip()
    return s.startswith("<!--") and s.endswith("-->") and "-->" not in s[4:-3]
