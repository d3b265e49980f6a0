"""Inverse kinematics of many targets at once: damped least squares from a seed.

Each target is a position of a tool point in the base frame B, with an orientation of
the tip frame that is either *required* (a full pose) or *preferred* (kept if the chain
can, e.g. the seed's own orientation for a position-only target). The two are solved as
prioritised tasks (Siciliano and Slotine's task priority): the position first, the
orientation in the null space of the position task. On a chain of six or more joints
both are met; on fewer joints the position is still met exactly and the orientation is
as close as the remaining freedom allows, instead of a weighted compromise that would
miss the position.

Staying on the seed's branch: every configuration starts at its seed, and each
iteration changes a joint by at most ``max_step`` (the step is scaled down as a whole,
so its direction is kept), so a solution is reached through small moves from the seed
as a robot program would, not by jumping to another elbow or wrist branch. On a
redundant chain the freedom left is resolved by the least-norm steps from the seed (no
explicit pull back toward it: tried, it fought the tasks near singular wrists). Joint
limits are enforced by clipping after each step, and a joint on a limit that the step
pushes outward is left out of the next step, so the others take over; a target
reachable only beyond a limit is reported as not reached, never clipped silently.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from kincal.models.kinematics import BLOCK, ChainKinematics
from kincal.errors import OptionError
from kincal.rotations import rotation_log


@dataclass(frozen=True)
class IkOptions:
    """Settings of the batched inverse kinematics.

    position_tolerance: [m] a target is reached when its tool point is this close.
    orientation_tolerance: [rad] the same for a required orientation.
    max_iterations: iterations per target (Newton converges in a few near the seed).
    max_step: [rad or m] largest change of one joint in one iteration.
    damping: [m] Levenberg damping of the least-squares steps; keeps the steps bounded
        near singular configurations, negligible elsewhere.
    """

    position_tolerance: float = 1e-6
    orientation_tolerance: float = 1e-6
    max_iterations: int = 100
    max_step: float = 0.1
    damping: float = 1e-6

    def __post_init__(self):
        for name in ("position_tolerance", "orientation_tolerance", "max_step", "damping"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise OptionError(f"IkOptions.{name} must be a positive number, got {v!r}")
        if int(self.max_iterations) < 1:
            raise OptionError(f"IkOptions.max_iterations must be >= 1, got {self.max_iterations}")


@dataclass(frozen=True)
class IkSolution:
    """Result per target (N rows).

    q: (N, n) joint values [rad or m]. position_error: (N,) distance of the tool point
    from its target [m]. orientation_error: (N,) angle between the tip orientation and
    its target [rad]. reached: (N,) position within tolerance, and the orientation too
    where it was required. at_limit: (N, n) joints sitting on a limit. iterations: (N,).
    """

    q: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray
    reached: np.ndarray
    at_limit: np.ndarray
    iterations: np.ndarray


def _damped_pinv(A: np.ndarray, damping: float) -> np.ndarray:
    """(N, n, m) damped pseudo-inverses A^T (A A^T + d^2 I)^-1 of (N, m, n) matrices."""
    m = A.shape[1]
    At = np.swapaxes(A, 1, 2)
    return At @ np.linalg.inv(A @ At + damping ** 2 * np.eye(m))


def _step(Jp, Jo, e_p, e_o, eye, damping) -> np.ndarray:
    """(N, n) joint step: the position task, then the orientation in its null space."""
    Jp_pinv = _damped_pinv(Jp, damping)
    dq1 = np.einsum("kij,kj->ki", Jp_pinv, e_p)
    null = eye - Jp_pinv @ Jp
    dq2 = np.einsum("kij,kj->ki", _damped_pinv(Jo @ null, damping),
                    e_o - np.einsum("kij,kj->ki", Jo, dq1))
    return dq1 + np.einsum("kij,kj->ki", null, dq2)


def solve(chain: ChainKinematics, tool, positions: np.ndarray, rotations: np.ndarray,
          required: np.ndarray, seeds: np.ndarray, lower: np.ndarray, upper: np.ndarray,
          options: IkOptions = IkOptions()) -> IkSolution:
    """Joint values putting ``tool`` (3,) [m, tip frame] at ``positions`` (N, 3) [m, B].

    rotations: (N, 3, 3) wanted tip orientations in B; required: (N,) bool, True where
    the orientation must be met, False where it is only preferred. seeds: (N, n) start
    values; lower, upper: (n,) joint limits (+-inf allowed). Solved in blocks of
    :data:`kincal.models.kinematics.BLOCK` targets: the memory of the iterations is bounded.
    """
    if len(seeds) > BLOCK:  # in blocks of targets: each is solved on its own anyway
        out: dict[str, np.ndarray] = {}
        for s in range(0, len(seeds), BLOCK):
            part = solve(chain, tool, positions[s:s + BLOCK], rotations[s:s + BLOCK],
                         required[s:s + BLOCK], seeds[s:s + BLOCK], lower, upper, options)
            for f in fields(IkSolution):
                v = getattr(part, f.name)
                out.setdefault(f.name, np.empty((len(seeds),) + v.shape[1:], v.dtype))[
                    s:s + BLOCK] = v
        return IkSolution(**out)
    q = np.clip(np.array(seeds, dtype=float), lower, upper)
    N, n = q.shape
    eye = np.eye(n)
    active = np.ones(N, dtype=bool)
    iterations = np.zeros(N, dtype=int)
    for _ in range(options.max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        R, p, Jp, Jo = chain.evaluate(q[idx], tool)
        e_p = positions[idx] - p
        e_o = rotation_log(rotations[idx] @ np.swapaxes(R, 1, 2))
        dq = _step(Jp, Jo, e_p, e_o, eye, options.damping)
        # a joint on a limit that the step pushes outward is taken out of the step, so the
        # other joints meet the position (the orientation gives way first if it must)
        blocked = ((q[idx] <= lower) & (dq < 0)) | ((q[idx] >= upper) & (dq > 0))
        rows = np.flatnonzero(blocked.any(axis=1))  # the step again for these rows only
        if rows.size:
            keep = (~blocked[rows])[:, None, :]
            dq[rows] = _step(Jp[rows] * keep, Jo[rows] * keep, e_p[rows], e_o[rows], eye,
                             options.damping)
        biggest = np.abs(dq).max(axis=1)
        dq *= np.minimum(1.0, options.max_step / np.maximum(biggest, 1e-300))[:, None]
        q_new = np.clip(q[idx] + dq, lower, upper)
        moved = np.abs(q_new - q[idx]).max(axis=1)
        q[idx] = q_new
        iterations[idx] += 1
        # done when the step no longer changes anything that matters
        done = (np.linalg.norm(e_p, axis=1) < 1e-3 * options.position_tolerance) & (
            np.linalg.norm(e_o, axis=1) < 1e-3 * options.orientation_tolerance)
        active[idx[done | (moved < 1e-14)]] = False
    R, p, _, _ = chain.evaluate(q, tool)
    pos_err = np.linalg.norm(positions - p, axis=1)
    rot_err = np.linalg.norm(rotation_log(rotations @ np.swapaxes(R, 1, 2)), axis=1)
    reached = (pos_err <= options.position_tolerance) & (
        ~np.asarray(required, bool) | (rot_err <= options.orientation_tolerance))
    span = np.maximum(np.where(np.isfinite(upper - lower), upper - lower, 1.0), 1e-12)
    at_limit = (q - lower <= 1e-9 * span) | (upper - q <= 1e-9 * span)
    return IkSolution(q, pos_err, rot_err, reached, at_limit, iterations)
