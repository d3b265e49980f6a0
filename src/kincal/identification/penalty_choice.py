"""Choosing the pull toward nominal on a calibration problem: the automatic rule, the
evidence priors, and the guard on cross-validation's choice.

The glue between :class:`~kincal.identification.problem.CalibrationProblem` and the
plain-numpy estimators (:mod:`kincal.identification.evidence`,
:mod:`kincal.identification.cross_validation`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import IdentifiabilityError, KincalWarning, OptionError
from kincal.identification import evidence
from kincal.identification.cross_validation import (SMALL_VOLUME, CrossValidation,
                                                    check_fold_count, free_fraction,
                                                    small_volume_warning)
from kincal.identification.layout import MM
from kincal.identification.selection import no_spare_note
from kincal.identification.solver import SolveSummary
from kincal.models.chain import Chain

if TYPE_CHECKING:
    from kincal.identification.problem import CalibrationProblem


def prior_classes(problem: CalibrationProblem) -> tuple[str | None, ...]:
    """(p,) prior class of every parameter (None: flat prior, the sets' frames): the error
    model's class (a joint's zero is an "offset" whatever the model calls it), with a
    prismatic joint's zero, a length, among the lengths (one prior scale per unit)."""
    lay = problem.layout
    fleet = problem.prior.covered if problem.prior is not None else np.zeros(lay.size, bool)
    return tuple("fleet" if f else None if not pen else
                 "length" if (c == "offset" and is_len) else
                 c if c in evidence.CLASSES else evidence.prior_class(n)
                 for n, c, pen, is_len, f in zip(lay.names, lay.classes, lay.is_penalised,
                                                 lay.is_length, fleet))


def noise_groups(problem: CalibrationProblem, J: np.ndarray | None = None, counts=None):
    """The residual rows' noise groups for the evidence: (rows (m,) group of each row, per
    set (dim,) group of each of a sample's rows, [(label, unit)] per group).

    A set that states its noise (``sigma``, ``sigma_deg``, ``--set-sigma-mm``, the tilt
    sigma) keeps its rows' weights as stated: all such rows are one group, their noise one
    scale of the stated sigmas (as with one noise for all). Every other set has a group per
    kind of row (:meth:`kincal.measurements.kind.KindModel.noise_rows`: a flush touch's
    height, its tilts), labelled with the set's file. With ``noise_mm`` given, one group.

    A noise level is seen only in what no parameter can fit: with J (m, p) the Jacobian
    at the start (the free columns), a group whose rows the parameters can fit exactly
    (rank of its rows = their number: 21 flush heights against 53 parameters) has no
    residual of its own and its noise is not identified (the evidence would drive it to
    0, fitting those rows exactly). Such a group joins its set's other rows (the set's
    rows as the kind weighs them, one noise), and a set whose rows all fit exactly joins
    the one group of every such row. counts: samples of each set in J's rows (a
    subsample's; default every sample); rows (m,) then follows them."""
    if J is not None and len(noise_groups(problem)[2]) == 1:
        J = None  # one group whatever the ranks (one set of one kind of row): none to check
    keys: list[tuple[str, str]] = []
    per_set = []
    counts = [km.N for km in problem.kinds] if counts is None else list(counts)
    rows_of = np.repeat(np.arange(len(problem.kinds)),
                        [n * km.dim for n, km in zip(counts, problem.kinds)])
    for i, km in enumerate(problem.kinds):
        name = str(km.data.source).replace("\\", "/").rsplit("/", 1)[-1]
        own = [(f"{name} {kind}".strip(), unit) for kind, unit, _ in km.noise_rows()]
        if problem.options.noise_mm is not None or km.noise_stated():
            own = [("stated sigmas", "mm")] * km.dim
        elif J is not None:
            mine = J[rows_of == i].reshape(counts[i], km.dim, -1)
            if len(set(own)) > 1 and not all(_has_residual(mine[:, [k for k, o in enumerate(
                    own) if o == key]].reshape(-1, J.shape[1])) for key in set(own)):
                own = [(name, "mm")] * km.dim
            if not _has_residual(mine.reshape(-1, J.shape[1])):
                own = [("rows fitted exactly", "mm")] * km.dim
        for key in own:
            if key not in keys:
                keys.append(key)
        per_set.append(np.array([keys.index(key) for key in own], dtype=np.intp))
    rows = np.concatenate([np.tile(g, n) for g, n in zip(per_set, counts)])
    return rows, per_set, keys


def _has_residual(J: np.ndarray) -> bool:
    """Whether rows J (r, p) leave a residual no combination of the columns can fit: more
    rows than their rank."""
    return J.shape[0] > np.linalg.matrix_rank(J)


def _noise_in_units(problem: CalibrationProblem, rows: np.ndarray, keys, row_noise):
    """Per group (label, sigma, unit): the group's noise in the weighted rows [mm] in its
    rows' own unit (over the median of its rows' weighted mm per unit); the stated sigmas'
    group as it is (the noise of a unit-weight sample, as noise_mm)."""
    per_unit = np.concatenate([
        (problem.weights[problem.offsets[i]:problem.offsets[i + 1], None]
         * np.column_stack([m for _, _, m in km.noise_rows()]) / MM).ravel()
        for i, km in enumerate(problem.kinds)])
    return tuple((label, float(s if unit == "mm" and label in ("stated sigmas",
                                                                "rows fitted exactly")
                               else s / np.median(per_unit[rows == g])), unit)
                 for g, ((label, unit), s) in enumerate(zip(keys, row_noise)))


INTERPOLATED = 1e-3  # estimated noise / RMS error at the start below which, with no more
#                      equations than parameters, the evidence fit is said to interpolate


def fit_evidence(problem: CalibrationProblem) -> tuple[SolveSummary, evidence.EvidenceFit]:
    """Per-class priors and the noise of each noise group (:func:`noise_groups`) by maximum
    evidence over every set's residuals (weighted by the sets' stated noise), iterated with
    the fit; the options' prior_mm / prior_deg / noise_mm are kept where given. The
    problem keeps the groups' noise levels as its ``row_scale`` (the last fit's weights)."""
    o = problem.options
    free = problem.free_mask()
    problem.row_scale = None
    residual = problem.residual_function()
    u_prior = problem.start() / problem.scale
    samples, subsample = evidence_samples(problem)
    linear = residual if samples is None else problem.residual_function(samples)
    r0, J0 = linear(u_prior, True)  # the hyperparameters' rows: every sample, or a subsample
    counts = None if samples is None else np.diff(np.searchsorted(samples, problem.offsets))
    rows, per_set, keys = noise_groups(problem, J0[:, free], counts)
    classes = prior_classes(problem)
    given = {} if o.prior_mm is None else {"length": o.prior_mm}
    if o.prior_deg is not None:
        given.update(twist=o.prior_deg, offset=o.prior_deg)
    _refuse_unused_tolerances(problem, {classes[i] for i in np.flatnonzero(free)} - {None},
                              set(classes) - {None})
    if o.prior_scale is not None:
        given["fleet"] = o.prior_scale

    def fit(w, u, row_scale):
        problem.row_scale = None if len(keys) == 1 else [row_scale[g] for g in per_set]
        return problem.fit(w, start=u * problem.scale, free=free,
                           residual=residual if len(keys) == 1 else problem.residual_function())

    sol, ev = evidence.estimate(
        fit, lambda u: linear(u, True), u_prior, u_prior, free, classes, given,
        o.noise_mm, shape=None if problem.prior is None else problem.prior.precision,
        rows=rows)
    del J0
    m, k = r0.size, int(free.sum())
    if o.noise_mm is None and m <= k and ev.noise_mm < INTERPOLATED * math.sqrt(np.mean(r0 ** 2)):
        raise IdentifiabilityError(
            f"{problem.n_poses} poses give {m} equations for {k} identifiable parameters and "
            f"the fit passes through every one (the noise estimated at {ev.noise_mm:.2g} mm): "
            "nothing is left to estimate the instrument's noise or how far to pull toward "
            "nominal. Measure more poses, or state the noise (--noise-mm) and the "
            "tolerances (--prior-mm, --prior-deg)")
    if not ev.converged:
        warnings.warn(
            f"the evidence's prior scales and noise did not settle in {ev.iterations} rounds "
            "(the fit is the last round's): the data barely tell how far to pull toward "
            "nominal; state the tolerances and noise (--prior-mm, --prior-deg, --noise-mm), "
            "or judge the result on held-out data (--validate)", KincalWarning)
    if samples is not None:  # every row's group, for their units
        rows = np.concatenate([np.tile(g, km.N) for g, km in zip(per_set, problem.kinds)])
    return sol, replace(ev, noise_groups=_noise_in_units(problem, rows, keys, ev.row_noise),
                        subsample=subsample)


EVIDENCE_MAX_POSES = 20_000  # more: the hyperparameters from a seeded subsample of them


def evidence_samples(problem: CalibrationProblem) -> tuple[np.ndarray | None,
                                                           tuple[int, int] | None]:
    """(sorted sample indices, (poses kept, poses)) of a seeded random subsample of the
    poses when a set has more than EVIDENCE_MAX_POSES (that many of each such set, the
    samples of a pose together, as the CV's subsample; every pose of a smaller set, so a
    few contacts beside a million points keep their rows and their noise), else (None,
    None). The evidence's hyperparameters (a few prior scales and noise levels, none
    growing with the data) are estimated on its rows, each linearisation a dense Jacobian
    of them (at 300,000 poses the whole one took 1.5 GB); the fit between the
    linearisations, and the final one, use every sample."""
    if all(len(np.unique(km.data.poses)) <= EVIDENCE_MAX_POSES for km in problem.kinds):
        return None, None
    rng = np.random.default_rng(problem.options.seed)
    keep = []
    for i, km in enumerate(problem.kinds):
        poses = np.unique(km.data.poses)
        if poses.size > EVIDENCE_MAX_POSES:
            poses = rng.choice(poses, EVIDENCE_MAX_POSES, replace=False)
        keep.append(problem.offsets[i] + np.flatnonzero(np.isin(km.data.poses, poses)))
    samples = np.concatenate(keep)
    groups = np.concatenate([km.data.poses + 10 ** 9 * i for i, km in enumerate(problem.kinds)])
    return samples, (len(np.unique(groups[samples])), problem.n_poses)


def _refuse_unused_tolerances(problem: CalibrationProblem, present: set, has: set) -> None:
    """A given tolerance whose classes have no free parameter in this problem would be kept
    and used nowhere: refused, naming the classes that are free here. present: the classes
    of the free (identified, not held) penalised parameters; has: of all the model's."""
    o = problem.options
    for option, value, unit, wants in (("prior_mm", o.prior_mm, "mm", ("length",)),
                                       ("prior_deg", o.prior_deg, "deg", ("twist", "offset"))):
        if value is not None and not present & set(wants):
            why = ("none of them is free here (held by --fix, or not identified by these "
                   "data)" if has & set(wants) else
                   f"error model {problem.model_name} has none on this chain")
            raise OptionError(
                f"{option} (--{option.replace('_', '-')}) {value:g} {unit} is the prior scale "
                f"of the {' and '.join(wants)} parameters, but {why}, so it would be used "
                f"nowhere (the free penalised classes: {', '.join(sorted(present)) or 'none'})"
                ": drop it" + ("" if has & set(wants) else
                               ", or choose a model that has them (--model complete)"))


def _tool_start(problem: CalibrationProblem) -> np.ndarray:
    """(3,) the first set's tool point at the start [m] (zero when its kind has none)."""
    lay = problem.layout
    names = lay.frame_names(0)
    if "tool.x" not in names:
        return np.zeros(3)
    k = [names.index("tool." + c) for c in "xyz"]  # by name: a flush set stores z, x, y
    return np.array(lay.frames(problem.start(), 0)[k], dtype=float)


def reach(problem: CalibrationProblem, samples: int = 500) -> float:
    """[m] largest distance of the tool point (the first set's, at the start) from the base
    frame's origin over seeded random joint values within the limits (joints without
    limits: +-pi)."""
    g = problem.robot.geometry
    lo, hi = g.ranges()
    q = np.random.default_rng(0).uniform(lo, hi, size=(samples, g.n))
    em = problem.kinds[0].error_model  # the first set's chain (problem.robot's)
    s = Chain(em, q).state(em.nominal, None, keep=False)
    return float(np.max(np.linalg.norm(s.p_tip + s.R_tip @ _tool_start(problem), axis=1)))


def measured_positions(problem: CalibrationProblem) -> np.ndarray | None:
    """(M, 3) the positions of every set that measures positions (point sets: the first
    measured point of each pose) [m], or None when no set does."""
    P = []
    for km in problem.kinds:
        d = km.data
        if getattr(d, "positions", None) is None:
            continue
        points = getattr(d, "points", None)
        P.append(d.positions if points is None else d.positions[points == 0])
    return np.vstack(P) if P else None


def extent_ratio(problem: CalibrationProblem) -> tuple[float, float, float]:
    """(extent [m], reach [m], extent / reach) of the measured positions: the largest
    distance of a measured point from their centroid, against the arm's reach; NaN extent
    when no set measures positions."""
    r = reach(problem)
    P = measured_positions(problem)
    if P is None:
        return math.nan, r, math.nan
    extent = float(np.max(np.linalg.norm(P - P.mean(axis=0), axis=1)))
    return extent, r, extent / r if r > 0 else 0.0


def automatic(problem: CalibrationProblem) -> tuple[str, str]:
    """("evidence" or "cv", why) for lambda "auto": evidence when the data cover a small
    measurement volume (CV inside it judges only interpolation and may choose almost no
    penalty), CV otherwise (it judges prediction where the robot is used, and is robust to
    errors no model carries, such as backlash), and evidence when no set measures
    positions: distances and contacts see only part of the motion, as a small volume does
    (on simulated EC66 flush touches on one table, CV let the fit drift along what the
    touches cannot see in 3 of 6 seeds, refused by the gate; evidence in none); and evidence
    for fewer than two poses per fold, which CV cannot split usefully (the default k; a k
    the user gave that the poses cannot meet is an error)."""
    o = problem.options
    if any(v is not None for v in (o.prior_mm, o.prior_deg, o.noise_mm)):
        return "evidence", "tolerances or noise given"
    if measured_positions(problem) is None:
        return "evidence", ("no set measures positions: distances and contacts see only part "
                            "of the motion, as a small volume does")
    if o.folds is not None:  # the user's k: an impossible one is an error, whatever is chosen
        check_fold_count(problem.n_poses, o.folds)
    elif problem.n_poses < 2 * o.fold_count:
        return "evidence", (f"{problem.n_poses} poses: too few for {o.fold_count}-fold "
                            f"cross-validation (at least {2 * o.fold_count}, two per fold)")
    extent, r, ratio = extent_ratio(problem)
    where = (f"the data span {extent * 1e3:.0f} mm from their centre, {100 * ratio:.1f} % of "
             f"the arm's reach")
    if ratio < SMALL_VOLUME:
        return "evidence", where + f" (< {100 * SMALL_VOLUME:.0f} %: a small measurement volume)"
    return "cv", where


def warn_after_fit(problem: CalibrationProblem, ident, cv: CrossValidation | None,
                   sol: SolveSummary, lam) -> None:
    """The warnings on a penalised fit: no equation left over to judge it by (whatever
    chose the penalty; ``ident`` the data's Identifiability), and CV's guard on a small
    measurement volume (:func:`cv_warning`)."""
    spare = no_spare_note(ident.equations, len(ident.kept))
    if spare:
        warnings.warn(f"{problem.n_poses} poses give {spare}", KincalWarning, stacklevel=3)
    note = cv_warning(problem, cv, sol, lam) if cv is not None else ""
    if note:
        warnings.warn(f"{problem.kinds[0].data.source}: {note}", KincalWarning, stacklevel=3)


def cv_warning(problem: CalibrationProblem, cv: CrossValidation, sol: SolveSummary,
               lam: float) -> str:
    """The guard's warning (or "") for CV's lambda on these data: small measurement volume
    and little pull or a flat curve (see cross_validation.small_volume_warning)."""
    extent, r, _ = extent_ratio(problem)
    if not math.isfinite(extent):
        return ""
    free = problem.free_mask()
    return small_volume_warning(cv, extent, r,
                                free_fraction(sol.jacobian_root(free),
                                              problem.layout.is_penalised[free], lam))
