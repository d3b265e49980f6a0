"""kincal: kinematic calibration of robots from URDF (any chain of the tree, one or several).

    from kincal import Robot, Measurements, calibrate, write_calibration, Outputs
    robot = Robot.load("ec66", tip="flange")
    data = Measurements.from_csv("poses.csv", robot.joint_names)
    result = calibrate(robot, data)            # one set, or a list of sets of any kind
    print(result.summary())
    write_calibration(result, Outputs(urdf="ec66_calibrated.urdf"))   # the gate, then files
"""

__version__ = "0.2.0"

from kincal.errors import KincalError, KincalWarning  # noqa: E402

# The public names are imported on first use (PEP 562), so that `import kincal` and
# `kincal --help` do not pay for Pinocchio, scipy and matplotlib (about 0.5 s).
_LAZY = {
    "CalibrationOptions": "kincal.identification.options",
    "CalibrationProblem": "kincal.identification.problem",
    "CalibrationResult": "kincal.identification.result",
    "SetResult": "kincal.identification.result",
    "calibrate": "kincal.identification.problem",
    "write_calibration": "kincal.export.outputs",
    "Outputs": "kincal.export.outputs",
    "CellFrames": "kincal.frames_file",
    "SolverOptions": "kincal.identification.solver",
    "Measurements": "kincal.measurements.data",
    "random_candidates": "kincal.planning.candidates",
    "read_candidates": "kincal.planning.candidates",
    "PoseSelection": "kincal.planning.pose_selection",
    "select_poses": "kincal.planning.pose_selection",
    "Robot": "kincal.robot",
    "PoseData": "kincal.measurements.pose",
    "DistanceData": "kincal.measurements.distance",
    "PlaneData": "kincal.measurements.plane",
    "FlushData": "kincal.measurements.flush",
    "read_set_file": "kincal.measurements.sets",
}

__all__ = ["Robot", "Measurements", "calibrate", "CalibrationOptions", "CalibrationProblem",
           "CalibrationResult", "SolverOptions", "select_poses", "PoseSelection",
           "random_candidates", "read_candidates", "SetResult", "write_calibration", "Outputs",
           "CellFrames", "PoseData", "DistanceData", "PlaneData", "FlushData", "read_set_file",
           "KincalError", "KincalWarning", "__version__"]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # later look-ups skip this function
        return value
    raise AttributeError(f"module 'kincal' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
