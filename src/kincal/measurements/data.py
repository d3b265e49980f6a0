"""Measured samples: joint values and the measured 3-D position of the tool point.

A CSV file has a header naming the chain joints as in the URDF (or other names, mapped
with ``joint_columns``) plus the position columns (``x,y,z`` by default), and optionally
``sigma`` (per-sample standard deviation of the position); for separators, comments and
line ends see :mod:`kincal.measurements.csv_table`. Units: metres and radians by default; ``length_unit="mm"`` reads positions,
sigma and prismatic joints in millimetres, ``angle_unit="deg"`` reads revolute joints in
degrees. Inside, everything is SI. Other columns are kept out of the fit and reported.

Every sample also carries the approach direction of each joint (see
:mod:`kincal.backlash`), computed from the acquisition order: the order of the rows, or
an ``order_column`` such as a time stamp. Only backlash terms use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from kincal.errors import DataError, listing, suggest
from kincal.measurements.csv_table import csv_line, read_columns
from kincal.models.backlash import approach_directions

LENGTH_UNITS = {"m": 1.0, "mm": 1e-3}
MAX_ABS_VALUE = 1e6
"""Largest magnitude of a joint value [rad or m] or position [m] accepted."""
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}


def unit_factors(length_unit: str, angle_unit: str, error=DataError) -> tuple[float, float]:
    """(metres per length unit, radians per angle unit) of a file's units; ``error`` (a
    KincalError class) for a unit that is not m/mm or rad/deg. The one check of every
    reader of joint values and positions (data, kinds, candidates, targets)."""
    if length_unit not in LENGTH_UNITS:
        raise error(f"unknown length unit {length_unit!r}; expected one of m, mm")
    if angle_unit not in ANGLE_UNITS:
        raise error(f"unknown angle unit {angle_unit!r}; expected one of rad, deg")
    return LENGTH_UNITS[length_unit], ANGLE_UNITS[angle_unit]


def _readonly(a) -> np.ndarray:
    """A read-only float array of a: a itself when it is one already (a block's view of
    its set's arrays, :meth:`Measurements.subset` with a slice), else a copy."""
    if isinstance(a, np.ndarray) and a.dtype == float and not a.flags.writeable:
        return a
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def joint_column_names(joint_names, joint_columns=None) -> dict[str, str]:
    """{URDF joint: CSV column} for the chain ``joint_names``, checked.

    joint_columns: a mapping {URDF joint name: CSV column name}, or None; joints it does
    not name are read from the column of their own name. Raises :class:`DataError` for a
    name that is not a chain joint (with suggestions), an empty column name, or two
    joints read from one column.
    """
    joint_names = tuple(joint_names)
    if joint_columns is None:
        return {j: j for j in joint_names}
    if not hasattr(joint_columns, "items"):
        raise DataError("joint_columns must be a mapping {URDF joint name: CSV column name}, "
                        f"got {type(joint_columns).__name__}")
    for urdf, column in joint_columns.items():
        if urdf not in joint_names:
            raise DataError(f"joint column mapping names {urdf!r}, which is not a joint of the "
                            f"chain.{suggest(str(urdf), joint_names)} Chain joints: "
                            f"{listing(joint_names)}")
        if not isinstance(column, str) or not column.strip():
            raise DataError(f"joint column mapping {urdf}={column!r}: expected a CSV column name")
    columns = {j: str(joint_columns.get(j, j)).strip() for j in joint_names}
    seen: dict[str, str] = {}
    for j, c in columns.items():
        if c in seen:
            raise DataError(f"joints {seen[c]} and {j} would both be read from column {c!r}; "
                            "map each chain joint to its own column")
        seen[c] = j
    return columns


@dataclass(frozen=True)
class Measurements:
    """N samples of one chain.

    joint_names: the chain joints, in chain order.
    joint_values: (N, n) [rad or m].
    positions: (N, 3) measured tool point in the measurement frame [m].
    sigma: (N,) standard deviation of each measured position [m], or None.
    rows: (N,) line numbers in the source file (1 = header), for messages.
    source: where the samples came from.
    ignored_columns: columns of the file that are not used.
    approach: (N, n) approach direction of each joint (+1, -1, 0), see kincal.backlash;
        None: computed from the order of the samples.
    order_source: how the acquisition order was known, for reports.
    points: (N,) which measured point a sample is (0 .. K-1), when several points on the
        tool are measured at each pose; None: all 0 (one point).
    poses: (N,) which pose a sample was taken at (samples of one pose share it, e.g. the
        K points of one file row); None: every sample its own pose. Cross-validation
        never splits a pose.
    fixed_joints: chain joints the file has no column for, held at one value during the
        measurements ((name, value [rad or m]), ...).
    """

    joint_names: tuple[str, ...]
    joint_values: np.ndarray
    positions: np.ndarray
    sigma: np.ndarray | None = None
    rows: np.ndarray | None = None
    source: str = "<memory>"
    ignored_columns: tuple[str, ...] = field(default=())
    length_unit: str = "m"  # the unit the source file used (values here are SI)
    angle_unit: str = "rad"
    approach: np.ndarray | None = None
    order_source: str = "the order of the samples"
    points: np.ndarray | None = None
    poses: np.ndarray | None = None
    fixed_joints: tuple[tuple[str, float], ...] = ()  # (joint, value [SI]) not in the file

    def __post_init__(self):
        try:
            q = _readonly(self.joint_values)
            P = _readonly(self.positions)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{self.source}: joint values and positions must be (N, n) and "
                            f"(N, 3) arrays of numbers ({exc})") from None
        if q.ndim != 2 or q.shape[1] != len(self.joint_names):
            raise DataError(f"{self.source}: joint values must be (N, {len(self.joint_names)}), "
                            f"got {q.shape}")
        if P.shape != (len(q), 3):
            raise DataError(f"{self.source}: positions must be ({len(q)}, 3), got {P.shape}")
        for name, arr in (("joint value", q), ("position", P)):
            bad = np.argwhere(~np.isfinite(arr))
            if bad.size:
                k = bad[0][0]
                raise DataError(f"{self.source}: sample {k + 1} has a non-finite {name}")
        object.__setattr__(self, "joint_values", q)
        object.__setattr__(self, "positions", P)
        rows = np.arange(2, len(q) + 2) if self.rows is None else np.asarray(self.rows)
        object.__setattr__(self, "rows", rows)
        if self.sigma is not None:
            from kincal.measurements.checks import check_sigmas

            object.__setattr__(self, "sigma", check_sigmas(self.sigma, len(q), self.source,
                                                           rows=rows if len(rows) == len(q)
                                                           else None))
        if len(P) > 1 and np.all(P == P[0]) and not np.all(q == q[0]):
            raise DataError(f"{self.source}: every measured position is ({P[0][0]:g}, "
                            f"{P[0][1]:g}, {P[0][2]:g}) [m]: the positions do not vary (a "
                            "template never filled in, or the wrong columns?) while the joints "
                            "move; expected the measured tool point of each pose")
        for name, arr in (("joint value", q), ("position", P)):
            # far beyond any robot (1000 km, 1e6 rad): the sums of squares would overflow
            big = np.argwhere(np.abs(arr) > MAX_ABS_VALUE)
            if big.size:
                k = big[0][0]
                raise DataError(f"{self.source}: line {rows[k]}: {name} {arr[tuple(big[0])]:g} "
                                f"(SI units); kincal accepts magnitudes up to {MAX_ABS_VALUE:g}")
        g = approach_directions(q) if self.approach is None else np.asarray(self.approach, float)
        if g.shape != q.shape or not np.all(np.isin(g, (-1.0, 0.0, 1.0))):
            raise DataError(f"{self.source}: approach directions must be ({len(q)}, "
                            f"{q.shape[1]}) values in {{-1, 0, 1}}, got shape {g.shape}")
        object.__setattr__(self, "approach", _readonly(g))
        for name, default in (("points", np.zeros(len(q), dtype=int)),
                              ("poses", np.arange(len(q)))):
            value = getattr(self, name)
            a = default if value is None else np.asarray(value)
            if a.shape != (len(q),) or (a.size and (a.dtype.kind not in "iu" or a.min() < 0)):
                raise DataError(f"{self.source}: {name} must be {len(q)} integers >= 0, got "
                                f"{a.dtype} of shape {a.shape}")
            if a.dtype != int or a.flags.writeable:  # a read-only int view is kept as is
                a = a.astype(int)
                a.setflags(write=False)
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return len(self.joint_values)

    @property
    def filled(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, approach, points, poses): the fields that may be given as None, which
        ``__post_init__`` has filled in."""
        rows, approach, points, poses = self.rows, self.approach, self.points, self.poses
        assert rows is not None and approach is not None and points is not None \
            and poses is not None  # filled in by __post_init__
        return rows, approach, points, poses

    @property
    def has_order_column(self) -> bool:
        """Whether the acquisition order came from an order column (not the sample order)."""
        return self.order_source.startswith("column ")

    @property
    def n_points(self) -> int:
        """Measured points per pose (K)."""
        return int(self.filled[2].max()) + 1 if len(self) else 1

    def per_sample_fields(self) -> tuple[str, ...]:
        """Names of the (N, ...) fields (None where not given), as the other kinds' sets."""
        return ("joint_values", "positions", "sigma", "rows", "approach", "points", "poses")

    def subset(self, index) -> "Measurements":
        """The samples ``index`` (indices, a mask, or a slice: then views of these arrays,
        no copy, as the blocks of a large fit take them)."""
        index = index if isinstance(index, slice) else np.asarray(index)
        rows, approach, points, poses = self.filled
        return replace(self, joint_values=self.joint_values[index],
                       positions=self.positions[index],
                       sigma=None if self.sigma is None else self.sigma[index],
                       rows=rows[index], approach=approach[index],
                       points=points[index], poses=poses[index])

    def for_chain(self, joint_names) -> "Measurements":
        """The same samples with columns in the order of ``joint_names`` (checked)."""
        joint_names = tuple(joint_names)
        if joint_names == self.joint_names:
            return self
        missing = [j for j in joint_names if j not in self.joint_names]
        if missing:
            raise DataError(f"{self.source}: no values for chain joints {', '.join(missing)}; "
                            f"the data has {listing(self.joint_names)}")
        idx = [self.joint_names.index(j) for j in joint_names]
        return replace(self, joint_names=joint_names, joint_values=self.joint_values[:, idx],
                       approach=self.filled[1][:, idx])

    @classmethod
    def from_csv(cls, path, joint_names, prismatic=(), length_unit: str = "m",
                 angle_unit: str = "rad", position_columns=("x", "y", "z"),
                 sigma_column: str | None = "sigma",
                 order_column: str | None = None, joint_columns=None) -> "Measurements":
        """Read a CSV file for the chain ``joint_names`` (see the module notes).

        joint_columns: {URDF joint name: CSV column} for files whose joint columns are
            not named after the URDF (joints not in it: their own name). The samples
            carry the URDF names.
        prismatic: names of prismatic chain joints (read with the length unit).
        position_columns: 3 names (x, y, z of the measured point), or 3 K names for K
            points measured at each pose (x1, y1, z1, x2, ...): each row then gives K
            samples of one pose, point k with its own position in the tip frame.
        order_column: a column giving the acquisition order (e.g. a time stamp) for the
            approach directions; None: the rows are in acquisition order.
        """
        if isinstance(joint_names, str):  # one joint, not its letters
            joint_names = (joint_names,)
        position_columns = tuple(position_columns)
        if not position_columns or len(position_columns) % 3:
            raise DataError(f"position columns come in threes (x, y, z of each measured "
                            f"point); got {len(position_columns)}: {', '.join(position_columns)}")
        if len(set(position_columns)) != len(position_columns):
            raise DataError(f"a position column is named twice: {', '.join(position_columns)}")
        L, A = unit_factors(length_unit, angle_unit)
        columns = joint_column_names(joint_names, joint_columns)
        wanted = list(columns.values()) + list(position_columns)
        if order_column in wanted:  # the order of the samples, not one of their values
            raise DataError(f"{path}: order column {order_column!r} is a "
                            f"{'position' if order_column in position_columns else 'joint'} "
                            "column; expected a column giving the acquisition order (a time "
                            "stamp or sample number)")
        extra = [c for c in (sigma_column, order_column) if c is not None]
        table = read_columns(path, wanted, extra, kind="data",
                             expected="the chain joints and positions",
                             aliases={c: j for j, c in columns.items() if c != j},
                             joints=tuple(columns.values()))
        path = table.path
        if order_column is not None and order_column not in table.values:
            raise DataError(f"{path}: no order column {order_column!r}."
                            + suggest(order_column, table.header)
                            + f" The header has {listing(table.header)}")
        rows = table.lines
        v = table.values
        q = np.column_stack([v[columns[j]] * (L if j in set(prismatic) else A)
                             for j in joint_names])
        K = len(position_columns) // 3
        P = np.stack([np.column_stack([v[c] for c in position_columns[3 * k:3 * k + 3]])
                      for k in range(K)], axis=1)  # (rows, K, 3)
        if L != 1.0:
            P *= L
        sigma = v[sigma_column] * L if sigma_column in v else None
        if sigma is not None and np.any(sigma <= 0):
            k = int(np.argmax(sigma <= 0))
            raise DataError(f"{path}, line {rows[k]}, column {sigma_column!r}: sigma must be > 0")
        if order_column is None:
            approach, order_source = approach_directions(q), "the order of the rows"
        else:
            approach = approach_directions(q, v[order_column], source=str(path), rows=rows)
            order_source = f"column {order_column!r}"
        n = len(q)  # one sample per row and point, row-major

        def each(a, k=K):  # a row's values for each of its k samples, read-only (kept)
            a = a if k == 1 else np.repeat(a, k, axis=0)
            a.setflags(write=False)
            return a

        ignored = table.ignored()
        del table, v  # the file's columns: only the arrays kept below stay
        return cls(tuple(joint_names), each(q), each(P.reshape(n * K, 3), 1),
                   None if sigma is None else np.repeat(sigma, K), np.repeat(rows, K),
                   str(path), ignored, length_unit, angle_unit, each(approach),
                   order_source, np.tile(np.arange(K), n), each(np.arange(n)))

    def to_csv_text(self) -> str:
        """The samples in the CSV layout :meth:`from_csv` reads, SI units, full precision:
        one row per pose; with K points per pose the columns x1, y1, z1, ..., xK, yK, zK
        (every pose must then have each point once)."""
        K = self.n_points
        _, _, points, poses = self.filled
        groups: np.ndarray | None
        if K == 1:  # one sample per pose, in the order of the samples
            groups = np.arange(len(self))[:, None]
        else:
            order = np.lexsort((points, poses))
            groups = order.reshape(-1, K) if len(self) % K == 0 else None
            if groups is None or np.any(points[groups] != np.arange(K)) or np.any(
                    poses[groups] != poses[groups[:, :1]]):
                raise DataError(f"{self.source}: writing as CSV needs each of the "
                                f"{len(np.unique(poses))} poses to have each of the {K} "
                                "points once")
        xyz = ["x", "y", "z"] if K == 1 else [f"{c}{k}" for k in range(1, K + 1) for c in "xyz"]
        cols = list(self.joint_names) + xyz + (["sigma"] if self.sigma is not None else [])
        table = [self.joint_values[groups[:, 0]], self.positions[groups].reshape(len(groups), -1)]
        if self.sigma is not None:
            table.append(self.sigma[groups[:, 0], None])
        rows = np.hstack(table).tolist()  # Python floats: repr gives the shortest exact text
        return "\n".join([csv_line(cols)] + [csv_line(map(repr, r)) for r in rows]) + "\n"
