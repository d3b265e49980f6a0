"""Using a calibration in a cell: compensated joint values for targets and programs.

Its own sub-package because it is a use of a calibration, not a step of one: it takes
the corrected robot and its frames (whatever produced them) and answers "which joint
values reach this target on the calibrated robot". One module per idea: batched chain
kinematics, batched inverse kinematics, the frames file, the targets file, and the two
public forms (:func:`compensate`, :func:`filter_program`).
"""

from kincal.compensation.compensate import Compensation, compensate, filter_program
from kincal.frames_file import CellFrames
from kincal.compensation.ik import IkOptions
from kincal.compensation.targets import Targets, read_targets
from kincal.measurements.fixed_joints import HeldJoints

__all__ = ["CellFrames", "Compensation", "HeldJoints", "IkOptions", "Targets", "compensate",
           "filter_program", "read_targets"]
