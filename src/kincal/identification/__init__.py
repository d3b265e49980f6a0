"""Identification: one calibration problem over one or many measurement sets (layout,
rank-revealing selection, solver, penalty by evidence or CV, plausibility), and its result.
Plain numpy/scipy above the robot layer; writes no files."""

from kincal.lazy import lazy_names

__all__ = ["CalibrationProblem", "CalibrationOptions", "CalibrationResult", "SetResult",
           "ParameterEstimate", "ParameterLayout", "Identifiability", "calibrate"]
__getattr__, __dir__ = lazy_names(__name__, {
    "CalibrationProblem": "problem", "calibrate": "problem", "CalibrationOptions": "options",
    "CalibrationResult": "result", "SetResult": "result", "ParameterEstimate": "result",
    "ParameterLayout": "layout", "Identifiability": "selection"})
