"""kincal: kinematic calibration of serial robots from URDF.

    from kincal import Robot, Measurements, calibrate
    robot = Robot.load("ec66", tip="flange")
    data = Measurements.from_csv("poses.csv", robot.joint_names)
    result = calibrate(robot, data, method="l2", lam="cv")
    print(result.summary()); result.export_urdf("ec66_calibrated.urdf")
"""

__version__ = "0.1.0"

from .calibration import (CalibrationOptions, CalibrationProblem, CalibrationResult,  # noqa: E402
                          calibrate)
from .errors import KincalError, KincalWarning  # noqa: E402
from .measurements import Measurements  # noqa: E402
from .candidates import random_candidates, read_candidates  # noqa: E402
from .pose_selection import PoseSelection, select_poses  # noqa: E402
from .robot import Robot  # noqa: E402
from .solver import SolverOptions  # noqa: E402

__all__ = ["Robot", "Measurements", "calibrate", "CalibrationOptions", "CalibrationProblem",
           "CalibrationResult", "SolverOptions", "select_poses", "PoseSelection",
           "random_candidates", "read_candidates", "KincalError", "KincalWarning", "__version__"]
