"""Targets to compensate: seed joint values and wanted tool positions (or poses).

A TARGETS.csv has the chain joints (named as in the URDF: the user's program, the seeds)
and ``x,y,z``, the wanted position of the measured tool point in the measurement frame;
optionally the wanted orientation of the tool frame in the measurement frame (as a pose
calibration's data measured it: the tip frame turned by the calibration's ``tool.rx .ry
.rz``; the tip frame's own after a point calibration), written as a pose file writes it
(:mod:`kincal.measurements.orientation_columns`: ``qx,qy,qz,qw`` by default, a unit
quaternion, scalar last; any other format when it is named). Revolute joints and
orientation angles in ``angle_unit``, positions and prismatic joints in
``length_unit``; inside, SI. Orientation columns that would not be read are refused, as a
pose file's are: an orientation is never dropped silently.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError, KincalNote, KincalWarning, OptionError
from kincal.measurements.checks import angle_unit_warnings, limit_warnings
from kincal.measurements.csv_table import read_columns
from kincal.measurements.data import unit_factors
from kincal.measurements.fixed_joints import HeldJoints
from kincal.measurements.orientation_columns import (DEFAULT_FORMAT, OrientationFormat,
                                                     found_columns, rotations,
                                                     unread_message)
from kincal.measurements.pose import QUATERNION_COLUMNS as QUATERNION


@dataclass(frozen=True)
class Targets:
    """N targets of one chain (SI).

    seeds: (N, n) joint values the solution starts from [rad or m]. positions: (N, 3)
    wanted tool point in the measurement frame [m]. rotations: (N, 3, 3) wanted tool
    frame orientation in the measurement frame, or None for positions only.
    lines: (N,) line numbers in the source file. source: for messages. orientation_format:
    the convention of the rotations where their columns do not fix it (angles, or
    quaternion columns named by the user; :func:`compensate` checks it), else "".
    """

    seeds: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray | None
    lines: np.ndarray
    source: str = "<targets>"
    orientation_format: str = ""

    def __len__(self) -> int:
        return len(self.seeds)


def joint_scales(kinds, length_unit: str, angle_unit: str) -> np.ndarray:
    """(n,) factors from file units to SI for the joints of ``kinds``."""
    L, A = unit_factors(length_unit, angle_unit, OptionError)
    return np.array([L if k == "prismatic" else A for k in kinds])


def read_targets(path, robot, length_unit: str = "m", angle_unit: str = "rad",
                 position_columns=("x", "y", "z"), orientation_format: str | None = None,
                 orientation_columns=None, held: HeldJoints | None = None) -> Targets:
    """Targets from a CSV file (see the module notes); values outside the joint limits and
    angles that look like degrees are warned about, as for measurements.
    position_columns: the names of the x, y, z columns. orientation_format, orientation_columns:
    how the wanted orientations are written (:class:`~kincal.measurements.orientation_columns.
    OrientationFormat`); both None: ``qx qy qz qw`` if the file has them, else positions only
    (other orientation columns refused). held: the joints the calibration held
    (:meth:`HeldJoints.of` its frames), whose columns the file may leave out (their seeds:
    the held values)."""
    position_columns = tuple(position_columns)
    if len(position_columns) != 3:
        raise OptionError(f"a target has one position: give 3 position columns, got "
                          f"{len(position_columns)} ({', '.join(position_columns)})")
    g = robot.geometry
    scale = joint_scales(g.kinds, length_unit, angle_unit)
    L, A = unit_factors(length_unit, angle_unit, OptionError)
    named = orientation_format is not None or orientation_columns is not None
    fmt = OrientationFormat(orientation_format or DEFAULT_FORMAT,
                            None if orientation_columns is None else tuple(orientation_columns))
    with warnings.catch_warnings():  # the reading below gives the notes
        warnings.simplefilter("ignore", KincalNote)
        header = read_columns(path, [], kind="targets", header_only=True).header
    columns: tuple[str, ...] = ()
    if named:
        columns = fmt.resolve(header, position_columns, str(path))
    elif any(c in header for c in QUATERNION):
        columns = QUATERNION
        missing = [c for c in QUATERNION if c not in header]
        if missing:
            given = [c for c in QUATERNION if c in header]
            raise DataError(f"{path}: orientation columns {', '.join(given)} without "
                            f"{', '.join(missing)}; give all of qx, qy, qz, qw (unit "
                            "quaternion, scalar last) or none, or name the format "
                            "(--orientation-format)")
    else:
        unused = found_columns(header, position_columns, robot.joint_names)
        if unused:
            raise DataError(unread_message(path, unused[0], position_columns,
                                           "to reach the orientations too",
                                           "remove them to reach the positions alone"))
    expected = (f"the chain joints (seeds) and {', '.join(position_columns)}"
                + (f" and {', '.join(columns)} ({fmt.name})" if columns else ""))
    held = held or HeldJoints()
    fixed = held.as_dict()
    table = read_columns(path, [*(j for j in robot.joint_names if j not in fixed),
                                *position_columns, *columns],
                         [j for j in robot.joint_names if j in fixed], kind="targets",
                         expected=expected, rows_name="targets")
    seeds = held.joint_values(table, robot.joint_names, scale)
    positions = np.column_stack([table.values[c] for c in position_columns]) * L
    R = None
    if columns:
        R = rotations(np.column_stack([table.values[c] for c in columns]), fmt.name, A,
                      str(table.path), table.lines, columns)
    for message in (limit_warnings(g.joint_names, g.kinds, g.lower, g.upper, seeds, table.lines)
                    + angle_unit_warnings(g.joint_names, g.kinds, seeds, angle_unit,
                                          g.lower, g.upper)):
        warnings.warn(f"{table.path}: {message}", KincalWarning)
    return Targets(seeds, positions, R, table.lines, str(table.path),
                   fmt.name if columns and fmt.unfixed else "")
