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

from dataclasses import dataclass

import numpy as np

from kincal.models.kinematics import BLOCK, ChainKinematics, damped_pinv
from kincal.errors import OptionError
from kincal.rotations import rotation_log


STALL_GAIN = 0.9  # an error counts as progress below this fraction of the best so far
STALL_NET = 0.1  # net move over the window / path length below which the joints wander
SINGULAR = 1e-3  # smallest / largest singular value of the task below which it is singular


# [m] accepted position tolerances: below 1 nm the iterations (stopped at a thousandth of
# it) would chase rounding; above 10 mm a target counts as reached where a calibration's
# corrections (millimetres) are not yet applied: the uncorrected seed would pass
POSITION_TOLERANCE_RANGE = (1e-9, 1e-2)


@dataclass(frozen=True)
class IkOptions:
    """Settings of the batched inverse kinematics.

    position_tolerance: [m] a target is reached when its tool point is this close (within
        :data:`POSITION_TOLERANCE_RANGE`; the iterations stop at a thousandth of it).
    orientation_tolerance: [rad] the same for a required orientation.
    max_iterations: iterations per target (Newton converges in a few near the seed).
    stall_window: a target whose error (position and orientation, each over its
        tolerance, summed) has not fallen below 0.9 times its best for this many
        iterations, while its joints wander in place (their net move over the window under
        STALL_NET of the path), is stopped there: near singular wrists and limits the
        iterations would otherwise run to max_iterations without progress. It is reported
        as it stands (not reached unless within the tolerances).
    max_step: [rad or m] largest change of one joint in one iteration.
    damping: [m] Levenberg damping of the least-squares steps; keeps the steps bounded
        near singular configurations, negligible elsewhere.
    """

    position_tolerance: float = 1e-6
    orientation_tolerance: float = 1e-6
    max_iterations: int = 100
    stall_window: int = 20
    max_step: float = 0.1
    damping: float = 1e-6

    def __post_init__(self):
        for name in ("position_tolerance", "orientation_tolerance", "max_step", "damping"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise OptionError(f"IkOptions.{name} must be a positive number, got {v!r}")
        lo, hi = POSITION_TOLERANCE_RANGE
        if not lo <= self.position_tolerance <= hi:
            raise OptionError(f"IkOptions.position_tolerance must be between {lo:g} and {hi:g} "
                              f"m, got {self.position_tolerance!r}")
        for name in ("max_iterations", "stall_window"):
            if int(getattr(self, name)) < 1:
                raise OptionError(f"IkOptions.{name} must be >= 1, got {getattr(self, name)}")


@dataclass(frozen=True)
class IkSolution:
    """Result per target (N rows).

    q: (N, n) joint values [rad or m]. position_error: (N,) distance of the tool point
    from its target [m]. orientation_error: (N,) angle between the tip orientation and
    its target [rad]. reached: (N,) position within tolerance, and the orientation too
    where it was required. at_limit: (N, n) joints sitting on a limit. iterations: (N,).
    singular: (N,) a target not reached whose joints end near a singular configuration
    (:func:`_singular`; False for the targets reached).
    """

    q: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray
    reached: np.ndarray
    at_limit: np.ndarray
    iterations: np.ndarray
    singular: np.ndarray


def _step(Jp, Jo, e_p, e_o, damping) -> np.ndarray:
    """(N, n) joint step: the position task, then the orientation in its null space.

    The projector N = I - Jp^+ Jp is applied through its factors, never made: Jo N =
    Jo - (Jo Jp^+) Jp and N v = v - Jp^+ (Jp v) (3 x 3 and 3 x n products instead of
    n x n ones; the same step up to rounding, tests/test_compensation.py)."""
    Jp_pinv = damped_pinv(Jp, damping ** 2)  # (N, n, 3)
    dq1 = np.einsum("kij,kj->ki", Jp_pinv, e_p)
    Jo_null = Jo - (Jo @ Jp_pinv) @ Jp
    dq2 = np.einsum("kij,kj->ki", damped_pinv(Jo_null, damping ** 2),
                    e_o - np.einsum("kij,kj->ki", Jo, dq1))
    return dq1 + dq2 - np.einsum("kij,kj->ki", Jp_pinv, np.einsum("kij,kj->ki", Jp, dq2))


def solve(chain: ChainKinematics, tool, positions: np.ndarray, rotations: np.ndarray,
          required: np.ndarray, seeds: np.ndarray, lower: np.ndarray, upper: np.ndarray,
          options: IkOptions = IkOptions()) -> IkSolution:
    """Joint values putting ``tool`` (3,) [m, tip frame] at ``positions`` (N, 3) [m, B].

    rotations: (N, 3, 3) wanted tip orientations in B; required: (N,) bool, True where
    the orientation must be met, False where it is only preferred. seeds: (N, n) start
    values; lower, upper: (n,) joint limits (+-inf allowed; lower = upper holds a joint
    there: it takes no step, and is never reported at a limit). At most
    :data:`kincal.models.kinematics.BLOCK` targets iterate at once: the memory of the
    iterations is bounded.
    """
    q = np.clip(np.array(seeds, dtype=float), lower, upper)
    N, n = q.shape
    # a held joint is left out of every step at once (the blocking below would take it out
    # too, at the cost of a second step per row and iteration)
    moving = np.asarray(lower) < np.asarray(upper)
    iterations = np.zeros(N, dtype=int)
    # a pool of at most BLOCK targets iterates together; a finished target's slot takes the
    # next target at once, so the few slow ones share their iterations with new targets
    # instead of each block waiting for its slowest (a target's numbers do not depend on
    # the others in its pool: tests/test_compensate_blocks.py)
    P, W = min(BLOCK, N), int(options.stall_window)
    target = np.full(P, -1)  # the target in each slot, -1: free
    best, last = np.zeros(P), np.zeros(P, dtype=int)  # stall test: best error, its age
    ring, moves = np.empty((W + 1, P, n)), np.zeros((W, P))  # the last W steps' q, moves
    queued = 0
    while True:
        free = np.flatnonzero(target < 0)[:N - queued]
        if free.size:
            target[free] = np.arange(queued, queued + free.size)
            queued += free.size
            best[free], last[free], ring[0, free], moves[:, free] = np.inf, 0, q[target[free]], 0
        slots = np.flatnonzero(target >= 0)
        if slots.size == 0:
            break
        idx = target[slots]
        t = iterations[idx]  # each target's own iteration count
        R, p, Jp, Jo = chain.evaluate(q[idx], tool)
        if not moving.all():
            Jp, Jo = Jp * moving, Jo * moving
        e_p = positions[idx] - p
        e_o = rotation_log(rotations[idx] @ np.swapaxes(R, 1, 2))
        n_p, n_o = np.linalg.norm(e_p, axis=1), np.linalg.norm(e_o, axis=1)
        merit = n_p / options.position_tolerance + n_o / options.orientation_tolerance
        better = merit < STALL_GAIN * best[slots]
        best[slots[better]], last[slots[better]] = merit[better], t[better]
        dq = _step(Jp, Jo, e_p, e_o, options.damping)
        # a joint on a limit that the step pushes outward is taken out of the step, so the
        # other joints meet the position (the orientation gives way first if it must)
        blocked = ((q[idx] <= lower) & (dq < 0)) | ((q[idx] >= upper) & (dq > 0))
        rows = np.flatnonzero(blocked.any(axis=1))  # the step again for these rows only
        if rows.size:
            keep = (~blocked[rows])[:, None, :]
            dq[rows] = _step(Jp[rows] * keep, Jo[rows] * keep, e_p[rows], e_o[rows],
                             options.damping)
        biggest = np.abs(dq).max(axis=1)
        dq *= np.minimum(1.0, options.max_step / np.maximum(biggest, 1e-300))[:, None]
        q_new = np.clip(q[idx] + dq, lower, upper)
        moved = np.abs(q_new - q[idx]).max(axis=1)
        q[idx] = q_new
        iterations[idx] += 1
        # done when the step no longer changes anything that matters
        done = (n_p < 1e-3 * options.position_tolerance) & (
            n_o < 1e-3 * options.orientation_tolerance)
        ring[(t + 1) % (W + 1), slots], moves[t % W, slots] = q_new, moved
        stalled = t - last[slots] >= W  # no progress in W iterations: moving on, or in place?
        slow = np.flatnonzero(stalled)
        if slow.size:
            net = np.abs(q_new[slow] - ring[(t[slow] + 1 - W) % (W + 1), slots[slow]]).max(axis=1)
            path = moves[:, slots[slow]].sum(axis=0)
            stalled[slow] = (net < STALL_NET * path) | (path < 1e-12)
        finished = done | (moved < 1e-14) | stalled | (t + 1 >= options.max_iterations)
        target[slots[finished]] = -1
    pos_err, rot_err = np.empty(N), np.empty(N)
    for s in range(0, N, BLOCK):  # the errors at the end, in blocks: no (N, 3, 3) arrays
        b = slice(s, s + BLOCK)
        R, p, _, _ = chain.evaluate(q[b], tool)
        pos_err[b] = np.linalg.norm(positions[b] - p, axis=1)
        rot_err[b] = np.linalg.norm(rotation_log(rotations[b] @ np.swapaxes(R, 1, 2)), axis=1)
    reached = (pos_err <= options.position_tolerance) & (
        ~np.asarray(required, bool) | (rot_err <= options.orientation_tolerance))
    span = np.maximum(np.where(np.isfinite(upper - lower), upper - lower, 1.0), 1e-12)
    at_limit = ((q - lower <= 1e-9 * span) | (upper - q <= 1e-9 * span)) & moving
    return IkSolution(q, pos_err, rot_err, reached, at_limit, iterations,
                      _singular(chain, tool, q, ~reached, np.asarray(required, bool), moving))


def _singular(chain, tool, q, rows, required, moving) -> np.ndarray:
    """(N,) whether each of ``rows`` ends where the task's Jacobian (the free joints'
    columns: the tool point's rows, and the orientation's where required, scaled to the
    position's) has a smallest singular value under :data:`SINGULAR` times its largest:
    the tool cannot move along some direction there (a stretched or folded arm, aligned
    wrist axes)."""
    out = np.zeros(len(q), bool)
    todo = np.flatnonzero(rows)
    for s in range(0, len(todo), BLOCK):
        k = todo[s:s + BLOCK]
        _, _, Jp, Jo = chain.evaluate(q[k], tool)
        Jp, Jo = Jp[:, :, moving], Jo[:, :, moving]
        if Jp.shape[2] == 0:
            continue
        scale = np.linalg.norm(Jp, axis=(1, 2)) / np.maximum(
            np.linalg.norm(Jo, axis=(1, 2)), 1e-300)
        J = np.concatenate([Jp, Jo * (scale * required[k])[:, None, None]], axis=1)
        sv = np.linalg.svd(J, compute_uv=False)  # (K, min(6, n)), largest first
        task = np.minimum(np.where(required[k], 6, 3), Jp.shape[2])  # directions it needs
        out[k] = sv[np.arange(len(k)), task - 1] < SINGULAR * sv[:, 0]
    return out
