"""Choosing the pull toward nominal on a calibration problem: the evidence priors, and the
guard on cross-validation's choice.

The glue between :class:`~kincal.identification.calibration.CalibrationProblem` and the
plain-numpy estimators (:mod:`kincal.identification.evidence`,
:mod:`kincal.identification.cross_validation`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kincal.identification import evidence
from kincal.identification.cross_validation import (
    CrossValidation,
    free_fraction,
    small_volume_warning, SMALL_VOLUME)
from kincal.identification.solver import SolveSummary
from kincal.measurements.point import MeasurementModel

if TYPE_CHECKING:
    from kincal.identification.calibration import CalibrationProblem


def prior_classes(problem: CalibrationProblem) -> tuple[str | None, ...]:
    """(p,) prior class of every parameter (None: flat prior, frames and tools)."""
    sp = problem.space
    return tuple(evidence.prior_class(n, bool(pen)) for n, pen in zip(sp.names, sp.is_penalised))


def fit_evidence(problem: CalibrationProblem, classes=None
                 ) -> tuple[SolveSummary, evidence.EvidenceFit]:
    """Per-class priors and the noise by maximum evidence, iterated with the fit; the
    options' prior_mm / prior_deg / noise_mm are kept where given. ``problem``: a
    CalibrationProblem, or any problem with the same fit interface (several measurement
    sets) given with its ``classes``."""
    o = problem.options
    free = problem.free_mask()
    residual = problem.residual_function()
    u_prior = problem.start() / problem.scale
    given = {} if o.prior_mm is None else {"length": o.prior_mm}
    if o.prior_deg is not None:
        given.update(twist=o.prior_deg, offset=o.prior_deg)
    return evidence.estimate(
        lambda w, u: problem.fit(w, start=u * problem.scale, free=free, residual=residual),
        lambda u: residual(u, True), u_prior, u_prior, free,
        prior_classes(problem) if classes is None else classes, given, o.noise_mm)


def reach(problem: CalibrationProblem, samples: int = 500) -> float:
    """[m] largest distance of the tool point from the base frame's origin over seeded
    random joint values within the limits (joints without limits: +-pi)."""
    g = problem.robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    q = np.random.default_rng(0).uniform(lo, hi, size=(samples, g.n))
    sp = problem.space
    x = problem.start().copy()
    x[sp.n_kinematic:sp.n_kinematic + 6] = 0.0  # the measurement frame at the base frame
    model = MeasurementModel(problem.error_model, q, np.zeros_like(q), sp.backlash,
                             np.zeros(samples, dtype=int), sp.n_points)
    return float(np.max(np.linalg.norm(model.predict(x), axis=1)))


def automatic_sets(problem) -> tuple[str, str]:
    """("evidence" or "cv", why) for lambda "auto" with several measurement sets or other
    kinds: the rule of :func:`automatic` on the positions of the sets that measure
    positions (points, poses) together; CV when no set does (distances, plane contacts)."""
    from kincal.models.kinematics import ChainKinematics

    o = problem.options
    if any(v is not None for v in (o.prior_mm, o.prior_deg, o.noise_mm)):
        return "evidence", "tolerances or noise given"
    P = [km.data.positions for km in problem.kinds
         if getattr(km.data, "positions", None) is not None]
    if not P:
        return "cv", "no set measures positions, so no measurement volume to judge"
    P = np.vstack(P)
    extent = float(np.max(np.linalg.norm(P - P.mean(axis=0), axis=1)))
    g = problem.robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    q = np.random.default_rng(0).uniform(lo, hi, size=(500, g.n))
    r = float(np.max(np.linalg.norm(ChainKinematics.of(g).evaluate(q)[1], axis=1)))
    ratio = extent / r if r > 0 else 0.0
    where = (f"the measured positions span {extent * 1e3:.0f} mm from their centre, "
             f"{100 * ratio:.1f} % of the arm's reach")
    if ratio < SMALL_VOLUME:
        return "evidence", where + f" (< {100 * SMALL_VOLUME:.0f} %: a small measurement volume)"
    return "cv", where


def extent_ratio(problem: CalibrationProblem) -> tuple[float, float, float]:
    """(extent [m], reach [m], extent / reach) of the measured positions: the largest
    distance of a measured point from their centroid, against the arm's reach."""
    P = problem.data.positions[problem.data.points == 0]
    extent = float(np.max(np.linalg.norm(P - P.mean(axis=0), axis=1)))
    r = reach(problem)
    return extent, r, extent / r if r > 0 else 0.0


def automatic(problem: CalibrationProblem) -> tuple[str, str]:
    """("evidence" or "cv", why) for lambda "auto": evidence when the data cover a small
    measurement volume (CV inside it judges only interpolation and may choose almost no
    penalty), CV otherwise (it judges prediction where the robot is used, and is robust to
    errors no model carries, such as backlash)."""
    o = problem.options
    if any(v is not None for v in (o.prior_mm, o.prior_deg, o.noise_mm)):
        return "evidence", "tolerances or noise given"
    extent, r, ratio = extent_ratio(problem)
    where = (f"the data span {extent * 1e3:.0f} mm from their centre, {100 * ratio:.1f} % of "
             f"the arm's reach")
    if ratio < SMALL_VOLUME:
        return "evidence", where + f" (< {100 * SMALL_VOLUME:.0f} %: a small measurement volume)"
    return "cv", where


def cv_warning(problem: CalibrationProblem, cv: CrossValidation, sol: SolveSummary,
               lam: float) -> str:
    """The guard's warning (or "") for CV's lambda on these data: small measurement volume
    and little pull or a flat curve (see cross_validation.small_volume_warning)."""
    free = problem.free_mask()
    extent, r, _ = extent_ratio(problem)
    return small_volume_warning(cv, extent, r,
                                free_fraction(sol.jacobian[:, free],
                                              problem.space.is_penalised[free], lam))
