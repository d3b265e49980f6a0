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

LOSSES = ("huber", "cauchy")
ROBUST_SCALE = 2.5  # c = 2.5 x median pose error when no scale is given


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
