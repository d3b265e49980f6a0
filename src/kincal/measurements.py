"""Measured samples: joint values and the measured 3-D position of the tool point.

A CSV file has a header naming the chain joints as in the URDF plus the position columns
(``x,y,z`` by default), and optionally ``sigma`` (per-sample standard deviation of the
position). Units: metres and radians by default; ``length_unit="mm"`` reads positions,
sigma and prismatic joints in millimetres, ``angle_unit="deg"`` reads revolute joints in
degrees. Inside, everything is SI. Other columns are kept out of the fit and reported.

Every sample also carries the approach direction of each joint (see
:mod:`kincal.backlash`), computed from the acquisition order: the order of the rows, or
an ``order_column`` such as a time stamp. Only backlash terms use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .backlash import approach_directions
from .csv_table import read_columns
from .errors import DataError, listing, suggest

LENGTH_UNITS = {"m": 1.0, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


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

    def __post_init__(self):
        q = _readonly(self.joint_values)
        P = _readonly(self.positions)
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
        if self.sigma is not None:
            s = _readonly(self.sigma)
            if s.shape != (len(q),) or not np.all(np.isfinite(s)) or np.any(s <= 0):
                raise DataError(f"{self.source}: sigma must be N positive finite values")
            object.__setattr__(self, "sigma", s)
        rows = np.arange(2, len(q) + 2) if self.rows is None else np.asarray(self.rows)
        object.__setattr__(self, "rows", rows)
        g = approach_directions(q) if self.approach is None else np.asarray(self.approach, float)
        if g.shape != q.shape or not np.all(np.isin(g, (-1.0, 0.0, 1.0))):
            raise DataError(f"{self.source}: approach directions must be ({len(q)}, "
                            f"{q.shape[1]}) values in {{-1, 0, 1}}, got shape {g.shape}")
        object.__setattr__(self, "approach", _readonly(g))

    def __len__(self) -> int:
        return len(self.joint_values)

    def subset(self, index) -> "Measurements":
        index = np.asarray(index)
        return Measurements(self.joint_names, self.joint_values[index], self.positions[index],
                            None if self.sigma is None else self.sigma[index], self.rows[index],
                            self.source, self.ignored_columns, self.length_unit, self.angle_unit,
                            self.approach[index], self.order_source)

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
        return Measurements(joint_names, self.joint_values[:, idx], self.positions, self.sigma,
                            self.rows, self.source, self.ignored_columns, self.length_unit,
                            self.angle_unit, self.approach[:, idx], self.order_source)

    @classmethod
    def from_csv(cls, path, joint_names, prismatic=(), length_unit: str = "m",
                 angle_unit: str = "rad", position_columns=("x", "y", "z"),
                 sigma_column: str | None = "sigma",
                 order_column: str | None = None) -> "Measurements":
        """Read a CSV file for the chain ``joint_names`` (see the module notes).

        prismatic: names of prismatic chain joints (read with the length unit).
        order_column: a column giving the acquisition order (e.g. a time stamp) for the
            approach directions; None: the rows are in acquisition order.
        """
        if length_unit not in LENGTH_UNITS:
            raise DataError(f"unknown length unit {length_unit!r}; expected one of m, mm")
        if angle_unit not in ANGLE_UNITS:
            raise DataError(f"unknown angle unit {angle_unit!r}; expected one of rad, deg")
        wanted = list(joint_names) + list(position_columns)
        extra = [c for c in (sigma_column, order_column) if c is not None]
        table = read_columns(path, wanted, extra, kind="data",
                             expected="the chain joints and positions")
        path = table.path
        if order_column is not None and order_column not in table.values:
            raise DataError(f"{path}: no order column {order_column!r}."
                            + suggest(order_column, table.header)
                            + f" The header has {listing(table.header)}")
        rows = table.lines
        L, A = LENGTH_UNITS[length_unit], ANGLE_UNITS[angle_unit]
        v = table.values
        q = np.column_stack([v[j] * (L if j in set(prismatic) else A) for j in joint_names])
        P = np.column_stack([v[c] for c in position_columns]) * L
        sigma = v[sigma_column] * L if sigma_column in v else None
        if sigma is not None and np.any(sigma <= 0):
            k = int(np.argmax(sigma <= 0))
            raise DataError(f"{path}, line {rows[k]}, column {sigma_column!r}: sigma must be > 0")
        if order_column is None:
            approach, order_source = approach_directions(q), "the order of the rows"
        else:
            approach = approach_directions(q, v[order_column], source=str(path), rows=rows)
            order_source = f"column {order_column!r}"
        return cls(tuple(joint_names), q, P, sigma, rows, str(path), table.ignored(),
                   length_unit, angle_unit, approach, order_source)

    def to_csv_text(self) -> str:
        """The samples in the CSV layout :meth:`from_csv` reads, SI units, full precision."""
        cols = list(self.joint_names) + ["x", "y", "z"] + (["sigma"] if self.sigma is not None else [])
        lines = [",".join(cols)]
        for k in range(len(self)):
            vals = list(self.joint_values[k]) + list(self.positions[k])
            if self.sigma is not None:
                vals.append(self.sigma[k])
            lines.append(",".join(repr(float(v)) for v in vals))
        return "\n".join(lines) + "\n"
