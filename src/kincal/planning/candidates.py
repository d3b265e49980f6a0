"""Candidate poses: joint configurations that could be measured, before they are.

From a CSV file whose header names the chain joints (no position columns needed), or
drawn at random within the joint limits. :mod:`kincal.pose_selection` picks among them.
Random poses are not checked for collisions; a user's candidates should be poses the
robot can safely reach and the instrument can see.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import DataError, KincalWarning, OptionError
from kincal.measurements.checks import (angle_unit_warnings, degrees_read_as_radians,
                                       limit_warnings)
from kincal.measurements.csv_table import csv_line, read_columns
from kincal.measurements.data import joint_column_names, unit_factors
from kincal.measurements.fixed_joints import HeldJoints, refuse_coupled

if TYPE_CHECKING:
    from kincal.robot import Robot


def random_candidates(robot: "Robot", m: int, rng) -> np.ndarray:
    """(m, n_joints) joint values uniform within the joint limits [rad or m].

    Joints without limits (continuous) are drawn in [-pi, pi]. rng: a numpy Generator or
    a seed. A chain holding a mimic joint and its master is refused (OptionError: drawn
    independently, the values would break the URDF's rule, which the robot follows).
    """
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
        raise OptionError(f"the number of random candidates must be an integer >= 1, got {m!r}")
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and rng < 0:
        raise OptionError(f"the seed must be an integer >= 0, got {rng}")
    refuse_coupled(robot, "drawing random candidates")
    g = robot.geometry
    lo, hi = g.ranges()
    try:
        generator = np.random.default_rng(rng)
    except (TypeError, ValueError):
        raise OptionError(f"rng must be a numpy Generator or a seed >= 0, got {rng!r}") from None
    return generator.uniform(lo, hi, size=(int(m), g.n))


def read_candidates(path, robot: "Robot", length_unit: str = "m", angle_unit: str = "rad",
                    kind: str = "candidates", joint_columns=None,
                    held: HeldJoints | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((M, n_joints) candidate joint values [SI], (M,) their line numbers) from a CSV file.

    The header names the chain joints as in the URDF (other columns are ignored).
    Revolute joints are read in ``angle_unit``, prismatic ones in ``length_unit``. Values
    outside the URDF limits are warned about, not dropped; values that show degrees read as
    radians (:func:`~kincal.measurements.checks.degrees_read_as_radians`: beyond a turn and
    a half and outside the limits) are refused: poses to command, or to simulate, plan and
    map at, so read are nonsense. kind: what the file is, for
    messages. joint_columns: {URDF joint: CSV column} for columns named otherwise (see
    :meth:`kincal.measurements.data.Measurements.from_csv`). held: the joints a calibration
    held (:class:`~kincal.measurements.fixed_joints.HeldJoints`), whose columns the file may
    leave out (read at the held values).
    """
    L, A = unit_factors(length_unit, angle_unit, OptionError)
    g = robot.geometry
    held = held or HeldJoints()
    columns = joint_column_names(robot.joint_names, joint_columns)
    fixed = held.as_dict()
    table = read_columns(path, [c for j, c in columns.items() if j not in fixed],
                         [c for j, c in columns.items() if j in fixed], kind=kind,
                         expected="the chain joints", rows_name="poses",
                         aliases={c: j for j, c in columns.items() if c != j})
    unit = [L if k == "prismatic" else A for k in g.kinds]
    q = held.joint_values(table, robot.joint_names, unit, columns)
    degrees = degrees_read_as_radians(g.joint_names, g.kinds, g.lower, g.upper, q, table.lines)
    if degrees:
        raise DataError(f"{table.path}: {degrees}")
    for message in (limit_warnings(g.joint_names, g.kinds, g.lower, g.upper, q, table.lines)
                    + angle_unit_warnings(g.joint_names, g.kinds, q, angle_unit, g.lower,
                                          g.upper)):
        warnings.warn(f"{table.path}: {message}", KincalWarning)
    return q, table.lines


def candidates_csv_text(joint_names, joint_values, source_lines=None) -> str:
    """Joint values as CSV: a header of joint names, SI units, full precision.

    source_lines: optional (n,) line numbers of the poses in the candidates file, written
    as a last column ``candidate_line`` (ignored when the file is read as data).
    """
    q = np.asarray(joint_values, float)
    header = list(joint_names) + (["candidate_line"] if source_lines is not None else [])
    lines = [csv_line(header)]
    for k, row in enumerate(q):
        cells = [repr(float(v)) for v in row]
        if source_lines is not None:
            cells.append(str(int(source_lines[k])))
        lines.append(csv_line(cells))
    return "\n".join(lines) + "\n"
