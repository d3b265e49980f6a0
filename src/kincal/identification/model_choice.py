"""The model chooses itself (``model="auto"``): candidate structures compared out of sample.

The candidates are the error models that can describe the chain (complete, placement,
offsets, mdh) and, where the samples carry approach directions (every set a point or pose
set, :data:`BACKLASH_KINDS`; the order of the rows or an order column), a backlash term per
joint added by forward selection (none when backlash joints are given: those are the
user's, in every candidate), and, where the URDF has inertials, a compliance term per joint
that carries a gravity torque (:mod:`kincal.models.compliance`), in the same forward
selection (none when compliance joints are given). Each is scored by its K-fold
cross-validated prediction error on **the folds
the penalty choice already makes** (same seed, same pose groups, same subsample): the
chain's default structure is cross-validated as any ``lam="cv"`` run does, and every
candidate is then fitted on those folds at that lambda and at 1/3x and 3x it (its own
best of the three counts: a bigger model may want another pull).

Why CV and not the evidence: CV judges the prediction error the user cares about and is
robust to errors no candidate carries (compliance, the rest of the backlash), which the
evidence's Gaussian noise model reads as noise; on data from a small measurement volume,
or without measured positions, where the penalty is chosen by the evidence because CV
judges only interpolation there, no out-of-sample comparison is trusted and the chain's
default structure is kept (the table says so).

The guard against choosing on noise. Another error model replaces the current best only
when its mean validation error is lower by more than ``GUARD`` standard errors of the
paired differences of the validation errors per pose (paired: every candidate predicts the
same held-out poses from the same folds; per pose, not per fold: five fold means give a
standard error with 4 degrees of freedom), so the default stays unless the data tell
otherwise. A joint term is nested in the current best (the same structure plus one
column), so it has a test with a stated false-positive rate: the score test at the best's
fit, an F test of the term's column with what the fit already absorbs projected out
(:func:`kincal.identification.diagnosis.nested_p`), its p-value times the number of terms
the step could add (Bonferroni) below ``ALPHA`` (0.001, the residual diagnosis's level:
at 0.01, simulated EC66 noise alone, seed 11, gave a compliance term p = 0.006 and a CV
gain of 3 %). Under the null (no term missing,
Gaussian noise) a forward selection adds a term with probability at most ``ALPHA``, as the
first step must reject. The CV guard was the weaker test for a term: on simulated EC66
data a planted 0.1 deg backlash of the last joint (F = 56 and 42, p ~ 1e-10) won only
2.7 and 2.8 standard errors of the paired scatter, where a per-pose difference of
Euclidean errors carries most of the noise of both fits. The term must also predict
better out of sample, by more than ``MIN_GAIN`` of the best's mean validation error: the
test reads errors no candidate carries as noise (on real data the residuals are not
i.i.d.), which CV does not; and a term whose column nearly repeats others' can win a
consistent 0.001 mm (on simulated EC66 data, a compliance term beside a planted
backlash), significant but not worth a term.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import KincalError, KincalWarning
from kincal.identification.diagnosis import ALPHA
from kincal.models import MODELS

if TYPE_CHECKING:
    from kincal.identification.options import CalibrationOptions

GUARD = 3.0  # standard errors of the paired validation differences another model must win by
MIN_GAIN = 0.01  # a joint term's CV gain, a fraction of the best's mean validation error
# ALPHA (imported): the family-wise false-positive rate of a joint term (score test,
# Bonferroni), the residual diagnosis's, so a term the diagnosis would name may be added
LAMBDA_STEPS = (1 / 3, 1.0, 3.0)  # each candidate's lambdas, times the default's CV lambda
# kinds whose samples see a joint's play directly (the tool point or the tool pose at the
# joint's effective value; a pose's orientation rows turn with it too): forward selection
# tries backlash terms on their sets. Distances and plane contacts see it only through one
# scalar per sample and keep the chain's default structure.
BACKLASH_KINDS = ("point", "pose")
MAX_TERMS = 3  # joint terms (backlash, compliance) forward selection may add
SCREEN = 3  # joint terms CV-scored per forward step: the strongest significant ones


def label(model: str, backlash, compliance=()) -> str:
    """"complete + backlash arm_6_joint + compliance arm_2_joint": a structure's name."""
    return (model + (" + backlash " + " ".join(backlash) if backlash else "")
            + (" + compliance " + " ".join(compliance) if compliance else ""))


@dataclass(frozen=True)
class Candidate:
    """One compared structure.

    model: error model; backlash: joints with a backlash term; free: parameters the fit
    moves (identifiable, incl. frames; None until the problem using a kept default counts
    them, :func:`counted`); fold_errors: (k,) mean validation error per fold
    [mm] at its best lambda (empty when not scored); sample_errors: its validation errors
    per pose [mm] (mean over the pose's samples), for the guard; lam: that lambda; note: why it was
    not scored, or what the guard said; chosen: the structure used; compliance: joints
    with a compliance term."""

    model: str
    backlash: tuple[str, ...]
    free: int | None
    fold_errors: np.ndarray
    lam: float
    note: str = ""
    chosen: bool = False
    sample_errors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    compliance: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        return label(self.model, self.backlash, self.compliance)

    @property
    def structure(self) -> tuple:
        return self.model, self.backlash, self.compliance

    @property
    def cv_error_mm(self) -> float:
        return float(np.mean(self.fold_errors)) if self.fold_errors.size else math.nan

    def as_dict(self) -> dict:
        return {"candidate": self.label, "model": self.model, "backlash": list(self.backlash),
                "compliance": list(self.compliance), "free_parameters": self.free,
                "cv_error_mm": None if not self.fold_errors.size else self.cv_error_mm,
                "fold_errors_mm": self.fold_errors.tolist(),
                "lambda": None if not self.fold_errors.size else self.lam,
                "note": self.note, "chosen": self.chosen}


@dataclass(frozen=True)
class ModelChoice:
    """The comparison behind ``model="auto"``: every candidate, the criterion, the choice.

    criterion: "cv" (K-fold CV prediction error, mean over folds [mm]) or "none" (the data
    cannot be compared out of sample: the default kept, ``reason`` says why)."""

    candidates: tuple[Candidate, ...]
    model: str
    backlash: tuple[str, ...]
    criterion: str
    reason: str
    folds: int
    compliance: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    step_p: tuple[float, ...] = ()  # per forward step, its strongest term's (Bonferroni) p

    def lines(self) -> list[str]:
        """The table of the summary (mm): candidate, free parameters, CV error, s.e."""
        if self.criterion != "cv":
            return [f"  model: {self.chosen_label}, kept: {self.reason}"]
        out = [f"  model: {self.chosen_label}, chosen by {self.folds}-fold CV among "
               f"{len(self.candidates)} candidates ({RULE})"]
        w = max(len(c.label) for c in self.candidates)
        out.append(f"    {'candidate':<{w}}  free  CV error [mm]    s.e.")
        for c in self.candidates:
            if c.fold_errors.size:
                se = np.std(c.fold_errors, ddof=1) / math.sqrt(c.fold_errors.size)
                err = f"{c.cv_error_mm:13.4f} {se:7.4f}"
            else:
                err = f"{'-':>13} {'':7}"
            mark = ("  <- chosen" + (f" ({c.note})" if c.note else "")) if c.chosen else (
                f"  {c.note}" if c.note else "")
            out.append(f"    {c.label:<{w}}  {c.free:>4}  {err}{mark}".rstrip())
        return out + [f"  {n}" for n in self.notes]

    @property
    def chosen_label(self) -> str:
        return label(self.model, self.backlash, self.compliance)

    def as_dict(self) -> dict:
        return {"criterion": self.criterion, "reason": self.reason, "folds": self.folds,
                "guard_standard_errors": GUARD, "guard_min_gain": MIN_GAIN,
                "term_test_alpha": ALPHA, "term_test_p_values": list(self.step_p),
                "chosen": {"model": self.model, "backlash": list(self.backlash),
                           "compliance": list(self.compliance)},
                "candidates": [c.as_dict() for c in self.candidates], "notes": list(self.notes)}


def beats(new: np.ndarray, best: np.ndarray) -> tuple[bool, str]:
    """(True, why) when validation errors ``new`` beat ``best`` (the same samples, the
    same folds) by more than GUARD standard errors of their paired differences and by more
    than MIN_GAIN of best's mean (a term whose columns nearly repeat others' can win a
    consistent but negligible 0.001 mm: significant, not worth a term)."""
    d = np.asarray(new) - np.asarray(best)
    se = float(np.std(d, ddof=1) / math.sqrt(d.size)) if d.size > 1 else math.inf
    gain = -float(np.mean(d))
    if gain > GUARD * se and gain > MIN_GAIN * float(np.mean(best)):
        return True, f"{gain:.3g} mm better, s.e. {se:.2g}"
    if gain > GUARD * se:
        return False, f"{gain:.3g} mm better, under {MIN_GAIN:.0%} of the best's error"
    return False, (f"{gain:.3g} mm better, within the scatter (s.e. {se:.2g})" if gain > 0
                   else "no better")


def counted(choice: ModelChoice | None, free_mask) -> ModelChoice | None:
    """``choice`` with the kept default's free parameters counted (``free_mask()``, the
    problem's own, called only when they are not counted yet)."""
    if choice is None or choice.criterion != "none" or choice.candidates[0].free is not None:
        return choice
    c = replace(choice.candidates[0], free=int(free_mask().sum()))
    return replace(choice, candidates=(c,) + choice.candidates[1:])


RULE = (f"another model must beat the best by more than {GUARD:g} s.e. of the paired "
        f"per-pose differences; a joint term must pass the score test at family-wise "
        f"{ALPHA:g} and gain {MIN_GAIN:.0%} of the error")


def adds(new: np.ndarray, best: np.ndarray, p: float) -> tuple[bool, str]:
    """(True, why) when a joint term whose score test gave the (Bonferroni) p-value ``p``
    is significant (p < ALPHA) and its validation errors ``new`` beat ``best`` (the same
    poses, the same folds) by more than MIN_GAIN of best's mean."""
    gain = float(np.mean(best)) - float(np.mean(new))
    if p >= ALPHA:
        return False, f"p = {p:.2g}, not significant at {ALPHA:g}"
    if gain > MIN_GAIN * float(np.mean(best)):
        return True, f"{gain:.3g} mm better, p = {p:.2g}"
    return False, (f"{gain:.3g} mm better (p = {p:.2g}), under {MIN_GAIN:.0%} of the best's "
                   "error" if gain > 0 else f"no better out of sample (p = {p:.2g})")


def resolve(problem_class, robots, sets, options: CalibrationOptions
            ) -> tuple[ModelChoice | None, CalibrationOptions]:
    """(None, options) unless options.model is "auto"; then :func:`choose`."""
    if options.model != "auto":
        return None, options
    return choose(problem_class, robots, sets, options)


def choose(CalibrationProblem, robots, sets, options: CalibrationOptions
           ) -> tuple[ModelChoice, CalibrationOptions]:
    """(the comparison, options with the chosen ``model`` and ``backlash``) for options
    whose model is "auto". CalibrationProblem: the problem class (passed in, so this module
    does not import the one that calls it); ``options``: validated CalibrationOptions; the
    user's own ``backlash`` joints stay in every candidate."""
    from kincal.identification import penalty_choice

    o = options

    def problem(model, backlash, compliance=o.compliance, **grid):
        with warnings.catch_warnings():  # the chosen problem gives them, once
            warnings.simplefilter("ignore", KincalWarning)
            return CalibrationProblem(robots, sets, replace(o, model=model, backlash=backlash,
                                                            compliance=compliance, **grid))

    k = o.fold_count

    def keep(default, reason):
        # its free parameters are counted by the problem that uses it (:func:`counted`):
        # analysing a problem here only to count them would double a large fit's analysis
        c = Candidate(default, tuple(o.backlash), None, np.zeros(0), math.nan, chosen=True,
                      compliance=tuple(o.compliance))
        return (ModelChoice((c,), default, tuple(o.backlash), "none", reason, k,
                            tuple(o.compliance)), replace(o, model=default))

    if o.prior is not None:  # a fleet prior covers its own model's parameters, no other's
        return keep(o.prior.model, f"the fleet prior's model (--prior): its {len(o.prior.names)} "
                    "parameters are those the prior covers")
    if o.method != "l2":  # the chain's default model: no problem needs building to know it
        from kincal.identification.chains import Chains

        return keep(Chains(robots, len(sets)).model_name,
                    f"method {o.method}: no penalty chosen by CV to compare the candidates "
                    "with; the chain's default")
    base = problem(None, o.backlash)
    default = base.model_name
    how = o.lam
    why = f"lambda {how:g} given" if isinstance(how, (int, float)) else f"lambda {how} given"
    if how == "auto":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", KincalWarning)
            how, auto_why = penalty_choice.automatic(base)
        why = f"lambda auto chose {how}: {auto_why}"
    if how != "cv":
        return keep(default, f"the penalty is not chosen by cross-validation ({why}); nothing "
                    "judges the candidates out of sample: the chain's default")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        cv0 = base.cross_validate()
    lam0, folds = cv0.best_lambda, cv0.folds

    def score(model, backlash, compliance=tuple(o.compliance)) -> Candidate:
        try:
            p = problem(model, backlash, compliance, progress=None)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", KincalWarning)
                free = p.free_mask()
                return replace(_fold_scores(p, free, folds, lam0, model, backlash),
                               compliance=compliance)
        except KincalError as e:  # a model that cannot describe this chain
            return Candidate(model, backlash, 0, np.zeros(0), math.nan,
                             "not applicable: " + str(e).split(";")[0][:70],
                             compliance=compliance)

    scored = [score(default, tuple(o.backlash))]
    best = scored[0]
    models = [m for m in MODELS if m != default]
    if o.fix or o.free:  # parameter names belong to one model
        models = []
    for m in models:
        c = score(m, tuple(o.backlash))
        if c.fold_errors.size:
            win, why = beats(c.sample_errors, best.sample_errors)
            c = replace(c, note=why)
            if win and (best is scored[0] or c.cv_error_mm < best.cv_error_mm):
                best = c
        scored.append(c)
    joints = [] if o.backlash else _backlash_joints(base, o.backlash)  # given: the user's
    soft, notes = (([], ()) if o.compliance else compliance_joints(base))
    order = base.robot.joint_names.index

    def grown(c, term, j):
        b = tuple(sorted(c.backlash + (j,), key=order)) if term == "b" else c.backlash
        s = tuple(sorted(c.compliance + (j,), key=order)) if term == "c" else c.compliance
        return score(c.model, b, s)

    def with_terms(c, pool):
        b = tuple(sorted(set(c.backlash) | {j for t, j in pool if t == "b"}, key=order))
        s = tuple(sorted(set(c.compliance) | {j for t, j in pool if t == "c"}, key=order))
        return problem(c.model, b, s, progress=None)

    used, screened = np.sort(np.concatenate(folds)), 0
    step_p: tuple[float, ...] = ()
    for _ in range(MAX_TERMS):
        pool = ([("b", j) for j in joints if j not in best.backlash]
                + [("c", j) for j in soft if j not in best.compliance])
        if not pool:
            break
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", KincalWarning)
            tests = _score_test(problem(best.model, best.backlash, best.compliance,
                                        progress=None), with_terms(best, pool), pool, used,
                                best.lam)
        step_p += (tests[0][2],)
        significant = [(t, j, pv) for t, j, pv in tests if pv < ALPHA]
        strong = significant[:SCREEN]
        screened += len(significant) - len(strong)  # significant, left out of the scoring
        if not strong:
            t, j, pv = tests[0]
            nb = sum(t == "b" for t, _ in pool)
            notes += (f"no further joint term significant at {ALPHA:g}: the strongest of "
                      f"{len(pool)} ({nb} backlash, {len(pool) - nb} compliance), "
                      f"{'backlash' if t == 'b' else 'compliance'} {j}, has p = {pv:.2g} "
                      "(Bonferroni)",)
            break
        step = [(c, pv) for c, pv in ((grown(best, t, j), pv) for t, j, pv in strong)
                if c.fold_errors.size]
        if not step:
            break
        top, p_top = min(step, key=lambda cp: cp[0].cv_error_mm)
        for c, pv in step:
            scored.append(replace(c, note=adds(c.sample_errors, best.sample_errors, pv)[1]))
        if not adds(top.sample_errors, best.sample_errors, p_top)[0]:
            break
        best = top
    if screened:
        notes += (f"{screened} significant joint-term candidates not CV-scored: each step scores "
                  f"at most the {SCREEN} strongest the score test at the current best's fit "
                  f"finds significant",)
    table = tuple(replace(c, chosen=c.structure == best.structure) for c in scored)
    reason = f"{k}-fold CV prediction error on the penalty's folds; {RULE}"
    return (ModelChoice(table, best.model, best.backlash, "cv", reason, k, best.compliance,
                        notes, step_p),
            replace(o, model=best.model, backlash=best.backlash, compliance=best.compliance))


def _score_test(p, wide, pool, used, lam) -> list:
    """[("b" or "c", joint, p-value)] for every term of ``pool``, strongest first: how much
    the term would lower the residual of ``p`` (the current best structure, fitted at
    ``lam`` on the samples ``used``) to first order, as an F test (a score test): the
    term's column of ``wide`` (p with every pool term), with what p's free parameters can
    absorb projected out, against the residual; the p-value times len(pool) (Bonferroni)."""
    from kincal.identification.cross_validation import fold_fitter
    from kincal.identification.diagnosis import nested_p

    free = p.free_mask()
    x = fold_fitter(p, free)(used, lam, None).u * p.scale
    xw = wide.x_nominal
    xw[[wide.layout.index(n) for n in p.layout.names]] = x
    r, J = wide.residual_function(used)(xw / wide.scale, True)
    U, sv, _ = np.linalg.svd(J[:, [wide.layout.index(n)
                                   for n in np.array(p.layout.names)[free]]],
                             full_matrices=False)
    U = U[:, sv > 1e-9 * sv[0]]
    r = r - U @ (U.T @ r)  # the linearised least-squares residual of p's free parameters
    rss, dof = float(r @ r), r.size - U.shape[1] - 1
    out = []
    for t, j in pool:
        col = J[:, wide.layout.index(f"{j}.{'backlash' if t == 'b' else 'compliance'}")]
        v = col - U @ (U.T @ col)
        vv = float(v @ v)
        gain = float(v @ r) ** 2 / vv if vv > 1e-12 * float(col @ col) else 0.0
        out.append((gain, t, j, nested_p(gain, rss - gain, dof, 1, len(pool))))
    return [(t, j, pv) for _, t, j, pv in sorted(out, key=lambda o: -o[0])]


def _fold_scores(p, free, folds, lam0, model, backlash) -> Candidate:
    """Candidate ``p`` fitted on the folds at each of LAMBDA_STEPS x lam0 (largest first,
    each from the previous one); its best lambda's validation errors per sample [mm]."""
    from kincal.identification.cross_validation import fold_fitter

    used = np.sort(np.concatenate(folds))
    fit = fold_fitter(p, free)
    lams = sorted((lam0 * s for s in LAMBDA_STEPS), reverse=True)
    errors = np.empty((len(lams), used.size))
    weighted = len(p.kinds) > 1
    for val in folds:
        train, start = np.setdiff1d(used, val), None
        at = np.searchsorted(used, val)
        for m, lam in enumerate(lams):
            start = fit(train, lam, start)
            e = p.sample_errors(start.u * p.scale, val, weighted)
            errors[m, at] = np.concatenate([v for _, v in e]) * 1e3
    best = int(np.argmin(errors.mean(axis=1)))
    fold = np.array([errors[best, np.searchsorted(used, f)].mean() for f in folds])
    # paired per pose: the points of one pose share its joint values, and its fold's fit
    groups = np.concatenate([km.data.poses + 10 ** 9 * i for i, km in enumerate(p.kinds)])
    _, pose = np.unique(groups[used], return_inverse=True)
    per_pose = np.bincount(pose, errors[best]) / np.bincount(pose)
    return Candidate(model, backlash, int(free.sum()), fold, float(lams[best]),
                     sample_errors=per_pose)


def _backlash_joints(problem, given) -> list[str]:
    """The chain joints a backlash term may be tried on: every set of a kind in
    BACKLASH_KINDS (the approach directions are the samples'), approached from both sides
    in every set."""
    if any(km.kind not in BACKLASH_KINDS for km in problem.kinds) or problem.chains.several:
        return []
    out = []
    for j, name in enumerate(problem.robot.joint_names):
        if name in given:
            continue
        if all(np.any(km.data.approach[:, j] > 0) and np.any(km.data.approach[:, j] < 0)
               for km in problem.kinds):
            out.append(name)
    return out


def compliance_joints(problem) -> tuple[list[str], tuple[str, ...]]:
    """(the chain joints a compliance term may be tried on: revolute, carrying an RMS
    gravity torque above MIN_TORQUE over the samples, :func:`kincal.models.compliance.loaded`;
    notes): one chain only; where the
    URDF has no inertials, none, and a note says so."""
    from kincal.models.compliance import loaded

    if problem.chains.several:
        return [], ()
    names, kinds = problem.robot.joint_names, problem.robot.geometry.kinds
    tau = np.concatenate([problem.robot.gravity_torques(km.data.joint_values)
                          for km in problem.kinds])
    if not np.any(tau):
        return [], ("compliance terms unavailable: the URDF has no inertials (masses) to "
                    "compute the gravity torques from",)
    return [j for j, ok in zip(names, loaded(kinds, tau)) if ok], ()
