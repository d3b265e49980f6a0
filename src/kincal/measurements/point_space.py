"""Names, units and layout of the calibration parameters.

The parameter vector x holds absolute values (not errors), in SI units:

    [ <joint_1>.a, .alpha, .d, .theta, ..., <joint_n>.theta,      kinematic (error model)
      base.x, base.y, base.z, base.rx, base.ry, base.rz,          measurement frame
      tool.x, tool.y, tool.z,                                      tool point in the tip frame
      tool2.x, ..., tool<K>.z,                                     further measured points
      <joint>.backlash, ...,                                       optional backlash terms
      <joint>.compliance, ... ]                                    optional compliance terms

The kinematic block is the error model's (:mod:`kincal.models`): four MD-H parameters
per joint for ``mdh``, plus ``.beta`` at nearly parallel axes for ``complete``, six
``.tx .ty .tz .rx .ry .rz`` per joint for ``placement``, one offset per joint for
``offsets``.

With K measured points per pose (several targets on the tool: their positions together
carry its orientation) point 1 is ``tool.*`` and point k >= 2 is ``tool<k>.*``. The
backlash terms (:mod:`kincal.backlash`) exist only for the joints asked for; each is
half the play of its joint [rad, or m for a prismatic joint], nominally 0. The compliance
terms (:mod:`kincal.models.compliance`) likewise, each the joint's deflection per N m of
gravity torque [rad/(N m)], nominally 0. Together they are the *joint terms*.

The measurement frame M sees the tool point at
``P = R_base (p_tip + R_tip t_tool) + t_base`` with ``R_base = Rx(rx) Ry(ry) Rz(rz)``.
Lengths are in metres, angles in radians; reports convert to mm and degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kincal.errors import ParameterError, listing, suggest
from kincal.models.base import ErrorModel

BASE = ("base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz")
TOOL = ("tool.x", "tool.y", "tool.z")
MM = 1e-3  # [m]
DEG = math.pi / 180.0  # [rad]


def _check_backlash_joints(joint_names: tuple[str, ...], backlash: tuple[str, ...],
                           term: str = "backlash") -> None:
    unknown = [j for j in backlash if j not in joint_names]
    if unknown:
        raise ParameterError(f"no chain joint {unknown[0]!r} for a {term} term."
                             + suggest(unknown[0], joint_names)
                             + f" Chain joints: {listing(joint_names, 60)}", valid=joint_names)
    if len(set(backlash)) != len(backlash):
        raise ParameterError(f"{term} joints given twice: {', '.join(backlash)}")


def name_index(names: tuple[str, ...], name: str) -> int:
    """Position of parameter ``name`` in ``names``; ParameterError listing the valid ones."""
    try:
        return names.index(name)
    except ValueError:
        raise ParameterError(f"unknown parameter {name!r}." + suggest(name, names)
                             + f" Valid names: {listing(names, 60)}", valid=names) from None


def expand_names(names: tuple[str, ...], patterns) -> tuple[str, ...]:
    """The ``names`` that ``patterns`` select, in their order, each once (the one matcher of
    --fix/--free names, for every parameter layout).

    A pattern is a name (``"joint_3.a"``) or a shell-style pattern (``"*.d"``,
    ``"joint_[456].*"``, ``"tool*"``; :func:`fnmatch.fnmatchcase`). A single string is one
    pattern. An unknown name, or a pattern that matches nothing, raises
    :class:`ParameterError` listing the valid names.
    """
    import fnmatch

    if isinstance(patterns, str):
        patterns = (patterns,)
    chosen = set()
    for pattern in patterns:
        if not isinstance(pattern, str):
            raise ParameterError(f"a parameter name or pattern must be a string, got "
                                 f"{pattern!r}", valid=names)
        if not any(c in pattern for c in "*?["):
            chosen.add(name_index(names, pattern))
            continue
        hits = [k for k, n in enumerate(names) if fnmatch.fnmatchcase(n, pattern)]
        if not hits:
            raise ParameterError(f"pattern {pattern!r} matches no parameter. Valid names: "
                                 f"{listing(names, 60)}", valid=names)
        chosen.update(hits)
    return tuple(names[k] for k in sorted(chosen))


@dataclass(frozen=True)
class ParameterSpace:
    """The parameters of one chain: stable names, units and vector layout.

    joint_names: the chain joints. kinematic_names / kinematic_is_length /
    kinematic_classes / kinematic_joint: the error model's parameters (names, True for
    lengths, class "length"/"twist"/"offset", chain index of the joint each belongs to).
    backlash: chain joints with a backlash term, in chain order; backlash_is_length: for
    each, True if the joint is prismatic (the term is a length). n_points: measured
    points per pose (K), each with its own position in the tip frame. compliance: chain
    joints with a compliance term, in chain order (after the backlash terms).
    """

    joint_names: tuple[str, ...]
    kinematic_names: tuple[str, ...]
    kinematic_is_length: tuple[bool, ...]
    kinematic_classes: tuple[str, ...]
    kinematic_joint: tuple[int, ...]
    backlash: tuple[str, ...] = ()
    backlash_is_length: tuple[bool, ...] = ()
    n_points: int = 1
    compliance: tuple[str, ...] = ()

    def __post_init__(self):
        _check_backlash_joints(self.joint_names, self.backlash)
        _check_backlash_joints(self.joint_names, self.compliance, "compliance")
        order = [self.joint_names.index(j) for j in self.backlash]
        if order != sorted(order):
            raise ParameterError("backlash joints must be in chain order")
        if len(self.backlash_is_length) != len(self.backlash):
            raise ParameterError("backlash_is_length needs one flag per backlash joint")
        if not (isinstance(self.n_points, (int, np.integer)) and self.n_points >= 1):
            raise ParameterError(f"n_points must be an integer >= 1, got {self.n_points!r}")

    @classmethod
    def of_model(cls, model: ErrorModel, backlash=(), n_points: int = 1,
                 compliance=()) -> "ParameterSpace":
        """The space of an error model's chain; ``backlash`` and ``compliance`` joints in
        any order."""
        joint_names = tuple(model.joint_names)
        _check_backlash_joints(joint_names, tuple(backlash))
        chosen = tuple(j for j in joint_names if j in set(backlash))
        lengths = tuple(model.kinds[joint_names.index(j)] == "prismatic" for j in chosen)
        return cls(joint_names, tuple(model.names), tuple(bool(b) for b in model.is_length),
                   tuple(model.classes), tuple(int(j) for j in model.joint_of), chosen, lengths,
                   int(n_points), tuple(j for j in joint_names if j in set(compliance)))

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def n_kinematic(self) -> int:
        return len(self.kinematic_names)

    @property
    def n_backlash(self) -> int:
        return len(self.backlash)

    @property
    def n_terms(self) -> int:
        """Joint terms: backlash and compliance."""
        return len(self.backlash) + len(self.compliance)

    @property
    def n_frames(self) -> int:
        """Measurement frame (6) and tool points (3 each)."""
        return 6 + 3 * self.n_points

    @property
    def names(self) -> tuple[str, ...]:
        kin = self.kinematic_names
        tools = TOOL + tuple(f"tool{k}.{c}" for k in range(2, self.n_points + 1)
                             for c in "xyz")
        return (kin + BASE + tools + tuple(f"{j}.backlash" for j in self.backlash)
                + tuple(f"{j}.compliance" for j in self.compliance))

    @property
    def size(self) -> int:
        return self.n_kinematic + self.n_frames + self.n_terms

    @property
    def is_length(self) -> np.ndarray:
        """(p,) True for lengths [m], False for angles [rad]."""
        return np.array(list(self.kinematic_is_length) + [True, True, True, False, False, False] + [True] * 3 * self.n_points
                        + list(self.backlash_is_length) + [False] * len(self.compliance),
                        dtype=bool)

    @property
    def is_kinematic(self) -> np.ndarray:
        """(p,) True for the error model's parameters (what the corrected URDF carries)."""
        mask = np.zeros(self.size, dtype=bool)
        mask[: self.n_kinematic] = True
        return mask

    @property
    def is_frame(self) -> np.ndarray:
        """(p,) True for the measurement frame and the tool point."""
        mask = np.zeros(self.size, dtype=bool)
        mask[self.n_kinematic: self.n_kinematic + self.n_frames] = True
        return mask

    @property
    def is_backlash(self) -> np.ndarray:
        mask = np.zeros(self.size, dtype=bool)
        mask[self.n_kinematic + self.n_frames:] = True
        return mask

    @property
    def is_penalised(self) -> np.ndarray:
        """(p,) the parameters with a nominal value that L2 pulls toward: all but frames."""
        return ~self.is_frame

    @property
    def backlash_joint_index(self) -> tuple[int, ...]:
        """Chain index of each backlash joint."""
        return tuple(self.joint_names.index(j) for j in self.backlash)

    @property
    def compliance_joint_index(self) -> tuple[int, ...]:
        """Chain index of each compliance joint."""
        return tuple(self.joint_names.index(j) for j in self.compliance)

    def reporting_scale(self) -> np.ndarray:
        """(p,) size of one reporting unit per parameter: 1 mm or 1 deg, in SI."""
        return np.where(self.is_length, MM, DEG)

    def index(self, name: str) -> int:
        return name_index(self.names, name)

    def expand(self, patterns) -> tuple[str, ...]:
        """The parameter names that ``patterns`` select (see :func:`expand_names`)."""
        return expand_names(self.names, patterns)

    def indices(self, names) -> np.ndarray:
        """(k,) indices of the parameters that ``names`` select (names or patterns, see
        :meth:`expand`)."""
        return np.array([self.index(n) for n in self.expand(names)], dtype=int)

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kinematic (p_k,), base (6,), tool (3,) of point 1) views of a parameter vector."""
        k = self.n_kinematic
        return x[..., :k], x[..., k:k + 6], x[..., k + 6:k + 9]

    def tools(self, x: np.ndarray) -> np.ndarray:
        """(n_points, 3) view of the measured points in the tip frame."""
        k = self.n_kinematic + 6
        return x[..., k:k + 3 * self.n_points].reshape(x.shape[:-1] + (self.n_points, 3))

    def backlash_values(self, x: np.ndarray) -> np.ndarray:
        """(n_terms,) view of the joint terms (backlash, then compliance) of a vector."""
        return x[..., self.n_kinematic + self.n_frames:]

    @property
    def classes(self) -> tuple[str, ...]:
        """(p,) class of every parameter: the error model's "length" / "twist" / "offset",
        "frame" for the measurement frame and tool points, "backlash"."""
        return (self.kinematic_classes + ("frame",) * self.n_frames
                + ("backlash",) * self.n_backlash + ("compliance",) * len(self.compliance))

    def join(self, kinematic, base, tools, backlash=None) -> np.ndarray:
        """The parameter vector. kinematic: the error model's vector (an MD-H model without
        beta also takes its (n, 4) table); tools: (3,) with one point, or (n_points, 3);
        backlash: the joint terms (backlash, then compliance); None means zero."""
        b = np.zeros(self.n_terms) if backlash is None else np.asarray(backlash, float)
        if b.shape != (self.n_terms,):
            raise ParameterError(f"{self.n_terms} joint-term values expected, got {b.shape}")
        t = np.asarray(tools, float)
        if t.size != 3 * self.n_points:
            raise ParameterError(f"{self.n_points} tool point(s) of 3 numbers expected, got "
                                 f"shape {t.shape}")
        kin = np.asarray(kinematic, float).ravel()
        if kin.size != self.n_kinematic:
            raise ParameterError(f"{self.n_kinematic} kinematic parameters expected, got {kin.size}")
        return np.concatenate([kin, np.asarray(base, float),
                               t.ravel(), b])
