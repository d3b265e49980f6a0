"""FRAMES.json's ``tilts_in_urdf``: contact-face tilts a calibrated URDF carries, checked
against the URDF a reader builds its model from.

When a flush calibration writes a URDF, the contact face's tilt goes into the origin of the
fixed joint above the tip link (:mod:`kincal.export.contact_fold`) and FRAMES.json holds
zero tilts and this record: the tip, the joint, the tilts [rad], and the joint's origin as
written and as it was before (xyz [m], rpy [rad]). A reader who evaluates or compensates
with another URDF than the one written beside (the nominal one, to compare nominal and
calibrated accuracy with the calibrated frames) would lose the tilt, and its numbers would
be those of another contact frame (TALOS: 0.4 deg). :func:`on_urdf`, the one place that
decides, compares that joint's origin in the URDF given (to :data:`TOLERANCE`):

- the origin as written: the URDF carries the tilt; nothing to do;
- the origin before: the URDF lacks it; the tilt goes back into the contact frame
  (``tool.rx``, ``tool.ry`` of the sets on that tip), the fold exactly undone (the tip
  frame is the URDF's, the face's tilt FRAMES.json's), and a note says so;
- any other: a warning naming the joint, the origin found and the two expected, and the
  tilt is not applied (the URDF's tip frame taken as the contact frame, as a reader of that
  URDF alone takes it). A warning, not a refusal: such a URDF is not one kincal wrote from
  this calibration or its start (another calibration's, a hand-edited one), so neither
  choice is known to be right; the warning says which was taken, and a refusal would leave
  no way to judge that URDF with these frames short of editing FRAMES.json.

A record of an older kincal (no origins) cannot be checked: the frames are used as they
are (the tilt taken to be in the URDF), with a warning.
"""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import KincalWarning
from kincal.rotations import rpy_to_matrix, transform

if TYPE_CHECKING:
    from kincal.frames_file import CellFrames

TOLERANCE = 1e-9  # [m or rotation entry] an origin equal to a recorded one
TILTS = ("tool.rx", "tool.ry")


@dataclass(frozen=True)
class Origin:
    """A URDF joint's ``<origin>``: xyz [m] and rpy [rad], as written."""

    xyz: tuple[float, ...]  # 3 values
    rpy: tuple[float, ...]  # 3 values

    @classmethod
    def of(cls, joint: ET.Element) -> "Origin":
        """The origin of a URDF ``<joint>`` element (zeros where not written)."""
        o = joint.find("origin")
        xyz, rpy = (tuple(float(v) for v in (o.get(k) or "0 0 0").split()) if o is not None
                    else (0.0, 0.0, 0.0) for k in ("xyz", "rpy"))
        if len(xyz) != 3 or len(rpy) != 3:
            raise ValueError(f"joint {joint.get('name')!r}: an origin's xyz and rpy are 3 "
                             "numbers each")
        return cls(xyz, rpy)

    @classmethod
    def from_dict(cls, value, where: str = "tilts_in_urdf") -> "Origin":
        if not isinstance(value, dict) or not all(
                isinstance(value.get(k), list) and len(value[k]) == 3 for k in ("xyz", "rpy")):
            raise TypeError(f"{where}: an origin is {{\"xyz\": [3 numbers], \"rpy\": "
                            "[3 numbers]}")
        return cls(*(tuple(float(v) for v in value[k]) for k in ("xyz", "rpy")))

    def as_dict(self) -> dict:
        return {"xyz": list(self.xyz), "rpy": list(self.rpy)}

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) the joint frame in its parent link [m]."""
        return transform(rpy_to_matrix(self.rpy), self.xyz)

    def equals(self, other: "Origin") -> bool:
        return float(np.abs(self.matrix - other.matrix).max()) <= TOLERANCE

    def __str__(self) -> str:  # every digit: two origins told apart show apart
        return (f"xyz=\"{' '.join(map(repr, self.xyz))}\" "
                f"rpy=\"{' '.join(map(repr, self.rpy))}\"")


def joint_origin(urdf_text: str, joint: str) -> Origin | None:
    """The origin of the URDF joint ``joint`` as ``urdf_text`` writes it; None without such
    a joint or with an origin of other than 3 + 3 numbers."""
    return dict(joint_origins(urdf_text, (joint,))).get(joint)


def joint_origins(urdf_text: str, joints) -> tuple[tuple[str, Origin], ...]:
    """((joint, origin as ``urdf_text`` writes it), ...) for the URDF joints ``joints``
    that the text has with an origin of 3 + 3 numbers, in the order of ``joints`` (the one
    reader of written origins: this module's record and :mod:`kincal.urdf_origins`')."""
    from kincal.urdf_source import urdf_tree  # the one reader of the element tree

    found: dict = {}
    for e in urdf_tree(urdf_text).findall("joint"):
        found.setdefault(e.get("name"), e)  # the first of a name, as urdfdom would refuse
    out = []
    for j in joints:
        if j in found:
            try:
                out.append((str(j), Origin.of(found[j])))
            except ValueError:
                pass  # an origin of other than 3 + 3 numbers: nothing to record or compare
    return tuple(out)


@dataclass(frozen=True)
class TiltInUrdf:
    """One contact face's tilt written into a URDF joint (an entry of FRAMES.json's
    ``tilts_in_urdf``). tip_frame: the tip link; joint: the fixed joint above it; tilts:
    (tool.rx, tool.ry) [rad]; written, before: the joint's origin in the URDF written beside
    FRAMES.json and before the fold (None in a file of an older kincal)."""

    tip_frame: str
    joint: str
    tilts: tuple[float, float]
    written: Origin | None = None
    before: Origin | None = None

    @classmethod
    def from_dict(cls, value) -> "TiltInUrdf":
        need = ("tip_frame", "joint", "tool.rx", "tool.ry")
        if not isinstance(value, dict) or not all(k in value for k in need):
            raise TypeError("tilts_in_urdf holds one object per tip, with "
                            + ", ".join(need) + " (and origin_written, origin_before)")
        origins = [None if value.get(k) is None else Origin.from_dict(value[k])
                   for k in ("origin_written", "origin_before")]
        return cls(str(value["tip_frame"]), str(value["joint"]),
                   (float(value["tool.rx"]), float(value["tool.ry"])), *origins)

    def as_dict(self) -> dict:
        out = {"tip_frame": self.tip_frame, "joint": self.joint, "tool.rx": self.tilts[0],
               "tool.ry": self.tilts[1]}
        if self.written is not None and self.before is not None:
            out |= {"origin_written": self.written.as_dict(),
                    "origin_before": self.before.as_dict()}
        return out | {"note": "the tilts are written into the joint's origin (origin_written; "
                              "origin_before: before), turned about the contact point; the "
                              "sets on the tip hold zero tilts. A reader given a URDF with "
                              "origin_before puts them back into the contact frame"}

    def said(self) -> str:
        rx, ry = (math.degrees(v) for v in self.tilts)
        return (f"the contact face's tilt on {self.tip_frame!r} (rx {rx:+.4f} deg, ry "
                f"{ry:+.4f} deg)")


def on_urdf(frames: "CellFrames", robot) -> "tuple[CellFrames, tuple[str, ...]]":
    """(the frames, notes): ``frames`` as they apply to the URDF of ``robot`` (a
    :class:`kincal.robot.Robot`), its contact-face tilts put back into the contact frame
    where that URDF lacks them (module notes; warnings where that cannot be told). The
    records of ``robot``'s tip are resolved and left out of the frames returned, so a second
    call changes nothing. The one place that decides, for every reader of FRAMES.json that
    builds a model from a URDF it is given (``kincal evaluate --frames``, ``compensate``)."""
    mine = [r for r in frames.tilts_in_urdf if r.tip_frame == robot.tip]
    if not mine:
        return frames, ()
    urdf = robot.source or robot.name
    sets, notes = list(frames.sets), []
    for r in mine:
        on_tip = [k for k, s in enumerate(sets) if (s.tip_frame or frames.tip_frame)
                  == r.tip_frame and s.has(*TILTS)]
        found = joint_origin(robot.urdf_text, r.joint)
        if r.written is None or r.before is None:
            warnings.warn(f"{frames.source} records {r.said()} as written into the origin of "
                          f"the fixed joint {r.joint} of the URDF written beside it, without "
                          "that origin (a file of an older kincal): whether "
                          f"{urdf} carries it cannot be checked; the frames are used as they "
                          "are (no tilt), so with another URDF (the nominal one) the contact "
                          "frame lacks it: write the files anew to have it checked",
                          KincalWarning)
        elif any(sets[k].value(n) != 0.0 for k in on_tip for n in TILTS):
            warnings.warn(f"{frames.source} records {r.said()} as written into the origin of "
                          f"the fixed joint {r.joint}, and holds non-zero tilts on that tip "
                          "too (an edited file?): its tilts are used as they are on "
                          f"{urdf}, the recorded ones not added", KincalWarning)
        elif found is not None and found.equals(r.written):
            pass  # the URDF carries the tilt
        elif found is not None and found.equals(r.before):
            for k in on_tip:
                s = sets[k]
                sets[k] = replace(s, values=tuple(dict(zip(TILTS, r.tilts)).get(n, v)
                                                  for n, v in zip(s.names, s.values)))
            notes.append(f"{r.said()} applied from {frames.source}: {urdf} has the origin of "
                         f"{r.joint} from before the calibration, which wrote the tilt into it "
                         "(the tip frame is the URDF's, the face's tilt FRAMES.json's)")
        else:
            warnings.warn(f"{urdf}: the fixed joint {r.joint} has "
                          + ("no origin kincal can read (no such joint?)" if found is None else
                             f"the origin {found}")
                          + f", neither the calibrated one ({r.written}) nor the one before "
                          f"the calibration ({r.before}) that {frames.source} records: "
                          f"{r.said()}, written into that origin, is not applied (this URDF's "
                          "tip frame is taken as the contact frame); use the URDF written "
                          "beside FRAMES.json, or the one the calibration started from",
                          KincalWarning)
    rest = tuple(r for r in frames.tilts_in_urdf if r.tip_frame != robot.tip)
    return replace(frames, sets=tuple(sets), tilts_in_urdf=rest), tuple(notes)
