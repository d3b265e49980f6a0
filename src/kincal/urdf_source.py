"""Read a URDF file as text and refuse what kincal cannot use safely.

The text is returned unchanged (line endings, comments and all) so that
:mod:`kincal.urdf_export` can later write corrected joint origins into it and
nothing else. The checks run on stdlib expat, which reports entity declarations
before expanding them, so an entity bomb is rejected without being expanded.

A xacro file (``.xacro`` suffix, or xacro elements or substitutions in the text) is
expanded first (:mod:`kincal.xacro_source`) and the expanded text checked and returned.
"""

from __future__ import annotations

import math
import os
import re
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from xml.parsers import expat

from kincal.errors import InputFileError, UrdfError
from kincal.input_files import check_regular_file

MAX_URDF_BYTES = 20 * 1024 * 1024
"""Largest URDF accepted [bytes]; real robots are well under 1 MB."""

MAX_ORIGIN_M = 1e6
"""Farthest a joint origin may lie from its parent link [m]: a typo (1e300 for 1e-3) beyond
it made the kinematics overflow into NaN and a traceback; a robot is far smaller."""

MAX_URDF_LINKS = 2000
"""Most links accepted. Real robots have tens to a few hundred; Pinocchio's URDF parser
recurses once per level of the tree and crashes the process (a segmentation fault, not
an exception) on chains of a few thousand links, so kincal refuses them first."""

XACRO_HINT = "run `xacro file.urdf.xacro > file.urdf` first and pass the generated URDF"


class XacroLeftError(UrdfError):
    """Xacro elements or substitutions in text that should be plain URDF."""

@contextmanager
def stderr_captured():
    """Collect what C++ code writes to file descriptor 2 (urdfdom's multi-line messages,
    which :mod:`kincal.robot` turns into one line).

    Yields a list that receives the captured text when the block ends; fd 2 is restored
    whatever happens (an exception or a signal included).
    """
    sys.stderr.flush()
    out: list[str] = []
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield out
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            out.append(tmp.read(65536).decode("utf-8", errors="replace"))


# Namespace URIs that xacro files bind (both spellings occur in the wild).
_XACRO_URIS = ("ros.org/wiki/xacro",)
# ${expr} and $(arg ...) / $(find ...) are xacro substitutions; plain URDF has none.
_SUBSTITUTION = re.compile(r"\$[{(]")
_DECLARED_ENCODING = re.compile(
    rb"""^(?:\xef\xbb\xbf)?\s*<\?xml[^>]*?encoding\s*=\s*["']([A-Za-z0-9._-]+)["']"""
)
_UTF8_NAMES = ("utf-8", "utf8", "us-ascii", "ascii")
_MOVING = ("revolute", "continuous", "prismatic")  # joints whose axis is used


def read_urdf_text(path, xacro_args=None) -> str:
    """The text of the URDF file at ``path``, checked by :func:`check_urdf_text`.

    Raises :class:`InputFileError` for a missing, unreadable or directory path and
    :class:`UrdfError` for a file over :data:`MAX_URDF_BYTES`, text that is not
    UTF-8, or anything :func:`check_urdf_text` rejects. Line endings are kept. A xacro
    file comes back expanded (see the module notes), ``xacro_args`` {name: value} set; they
    are refused for a plain URDF (they would be ignored).
    """
    p = Path(path)
    if p.exists() and not p.is_dir():  # a FIFO would block open(); a device never ends
        check_regular_file(p, "URDF", 2**62)  # the size is bounded below, while reading
    try:
        with open(p, "rb") as f:
            # read one byte past the limit: also bounds special files whose stat size lies
            data = f.read(MAX_URDF_BYTES + 1)
    except FileNotFoundError:
        raise InputFileError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise InputFileError(f"{p}: is a directory, expected a URDF file") from None
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    if len(data) > MAX_URDF_BYTES:
        raise UrdfError(f"{p}: larger than {MAX_URDF_BYTES // 2**20} MB; not a URDF kincal will read")
    declared = _DECLARED_ENCODING.match(data)
    if declared and declared.group(1).decode("ascii").lower() not in _UTF8_NAMES:
        # kincal writes the text back as UTF-8; accepting another encoding would
        # leave an XML declaration that lies about the corrected file
        raise UrdfError(
            f"{p}: declares encoding {declared.group(1).decode('ascii')!r}; kincal reads "
            "UTF-8 URDFs only (convert with `iconv -t UTF-8` and fix the XML declaration)"
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UrdfError(f"{p}: not UTF-8 text (invalid byte at offset {exc.start})") from None
    try:
        check_urdf_text(text, source=str(p))
    except XacroLeftError:
        pass  # a xacro file: expanded below
    else:
        if p.suffix != ".xacro":
            if xacro_args:
                raise UrdfError(f"{p}: is plain URDF, not xacro: the xacro arguments "
                                f"{' '.join(f'{k}:={v}' for k, v in xacro_args.items())} would "
                                "be ignored; drop them, or give the .xacro file")
            return text
    from kincal.xacro_source import expand_xacro

    text = expand_xacro(p, MAX_URDF_BYTES, xacro_args)
    check_urdf_text(text, source=f"{p} (expanded by xacro)")
    return text


def urdf_tree(text: str):
    """The URDF ``text`` (checked) as an ElementTree element, its element names as urdfdom
    reads them: a default namespace (``<robot xmlns="http://drake.mit.edu">``, which Drake's
    URDFs declare and urdfdom ignores) is taken off, so that ``findall("joint")`` finds the
    joints there too. Raises ``xml.etree.ElementTree.ParseError`` for text that is not XML."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(text.encode("utf-8"))
    if root.tag.startswith("{"):  # "{uri}robot": the root is <robot>, so uri is the default
        prefix = root.tag[:root.tag.index("}") + 1]
        for e in root.iter():
            if isinstance(e.tag, str) and e.tag.startswith(prefix):
                e.tag = e.tag[len(prefix):]
    return root


def check_urdf_text(text: str, source: str = "<string>") -> None:
    """Raise :class:`UrdfError` unless ``text`` is plain, safe URDF XML.

    Rejected: malformed XML (message gives ``source:line:column``, undefined
    entities included); a DOCTYPE with an internal subset (entity declarations) or
    an external DTD; xacro elements (``<xacro:macro>``, ``<xacro:include>``, ...) or
    ``${...}`` / ``$(...)`` substitutions in attribute values; a root element other
    than ``<robot>``. An ``xmlns:xacro`` declaration alone is accepted: generated
    URDFs often keep it.
    """
    start = text.lstrip("\ufeff \t\r\n")
    if start and not start.startswith("<"):  # a data file given as the robot, say
        first = start.splitlines()[0][:40]
        raise UrdfError(f"{source}: not XML (it begins {first!r}): expected a URDF or xacro "
                        "file, which begins with '<' (is a data file given in its place?)")
    # The encoding argument overrides the document's declaration: we hand expat
    # the str encoded as UTF-8, whatever the declaration says.
    parser = expat.ParserCreate(encoding="UTF-8")
    xacro_prefixes = {"xacro"}
    seen_root = False
    n_links = 0
    joint = None  # (name, type) of the <joint> being read
    origins = 0  # the <origin> elements of that joint so far (its own, not its children's)
    depth, joint_depth = 0, -1  # of the element being read, and of that joint
    parent_of: dict[str, str] = {}  # child link: the joint it hangs from

    def fail(problem: str, error=UrdfError):
        where = f"{source}:{parser.CurrentLineNumber}:{parser.CurrentColumnNumber + 1}"
        raise error(f"{where}: {problem}")

    def on_doctype(name, system_id, public_id, has_internal_subset):
        # Called before the internal subset is read: a bomb stops here, unexpanded.
        if has_internal_subset:
            fail("DOCTYPE with an internal subset (entity declarations) is not accepted in a URDF")
        # expat does not load external DTDs, so the entities one declares would be
        # dropped silently from attribute values instead of failing
        if system_id or public_id:
            fail("DOCTYPE referring to an external DTD is not accepted in a URDF")

    def on_entity_decl(name, *rest):
        fail(f"entity declaration {name!r} is not accepted in a URDF")

    def on_start(name, attrs):
        nonlocal seen_root, depth
        depth += 1
        for key, value in attrs.items():
            if key.startswith("xmlns:") and any(uri in value for uri in _XACRO_URIS):
                xacro_prefixes.add(key[len("xmlns:"):])
        prefix, colon, _ = name.partition(":")
        if colon and prefix in xacro_prefixes:
            fail(f"xacro element <{name}> left in the URDF; {XACRO_HINT}", XacroLeftError)
        for key, value in attrs.items():
            if _SUBSTITUTION.search(value):
                fail(f"xacro substitution in <{name} {key}={value!r}>; {XACRO_HINT}",
                     XacroLeftError)
        if not seen_root:
            seen_root = True
            if name != "robot":
                fail(f"root element is <{name}>, expected <robot>")
        _check_element(name, attrs)

    def _check_element(name, attrs):
        nonlocal n_links, joint, origins, joint_depth
        own = joint is not None and depth == joint_depth + 1  # an element of the joint's own
        if name == "link":
            n_links += 1
            if n_links > MAX_URDF_LINKS:
                fail(f"more than {MAX_URDF_LINKS} links; kincal reads URDFs of at most "
                     f"{MAX_URDF_LINKS} links (Pinocchio's parser cannot take much deeper trees)")
        elif name == "joint" and "type" in attrs:  # <joint> inside <transmission> has no type
            joint, origins, joint_depth = (attrs.get("name", "?"), attrs["type"]), 0, depth
        elif name == "child" and own:
            link = attrs.get("link", "")
            if link in parent_of:  # urdfdom's own words for it name no joint
                fail(f"link {link!r} is the child of two joints ({parent_of[link]!r} and "
                     f"{joint[0]!r}): a URDF link hangs from one joint (a tree)")
            parent_of[link] = joint[0]
        elif name == "axis" and joint is not None and joint[1] in _MOVING:
            values = _floats(attrs.get("xyz", "1 0 0"))
            if values is None or len(values) != 3 or not all(map(math.isfinite, values)):
                fail(f"joint {joint[0]!r}: axis xyz={attrs.get('xyz')!r}, expected 3 finite numbers")
            if math.hypot(*values) < 1e-12:
                fail(f"joint {joint[0]!r}: axis xyz={attrs.get('xyz')!r} has zero length; a joint "
                     "axis needs a direction")
            if not math.isfinite(math.fsum(v * v for v in values)):  # Pinocchio normalises it
                fail(f"joint {joint[0]!r}: axis xyz={attrs.get('xyz')!r} is too long to "
                     "normalise; a joint axis is a direction, such as 0 0 1")
        elif name == "origin" and joint is not None:
            origins += own
            if own and origins > 1:  # urdfdom reads the first: which would a correction edit?
                fail(f"joint {joint[0]!r} has a second <origin>: a URDF joint has at most "
                     "one (its placement in the parent link)")
            xyz = _floats(attrs.get("xyz", "0 0 0"))
            if xyz is not None and any(abs(v) > MAX_ORIGIN_M for v in xyz):
                fail(f"joint {joint[0]!r}: origin xyz={attrs.get('xyz')!r} lies more than "
                     f"{MAX_ORIGIN_M:g} m from its parent link; expected metres")
        elif name == "limit" and joint is not None and joint[1] in ("revolute", "prismatic"):
            lo, hi = _floats(attrs.get("lower", "0")), _floats(attrs.get("upper", "0"))
            if lo is None or hi is None or len(lo) != 1 or len(hi) != 1:
                fail(f"joint {joint[0]!r}: limit lower={attrs.get('lower')!r} "
                     f"upper={attrs.get('upper')!r}, expected numbers")
            if lo[0] > hi[0]:
                fail(f"joint {joint[0]!r}: limit lower={lo[0]:g} is above upper={hi[0]:g}")

    def on_end(name):
        nonlocal joint, depth
        if name == "joint" and depth == joint_depth:
            joint = None
        depth -= 1

    parser.StartDoctypeDeclHandler = on_doctype
    parser.EntityDeclHandler = on_entity_decl
    parser.UnparsedEntityDeclHandler = on_entity_decl
    parser.StartElementHandler = on_start
    parser.EndElementHandler = on_end
    try:
        parser.Parse(text.encode("utf-8", errors="surrogatepass"), True)
    except expat.ExpatError as exc:
        raise UrdfError(
            f"{source}:{exc.lineno}:{exc.offset + 1}: malformed XML: {expat.ErrorString(exc.code)}"
        ) from None


def _floats(text: str):
    """The numbers of a space-separated attribute, or None if one is not a number."""
    try:
        return [float(v) for v in text.split()]
    except ValueError:
        return None
