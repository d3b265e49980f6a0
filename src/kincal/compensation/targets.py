"""Targets to compensate: seed joint values and wanted tool positions (or poses).

A TARGETS.csv has the chain joints (named as in the URDF: the user's program, the seeds)
and ``x,y,z``, the wanted position of the measured tool point in the measurement frame;
optionally ``qx,qy,qz,qw`` (a unit quaternion, scalar last), the wanted orientation of
the tip frame in the measurement frame. Revolute joints in ``angle_unit``, positions and
prismatic joints in ``length_unit``; inside, SI.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError, KincalWarning, OptionError
from kincal.measurements.checks import angle_unit_warnings, limit_warnings
from kincal.measurements.csv_table import read_columns
from kincal.measurements.data import LENGTH_UNITS, unit_factors
from kincal.measurements.orientation_columns import UNIT_TOL
from kincal.measurements.pose import QUATERNION_COLUMNS

# the columns and the tolerance of a pose file's quaternions: |norm - 1| accepted (and
# normalised) for rounded quaternions, as a pose file's are
QUATERNION = QUATERNION_COLUMNS
UNIT_QUATERNION_TOL = UNIT_TOL


@dataclass(frozen=True)
class Targets:
    """N targets of one chain (SI).

    seeds: (N, n) joint values the solution starts from [rad or m]. positions: (N, 3)
    wanted tool point in the measurement frame [m]. quaternions: (N, 4) wanted tip
    orientation in the measurement frame (qx, qy, qz, qw), or None for positions only.
    lines: (N,) line numbers in the source file. source: for messages.
    """

    seeds: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray | None
    lines: np.ndarray
    source: str = "<targets>"

    def __len__(self) -> int:
        return len(self.seeds)


def joint_scales(kinds, length_unit: str, angle_unit: str) -> np.ndarray:
    """(n,) factors from file units to SI for the joints of ``kinds``."""
    L, A = unit_factors(length_unit, angle_unit, OptionError)
    return np.array([L if k == "prismatic" else A for k in kinds])


def read_targets(path, robot, length_unit: str = "m", angle_unit: str = "rad",
                 position_columns=("x", "y", "z")) -> Targets:
    """Targets from a CSV file (see the module notes); values outside the joint limits and
    angles that look like degrees are warned about, as for measurements.
    position_columns: the names of the x, y, z columns."""
    position_columns = tuple(position_columns)
    if len(position_columns) != 3:
        raise OptionError(f"a target has one position: give 3 position columns, got "
                          f"{len(position_columns)} ({', '.join(position_columns)})")
    g = robot.geometry
    scale = joint_scales(g.kinds, length_unit, angle_unit)
    table = read_columns(path, list(robot.joint_names) + list(position_columns),
                         optional=QUATERNION, kind="targets",
                         expected=f"the chain joints (seeds) and {', '.join(position_columns)}",
                         rows_name="targets")
    given = [c for c in QUATERNION if c in table.values]
    if given and len(given) < 4:
        missing = [c for c in QUATERNION if c not in table.values]
        raise DataError(f"{table.path}: orientation columns {', '.join(given)} without "
                        f"{', '.join(missing)}; give all of qx, qy, qz, qw (unit quaternion, "
                        "scalar last) or none")
    seeds = np.column_stack([table.values[j] for j in robot.joint_names]) * scale
    positions = np.column_stack([table.values[c] for c in position_columns]) * LENGTH_UNITS[
        length_unit]
    quats = None
    if given:
        quats = np.column_stack([table.values[c] for c in QUATERNION])
        norm = np.linalg.norm(quats, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > UNIT_QUATERNION_TOL)
        if bad.size:
            k = bad[0]
            raise DataError(f"{table.path}, line {table.lines[k]}: the quaternion (qx, qy, qz, qw) "
                            f"has norm {norm[k]:.6g}; expected a unit quaternion, scalar last "
                            f"({bad.size} row(s) like this)")
        quats = quats / norm[:, None]
    for message in (limit_warnings(g.joint_names, g.kinds, g.lower, g.upper, seeds, table.lines)
                    + angle_unit_warnings(g.joint_names, g.kinds, seeds, angle_unit)):
        warnings.warn(f"{table.path}: {message}", KincalWarning)
    return Targets(seeds, positions, quats, table.lines, str(table.path))
