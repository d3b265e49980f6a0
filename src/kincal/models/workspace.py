"""The workspace a robot's chain sweeps, as the plausibility gate compares two robots of one
chain: seeded configurations over the joint limits, the tool point there, the reach as a
yardstick, and how far one robot puts the tool point from where another does. Robots only
(no calibration problem): the gate (:mod:`kincal.identification.tool_motion`) and the
compensation's check of a nominal robot use the same measure.

Plain numpy over the vectorised chain (:class:`kincal.models.kinematics.ChainKinematics`).
"""

from __future__ import annotations

import math

import numpy as np

from kincal.models import per_geometry
from kincal.models.geometry import chain_length  # the yardstick's chain part
from kincal.models.kinematics import ChainKinematics
from kincal.rotations import aligned_distances

N_CONFIGURATIONS = 300  # joint configurations for the workspace comparison (seeded)
CHANGE = 0.10  # the gate's limit on the corrections' RMS tool motion, a fraction of the reach


def reach(chain_m: float, tool_m: float) -> float:
    """[m] the gate's yardstick (:mod:`kincal.identification.plausibility`'s notes): the chain plus the capped tool distance."""
    return chain_m + min(tool_m, max(chain_m, 1.0))


def between(robot, other, tool, other_tool=None) -> tuple[float, np.ndarray]:
    """(reach [m], (M,) distances [mm]): how far ``other`` (a robot of the same chain) puts
    its tool point (``other_tool``, default ``tool``, tip frame [m]) from where ``robot``
    puts ``tool``, at the gate's seeded configurations, a rigid motion aligned away."""
    tool = np.asarray(tool, float)
    q, motions, length = _kept(robot)  # both robots' points by the same arithmetic
    d = aligned_distances(tool_points(robot, q, tool, motions), tool_points(
        other, q, tool if other_tool is None else np.asarray(other_tool, float), motions))
    return reach(length, float(np.linalg.norm(tool))), d * 1e3


def _kept(robot) -> tuple[np.ndarray, np.ndarray, float]:
    """(the configurations, their joint motions' coefficients, the chain's length [m] at zero
    joint values): they depend on the robot alone, kept per robot (models.per_geometry)."""
    g = robot.geometry
    return per_geometry(("gate configurations", N_CONFIGURATIONS), g, lambda: (
        *configurations(robot), chain_length(g.joint_frames, g.T_base_tip)))


def chain_length_of(robot) -> float:
    """[m] the robot's chain length at zero joint values (the reach's chain part)."""
    return _kept(robot)[2]


def configurations(robot) -> tuple[np.ndarray, np.ndarray]:
    """(q (M, n), motions), read-only: the gate's seeded joint values over the robot's
    limits (unbounded revolute: a turn) and their joint motions' coefficients
    (:meth:`kincal.models.kinematics.ChainKinematics.motions`), which the corrected robot's
    chain shares (its placements alone differ)."""
    g = robot.geometry
    span = np.where(np.array(g.kinds) == "prismatic", 1.0, math.pi)
    lo = np.maximum(np.where(np.isfinite(g.lower), g.lower, -span), -span)
    hi = np.minimum(np.where(np.isfinite(g.upper), g.upper, span), span)
    q = np.random.default_rng(0).uniform(lo, hi, (N_CONFIGURATIONS, g.n))
    motions = ChainKinematics.of(g).motions(q)
    q.flags.writeable = motions.flags.writeable = False
    return q, motions


def tool_points(robot, q: np.ndarray, tool: np.ndarray, motions=None) -> np.ndarray:
    """(M, 3) the point ``tool`` of the tip frame [m], in the base frame, at joint values q
    (``motions``: their coefficients, if made before).

    Through the vectorised chain of the robot's own geometry (read from its Pinocchio
    model, so the corrected robot's is what the URDF export writes): a few products over
    all configurations per joint instead of a Pinocchio call per configuration; tests
    check it against :meth:`kincal.robot.Robot.tip_poses`."""
    return ChainKinematics.of(robot.geometry).tip_points(q, tool, motions)
