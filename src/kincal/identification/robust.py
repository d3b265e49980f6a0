"""Robust losses for the per-pose position error: explicit, reported, off by default.

Plain numpy. Iteratively reweighted least squares: each pose gets a weight from its
current Euclidean error e [mm] and a scale c [mm]; the fit is repeated with those
weights until they settle. Huber: w = 1 for e <= c, else c / e. Cauchy:
w = 1 / (1 + (e / c)^2). The default scale is ROBUST_SCALE times the median pose error
of the plain fit, so the loss adapts to the data's noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.measurements.checks import SIGMA_RANGE_M

LOSSES = ("huber", "cauchy")
ROBUST_SCALE = 2.5  # c = 2.5 x median pose error when no scale is given
# [m] a given scale c: a pose error's size, in the range of a stated measurement noise;
# beyond it no pose is down-weighted (the loss is plain squares), below it every pose is
SCALE_RANGE_M = SIGMA_RANGE_M


def weights(errors_mm: np.ndarray, loss: str, scale_mm: float) -> np.ndarray:
    e = np.asarray(errors_mm, dtype=float)
    if loss == "huber":
        return np.where(e <= scale_mm, 1.0, scale_mm / np.maximum(e, 1e-300))
    if loss == "cauchy":
        return 1.0 / (1.0 + (e / scale_mm) ** 2)
    raise ValueError(loss)


@dataclass(frozen=True)
class Downweighted:
    """A sample the robust loss trusted less: its file line, error [mm] and weight."""

    row: int
    error_mm: float
    weight: float


def irls(problem, sol, lam, rounds: int = 20):
    """Reweight a calibration problem's samples by its robust loss until the weights settle
    (iteratively reweighted least squares); each sample's error is its size [mm]. Returns
    (solution, the samples trusted less than 0.5 as :class:`Downweighted`, worst first)."""
    o = problem.options
    base_weights = problem.weights

    def errors(sol):
        e = problem.sample_errors(sol.u * problem.scale)
        return np.concatenate([v for _, v in e]) / 1e-3

    try:
        w = np.ones(problem.n_samples)
        for _ in range(rounds):
            e = errors(sol)
            c = o.robust_scale_mm or ROBUST_SCALE * float(np.median(e))
            w_new = weights(e, o.robust, max(c, 1e-9))
            problem.weights = base_weights * np.sqrt(w_new)  # residuals carry sqrt(weight)
            sol = problem.fit(lam, start=sol.u * problem.scale)
            done = np.max(np.abs(w_new - w)) < 1e-4
            w = w_new
            if done:
                break
    finally:
        problem.weights = base_weights
    e = errors(sol)
    rows = np.concatenate([km.data.rows for km in problem.kinds])
    low = np.flatnonzero(w < 0.5)
    return sol, tuple(Downweighted(int(rows[k]), float(e[k]), float(w[k]))
                      for k in low[np.argsort(w[low])])
