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

from kincal.measurements.orientation_columns import AT_LEAST_DEG, FAR_WORSE, other_reading


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


def nominal_errors(CalibrationProblem, robot, data) -> tuple[float, float]:
    """(mean position error [mm], mean orientation error [deg]) of pose data with the
    nominal model and the frames fitted (the start of a calibration). CalibrationProblem:
    the problem class (passed in: the gate, which the problem calls, calls this)."""
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.statistics import angle_errors

    with warnings.catch_warnings():  # the calibration itself gives the data's warnings
        warnings.simplefilter("ignore")
        problem = CalibrationProblem(robot, [data], CalibrationOptions(method="frames"))
        r = problem.residuals(problem.start(), 0)
    km = problem.kinds[0]
    angles = angle_errors(km, r)
    assert angles is not None  # pose data have orientation errors
    return (float(np.mean(km.sample_errors(r))) * 1e3, float(np.degrees(np.mean(angles))))


def convention_evidence(CalibrationProblem, robot, data, other_data, fmt: str, other: str
                        ) -> ConventionEvidence:
    """The nominal-model errors of ``data`` (read as ``fmt``) and of ``other_data`` (the
    same file read as ``other``); CalibrationProblem: the problem class."""
    p, o = nominal_errors(CalibrationProblem, robot, data)
    p2, o2 = nominal_errors(CalibrationProblem, robot, other_data)
    return ConventionEvidence(str(data.source), fmt, other, p, o, p2, o2)


MAX_CHECKED = 2000  # poses the check fits the frames to (evenly spaced): a bounded cost


def checked(CalibrationProblem, robot, data):
    """``data`` with its orientation convention checked: pose data read in a convention
    their columns do not fix (``PoseData.orientation_format``) and not checked before get
    ``convention_doubt``, the evidence's message when the other reading fits the nominal
    model far better (warned about, :class:`kincal.errors.KincalWarning`; the plausibility
    gate refuses a calibration of them), else "". Other data come back as they are.
    CalibrationProblem: the problem class (passed in, so that the gate, which the problem
    calls, does not import it)."""
    from dataclasses import replace

    from kincal.errors import KincalWarning
    from kincal.measurements.orientation_columns import OTHER_CONVENTION

    fmt = getattr(data, "orientation_format", "")
    if fmt not in OTHER_CONVENTION or data.convention_doubt is not None:
        return data
    sample = data if len(data) <= MAX_CHECKED else data.subset(
        np.unique(np.linspace(0, len(data) - 1, MAX_CHECKED).astype(int)))
    plain = replace(sample, orientation_format="", convention_doubt="")
    other = replace(plain, rotations=other_reading(sample.rotations, fmt))
    evidence = convention_evidence(CalibrationProblem, robot, plain, other, fmt,
                                   OTHER_CONVENTION[fmt])
    if evidence.suspicious:
        warnings.warn(evidence.message(), KincalWarning)
    return replace(data, convention_doubt=evidence.message() if evidence.suspicious else "")
