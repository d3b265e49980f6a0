"""Does a pose file's orientation convention look wrong? Evidence from the nominal model.

Roll/pitch/yaw angles read in the wrong order (``R = Rz Ry Rx`` against ``Rx Ry Rz``), or a
quaternion read scalar-last when it is scalar-first, still give valid rotations: nothing in
the file refuses them. What gives them away is the nominal model: with the measurement and
tool frames fitted, a right reading leaves an orientation error of the order of what the
position error suggests (a few millimetres at a reach of a metre: a fraction of a degree),
a wrong one tens of degrees. :func:`convention_evidence` fits the frames to both readings
(nominal kinematics, no calibration) and says so when the reading asked for is far worse.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

FAR_WORSE = 5.0  # the reading asked for is this many times worse than the other ...
AT_LEAST_DEG = 5.0  # ... and at least this bad [deg] (mean): warned about


@dataclass(frozen=True)
class ConventionEvidence:
    """Nominal-model errors of one pose file under two readings of its orientations.

    fmt / other: the formats; position_mm / other_position_mm: mean position error [mm];
    orientation_deg / other_orientation_deg: mean orientation error [deg], each with the
    measurement and tool frames fitted to that reading."""

    source: str
    fmt: str
    other: str
    position_mm: float
    orientation_deg: float
    other_position_mm: float
    other_orientation_deg: float

    @property
    def suspicious(self) -> bool:
        return (self.orientation_deg >= AT_LEAST_DEG
                and self.orientation_deg >= FAR_WORSE * self.other_orientation_deg)

    def message(self) -> str:
        return (f"{self.source}: the orientations read as {self.fmt} leave a mean orientation "
                f"error of {self.orientation_deg:.1f} deg with the nominal model (frames "
                f"fitted; mean position error {self.position_mm:.1f} mm), read as {self.other} "
                f"{self.other_orientation_deg:.2f} deg (position {self.other_position_mm:.1f} "
                f"mm): is the file's convention {self.other}? (--orientation-format)")


def nominal_errors(robot, data) -> tuple[float, float]:
    """(mean position error [mm], mean orientation error [deg]) of pose data with the
    nominal model and the frames fitted (the start of a calibration)."""
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.problem import CalibrationProblem
    from kincal.identification.statistics import angle_errors

    with warnings.catch_warnings():  # the calibration itself gives the data's warnings
        warnings.simplefilter("ignore")
        problem = CalibrationProblem(robot, [data], CalibrationOptions(method="frames"))
        r = problem.residuals(problem.start(), 0)
    km = problem.kinds[0]
    angles = angle_errors(km, r)
    assert angles is not None  # pose data have orientation errors
    return (float(np.mean(km.sample_errors(r))) * 1e3, float(np.degrees(np.mean(angles))))


def convention_evidence(robot, data, other_data, fmt: str, other: str) -> ConventionEvidence:
    """The nominal-model errors of ``data`` (read as ``fmt``) and of ``other_data`` (the
    same file read as ``other``)."""
    p, o = nominal_errors(robot, data)
    p2, o2 = nominal_errors(robot, other_data)
    return ConventionEvidence(str(data.source), fmt, other, p, o, p2, o2)


def warn_if_other_convention(robot, data, fmt: str, read_as) -> ConventionEvidence | None:
    """Warn (:class:`kincal.errors.KincalWarning`) when pose ``data``, read in the format
    ``fmt``, look like the other convention. read_as: format -> the same file read in that
    format (a KincalError there: no check). Returns the evidence, or None when the format
    has no other convention."""
    from kincal.errors import KincalError, KincalWarning
    from kincal.measurements.orientation_columns import OTHER_CONVENTION

    other = OTHER_CONVENTION.get(fmt)
    if other is None:
        return None
    try:
        other_data = read_as(other)
    except KincalError:
        return None
    evidence = convention_evidence(robot, data, other_data, fmt, other)
    if evidence.suspicious:
        warnings.warn(evidence.message(), KincalWarning)
    return evidence
