"""kincal: kinematic calibration of serial robots from URDF.

    from kincal import Robot
    from kincal import Measurements
    from kincal import calibrate
    robot = Robot.load("ec66", tip="flange")
    data = Measurements.from_csv("poses.csv", robot.joint_names)
    result = calibrate(robot, data, method="l2", lam="cv")
    print(result.summary()); result.export_urdf("ec66_calibrated.urdf")
"""

__version__ = "0.1.0"

from kincal.errors import KincalError, KincalWarning  # noqa: E402
from kincal.identification.calibration import (  # noqa: E402
                                               CalibrationOptions,
                                               CalibrationProblem,
                                               CalibrationResult,
                                               calibrate,
)
from kincal.identification.solver import SolverOptions  # noqa: E402
from kincal.measurements.data import Measurements  # noqa: E402
from kincal.planning.candidates import random_candidates, read_candidates  # noqa: E402
from kincal.planning.pose_selection import PoseSelection, select_poses  # noqa: E402
from kincal.robot import Robot  # noqa: E402

__all__ = ["Robot", "Measurements", "calibrate", "CalibrationOptions", "CalibrationProblem",
           "CalibrationResult", "SolverOptions", "select_poses", "PoseSelection",
           "random_candidates", "read_candidates", "KincalError", "KincalWarning", "__version__"]
