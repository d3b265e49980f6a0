"""The corrected URDF read back, strictly, before it is written.

kincal's models live in Pinocchio; the corrected URDF is the original text with joint
origins edited in place. Before the one writer commits it, :func:`check_readback` reads
that text back two ways and refuses it (one ExportError line naming what differs; nothing
is written) unless both agree with the calibration:

1. The text, parsed by the standard library's XML parser, against the original URDF,
   element by element: every element, attribute and text of the original is kept, in
   order; only the ``xyz`` / ``rpy`` of ``<origin>`` in the calibrated chains' joints may
   differ (an ``<origin>`` may be added to such a joint that had none), plus the fixed
   frames that ``add_frames`` asked for (links and fixed joints named ``kincal_*``, new
   names); every number written is finite; and each calibrated joint's written origin is
   the corrected placement to :data:`ORIGIN_TOLERANCE` (a joint whose offset the readable
   export moved into its child joints, and those children, are checked by 3 instead).
2. The text loaded by Pinocchio's URDF reader (urdfdom), a model built from the text and
   not from the calibrated model in memory: every calibrated chain's forward kinematics at
   seeded joint values spread over the limits equals the calibrated model's to
   :data:`TOLERANCE_M`.

Check 1 leaves the written file no room to say anything but the corrected origins; check 2
that those origins, as a URDF reader composes them, give the calibrated kinematics. (The
tests also read the written file with yourdfpy, a third reader, to 1e-12: kept out of the
command itself because importing it costs 0.45 s, trimesh, scipy and networkx.)
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from kincal.errors import ExportError
from kincal.urdf_source import urdf_tree

TOLERANCE_M = 1e-9  # [m] largest position difference accepted (and 1e-9 in rotation)
ORIGIN_TOLERANCE = 1e-12  # [m, 1] written origin against the corrected placement
N_CONFIGURATIONS = 12
ADDED_PREFIX = "kincal_"  # the names of the fixed frames add_frames writes


def chain_robots(result):
    """The calibrated robots of every distinct chain of ``result`` (Pinocchio models)."""
    from kincal.robot import Robot

    c = result.corrected
    seen, out = set(), []
    for s in result.sets:
        base = getattr(s, "base_frame", "") or c.base
        tip = getattr(s, "tip_frame", "") or c.tip
        if (base, tip) in seen:
            continue
        seen.add((base, tip))
        out.append(c if (base, tip) == (c.base, c.tip) else
                   Robot(c.model, c.urdf_text, c.name, base, tip, c.source, c.off_chain,
                         c.xacro_args))
    return out


def chain_ends(result) -> tuple[str, ...]:
    """The base and tip frames of every chain of ``result``."""
    return tuple(f for r in chain_robots(result) for f in (r.base, r.tip))


def _refuse(what: str) -> ExportError:
    return ExportError(f"the corrected URDF, read back before writing, {what}; nothing is "
                       "written (please report this: the URDF text does not say what was "
                       "calibrated)")


def _numbers(value: str, where: str) -> np.ndarray:
    """(3,) the finite numbers of an xyz / rpy attribute."""
    try:
        v = np.array([float(t) for t in value.split()])
    except ValueError:
        raise _refuse(f"has {where}=\"{value}\", not three numbers") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise _refuse(f"has {where}=\"{value}\", not three finite numbers")
    return v


def _same(a: ET.Element, b: ET.Element, where: str) -> None:
    """a and b identical: tag, attributes, text and children, recursively."""
    if a.tag != b.tag:
        raise _refuse(f"has <{b.tag}> where the original has <{a.tag}> ({where})")
    if a.attrib != b.attrib:
        keys = sorted(set(a.attrib) | set(b.attrib))
        k = next(k for k in keys if a.attrib.get(k) != b.attrib.get(k))
        raise _refuse(f"changes {where} attribute {k!r} from {a.attrib.get(k)!r} to "
                      f"{b.attrib.get(k)!r}")
    if (a.text or "").strip() != (b.text or "").strip():
        raise _refuse(f"changes the text of {where}")
    if len(a) != len(b):
        raise _refuse(f"has {len(b)} elements in {where} where the original has {len(a)}")
    for i, (ca, cb) in enumerate(zip(a, b)):
        _same(ca, cb, f"{where}/{ca.tag}[{i}]")


def _label(e: ET.Element) -> str:
    return f"<{e.tag} name=\"{e.get('name', '')}\">"


def written_origins(original: str, text: str, movable, add_frames: bool
                    ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{joint: (xyz, rpy)} written for the joints in ``movable``, after checking that
    ``text`` is ``original`` with only those joints' origin xyz / rpy changed (and, with
    ``add_frames``, fixed ``kincal_*`` frames added); ExportError naming the first other
    difference."""
    try:
        # element names as urdfdom reads them (a default namespace taken off)
        old, new = urdf_tree(original), urdf_tree(text)
    except ET.ParseError as exc:
        raise _refuse(f"is not well-formed XML ({exc})") from None
    if old.tag != new.tag or old.attrib != new.attrib:
        raise _refuse("changes the <robot> element")
    names = {e.get("name") for e in old}
    kept = []
    for e in new:
        if e.get("name") not in names and e.tag in ("link", "joint") and add_frames \
                and str(e.get("name", "")).startswith(ADDED_PREFIX):
            if e.tag == "joint":
                if e.get("type") != "fixed":
                    raise _refuse(f"adds {_label(e)} that is not a fixed joint")
                for o in e.iter("origin"):
                    for k in ("xyz", "rpy"):
                        _numbers(o.get(k, "0 0 0"), f"{_label(e)} origin {k}")
            continue
        kept.append(e)
    if len(kept) != len(old):
        extra = [_label(e) for e in new if e.get("name") not in names]
        raise _refuse(f"has {len(kept)} elements where the original has {len(old)}"
                      + (f" (new: {', '.join(extra[:3])})" if extra else ""))
    out = {}
    for a, b in zip(old, kept):
        where = _label(a)
        if a.tag != "joint" or a.get("name") not in movable:
            _same(a, b, where)
            continue
        if a.tag != b.tag or a.attrib != b.attrib:
            _same(ET.Element(a.tag, a.attrib), ET.Element(b.tag, b.attrib), where)
        ao = [c for c in a if c.tag != "origin"]
        bo = [c for c in b if c.tag != "origin"]
        if len(ao) != len(bo) or len(a) - len(ao) > 1 or len(b) - len(bo) > 1 \
                or len(b) - len(bo) < len(a) - len(ao):
            raise _refuse(f"changes the elements of {where}")
        for i, (ca, cb) in enumerate(zip(ao, bo)):
            _same(ca, cb, f"{where}/{ca.tag}[{i}]")
        o_old = next((c for c in a if c.tag == "origin"), None)
        o_new = next((c for c in b if c.tag == "origin"), ET.Element("origin"))
        other = set(o_new.attrib) - {"xyz", "rpy"}
        for k in sorted(other | (set(o_old.attrib) if o_old is not None else set())):
            if k not in ("xyz", "rpy") and (o_old is None or o_old.get(k) != o_new.get(k)):
                raise _refuse(f"changes {where} origin attribute {k!r}")
        if len(o_new) or (o_new.text or "").strip():
            raise _refuse(f"puts content into the origin of {where}")
        out[str(a.get("name"))] = (_numbers(o_new.get("xyz", "0 0 0"), f"{where} origin xyz"),
                                   _numbers(o_new.get("rpy", "0 0 0"), f"{where} origin rpy"))
    return out


def _regauged(result) -> set[str]:
    """The joints whose origins the readable export re-expressed (a joint offset moved into
    its child joints, :mod:`kincal.export.readable_export`): those and their children."""
    from kincal.export.readable_export import corrected_text, regauged_joints

    _, moved = corrected_text(result.robot, result.corrected, True,
                              joints=tuple(result.error_model.joint_names),
                              ends=chain_ends(result))
    return regauged_joints(moved)


def check_readback(result, text: str, add_frames: bool = False, folds=()) -> None:
    """ExportError unless ``text`` is the original URDF of ``result`` with only its
    calibrated joint origins changed, to the corrected placements, and Pinocchio's reading
    of it gives every chain of ``result`` its calibrated forward kinematics (module notes).
    folds: the contact folds (:mod:`kincal.export.contact_fold`): those fixed joints'
    origins too, and those chains' tip frames turned by the fold's change."""
    from kincal.errors import UrdfError
    from kincal.robot import Robot, _build_model
    from kincal.rotations import rpy_to_matrix, transform

    joints = tuple(result.error_model.joint_names)
    want = {**result.corrected.urdf_origins(joints), **{f.joint: f.origin for f in folds}}
    exempt = _regauged(result)  # the regauged joints and their children, on the chain or not
    origins = written_origins(result.robot.urdf_text, text,
                              set(joints) | exempt | {f.joint for f in folds}, add_frames)
    change = {f.tip: f.change for f in folds}
    for name, T in want.items():
        if name in exempt:
            continue
        xyz, rpy = origins[name]
        d = float(np.abs(transform(rpy_to_matrix(rpy), xyz) - T).max())
        if not d <= ORIGIN_TOLERANCE:
            raise _refuse(f"gives joint {name} the origin xyz=\"{' '.join(map(repr, xyz))}\" "
                          f"rpy=\"{' '.join(map(repr, rpy))}\", {d:.3g} (m or rotation entry) "
                          "from its corrected placement")
    try:
        model = _build_model(text, "the corrected URDF")
    except UrdfError as exc:
        raise _refuse(f"is not read by Pinocchio ({exc})") from None
    rng = np.random.default_rng(0)
    for robot in chain_robots(result):
        g = robot.geometry
        lo, hi = g.ranges()
        q = np.vstack([np.zeros(g.n), rng.uniform(lo, hi, size=(N_CONFIGURATIONS - 1, g.n))])
        read = Robot(model, text, robot.name, robot.base, robot.tip, robot.source,
                     dict(robot.off_chain), robot.xacro_args)
        expected = robot.tip_poses(q)
        if robot.tip in change:
            expected = expected @ change[robot.tip]
        diff = np.abs(read.tip_poses(q) - expected)[:, :3, :].max(axis=(1, 2))
        where = int(np.argmax(diff))
        if not (math.isfinite(diff[where]) and diff[where] <= TOLERANCE_M):
            raise _refuse(f"(loaded by Pinocchio) differs from the calibrated model of "
                          f"{robot.base} -> {robot.tip} by {diff[where]:.3g} (m or rotation "
                          f"entry) at joint values {np.round(q[where], 4).tolist()}")
