"""The parameter vector of a calibration: stable names, units and slices.

One layout for every calibration, whatever its measurement sets::

    [ kinematic (the error model) | set 1 frames | set 2 frames | ... | backlash ]

The kinematic block is the error model's (``joint_3.a``, ``joint_2.beta``, ...). Each
measurement set adds the frame parameters of its kind (:mod:`kincal.measurements`): set 1
keeps the kind's names (``base.x``, ``tool.z``, ``pivot.y``, ``plane.d``), set k >= 2
prefixes them ``set<k>.``; a frame a set shares with an earlier set (a plane several files
touch, ``--shared-plane``) is the earlier set's, once. The joint terms come last: the
backlash terms (``<joint>.backlash``), half the play of a joint [rad, or m for a prismatic
joint], then the compliance terms (``<joint>.compliance``), a joint's deflection per N m
of gravity torque [rad/(N m)]; "backlash" in the names of the slice below means both.

For one point set the names and order are those of
:class:`kincal.measurements.point_space.ParameterSpace` (kinematic, base, tool points,
backlash), so a vector of one means the same in both. Lengths are in metres, angles in
radians; reports convert to mm and degrees. Frames have no nominal value and are not
penalised; the kinematic and backlash parameters are pulled toward nominal by L2.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from kincal.errors import ParameterError, listing, suggest
from kincal.measurements.point_space import DEG, MM, expand_names, name_index


@dataclass(frozen=True)
class ParameterLayout:
    """Names, units and slices of the parameter vector (see the module notes).

    kinematic_names / kinematic_is_length / kinematic_classes: the error model's
    parameters ("length" / "twist" / "offset" classes). set_frames: per set, its kind's
    frame names (unprefixed) and length flags. backlash: chain joints with a backlash
    term, in chain order; backlash_is_length: True for prismatic joints. aliases: per set,
    per frame name, -1 for the set's own parameter, or the index of the earlier set whose
    parameter of that name it shares (a plane several files touch: ``--shared-plane``);
    () for none shared. compliance: chain joints with a compliance term, in chain order;
    torque_rms: their RMS gravity torque over the samples [N m] (one reporting unit of a
    compliance is 1 deg of deflection at that torque; () before the samples are known).
    """

    kinematic_names: tuple[str, ...]
    kinematic_is_length: tuple[bool, ...]
    kinematic_classes: tuple[str, ...]
    set_frames: tuple[tuple[tuple[str, ...], tuple[bool, ...]], ...]
    backlash: tuple[str, ...] = ()
    backlash_is_length: tuple[bool, ...] = ()
    aliases: tuple[tuple[int, ...], ...] = ()
    compliance: tuple[str, ...] = ()
    torque_rms: tuple[float, ...] = ()

    @classmethod
    def of(cls, error_model, kinds, backlash=(), aliases=(), compliance=(),
           torque_rms=()) -> "ParameterLayout":
        """The layout of an error model's chain measured by ``kinds`` (KindModels);
        ``backlash`` are chain joints (any order: kept in chain order); aliases: see the
        class notes."""
        joints = tuple(error_model.joint_names)
        unknown = [j for j in backlash if j not in joints]
        if unknown:
            raise ParameterError(f"no chain joint {unknown[0]!r} for a backlash term."
                                 + suggest(unknown[0], joints)
                                 + f" Chain joints: {listing(joints, 60)}", valid=joints)
        if len(set(backlash)) != len(tuple(backlash)):
            raise ParameterError(f"backlash joints given twice: {', '.join(backlash)}")
        unknown = [j for j in compliance if j not in joints]
        if unknown:
            raise ParameterError(f"no chain joint {unknown[0]!r} for a compliance term."
                                 + suggest(unknown[0], joints)
                                 + f" Chain joints: {listing(joints, 60)}", valid=joints)
        chosen = tuple(j for j in joints if j in set(backlash))
        return cls(tuple(error_model.names), tuple(bool(b) for b in error_model.is_length),
                   tuple(error_model.classes),
                   tuple((tuple(k.frame_names), tuple(bool(b) for b in k.frame_is_length))
                         for k in kinds),
                   chosen,
                   tuple(error_model.kinds[joints.index(j)] == "prismatic" for j in chosen),
                   tuple(tuple(int(a) for a in row) for row in aliases),
                   tuple(j for j in joints if j in set(compliance)),
                   tuple(float(t) for t in torque_rms))

    def own(self, i: int) -> tuple[bool, ...]:
        """Per frame name of set i: True for its own parameter, False for a shared one."""
        if not self.aliases:
            return (True,) * len(self.set_frames[i][0])
        return tuple(a < 0 for a in self.aliases[i])

    # ------------------------------------------------------------------ sizes
    @property
    def n_kinematic(self) -> int:
        return len(self.kinematic_names)

    @property
    def n_sets(self) -> int:
        return len(self.set_frames)

    @property
    def n_frames(self) -> int:
        """Frame parameters of all sets together (a shared one once)."""
        return sum(sum(self.own(i)) for i in range(self.n_sets))

    @property
    def n_backlash(self) -> int:
        return len(self.backlash)

    @property
    def n_terms(self) -> int:
        """Joint terms: backlash and compliance."""
        return len(self.backlash) + len(self.compliance)

    @cached_property  # the fields are frozen; the solver asks at every block
    def size(self) -> int:
        return self.n_kinematic + self.n_frames + self.n_terms

    @cached_property
    def frame_slices(self) -> tuple[slice | np.ndarray, ...]:
        """Per set, the slice of its frame parameters in the vector (an index array for a
        set sharing some with an earlier set)."""
        out: list[slice | np.ndarray] = []
        where: list[list[int]] = []
        start = self.n_kinematic
        for i, (names, _) in enumerate(self.set_frames):
            own = self.own(i)
            pos: list[int] = []
            for k, (name, mine) in enumerate(zip(names, own)):
                if mine:
                    pos.append(start)
                    start += 1
                else:
                    owner = self.aliases[i][k]
                    pos.append(where[owner][self.set_frames[owner][0].index(name)])
            where.append(pos)
            out.append(slice(pos[0], pos[-1] + 1) if all(own) and pos else
                       np.array(pos, dtype=int) if pos else slice(start, start))
        return tuple(out)

    @cached_property  # the fields are frozen; every residual evaluation splits by it
    def backlash_slice(self) -> slice:
        return slice(self.n_kinematic + self.n_frames, self.size)

    # ------------------------------------------------------------------ names
    def set_prefix(self, i: int) -> str:
        return "" if i == 0 else f"set{i + 1}."

    def frame_names(self, i: int) -> tuple[str, ...]:
        """Set i's frame parameter names as they appear in the layout (prefixed; a shared
        one by the set that owns it)."""
        if not self.aliases:
            return tuple(self.set_prefix(i) + n for n in self.set_frames[i][0])
        return tuple(self.set_prefix(i if a < 0 else a) + n
                     for n, a in zip(self.set_frames[i][0], self.aliases[i]))

    @cached_property  # the fields are frozen; the fit and its checks look names up often
    def names(self) -> tuple[str, ...]:
        return (self.kinematic_names
                + tuple(n for i in range(self.n_sets)
                        for n, own in zip(self.frame_names(i), self.own(i)) if own)
                + tuple(f"{j}.backlash" for j in self.backlash)
                + tuple(f"{j}.compliance" for j in self.compliance))

    @cached_property  # read-only: the fields are frozen, the fit asks often
    def is_length(self) -> np.ndarray:
        """(p,) True for lengths [m], False for angles [rad]."""
        return _read_only(np.array(list(self.kinematic_is_length)
                                   + [b for i, (_, flags) in enumerate(self.set_frames)
                                      for b, own in zip(flags, self.own(i)) if own]
                                   + list(self.backlash_is_length)
                                   + [False] * len(self.compliance), dtype=bool))

    def penalty_scale(self, length_scale: float, angle_scale: float) -> np.ndarray:
        """(p,) the unit s of the penalty per parameter [SI]: ``length_scale`` for lengths,
        ``angle_scale`` for angles, and for a compliance that deflection at the joint's RMS
        torque (the solver's variables are x / s)."""
        out = np.where(self.is_length, length_scale, angle_scale)
        if self.compliance and self.torque_rms:
            out[self.is_compliance] = angle_scale / np.asarray(self.torque_rms, float)
        return out

    def _mask(self, sl: slice) -> np.ndarray:
        mask = np.zeros(self.size, dtype=bool)
        mask[sl] = True
        return mask

    @cached_property  # read-only: the fields are frozen, the fit asks often
    def is_kinematic(self) -> np.ndarray:
        """(p,) the error model's parameters (what the corrected URDF carries)."""
        return _read_only(self._mask(slice(0, self.n_kinematic)))

    @cached_property  # read-only: the fields are frozen, the fit asks often
    def is_frame(self) -> np.ndarray:
        """(p,) the sets' frame parameters (measurement frames, tool points, planes, ...)."""
        return _read_only(self._mask(slice(self.n_kinematic, self.n_kinematic + self.n_frames)))

    @cached_property  # read-only: the fields are frozen, the fit asks often
    def is_backlash(self) -> np.ndarray:
        """(p,) the joint terms (backlash and compliance)."""
        return _read_only(self._mask(self.backlash_slice))

    @cached_property  # read-only: the fields are frozen, the fit asks often
    def is_compliance(self) -> np.ndarray:
        return _read_only(self._mask(slice(self.size - len(self.compliance), self.size)))

    @cached_property  # read-only: the fields are frozen, the fit asks often
    def is_penalised(self) -> np.ndarray:
        """(p,) the parameters with a nominal value that L2 pulls toward: all but frames."""
        return _read_only(~self.is_frame)

    @property
    def classes(self) -> tuple[str, ...]:
        """(p,) class of every parameter: the error model's "length" / "twist" / "offset",
        "frame", "backlash", "compliance"."""
        return (self.kinematic_classes + ("frame",) * self.n_frames
                + ("backlash",) * self.n_backlash + ("compliance",) * len(self.compliance))

    def reporting_scale(self) -> np.ndarray:
        """(p,) size of one reporting unit per parameter: 1 mm or 1 deg, in SI; for a
        compliance, 1 deg at the joint's RMS torque (1 deg/(N m) before it is known)."""
        out = np.where(self.is_length, MM, DEG)
        if self.compliance and self.torque_rms:
            out[self.is_compliance] = DEG / np.asarray(self.torque_rms, float)
        return out

    # ----------------------------------------------------------- look-ups
    @cached_property
    def _positions(self) -> dict[str, int]:
        return {n: i for i, n in reversed(list(enumerate(self.names)))}

    def index(self, name: str) -> int:
        i = self._positions.get(name)
        return name_index(self.names, name) if i is None else i  # unknown: the error

    def expand(self, patterns) -> tuple[str, ...]:
        """The names that ``patterns`` select, in parameter order, each once: names
        (``"joint_3.a"``) or shell-style patterns (``"*.d"``, ``"joint_[456].*"``); unknown
        ones raise ParameterError listing the valid names (:func:`expand_names`)."""
        return expand_names(self.names, patterns)

    def indices(self, patterns) -> np.ndarray:
        """(k,) indices of the parameters that ``patterns`` select (see :meth:`expand`)."""
        return np.array([self.index(n) for n in self.expand(patterns)], dtype=int)

    # ----------------------------------------------------------- vectors
    def kinematic(self, x: np.ndarray) -> np.ndarray:
        return x[..., :self.n_kinematic]

    def frames(self, x: np.ndarray, i: int) -> np.ndarray:
        """Set i's frame parameters (a view; a copy for a set sharing some)."""
        return x[..., self.frame_slices[i]]

    def backlash_values(self, x: np.ndarray) -> np.ndarray:
        return x[..., self.backlash_slice]

    def split(self, x: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kinematic, set i's frames, backlash) views of a parameter vector (or of (N, p)
        vectors, one per sample)."""
        return self.kinematic(x), self.frames(x, i), self.backlash_values(x)

    def wrap_frame_angles(self, x: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
        """A copy of x with each frame angle moved by whole turns to within half a turn of
        its value in ``near`` (default 0): the same frames. Each frame angle is an angle of
        a rotation or of a plane's normal, so a turn changes nothing the fit sees; a nearly
        free one (a plane's rx at a normal near +-x, where Rx(rx) barely turns it) wanders
        by whole turns in a fit (-101 rad, which FRAMES.json's reader refuses as corrupt)."""
        angle = self.is_frame & ~self.is_length
        out = np.array(x, dtype=float)
        ref = 0.0 if near is None else np.asarray(near, dtype=float)[angle]
        out[angle] -= 2 * np.pi * np.round((out[angle] - ref) / (2 * np.pi))
        return out

    # ------------------------------------------- one set of points (the common case)
    @property
    def n_points(self) -> int:
        """Measured points per pose of the first set (tool.*, tool2.*, ...; 0 if none)."""
        names = self.set_frames[0][0] if self.set_frames else ()
        k = 0
        while all(("tool." if k == 0 else f"tool{k + 1}.") + c in names for c in "xyz"):
            k += 1
        return k

    def join(self, kinematic, base, tools, backlash=None) -> np.ndarray:
        """The vector of a layout of one point set: kinematic, base (6,), tool points
        (K, 3) or (3,), joint terms: backlash, then compliance (None: zero) [SI]."""
        if self.n_sets != 1 or self.set_frames[0][0][:6] != tuple(
                f"base.{c}" for c in ("x", "y", "z", "rx", "ry", "rz")):
            raise ParameterError("join() builds the vector of one point set; with other sets, "
                                 "fill the frames through frame_slices")
        b = np.zeros(self.n_terms) if backlash is None else np.asarray(backlash, float)
        x = np.concatenate([np.asarray(kinematic, float).ravel(), np.asarray(base, float),
                            np.asarray(tools, float).ravel(), b])
        if x.size != self.size:
            raise ParameterError(f"{self.size} values expected, got {x.size}")
        return x


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a
