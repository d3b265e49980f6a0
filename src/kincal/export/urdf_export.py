"""Write corrected joint origins into the user's own URDF text, changing nothing else.

A joint origin is the pose of the joint frame in its parent link frame, as URDF's
``<joint><origin xyz="x y z" rpy="r p y"/>`` means it: T = [Rz(y) Ry(p) Rx(r), xyz],
metres and radians, given here as a 4x4 homogeneous array.

Edits are made at exact byte offsets reported by expat during a real parse, so
comments, CDATA, ``<transmission><joint>`` and ``<gazebo>`` blocks, quoting style,
attribute order and line endings stay byte-for-byte as the user wrote them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Mapping
from xml.parsers import expat

import numpy as np

from kincal.errors import ExportError, FrameError, UrdfError, listing, suggest
from kincal.rotations import matrix_to_rpy, rpy_to_matrix
from kincal.urdf_source import check_urdf_text

RPY_KEEP_TOLERANCE = 1e-15
"""Max abs rotation-matrix element difference under which the original rpy text is kept."""

# A start tag as expat has already validated it; group 1 is "/" when self-closing.
_START_TAG = re.compile(rb"""<[^\s/>]+(?:\s+[^\s=/>]+\s*=\s*(?:"[^"]*"|'[^']*'))*\s*(/?)>""")
_ATTRIBUTE = re.compile(rb"""([^\s=/>]+)\s*=\s*("[^"]*"|'[^']*')""")


@dataclass(frozen=True)
class JointEdit:
    """What happened to one joint's ``<origin>``.

    ``old_*`` / ``new_*``: attribute values as XML reads them (tabs and line breaks
    become spaces), None when absent (URDF reads zeros). ``rpy_change``: new minus
    old rpy [rad], shape (3,), read-only.
    """

    joint: str
    old_xyz: str | None
    new_xyz: str | None
    old_rpy: str | None
    new_rpy: str | None
    rpy_change: np.ndarray
    origin_added: bool = False

    @property
    def changed(self) -> bool:
        return self.origin_added or self.old_xyz != self.new_xyz or self.old_rpy != self.new_rpy


@dataclass(frozen=True)
class EditResult:
    """The edited URDF text and one :class:`JointEdit` per requested joint, in file order."""

    text: str
    edits: tuple[JointEdit, ...] = field(default=())

    def for_joint(self, name: str) -> JointEdit:
        for edit in self.edits:
            if edit.joint == name:
                return edit
        raise FrameError(f"no edit for joint {name!r}", valid=tuple(e.joint for e in self.edits))


@dataclass
class _Joint:
    """Byte offsets of one top-level ``<robot><joint>`` (mutable while scanning)."""

    name: str
    start: int
    first_child: int | None = None
    origin_start: int | None = None
    origin_attrs: dict | None = None  # values as expat normalised them


@dataclass
class _Scan:
    joints: dict = field(default_factory=dict)  # name -> _Joint, file order
    links: list = field(default_factory=list)
    first_child_of_robot: int | None = None
    robot_end: int | None = None  # offset of "</robot>"


def _scan(data: bytes, source: str) -> _Scan:
    """Locate top-level joints, their first ``<origin>`` child, links and ``</robot>``."""
    scan, stack = _Scan(), []  # type: _Scan, list[str]
    joint: _Joint | None = None
    parser = expat.ParserCreate(encoding="UTF-8")

    def on_start(name, attrs):
        nonlocal joint
        pos = parser.CurrentByteIndex
        if len(stack) == 1:
            if scan.first_child_of_robot is None:
                scan.first_child_of_robot = pos
            if name == "link":
                scan.links.append(attrs.get("name", ""))
            elif name == "joint" and "name" in attrs:
                if attrs["name"] in scan.joints:
                    raise UrdfError(f"{source}: joint {attrs['name']!r} is defined twice")
                joint = scan.joints[attrs["name"]] = _Joint(attrs["name"], pos)
        elif len(stack) == 2 and stack[1] == "joint" and joint is not None:
            if joint.first_child is None:
                joint.first_child = pos
            # urdfdom reads the first <origin> only, so that is the one to edit
            if name == "origin" and joint.origin_start is None:
                joint.origin_start, joint.origin_attrs = pos, dict(attrs)
        stack.append(name)

    def on_end(name):
        nonlocal joint
        stack.pop()
        if len(stack) == 1 and name == "joint":
            joint = None
        elif not stack:
            scan.robot_end = parser.CurrentByteIndex

    parser.StartElementHandler = on_start
    parser.EndElementHandler = on_end
    parser.Parse(data, True)
    return scan


def _rigid(name: str, T) -> tuple[np.ndarray, np.ndarray]:
    """(R, p) of a 4x4 rigid transform, or ExportError saying why it is not one."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ExportError(f"origin of {name!r}: expected a finite 4x4 transform, got shape {T.shape}")
    R = T[:3, :3]
    if (np.max(np.abs(R.T @ R - np.eye(3))) > 1e-9 or np.linalg.det(R) < 0
            or np.any(T[3] != (0.0, 0.0, 0.0, 1.0))):
        raise ExportError(f"origin of {name!r} is not a rigid transform (orthonormal rotation "
                          "with determinant +1, last row 0 0 0 1)")
    return R, T[:3, 3].copy()


def _parse_triple(value: str | None, what: str, source: str) -> tuple[list[str], np.ndarray]:
    if value is None:
        return [], np.zeros(3)
    tokens = value.split()  # expat has already turned tabs and line breaks into spaces
    try:
        numbers = np.array([float(t) for t in tokens])
    except ValueError:
        numbers = np.zeros(0)
    if numbers.shape != (3,) or not np.all(np.isfinite(numbers)):
        raise UrdfError(f"{source}: {what}={value!r} is not three numbers")
    return tokens, numbers


# [m] or [rad]: a component that moved less than this is arithmetic noise (the corrected
# placements go through products of rotations), not a correction: it keeps its text
KEEP_TOLERANCE = 1e-14


def _same(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    return np.abs(new - old) <= KEEP_TOLERANCE


def _new_value(tokens: list[str], old: np.ndarray, new: np.ndarray) -> str:
    """Components equal to the parsed original (to KEEP_TOLERANCE) keep their spelling."""
    keep = _same(old, new)
    return " ".join(tokens[i] if tokens and keep[i] else _number(new[i]) for i in range(3))


def _number(value: float) -> str:
    # repr is the shortest text that reads back as the same double; + 0.0 turns -0.0 into 0.0
    return repr(float(value) + 0.0)


def _quote_of(tag: bytes) -> bytes:
    match = _ATTRIBUTE.search(tag)
    return match.group(2)[:1] if match else b'"'


def _edit_joint(data: bytes, joint: _Joint, T, source: str):
    """(byte replacements, JointEdit) for one joint; replacements are (start, end, bytes)."""
    R_new, p_new = _rigid(joint.name, T)
    attrs = joint.origin_attrs or {}
    xyz_tokens, xyz_old = _parse_triple(attrs.get("xyz"), f"joint {joint.name!r} origin xyz", source)
    rpy_tokens, rpy_old = _parse_triple(attrs.get("rpy"), f"joint {joint.name!r} origin rpy", source)

    new_xyz = attrs.get("xyz")
    if not np.all(_same(xyz_old, p_new)):
        new_xyz = _new_value(xyz_tokens, xyz_old, p_new)
    rpy_new_values = rpy_old
    new_rpy = attrs.get("rpy")
    # 1e-15: a rotation rebuilt from the same rpy elsewhere (e.g. via a quaternion
    # in Pinocchio) differs by a few ulps; that is no reason to rewrite the text
    if np.max(np.abs(R_new - rpy_to_matrix(rpy_old))) > RPY_KEEP_TOLERANCE:
        rpy_new_values = matrix_to_rpy(R_new, near=rpy_old)
        new_rpy = _new_value(rpy_tokens, rpy_old, rpy_new_values)
    rpy_change = np.asarray(rpy_new_values - rpy_old, dtype=float)
    rpy_change.flags.writeable = False

    replacements = []
    if joint.origin_start is not None:
        tag = _tag_at(data, joint.origin_start)
        quote = _quote_of(tag.group(0))
        spans = {m.group(1): m.span(2) for m in _ATTRIBUTE.finditer(data, tag.start(), tag.end())}
        appended = b""
        for key, old, new in ((b"xyz", attrs.get("xyz"), new_xyz), (b"rpy", attrs.get("rpy"), new_rpy)):
            if new is None or new == old:  # None: no value before and none needed
                continue
            if key in spans:  # replace inside the quotes, keeping the user's quote character
                start, end = spans[key]
                replacements.append((start + 1, end - 1, new.encode()))
            else:
                appended += b" " + key + b"=" + quote + new.encode() + quote
        if appended:
            last = max((end for _, end in spans.values()), default=tag.start() + len(b"<origin"))
            replacements.append((last, last, appended))
        origin_added = False
    else:
        origin_added = new_xyz is not None or new_rpy is not None
        if origin_added:
            replacements.append(_insert_origin(data, joint, new_xyz, new_rpy))
    edit = JointEdit(joint.name, attrs.get("xyz"), new_xyz, attrs.get("rpy"), new_rpy, rpy_change,
                     origin_added)
    return replacements, edit


def _tag_at(data: bytes, pos: int) -> re.Match[bytes]:
    """The start tag that the scan located at ``pos`` (a miss is a bug of the scan)."""
    tag = _START_TAG.match(data, pos)
    if tag is None:
        raise AssertionError(f"urdf_export: no start tag at byte {pos}, where the scan saw one")
    return tag


def _insert_origin(data: bytes, joint: _Joint, xyz: str | None, rpy: str | None):
    """Replacement adding ``<origin/>`` as the first child of a joint that has none."""
    tag = _tag_at(data, joint.start)
    quote = _quote_of(tag.group(0))
    attributes = b"".join(
        b" " + key + b"=" + quote + value.encode() + quote
        for key, value in ((b"xyz", xyz), (b"rpy", rpy)) if value is not None
    )
    origin = b"<origin" + attributes + b"/>"
    if tag.group(1):  # <joint .../> must become <joint ...><origin/></joint>
        return (tag.end() - 2, tag.end(), b">" + origin + b"</joint>")
    if joint.first_child is None:
        return (tag.end(), tag.end(), origin)
    # put it before the first child, followed by the same whitespace that precedes
    # that child, so it is indented like its siblings whatever the line endings
    start = joint.first_child
    while start > tag.end() and data[start - 1:start] in b" \t\r\n":
        start -= 1
    return (joint.first_child, joint.first_child, origin + data[start:joint.first_child])


def _apply(data: bytes, replacements) -> bytes:
    pieces, pos = [], 0
    for start, end, new in sorted(replacements):
        pieces += [data[pos:start], new]
        pos = end
    return b"".join(pieces) + data[pos:]


def edit_joint_origins(text: str, origins: Mapping[str, np.ndarray], source: str = "<string>") -> EditResult:
    """Write new joint origins into ``text``, a URDF, leaving every other byte as it was.

    ``origins`` maps a top-level joint name to T_parentlink_joint, the 4x4 pose of
    the joint frame in its parent link frame [m, rad]. Only the first ``<origin>``
    directly inside ``<robot><joint name=...>`` is edited (what URDF parsers read).
    The xyz / rpy attribute text is kept when its value is unchanged (rpy: rotation
    equal to within :data:`RPY_KEEP_TOLERANCE`); otherwise it is rewritten with
    ``repr`` numbers, single spaces, components equal to the original keeping their
    spelling, and rpy chosen closest to the original triple. Raises
    :class:`FrameError` for unknown joint names, :class:`UrdfError` for bad input.
    """
    check_urdf_text(text, source)
    data = text.encode("utf-8")
    scan = _scan(data, source)
    unknown = [name for name in origins if name not in scan.joints]
    if unknown:
        raise FrameError(
            f"{source}: no joint named {', '.join(map(repr, unknown))}."
            f"{suggest(unknown[0], scan.joints)} Joints: {listing(scan.joints)}",
            valid=tuple(scan.joints),
        )
    replacements, edits = [], []
    for name, joint in scan.joints.items():
        if name in origins:
            joint_replacements, edit = _edit_joint(data, joint, origins[name], source)
            replacements += joint_replacements
            edits.append(edit)
    return EditResult(_apply(data, replacements).decode("utf-8"), tuple(edits))


def add_fixed_frame(text: str, parent_link: str, child_link: str, joint_name: str, T) -> str:
    """``text`` with a fixed joint ``joint_name`` and an empty link ``child_link`` added.

    ``T`` is T_parent_child, the 4x4 pose of ``child_link`` in ``parent_link`` [m, rad]
    (rpy written closest to zeros). The block goes just before ``</robot>``, after a
    comment saying kincal added it; the rest of the text is unchanged. Raises
    :class:`FrameError` if ``parent_link`` is unknown or a new name is taken (by a
    link or a joint: Pinocchio names frames after both).
    """
    check_urdf_text(text)
    data = text.encode("utf-8")
    scan = _scan(data, "<string>")
    if parent_link not in scan.links:
        raise FrameError(f"no link named {parent_link!r}.{suggest(parent_link, scan.links)} "
                         f"Links: {listing(scan.links)}", valid=tuple(scan.links))
    if child_link in scan.links or child_link in scan.joints:
        raise FrameError(f"a link or joint named {child_link!r} already exists; choose another name")
    if joint_name in scan.joints or joint_name in scan.links or joint_name == child_link:
        raise FrameError(f"a joint or link named {joint_name!r} already exists; choose another name")
    R, p = _rigid(joint_name, T)
    xyz = " ".join(_number(v) for v in p)
    rpy = " ".join(_number(v) for v in matrix_to_rpy(R))

    newline = "\r\n" if b"\r\n" in data else "\n"
    # indent like the robot's first child; the joint's children one level deeper
    i = _line_indent(data, scan.first_child_of_robot or 0).decode() or "  "
    block = newline.join([
        f"{i}<!-- added by kincal: a fixed frame identified by the calibration -->",
        f'{i}<joint name="{_attr(joint_name)}" type="fixed">',
        f'{i}{i}<parent link="{_attr(parent_link)}"/>',
        f'{i}{i}<child link="{_attr(child_link)}"/>',
        f'{i}{i}<origin xyz="{xyz}" rpy="{rpy}"/>',
        f"{i}</joint>",
        f'{i}<link name="{_attr(child_link)}"/>',
        "",
    ]).encode()
    at = scan.robot_end
    line_start = data.rfind(b"\n", 0, at) + 1
    if data[line_start:at].strip():  # "</robot>" shares its line with other content
        block = newline.encode() + block
    else:  # start the block at the beginning of the "</robot>" line
        at = line_start
    return (data[:at] + block + data[at:]).decode("utf-8")


def _attr(value: str) -> str:
    # by hand, not xml.sax.saxutils.escape: that module imports urllib.request, http and
    # ssl, start-up time that every `kincal calibrate` paid for four replacements
    return (value.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;"))


def _line_indent(data: bytes, pos: int) -> bytes:
    """Whitespace from the start of the line to ``pos`` (empty if other text precedes)."""
    prefix = data[data.rfind(b"\n", 0, pos) + 1:pos]
    return b"" if prefix.strip() else prefix


def add_frames_of(result, text: str) -> str:
    """``text`` plus fixed frames for each measurement set of ``result`` that has them:
    ``kincal_measurement_frame`` (child of the set's base link, the pose of the measurement
    frame M in the base frame) and ``kincal_tool_point`` (child of the set's tip link, at the
    tool point, turned as the tool frame a pose set identified; ``kincal_tool_point_<k>`` for
    point k >= 2); sets k >= 2 add ``_set<k>`` to the names."""
    from kincal.rotations import base_rotation, inverse, transform

    robot = result.robot
    for i, s in enumerate(result.sets):
        suffix = "" if i == 0 else f"_set{i + 1}"
        # each set's own chain: several chains have other bases and tips than the first's
        base_link, T_bl = robot.link_of(getattr(s, "base_frame", "") or robot.base)
        tip_link, T_tl = robot.link_of(getattr(s, "tip_frame", "") or robot.tip)
        names = s.frame_names
        if all(f"base.{c}" in names for c in ("x", "y", "z", "rx", "ry", "rz")):
            b = [s.frame(f"base.{c}") for c in ("x", "y", "z", "rx", "ry", "rz")]
            T_MB = transform(base_rotation(*b[3:]), b[:3])  # base frame expressed in M
            name = "kincal_measurement_frame" + suffix
            text = add_fixed_frame(text, base_link, name, name + "_joint", T_bl @ inverse(T_MB))
        # a pose set measured the tool frame's orientation too: its frame is FRAMES.json's
        # T_tip_tool, not the tip's axes at the tool point (a flush face's tilt is not, see
        # kincal.export.contact_fold)
        R_tool = (base_rotation(*(s.frame(f"tool.{c}") if f"tool.{c}" in names else 0.0
                                  for c in ("rx", "ry", "rz"))) if s.kind == "pose" else None)
        k = 1
        while all(("tool." if k == 1 else f"tool{k}.") + c in names for c in "xyz"):
            t = [s.frame(("tool." if k == 1 else f"tool{k}.") + c) for c in "xyz"]
            name = "kincal_tool_point" + ("" if k == 1 else f"_{k}") + suffix
            text = add_fixed_frame(text, tip_link, name, name + "_joint",
                                   T_tl @ transform(R_tool if k == 1 else None, t))
            k += 1
    return text
