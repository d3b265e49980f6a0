"""FRAMES.json: the frames of a calibrated cell, one versioned schema read everywhere.

What ``kincal calibrate --frames-out`` writes and ``kincal evaluate``, ``kincal
compensate`` and the API read. Version 2 (``"format": "kincal-frames", "version": 2``)::

    {"format": "kincal-frames", "version": 2,
     "robot": "ec66", "chain_hash": "sha256:...", "base_frame": "base_link",
     "tip_frame": "flange", "joints": ["joint_1", ...],
     "sets": [{"kind": "point", "source": "points.csv", "base_frame": "base_link",
               "tip_frame": "flange", "frames": {"base.x": ..., "base.rz": ..., "tool.x": ...},
               "T_measurement_base": [[...]], "pose_measurement_base": {...},
               "T_tip_tool": [[...]]}, ...],
     "backlash": {"joint_6": ...}, "convention": "...", "backlash_convention": "..."}

A set may also hold ``"fixed_joints": {"joint": value}`` (``--joint-value``: joints held
during the measurements [rad or m]); optional and additive, so the version stays 2, as are
the records of the URDF written beside: ``"tilts_in_urdf"``, the contact-face tilts it
carries (:mod:`kincal.tilts_in_urdf`), ``"urdf_origins"``, its calibrated joints' origins
(:mod:`kincal.urdf_origins`), checked by the readers given a URDF.

Frames are in metres and radians, named as the kinds name them (``base.*`` the pose of the
robot's base frame B in the measurement frame M, ``R_base = rotx(rx) roty(ry) rotz(rz)``;
``tool.*`` the tool point (or frame) in the tip frame; ``pivot.*``, ``plane.*``, ...). The
4x4 matrices are derived, for cells that take those; on reading they must agree with the
named values. Each set records the chain it was measured on (``base_frame``,
``tip_frame``; an older file's sets are on its top-level chain); with several chains,
``"chains"`` lists them and the top-level chain keys are the first's. ``chain_hash``
identifies the robot model and chain (robot name, base, tip, joint names, kinds and axes;
not the joint origins, which a calibration changes): frames never go to another robot.

Version 1's top-level keys (``base``, ``tool``, ``tool_points``, ``T_measurement_base``,
``T_tip_tool``) are of the first point or pose set (else of the first set with a tool
point), for version 1 readers; version 1 and ``kincal-frames-sets-1`` are still read.
Values are checked: finite, within 1 km and 100 rad, nesting at most 32 deep.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from kincal.errors import DataError, InputFileError
from kincal.input_files import json_depth, non_finite_path
from kincal.rotations import base_rotation, matrix_to_quaternion, transform
from kincal import urdf_origins
from kincal.tilts_in_urdf import TiltInUrdf

AXES6 = ("x", "y", "z", "rx", "ry", "rz")  # a frame's named values: translation, rotation
POINT_FRAMES = tuple(f"base.{c}" for c in AXES6) + ("tool.x", "tool.y", "tool.z")  # 1 point

FORMAT = "kincal-frames"
VERSION = 2
CONVENTION = ("P_measured = R_base (p_tip + R_tip t_tool) + t_base, R_base = rotx(rx) "
              "roty(ry) rotz(rz); metres and radians")
# [m] the largest length kincal accepts in a robot cell (a frame's translation, a tool point
# or frame guess, a point, a volume's size: a cube, sphere, floor, pivot): 1 km is a slip
MAX_LENGTH = 1e3
MAX_ANGLE = 100.0  # [rad]
MAX_COMPLIANCE = 1.0  # [rad/(N m)] largest compliance accepted (1 rad at 1 N m)
MAX_DEPTH = 32
ANGLE_NAMES = ("rx", "ry", "rz")


def chain_hash(robot) -> str:
    """A hash of the robot model and chain that a calibration does not change: robot name,
    base and tip frames, chain joint names, kinds and axes."""
    g = robot.geometry
    text = json.dumps([robot.model_name, robot.base, robot.tip, list(g.joint_names), list(g.kinds),
                       [[round(float(v), 6) + 0.0 for v in a] for a in g.axes]])
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class SetFrames:
    """One measurement set's frames: its kind, source, and named values [m, rad]; the chain
    it was measured on (base_frame, tip_frame; "" for the file's top-level chain)."""

    kind: str
    source: str
    names: tuple[str, ...]
    values: tuple[float, ...]
    base_frame: str = ""
    tip_frame: str = ""
    joints: tuple[str, ...] = ()  # the chain joints of that chain, root first
    fixed_joints: tuple[tuple[str, float], ...] = ()  # held, absent from the file [rad, m]

    def value(self, name: str) -> float:
        return self.values[self.names.index(name)]

    def has(self, *names: str) -> bool:
        return all(n in self.names for n in names)

    @property
    def base(self) -> np.ndarray:
        """(6,) the measurement frame (base.x ... base.rz)."""
        return np.array([self.value("base." + c) for c in AXES6])

    @property
    def tools(self) -> np.ndarray:
        """(K, 3) the tool points in the tip frame: tool.*, then tool2.*, ..."""
        out, k = [[self.value("tool." + c) for c in "xyz"]], 2
        while self.has(f"tool{k}.x", f"tool{k}.y", f"tool{k}.z"):
            out, k = out + [[self.value(f"tool{k}.{c}") for c in "xyz"]], k + 1
        return np.array(out)

    def as_points(self) -> "SetFrames | None":
        """The frames this set holds for point data (the point kind's names): a point set's
        own; a pose set's measurement frame and its tool frame's origin on the tip, the
        tool point of one measured point (the tool's orientation, which points do not see,
        left out); None for a set without a measurement frame and tool point (contacts).
        The one place that says which frames of a pose set serve points."""
        if self.kind not in ("point", "pose") or not self.has(*POINT_FRAMES):
            return None
        if self.kind == "point":
            return self
        return replace(self, kind="point", names=POINT_FRAMES,
                       values=tuple(self.value(n) for n in POINT_FRAMES))

    @property
    def tool_rotation(self) -> np.ndarray | None:
        """(3, 3) the tool frame's rotation in the tip frame (a pose set's tool.rx .ry .rz,
        a flush set's face tilts; ``R = rotx(rx) roty(ry) rotz(rz)``), None for a set that
        has none (points)."""
        if not any(self.has("tool." + c) for c in ANGLE_NAMES):
            return None
        return base_rotation(*(self.value("tool." + c) if self.has("tool." + c) else 0.0
                               for c in ANGLE_NAMES))

    def derived(self) -> dict:
        """The 4x4 matrices and quaternion of the measurement frame and tool points."""
        out: dict = {}
        if self.has(*("base." + c for c in AXES6)):
            b = self.base
            T = transform(base_rotation(*b[3:]), b[:3])
            out["T_measurement_base"] = T.tolist()
            out["pose_measurement_base"] = dict(zip(
                ("x", "y", "z", "qx", "qy", "qz", "qw"),
                [*map(float, b[:3]), *map(float, matrix_to_quaternion(T[:3, :3]))]))
        if self.has("tool.x", "tool.y", "tool.z"):
            rot = self.tool_rotation  # a tool frame (poses), a contact face's tilt (flush)
            for k, t in enumerate(self.tools, start=1):
                out["T_tip_tool" + ("" if k == 1 else f"_{k}")] = transform(
                    rot if k == 1 else None, t).tolist()
        planes = sorted({n.split(".")[0] for n in self.names if n.startswith("plane")
                         and n.endswith(".d")})
        for p in planes:  # plane{k}: normal Rx(rx) Ry(ry) e_z and offset, in the base frame
            rx, ry, d = (self.value(f"{p}.{c}") for c in ("rx", "ry", "d"))
            n = base_rotation(rx, ry, 0.0)[:, 2]
            out[f"{p}_in_base"] = {"normal": [float(v) for v in n], "offset_m": float(d)}
        return out


@dataclass(frozen=True)
class CellFrames:
    """The frames of a calibration: the chain they belong to and each set's frames.

    robot / chain_hash: the robot model (:func:`chain_hash`; "" when an old file does not
    say). base_frame, tip_frame, joints: the chain. sets: one :class:`SetFrames` per set.
    backlash: {joint: half the play [rad or m]}; compliance: {joint: deflection per N m of
    gravity torque [rad/(N m)]} (:mod:`kincal.models.compliance`). source: for messages.
    tilts_in_urdf: contact-face tilts the URDF written beside carries
    (:mod:`kincal.tilts_in_urdf`); urdf_origins: its calibrated joints' origins
    ((joint, Origin), ...; :mod:`kincal.urdf_origins`).
    """

    robot: str
    chain_hash: str
    base_frame: str
    tip_frame: str
    joints: tuple[str, ...]
    sets: tuple[SetFrames, ...]
    backlash: dict = field(default_factory=dict)
    source: str = "<frames>"
    compliance: dict = field(default_factory=dict)
    tilts_in_urdf: tuple[TiltInUrdf, ...] = ()
    urdf_origins: tuple = ()

    @classmethod
    def of_points(cls, base, tools, *, robot: str = "", base_frame: str = "",
                  tip_frame: str = "", joints=(), backlash=None,
                  source: str = "<frames>") -> "CellFrames":
        """The frames of one point set: base (6,) [m, rad] and tool points (K, 3) [m]."""
        t = np.atleast_2d(np.asarray(tools, float))
        names = [f"base.{c}" for c in AXES6]
        for k in range(1, len(t) + 1):
            names += [("tool." if k == 1 else f"tool{k}.") + c for c in "xyz"]
        values = tuple(float(v) for v in np.r_[np.asarray(base, float), t.ravel()])
        return cls(robot, "", base_frame, tip_frame, tuple(joints),
                   (SetFrames("point", "", tuple(names), values),), dict(backlash or {}), source)

    # ------------------------------------------------------------ writing
    def as_dict(self) -> dict:
        from kincal.models.backlash import CONVENTION as BACKLASH_CONVENTION
        from kincal.models.compliance import CONVENTION as COMPLIANCE_CONVENTION

        out = {"format": FORMAT, "version": VERSION, "robot": self.robot,
               "chain_hash": self.chain_hash, "base_frame": self.base_frame,
               "tip_frame": self.tip_frame, "joints": list(self.joints),
               "convention": CONVENTION,
               "sets": [{"kind": s.kind, "source": s.source,
                         "base_frame": s.base_frame or self.base_frame,
                         "tip_frame": s.tip_frame or self.tip_frame,
                         "joints": list(s.joints or self.joints),
                         "frames": dict(zip(s.names, map(float, s.values))), **s.derived(),
                         **({"fixed_joints": {j: float(v) for j, v in s.fixed_joints}}
                            if s.fixed_joints else {})}
                        for s in self.sets]}
        for key, terms, convention in (("backlash", self.backlash, BACKLASH_CONVENTION),
                                       ("compliance", self.compliance, COMPLIANCE_CONVENTION)):
            if terms:
                out |= {key: {j: float(v) for j, v in terms.items()},
                        key + "_convention": convention}
        if self.tilts_in_urdf:
            out["tilts_in_urdf"] = [t.as_dict() for t in self.tilts_in_urdf]
        if self.urdf_origins:
            out["urdf_origins"] = urdf_origins.as_dict(self.urdf_origins)
        if len(self.chains()) > 1:  # the top-level chain keys are the first's; say which
            out["chains"] = [{"base_frame": b, "tip_frame": t} for b, t in self.chains()]
        try:  # version 1's keys, of the first point or pose set, for readers of version 1
            s = self.located()
        except DataError:  # no measurement frame: the first set's tool point (contacts)
            first = next((t for t in self.sets if t.has("tool.x", "tool.y", "tool.z")), None)
            if first is not None:
                out["tool"] = dict(zip("xyz", map(float, first.tools[0])))
                out.update(first.derived())
            return out
        tools = s.tools
        out["base"] = dict(zip(AXES6, map(float, s.base)))
        out["tool"] = dict(zip("xyz", map(float, tools[0])))
        if len(tools) > 1:
            out["tool_points"] = [dict(zip("xyz", map(float, t))) for t in tools]
        out.update(s.derived())
        return out

    def dumps(self, provenance: dict | None = None) -> str:
        """The file's text; ``provenance`` (who made it, from what) is kept under its own
        key, which readers ignore."""
        out = self.as_dict()
        if provenance is not None:
            out["provenance"] = provenance
        return json.dumps(out, indent=2) + "\n"

    # ------------------------------------------------------------ reading
    @classmethod
    def read(cls, path) -> "CellFrames":
        """From a FRAMES.json file (any version); DataError naming what is wrong."""
        from kincal.input_files import read_json

        data = read_json(path, "frames", "a kincal frames file", DataError,
                         expected="the FRAMES.json that kincal calibrate --frames-out wrote")
        return cls.from_dict(data, str(Path(path)))

    @classmethod
    def from_dict(cls, data, source: str = "<frames>") -> "CellFrames":
        """From the content of a FRAMES.json of any version."""
        if not isinstance(data, dict):
            raise DataError(f"{source}: not a kincal frames file (a JSON object was expected)")
        if json_depth(data, MAX_DEPTH + 1) > MAX_DEPTH:
            raise DataError(f"{source}: not a kincal frames file (JSON nested more than "
                            f"{MAX_DEPTH} deep)")
        bad = non_finite_path(data)
        if bad:
            raise DataError(f"{source}: {bad} is not a finite number; frames are finite "
                            "values in metres and radians (a corrupted or hand-edited file?)")
        try:
            if data.get("format") == FORMAT:
                if data.get("version") != VERSION:
                    raise DataError(f"{source}: frames file version {data.get('version')!r}; "
                                    f"this kincal reads versions 1 and {VERSION}")
                frames = cls._from_v2(data, source)
            elif data.get("format") == "kincal-frames-sets-1":
                frames = cls._from_sets1(data, source)
            elif "base" in data and "tool" in data:
                frames = cls._from_v1(data, source)
            else:
                raise DataError(f"{source}: not a kincal frames file: expected \"format\": "
                                f"\"{FORMAT}\" (or an older file's \"base\" and \"tool\")")
        except (ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
            raise DataError(f"{source}: not a kincal frames file ({exc.__class__.__name__}: "
                            f"{exc})") from None
        frames._check_values(data)
        return frames

    @classmethod
    def _from_v2(cls, data: dict, source: str) -> "CellFrames":
        sets = []
        base, tip = str(data.get("base_frame", "")), str(data.get("tip_frame", ""))
        for s in data["sets"]:
            f = s["frames"]
            if not isinstance(f, dict):
                raise TypeError("a set's frames must be an object of named values")
            sets.append(SetFrames(str(s["kind"]), str(s.get("source", "")),
                                  tuple(str(k) for k in f), tuple(float(v) for v in f.values()),
                                  str(s.get("base_frame", base)), str(s.get("tip_frame", tip)),
                                  tuple(str(j) for j in s.get("joints", data.get("joints", ()))),
                                  _fixed(s.get("fixed_joints", {}))))
        if not sets:
            raise DataError(f"{source}: the frames file holds no measurement set")
        return cls(str(data.get("robot", "")), str(data.get("chain_hash", "")),
                   str(data.get("base_frame", "")), str(data.get("tip_frame", "")),
                   tuple(str(j) for j in data.get("joints", ())), tuple(sets),
                   _backlash(data), source, _backlash(data, "compliance"),
                   tuple(map(TiltInUrdf.from_dict, data.get("tilts_in_urdf", []))),
                   urdf_origins.from_dict(data.get("urdf_origins", {})))

    @classmethod
    def _from_v1(cls, data: dict, source: str) -> "CellFrames":
        names, values = [], []
        for c in AXES6:
            names.append("base." + c)
            values.append(float(data["base"][c]))
        tools = data.get("tool_points", [data["tool"]])
        if not tools:
            raise DataError(f"{source}: the frames contain no tool point")
        for k, t in enumerate(tools, start=1):
            for c in "xyz":
                names.append(("tool." if k == 1 else f"tool{k}.") + c)
                values.append(float(t[c]))
        return cls("", "", str(data.get("base_frame", "")), str(data.get("tip_frame", "")),
                   tuple(str(j) for j in data.get("joints", ())),
                   (SetFrames("point", "", tuple(names), tuple(values)),),
                   _backlash(data), source)

    @classmethod
    def _from_sets1(cls, data: dict, source: str) -> "CellFrames":
        sets = tuple(SetFrames(str(s["kind"]), str(s.get("source", "")),
                               tuple(str(k) for k in s["frames"]),
                               tuple(float(v) for v in s["frames"].values()))
                     for s in data["sets"])
        if not sets:
            raise DataError(f"{source}: the frames file holds no measurement set")
        return cls("", "", str(data.get("base", "")), str(data.get("tip", "")), (), sets,
                   _backlash(data), source)

    def _check_values(self, data: dict) -> None:
        """Finite, not absurd, and the 4x4 matrices (where given) agree with the values."""
        for k, s in enumerate(self.sets, start=1):
            for name, v in zip(s.names, s.values):
                angle = name.rsplit(".", 1)[-1] in ANGLE_NAMES
                limit = MAX_ANGLE if angle else MAX_LENGTH
                if not math.isfinite(v) or abs(v) > limit:
                    raise DataError(
                        f"{self.source}: set {k} frame {name} = {v!r} is "
                        + ("not finite" if not math.isfinite(v) else
                           f"beyond {limit:g} {'rad' if angle else 'm'}")
                        + "; frames are in metres and radians (a corrupted or hand-edited file?)")
        for j, v in self.backlash.items():
            if not math.isfinite(v) or abs(v) > MAX_ANGLE:
                raise DataError(f"{self.source}: backlash of {j} = {v!r} is not a plausible "
                                "half play [rad or m]")
        for j, v in self.compliance.items():
            if not math.isfinite(v) or abs(v) > MAX_COMPLIANCE:
                raise DataError(f"{self.source}: compliance of {j} = {v!r} is not a plausible "
                                f"compliance (|c| <= {MAX_COMPLIANCE:g} rad/(N m))")
        given = [s.get("T_measurement_base") for s in data.get("sets", [])] \
            if isinstance(data.get("sets"), list) else [data.get("T_measurement_base")]
        for k, (s, T) in enumerate(zip(self.sets, given), start=1):
            if T is None or not s.has("base.x", "base.rz"):
                continue
            T = np.asarray(T, dtype=float)
            want = np.asarray(s.derived()["T_measurement_base"])
            if T.shape != (4, 4) or not np.allclose(T, want, atol=1e-6):
                raise DataError(f"{self.source}: set {k}'s T_measurement_base contradicts its "
                                "base.* values (differs by "
                                + (f"{np.abs(T - want).max():.3g}" if T.shape == (4, 4)
                                   else f"shape {T.shape}")
                                + "); fix one of them or write the file anew")

    def chains(self) -> tuple[tuple[str, str], ...]:
        """The (base, tip) frames of the chains the sets were measured on, first seen first."""
        return tuple(dict.fromkeys(map(self._chain_of, self.sets)))

    def _chain_of(self, s: SetFrames) -> tuple[str, str]:
        return s.base_frame or self.base_frame, s.tip_frame or self.tip_frame

    def _on(self, chain: tuple[str, str]) -> tuple[SetFrames, ...]:
        """The sets measured on ``chain`` (base, tip); a set naming none is on the file's."""
        return tuple(s for s in self.sets if self._chain_of(s) == chain)

    def for_chain(self, base: str | None, tip: str | None) -> "CellFrames":
        """The frames of the sets measured on the chain ``base`` -> ``tip`` (None: the one
        recorded chain with the other frame), checked by its base, tip and joints (the chain
        hash is the top-level chain's); refused unless they name one chain: a data file does
        not say which it was measured on, and another chain's frames judge it metres off."""
        chains = self.chains()
        fit = [c for c in chains if base in (None, c[0]) and tip in (None, c[1])]
        if (base is None or tip is None) and len(fit) > 1:
            given = " ".join(f"--{r} {v}" for r, v in (("base", base), ("tip", tip)) if v)
            raise DataError(f"{self.source} holds the frames of {len(chains)} chains "
                            f"({', '.join(map(' -> '.join, chains))})"
                            + (f", {len(fit)} of them with {given}" if given else "")
                            + ": give --base and --tip of the chain meant (the data or "
                            "targets of another chain are metres off with these frames)")
        base, tip = fit[0] if (base is None) != (tip is None) and len(fit) == 1 else (base, tip)
        base, tip = base or self.base_frame, tip or self.tip_frame
        top = (base, tip) == (self.base_frame, self.tip_frame)
        mine = self._on((base, tip))
        if not mine:
            return self
        joints = set(self.joints if top else mine[0].joints)
        others = {j for s in self.sets for j in s.joints} - joints
        # the backlash and compliance terms of the other chains' joints are theirs; a term on
        # no chain of the file stays, for check_chain to refuse
        backlash, compliance = ({j: v for j, v in terms.items() if j not in others}
                                for terms in (self.backlash, self.compliance))
        if top:  # its own sets only: another chain's frames would be read on this one
            return replace(self, sets=mine, backlash=backlash, compliance=compliance)
        return CellFrames(self.robot, "", base, tip, mine[0].joints, mine, backlash,
                          self.source, compliance, self.tilts_in_urdf, self.urdf_origins)

    # ------------------------------------------------------------ checks
    def check_chain(self, robot) -> None:
        """Refuse frames identified on another robot or chain than ``robot``'s."""
        if self.robot and self.robot != robot.model_name:
            raise DataError(f"{self.source} belongs to the robot {self.robot!r}, not "
                            f"{robot.model_name!r} (the robot names of the URDFs): frames from "
                            "another robot would give wrong numbers")
        theirs = {"base frame": self.base_frame, "tip frame": self.tip_frame}
        mine = {"base frame": robot.base, "tip frame": robot.tip}
        for what in theirs:
            if theirs[what] and theirs[what] != mine[what]:
                raise DataError(f"{self.source} belongs to the {what} {theirs[what]!r}, this "
                                f"robot's chain has {mine[what]!r} ({robot.base} -> {robot.tip}): "
                                "frames from another robot or tip would give wrong joint "
                                "values; use the frames written with this calibration, or "
                                f"--tip/--base {theirs[what]} if that is the chain you meant")
        if self.joints and tuple(self.joints) != tuple(robot.joint_names):
            raise DataError(f"{self.source} was identified on the chain joints "
                            f"{', '.join(self.joints)}, this robot's chain has "
                            f"{', '.join(robot.joint_names)}: frames from another robot")
        if self.chain_hash and self.chain_hash != chain_hash(robot):
            raise DataError(f"{self.source} was identified on another robot model or chain "
                            f"than {robot.name} ({robot.base} -> {robot.tip}): its chain hash "
                            "differs (joint kinds or axes)")
        for term, values in (("backlash", self.backlash), ("compliance", self.compliance)):
            unknown = [j for j in values if j not in robot.joint_names]
            if unknown:
                raise DataError(f"{self.source}: no chain joint {unknown[0]!r} for a {term} "
                                f"term (chain joints of {robot.name}: "
                                f"{', '.join(robot.joint_names)})")

    def located(self, frame: bool = True) -> SetFrames:
        """The first set with a measurement frame and tool point (points, poses) on the
        file's chain (a set of another chain has its tool point in another tip frame);
        frame=False: else the first with a tool point (distances, contacts: a program
        filter needs no measurement frame)."""
        chain = (self.base_frame, self.tip_frame)
        for s in sorted(self._on(chain), key=lambda s: s.as_points() is None):
            if s.as_points() is not None or not frame and s.has("tool.x", "tool.y", "tool.z"):
                return s
        elsewhere = dict.fromkeys(" -> ".join(self._chain_of(s)) for s in self.sets
                                  if s.as_points() is not None)
        raise DataError(f"{self.source}: no measurement set on the chain {' -> '.join(chain)} "
                        "has a measurement frame and tool point (kinds "
                        + ", ".join(s.kind for s in self._on(chain)) + "); targets in a "
                        "measurement frame need a point or pose calibration"
                        + (f" (its point or pose sets are on {', '.join(elsewhere)}: give "
                           "that chain's --tip/--base)" if elsewhere else ""))

    @property
    def base(self) -> np.ndarray:
        """(6,) measurement frame of the first point or pose set."""
        return self.located().base

    @property
    def tools(self) -> np.ndarray:
        """(K, 3) its tool points in the tip frame [m]."""
        return self.located().tools

    @property
    def tool_rotation(self) -> np.ndarray:
        """(3, 3) its tool frame's rotation in the tip frame (identity for points)."""
        R = self.located().tool_rotation
        return np.eye(3) if R is None else R

    @property
    def T_measurement_base(self) -> np.ndarray:
        """(4, 4) pose of the base frame B in the measurement frame M [m]."""
        b = self.base
        return transform(base_rotation(*b[3:]), b[:3])


def _fixed(value) -> tuple[tuple[str, float], ...]:
    """A set's optional "fixed_joints" {joint: value [rad or m]} (absent before it existed)."""
    if not isinstance(value, dict):
        raise TypeError("a set's fixed_joints must be an object {joint: value}")
    return tuple((str(j), float(v)) for j, v in value.items())


def _backlash(data: dict, key: str = "backlash") -> dict:  # or compliance
    b = data.get(key, {})
    if not isinstance(b, dict):
        raise TypeError(f"{key} must be an object {{joint: value}}")
    return {str(j): float(v) for j, v in b.items()}

