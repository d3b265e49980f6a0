"""A flush contact face's tilt carried by the corrected URDF, not by FRAMES.json alone.

A flush calibration identifies the contact frame on the tip: the contact point ``t`` and
the face's two tilts ``R_c = Rx(tool.rx) Ry(tool.ry)`` (:mod:`kincal.measurements.flush`).
The data can barely tell those tilts from the last joints' placement turns, so the split
is the prior's; a reader who takes the tip frame from the URDF and the contact point from
FRAMES.json (as a robot's stack does, and FIGAROH's validation) would lose the tilt and
judge the face off by it (TALOS: pitch 0.267 -> 0.490 deg held out, docs/results.md).

So when a URDF is written, the tilt goes into the origin of the fixed joint above the tip
link (``gripper_left_base_link_joint`` on TALOS), turned about the contact point:
``origin' = origin @ D``, ``D = [R_c, t - R_c t]``, so the new tip frame is the contact
frame's orientation and the contact point keeps its coordinates ``t`` (the user's
``--tool-offset``); FRAMES.json then holds the same point with zero tilts and a
``tilts_in_urdf`` record of the tilts and the joint's origin as written and before, by which
a reader given another URDF (the nominal one) puts the tilt back
(:mod:`kincal.tilts_in_urdf`). The contact point and face normal are the same as before to
first order (kincal's flush height moves by ``(R_c^T d - d) . t`` for a residual tilt
``d``: micrometres).

It is folded only where that is exact and harmless: the tip is a link whose parent joint
is fixed and on the chain (the tip below the chain's last joint, not an ancestor of the
base), every set on that tip is a flush set with the same contact frame, no other set's
chain passes through that joint (one end below the tip: the turn would move it), the readable
export did not already move another offset into that joint, and the tilt is at most
:data:`MAX_FOLD_DEG` (a larger one is the face's design, not an error: turning the tip
link's meshes by it would mislead; FRAMES.json keeps it, with a note).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

import numpy as np

from kincal.rotations import base_rotation, transform
from kincal.tilts_in_urdf import TILTS, Origin, TiltInUrdf, joint_origin

MAX_FOLD_DEG = 5.0  # [deg] largest face tilt written into a URDF joint origin


@dataclass(frozen=True)
class Fold:
    """One tip's face tilt written into the fixed joint above it.

    joint: the fixed URDF joint; tip: the tip link; tilts: (rx, ry) [rad]; change: (4, 4)
    D, the tip frame's change in itself; origin: (4, 4) the joint's new URDF origin [m];
    sets: the indices of the result's sets on that tip; before: the joint's origin as the
    URDF wrote it before the fold."""

    joint: str
    tip: str
    tilts: tuple[float, float]
    change: np.ndarray
    origin: np.ndarray
    sets: tuple[int, ...]
    before: Origin

    @property
    def nominal(self) -> np.ndarray:
        """(4, 4) the joint's URDF origin before the fold [m]."""
        return self.before.matrix

    def describe(self) -> str:
        rx, ry = (math.degrees(v) for v in self.tilts)
        return (f"the contact face's tilt (rx {rx:+.4f} deg, ry {ry:+.4f} deg against "
                f"{self.tip}) is written into the origin of the fixed joint {self.joint}, "
                "turned about the contact point: the URDF's tip frame is the contact frame "
                "and FRAMES.json holds the contact point with zero tilts")


def _joints_by_child(robot) -> dict:
    """{child link: its URDF joint element}, read from the URDF text (the tree as written),
    not the model in memory."""
    from kincal.urdf_source import urdf_tree

    root = urdf_tree(robot.urdf_text)
    return {child.get("link", ""): e for e in root.findall("joint")
            if (child := e.find("child")) is not None}


def _crosses(joints: dict, link: str, frame: str) -> bool:
    """Whether ``frame`` (a link, or a joint: its child link) hangs below ``link``."""
    by_name = {e.get("name"): child for child, e in joints.items()}
    frame, seen = by_name.get(frame, frame), set()
    while frame not in seen:
        if frame == link:
            return True
        seen.add(frame)
        above = joints.get(frame)
        parent = None if above is None else above.find("parent")
        if parent is None:
            return False
        frame = parent.get("link", "")
    return False


def _fixed_joint_above(robot, tip: str, joints: dict):
    """(joint name, its URDF origin) of the fixed joint above the link ``tip`` when
    it lies between the chain's last joint and the tip; else (None, why). joints:
    :func:`_joints_by_child` of the robot."""
    above = joints.get(tip)
    if above is None:
        return None, f"the tip {tip!r} is not a link below a joint"
    if above.get("type") != "fixed":
        return None, f"the tip link {tip!r} hangs on a moving joint"
    rev = robot.geometry.is_reversed
    names = robot.joint_names
    link, seen = tip, set()
    j: ET.Element | None = above
    while j is not None and j.get("type") == "fixed" and link not in seen:
        seen.add(link)
        parent = j.find("parent")
        link = "" if parent is None else parent.get("link", "")
        j = joints.get(link)
    if (j is None or not names or j.get("name") != names[-1]
            or (rev is not None and bool(rev[-1]))):
        return None, f"the tip link {tip!r} is not below the chain's last joint"
    return str(above.get("name")), Origin.of(above)


def folds(result, exclude=()) -> tuple[tuple[Fold, ...], tuple[str, ...]]:
    """(the folds the corrected URDF makes, notes of face tilts left in FRAMES.json only).

    exclude: joints whose origins the export already rewrites otherwise (regauged)."""
    from kincal.export.readback import chain_robots

    robots: dict = {}  # the chains' robots by tip, made when a flush tip needs them
    tree: dict = {}  # the URDF's joints by child link, likewise
    by_tip: dict[str, list[int]] = {}
    for i, s in enumerate(result.sets):
        by_tip.setdefault(s.tip_frame or result.robot.tip, []).append(i)
    out, notes = [], []
    for tip, idx in by_tip.items():
        flush = [i for i in idx if result.sets[i].kind == "flush"]
        if not flush:
            continue
        tools = {tuple(float(result.sets[i].frame(n))
                       for n in (*TILTS, "tool.x", "tool.y", "tool.z")) for i in flush}
        rx, ry, *t = next(iter(tools))
        if rx == 0.0 and ry == 0.0:
            continue
        said = (f"the contact face's tilt on {tip!r} (rx {math.degrees(rx):+.4f} deg, ry "
                f"{math.degrees(ry):+.4f} deg) is in FRAMES.json only")
        if len(flush) != len(idx) or len(tools) != 1:
            notes.append(f"{said}: other sets on that tip, or several contact frames")
            continue
        if max(abs(rx), abs(ry)) > math.radians(MAX_FOLD_DEG):
            notes.append(f"{said}: more than {MAX_FOLD_DEG:g} deg is the face's design, not "
                         "written into a URDF joint; a reader of the URDF alone must apply it")
            continue
        robots = robots or {r.tip: r for r in chain_robots(result)}
        tree = tree or _joints_by_child(robots[tip])
        joint, before = _fixed_joint_above(robots[tip], tip, tree)
        # another set's chain through that joint (one of its ends below the tip) would turn
        crossing = [f"{s.base_frame} -> {s.tip_frame}" for i, s in enumerate(result.sets)
                    if i not in idx and _crosses(tree, tip, s.tip_frame or result.robot.tip)
                    != _crosses(tree, tip, s.base_frame or result.robot.base)]
        if (joint is None or joint in exclude or joint in result.error_model.joint_names
                or crossing):
            why = (before if joint is None else f"{joint} already carries another change"
                   if not crossing else f"{joint} is also on the chain {crossing[0]}, which "
                   "the turn would move")
            notes.append(f"{said}: {why}, so no URDF joint can carry it")
            continue
        R = base_rotation(rx, ry, 0.0)
        tv = np.array(t)
        D = transform(R, tv - R @ tv)
        out.append(Fold(joint, tip, (rx, ry), D, before.matrix @ D, tuple(idx), before))
    return tuple(out), tuple(notes)


def folded_frames(frames, made: tuple[Fold, ...], text: str):
    """The CellFrames ``frames`` with the folded sets' tilts set to zero and the folds
    recorded (``tilts_in_urdf``), with the joints' origins as ``text``, the URDF written,
    has them and as they were."""
    if not made:
        return frames
    zero = {i for f in made for i in f.sets}
    sets = []
    for i, s in enumerate(frames.sets):
        if i in zero:
            s = replace(s, values=tuple(0.0 if n in TILTS else v
                                        for n, v in zip(s.names, s.values)))
        sets.append(s)
    return replace(frames, sets=tuple(sets), tilts_in_urdf=tuple(
        TiltInUrdf(f.tip, f.joint, f.tilts, joint_origin(text, f.joint), f.before)
        for f in made))
