"""How far a calibration's corrections move the tool point over the joint range: the
plausibility gate's workspace comparison and its yardstick, the reach
(:mod:`kincal.identification.plausibility`, its module notes say why).

Plain numpy over the vectorised chain (:class:`kincal.models.kinematics.ChainKinematics`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from kincal.models import per_geometry
from kincal.models.geometry import chain_length  # the yardstick's chain part
from kincal.models.kinematics import ChainKinematics
from kincal.rotations import aligned_distances

if TYPE_CHECKING:
    from kincal.identification.problem import CalibrationProblem
    from kincal.identification.result import CalibrationResult

N_CONFIGURATIONS = 300  # joint configurations for the workspace comparison (seeded)


def reach(chain_m: float, tool_m: float) -> float:
    """[m] the gate's yardstick (module notes): the chain plus the capped tool distance."""
    return chain_m + min(tool_m, max(chain_m, 1.0))


def n_chains(problem: CalibrationProblem) -> int:
    chains = getattr(problem, "chains", None)
    return len(chains.chain_robots) if chains is not None and chains.several else 1


def change(problem: CalibrationProblem, result: CalibrationResult,
            chain: int) -> tuple[float, np.ndarray, float]:
    """(reach [m], (M,) distances [mm], their RMS) of chain ``chain`` (each is judged): how
    far the corrected model moves its tool point (the chain's first set's; none: the tip)
    from the nominal one's at seeded configurations over the joint limits (a turn if none)."""
    lay = result.layout
    if n_chains(problem) == 1:
        robot, corrected, first = problem.robot, result.corrected, 0
    else:
        robot = problem.chains.chain_robots[chain]
        corrected = robot.with_origins(result.corrected.urdf_origins(
            tuple(problem.error_model.joint_names)))
        first = problem.chains.of_set.index(chain)
    tool_start, tool = np.zeros(3), np.zeros(3)
    name = lay.set_prefix(first) + "tool."
    if name + "x" in lay.frame_names(first):  # by name: a flush set stores z, x, y
        k = [lay.index(name + c) for c in "xyz"]
        tool_start, tool = result.x_start[k], result.x[k]
    L, d = between(robot, corrected, tool_start, tool)
    return L, d, math.sqrt(float(np.add.reduce(d * d)) / d.size)  # np.sqrt(np.mean(d ** 2))


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


def farthest_tool(problem: CalibrationProblem, result: CalibrationResult):
    """(distance [m], its chain's length [m], the set, its kind) of the identified tool point
    farthest from its tip frame in chain lengths (tool.*, tool2.*, ... of every set that has
    one); None when no set has a tool point."""
    out = None
    for s, robot in zip(result.sets, problem.robots):
        names = list(s.frame_names)
        stems = [n[:-1] for n in names if n.startswith("tool") and n.endswith(".x")]
        if not stems:
            continue
        length = max(chain_length_of(robot), 1e-9)
        far = max(float(np.linalg.norm([s.frames[names.index(t + c)] for c in "xyz"]))
                  for t in stems)
        if out is None or far / length > out[0] / out[1]:
            out = (far, length, s.source, s.kind)
    return out


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
