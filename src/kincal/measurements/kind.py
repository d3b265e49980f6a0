"""What every measurement kind provides: the shared interface of the kinds.

A measurement kind says what an instrument reports about the robot's chain at each sample
and which frame parameters (where the instrument is, what it touches on the tool) it
needs besides the robot's kinematic ones. The kinds:

- ``point`` (:mod:`.point`): 3-D positions of points on the tool (laser tracker, R-test,
  motion capture); frames ``base.*`` (measurement frame) and ``tool.*``;
- ``pose`` (:mod:`.pose`): position and orientation of a tool frame (6-DoF tracker probe,
  optical CMM); frames ``base.*`` and ``tool.x .y .z .rx .ry .rz``;
- ``distance`` (:mod:`.distance`): the distance from the tool point to a fixed pivot
  (drawstring encoder, ballbar); frames ``pivot.*`` (base frame) and ``tool.*``;
- ``plane`` (:mod:`.plane`): the tool point touches a plane (touch probe on a surface
  plate); frames ``plane.rx .ry .d`` per plane and ``tool.*``;
- ``flush`` (:mod:`.flush`): a flat face of the tool pressed flat on a plane (its height
  and two tilts); frames ``plane.rx .ry .d`` per plane and ``tool.rx .ry .x .y .z``.

A kind's model (:class:`KindModel`) is built from an error model and the samples; for a
kinematic vector, its frame vector and the backlash values it returns the weighted
residuals, measured minus predicted, ``(N, dim)`` in metres (orientation rows are turned
into metres by the set's position-to-orientation sigma ratio), and their analytic
derivatives through :class:`kincal.models.chain.ChainState`. Plain numpy.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from kincal.errors import DataError
from kincal.measurements.checks import SIGMA_RANGE_DEG, SIGMA_RANGE_M, check_sigmas  # noqa: F401
from kincal.models.backlash import approach_directions
from kincal.models.base import ErrorModel
from kincal.models.chain import Chain

DEFAULT_SIGMA = 0.05e-3  # [m] position / distance noise assumed when a set states none


def sample_weights(sigmas, counts) -> np.ndarray:
    """(sum(counts),) each sample's weight from its set's stated sigmas [m] (a set's (N,)
    array, or None: :data:`DEFAULT_SIGMA`), normalised to RMS 1; all 1 when no set states
    one. sigmas, counts: per set. The one weighting of sets against each other (the fit's,
    and the residual diagnosis's)."""
    if all(s is None for s in sigmas):
        return np.ones(int(sum(counts)))
    sig = np.concatenate([np.full(n, DEFAULT_SIGMA) if s is None else np.asarray(s, float)
                          for s, n in zip(sigmas, counts)])
    inv = sig.min() / sig  # in (0, 1]: no overflow whatever the unit of the sigmas
    return inv / np.sqrt(np.mean(inv ** 2))


def readonly(a, dtype=float) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, kw_only=True)
class SampleSet:
    """Fields every kind's samples share (the kind's own values are in its subclass).

    joint_names: the chain joints, in chain order. joint_values: (N, n) [rad or m].
    sigma: (N,) standard deviation of each sample's length reading (position, distance)
        [m], or None (then :data:`DEFAULT_SIGMA` when sets are weighed against each other).
    rows: (N,) line numbers in the source file (1 = header). source: for messages.
    approach: (N, n) approach directions (+1/-1/0) for backlash terms; None: from the
        order of the samples. poses: (N,) pose of each sample (cross-validation keeps a
        pose in one fold); None: every sample its own pose. fixed_joints: chain joints
        the file has no column for, held at one value during the measurements
        ((name, value [rad or m]), ...; see :mod:`kincal.measurements.fixed_joints`).
    """

    joint_names: tuple[str, ...]
    joint_values: np.ndarray
    sigma: np.ndarray | None = None
    rows: np.ndarray | None = None
    source: str = "<memory>"
    approach: np.ndarray | None = None
    poses: np.ndarray | None = None
    ignored_columns: tuple[str, ...] = field(default=())
    fixed_joints: tuple[tuple[str, float], ...] = ()  # (joint, value [SI]) not in the file
    angle_unit: str = "rad"  # how the file wrote revolute joints (for the unit checks)

    kind = "abstract"

    def __post_init__(self):
        q = readonly(self.joint_values)
        if q.ndim != 2 or q.shape[1] != len(self.joint_names):
            raise DataError(f"{self.source}: joint values must be (N, {len(self.joint_names)}),"
                            f" got {q.shape}")
        if not np.all(np.isfinite(q)):
            k = int(np.argwhere(~np.isfinite(q))[0][0])
            raise DataError(f"{self.source}: sample {k + 1} has a non-finite joint value")
        object.__setattr__(self, "joint_values", q)
        n = len(q)
        object.__setattr__(self, "rows", readonly(
            np.arange(2, n + 2) if self.rows is None else self.rows, int))
        if self.sigma is not None:
            object.__setattr__(self, "sigma", check_sigmas(self.sigma, n, self.source,
                                                           rows=self.rows))
        g = approach_directions(q) if self.approach is None else np.asarray(self.approach, float)
        if g.shape != q.shape:
            raise DataError(f"{self.source}: approach directions must be {q.shape}")
        object.__setattr__(self, "approach", readonly(g))
        object.__setattr__(self, "poses", readonly(
            np.arange(n) if self.poses is None else self.poses, int))

    def __len__(self) -> int:
        return len(self.joint_values)

    def per_sample_fields(self) -> tuple[str, ...]:
        """Names of the (N, ...) fields a subset must cut (the kind adds its own)."""
        return ("joint_values", "sigma", "rows", "approach", "poses")

    def subset(self, index) -> "SampleSet":
        index = index if isinstance(index, slice) else np.asarray(index)
        cut: dict[str, Any] = {}
        for name in self.per_sample_fields():
            value = getattr(self, name)
            cut[name] = None if value is None else value[index]
        return replace(self, **cut)

    def for_chain(self, joint_names) -> "SampleSet":
        """The same samples with joint columns in the order of ``joint_names``."""
        joint_names = tuple(joint_names)
        if joint_names == self.joint_names:
            return self
        missing = [j for j in joint_names if j not in self.joint_names]
        if missing:
            raise DataError(f"{self.source}: no values for chain joints {', '.join(missing)}")
        idx = [self.joint_names.index(j) for j in joint_names]
        assert self.approach is not None  # filled in by __post_init__
        return replace(self, joint_names=joint_names, joint_values=self.joint_values[:, idx],
                       approach=self.approach[:, idx])


class KindModel:
    """Residuals and Jacobian of one measurement set (the interface; see the module notes).

    Subclasses set ``kind``, ``dim`` (residual rows per sample), ``frame_names`` and
    ``frame_is_length`` and implement :meth:`residuals`, :meth:`start` and
    :meth:`sample_errors`. error_model: the chain's model; data: the kind's samples;
    backlash: chain indices of the joints with a backlash term; compliance: those with a
    compliance term, torque: (N, n) the samples' gravity torques [N m] in the chain's order.
    """

    kind = "abstract"
    dim = 1
    frame_names: tuple[str, ...] = ()
    frame_is_length: tuple[bool, ...] = ()

    def __init__(self, error_model: ErrorModel, data: SampleSet, backlash=(), compliance=(),
                 torque=None):
        self.error_model = error_model
        self.data = data.for_chain(error_model.joint_names)
        self.backlash = tuple(int(i) for i in backlash)
        self.chain = Chain(error_model, self.data.joint_values, self.data.approach,
                           self.backlash, torque, tuple(int(i) for i in compliance))
        self.N = len(self.data)

    def subset(self, rows) -> "KindModel":
        other = object.__new__(type(self))
        other.__dict__.update(self.__dict__)
        other.data = self.data.subset(rows)
        other.chain = self.chain.subset(rows)
        other.N = len(other.data)
        return other

    @property
    def n_frames(self) -> int:
        return len(self.frame_names)

    def residuals(self, kin: np.ndarray, frames: np.ndarray, backlash: np.ndarray,
                  jacobian: bool = False, kinematic: bool = True):
        """(r (N, dim) [m], and if ``jacobian``: (dr/dkin (N, dim, p_k), dr/dframes
        (N, dim, f), dr/dbacklash (N, dim, nb))). kinematic=False: kinematic and backlash
        columns zero (frame-only fits)."""
        raise NotImplementedError  # pragma: no cover - interface

    def start(self, kin: np.ndarray, tool_guess=None) -> np.ndarray:
        """(f,) first guess of the frame parameters with kinematics ``kin`` (closed form;
        the caller refines it by Gauss-Newton on the frames)."""
        raise NotImplementedError  # pragma: no cover - interface

    def sample_errors(self, r: np.ndarray) -> np.ndarray:
        """(N,) size of each sample's error [m] from its residual rows (for statistics)."""
        return np.linalg.norm(r, axis=1)

    def angle_rows(self, r: np.ndarray) -> np.ndarray | None:
        """(N, k) each sample's orientation error as angles [rad] from its residual rows
        (poses: the rotation vector between measured and predicted; flush touches: the
        roll and pitch against the plane), None for kinds without an orientation."""
        return None

    def notes(self) -> tuple[str, ...]:
        """What this kind cannot see, for the identifiability report."""
        return ()

    def noise_rows(self) -> tuple[tuple[str, str, np.ndarray], ...]:
        """Per residual row of a sample: (kind of row, its unit, (N,) metres of the row per
        unit). Rows of one kind share a noise level where the evidence estimates it
        (variance components, :mod:`kincal.identification.evidence`); here every row is a
        length in mm."""
        return tuple(("", "mm", np.full(self.N, 1e-3)) for _ in range(self.dim))

    def noise_stated(self) -> bool:
        """Whether the set states its noise (a ``sigma`` column or ``--set-sigma-mm``)."""
        return self.data.sigma is not None

    def _zero_chain_columns(self, dim: int):
        return (np.zeros((self.N, dim, self.error_model.size)),
                np.zeros((self.N, dim, len(self.chain.terms))))


@dataclass(frozen=True)
class SetColumns:
    """What :func:`read_set` read: joint values (N, n) [SI], the other wanted columns
    ``values`` {name: (N,)} (unconverted), line numbers, approach directions, the file."""

    joint_values: np.ndarray
    values: dict
    rows: np.ndarray
    approach: np.ndarray
    source: str
    ignored: tuple[str, ...]


def read_set(path, joint_names, wanted, optional=(), prismatic=(), angle_unit="rad",
             length_unit="m", joint_columns=None, expected="") -> SetColumns:
    """Read the chain joints and the ``wanted`` columns of a CSV file (shared by the kinds;
    the point kind has its own reader, :meth:`kincal.measurements.data.Measurements.from_csv`)."""
    from kincal.measurements.csv_table import read_columns
    from kincal.measurements.data import joint_column_names, unit_factors

    L, A = unit_factors(length_unit, angle_unit)
    columns = joint_column_names(joint_names, joint_columns)
    table = read_columns(path, list(columns.values()) + list(wanted), optional, kind="data",
                         expected=expected or "the chain joints",
                         aliases={c: j for j, c in columns.items() if c != j},
                         joints=tuple(columns.values()))
    q = np.column_stack([table.values[columns[j]] * (L if j in set(prismatic) else A)
                         for j in joint_names])
    return SetColumns(q, table.values, np.asarray(table.lines), approach_directions(q),
                      str(table.path), table.ignored())
