"""Residual diagnosis: a pattern a missing term would explain, named with its size.

After any fit (``--model`` chosen or given), the residuals of a point set are tested
against what each joint's missing term would leave: backlash (the joint off by +-b with
its approach direction), a scale error of a prismatic joint (off by k * q), a periodic
error of a revolute joint (off by c * cos q + s * sin q). Each pattern is the joint's own
motion ``dP/dq_j`` times that function of the samples, with what the fitted parameters
can already absorb projected out; the pattern with the largest F statistic is reported
when its p-value, times the number of patterns tried (Bonferroni), is below ``ALPHA``.
Plain numpy/scipy over the result's arrays; the Jacobian comes from the point model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ALPHA = 1e-3  # family-wise false-alarm rate of a reported pattern


@dataclass(frozen=True)
class Finding:
    """A pattern in the residuals. cause: "backlash", "scale" or "periodic"; size: half
    the play [deg], the scale error [%] or the amplitude [deg]; rms_mm: (now, with the
    term) sample RMS [mm]; p_value: Bonferroni-corrected."""

    joint: str
    cause: str
    size: float
    rms_mm: tuple[float, float]
    p_value: float

    def line(self) -> str:
        what = {"backlash": f"backlash of about {abs(self.size):.3g} deg half-play "
                            f"(--backlash {self.joint})",
                "scale": f"a scale error of about {self.size:+.3g} % of its travel",
                "periodic": f"a periodic error of about {self.size:.3g} deg amplitude "
                            "(once per turn)"}[self.cause]
        return (f"diagnosis: the residuals follow {self.joint}: {what}; modelled, the RMS "
                f"would go from {self.rms_mm[0]:.3g} to {self.rms_mm[1]:.3g} mm "
                f"(p = {self.p_value:.2g})")

    def as_dict(self) -> dict:
        unit = "%" if self.cause == "scale" else "deg"
        return {"joint": self.joint, "cause": self.cause, f"size_{unit}": self.size,
                "rms_now_mm": self.rms_mm[0], "rms_with_term_mm": self.rms_mm[1],
                "p_value": self.p_value}


def diagnose(result) -> Finding | None:
    """The strongest significant pattern in the first point set's residuals, or None (also
    for other kinds, several sets or chains)."""
    from scipy import stats

    from kincal.measurements.point import MeasurementModel

    if len(result.sets) != 1 or result.sets[0].kind != "point" or (
            result.chains is not None and result.chains.several):
        return None
    s = result.sets[0]
    em = result.error_model
    d = s.data.for_chain(em.joint_names)
    q, g, n = d.joint_values, d.approach, em.n
    r = np.asarray(s.residuals, float).reshape(-1)  # (3N,) measured - predicted [m]
    joints = tuple(em.joint_names)
    x = np.concatenate([result.kinematic, result.base, result.tools.ravel(), np.zeros(n)])
    _, J = MeasurementModel(em, q, np.ones_like(q), joints, d.points,
                            d.n_points).jacobian(x)
    Jq = J[:, :, -n:]  # (N, 3, n) the measured point's motion per joint [m per rad or m]
    have = [joints.index(j) for j in result.layout.backlash if j in joints]
    A = np.column_stack([J[:, :, :-n].reshape(len(r), -1)]
                        + [(Jq[:, :, j] * g[:, j:j + 1]).reshape(-1, 1) for j in have])
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    U = U[:, sv > 1e-9 * sv[0]]
    rank = U.shape[1]
    resid = r - U @ (U.T @ r)  # the fit already absorbed its own directions
    rss = float(resid @ resid)
    tests = []
    for j, name in enumerate(joints):
        prismatic = em.kinds[j] == "prismatic"
        if j not in have and np.any(g[:, j] > 0) and np.any(g[:, j] < 0):
            tests.append((name, "backlash", [g[:, j]], j))
        if prismatic:
            tests.append((name, "scale", [q[:, j]], j))
        else:
            tests.append((name, "periodic", [np.cos(q[:, j]), np.sin(q[:, j])], j))
    best = None
    m = len(r)
    for name, cause, fs, j in tests:
        C = np.column_stack([(Jq[:, :, j] * f[:, None]).reshape(-1) for f in fs])
        C = C - U @ (U.T @ C)
        if np.linalg.norm(C) <= 1e-12 * max(float(np.linalg.norm(A)), 1e-300):
            continue
        coef, *_ = np.linalg.lstsq(C, resid, rcond=None)
        gain = float(np.sum((C @ coef) ** 2))
        k, dof = len(fs), m - rank - len(fs)
        if dof <= 0 or rss - gain <= 0:
            continue
        F = (gain / k) / ((rss - gain) / dof)
        p = min(1.0, float(stats.f.sf(F, k, dof)) * len(tests))
        if p < ALPHA and (best is None or F > best[0]):
            N = len(q)
            size = (100 * coef[0] if cause == "scale" else
                    math.degrees(float(np.hypot(*coef))) if cause == "periodic"
                    else math.degrees(coef[0]))
            rms = (math.sqrt(float(r @ r) / N) * 1e3,
                   math.sqrt(max(float(r @ r) - gain, 0.0) / N) * 1e3)
            best = (F, Finding(name, cause, float(size), rms, p))
    return None if best is None else best[1]
