"""Joint backlash: the approach direction of each joint before each sample.

A joint with backlash (play in its gears) does not sit exactly where its motor encoder
says: it lags on one flank or the other of the play, depending on the direction it last
moved in. kincal models this with one coefficient b per chosen joint:

    q_effective = q_measured + b * g,   g = +1 / -1: the sign of the joint's last motion
                                        before the sample, 0 before its first motion

so b is half the play (signed: b > 0 when the joint overshoots its reading in the
direction it moved) [rad, or m for a prismatic joint], and 2 |b| is the play. The term acts
like the joint's own offset (MD-H theta, or d for a prismatic joint) with the sign g, so
it is identifiable only from samples approached from both directions.

The direction needs the order in which the samples were taken: the order of the samples
(the rows of the file) by default, or an order column such as a time stamp. A motion
smaller than ``MOVE_TOL`` keeps the previous direction (the joint stays on its flank).
"""

from __future__ import annotations

import numpy as np

from kincal.errors import DataError

MOVE_TOL = 1e-3  # [rad or m] a joint motion smaller than this does not set a direction
CONVENTION = ("q_effective = q + backlash * g, g = +1 / -1 the sign of the joint's last "
              "motion before the sample (0 before its first); radians (metres if prismatic)")


def approach_directions(joint_values: np.ndarray, order: np.ndarray | None = None,
                        tol: float = MOVE_TOL, source: str = "<memory>",
                        rows: np.ndarray | None = None) -> np.ndarray:
    """(N, n) approach direction (+1, -1, or 0 before the first motion) per sample and joint.

    joint_values: (N, n) [rad or m], one row per sample. order: (N,) keys giving the
    acquisition order (e.g. time stamps), or None when the samples are in that order.
    Equal keys make the order ambiguous and raise DataError (``rows`` names the lines).
    """
    q = np.asarray(joint_values, dtype=float)
    N = len(q)
    if order is None:
        seq = np.arange(N)
    else:
        order = np.asarray(order, dtype=float)
        if order.shape != (N,) or not np.all(np.isfinite(order)):
            raise DataError(f"{source}: the order column needs one finite number per sample")
        seq = np.argsort(order, kind="stable")
        same = np.flatnonzero(np.diff(order[seq]) == 0)
        if same.size:
            a, b = seq[same[0]], seq[same[0] + 1]
            where = (f"lines {rows[a]} and {rows[b]}" if rows is not None
                     else f"samples {a + 1} and {b + 1}")
            raise DataError(f"{source}: {where} have the same order value {order[a]!r}; the "
                            "approach directions need a strict acquisition order")
    # each sample (in acquisition order) takes the sign of the last step larger than tol
    # at or before it: a forward fill over the order, vectorised (200,000 samples: ms)
    out = np.zeros_like(q)
    if N < 2:
        return out
    step = np.diff(q[seq], axis=0)                                     # (N-1, n)
    moved = np.abs(step) > tol
    last = np.where(moved, np.arange(1, N)[:, None], 0)                # 1-based, 0: none
    last = np.maximum.accumulate(last, axis=0)
    signs = np.vstack([np.zeros((1, q.shape[1])), np.sign(step)])      # row 0: no motion
    out[seq[1:]] = np.take_along_axis(signs, last, axis=0)
    return out
