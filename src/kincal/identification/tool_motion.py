"""How far a calibration's corrections move the tool point over the joint range: the
plausibility gate's workspace comparison (:mod:`kincal.identification.plausibility`, its
module notes say why), on the robots' workspace measures (:mod:`kincal.models.workspace`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from kincal.models.workspace import between, chain_length_of

if TYPE_CHECKING:
    from kincal.identification.problem import CalibrationProblem
    from kincal.identification.result import CalibrationResult


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
