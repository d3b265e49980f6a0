"""k-fold cross-validation of the L2 weight lambda (Algorithm 1 of the paper).

Plain numpy. The poses are split into k folds by a seeded permutation (the samples of one
pose, several measured points, always stay together); for each
candidate lambda and fold, the parameters are fitted on the other folds and the mean
Euclidean position error on the held-out fold is recorded. The lambda with the lowest
mean over folds wins.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from kincal.errors import OptionError
from kincal.identification.layout import MM


@dataclass(frozen=True)
class CrossValidation:
    """The CV curve.

    lambdas: (M,) candidates, ascending. fold_errors: (M, k) mean validation position
    error per candidate and fold [mm]. mean_error: (M,) their mean [mm].
    best_index, best_lambda: the minimiser. folds: sample indices of each fold.
    subsample: (poses used, poses in the data) when the CV ran on a random subsample of
        the poses (CalibrationOptions.cv_max_poses), else None.
    """

    lambdas: np.ndarray
    fold_errors: np.ndarray
    mean_error: np.ndarray
    best_index: int
    best_lambda: float
    folds: tuple[np.ndarray, ...]
    seed: int
    subsample: tuple[int, int] | None = None

    def as_dict(self) -> dict:
        return {"lambdas": self.lambdas.tolist(), "mean_error_mm": self.mean_error.tolist(),
                "fold_errors_mm": self.fold_errors.tolist(), "best_lambda": self.best_lambda,
                "best_index": self.best_index, "seed": self.seed,
                "folds": [f.tolist() for f in self.folds],
                "subsample_poses": None if self.subsample is None else list(self.subsample)}


def lambda_grid(lo: float = 1e-6, hi: float = 1e3, count: int = 50) -> np.ndarray:
    """``count`` candidates log-spaced from ``lo`` to ``hi`` (the paper's default)."""
    check_grid(lo, hi, count)
    return np.logspace(np.log10(lo), np.log10(hi), int(count))


def check_grid(lo: float, hi: float, count: int) -> None:
    """OptionError unless :func:`lambda_grid` can make this grid (options are checked
    without making it: most fits never use it)."""
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
        raise OptionError(f"lambda grid needs 0 < min < max, got min={lo:g}, max={hi:g}")
    if not 2 <= int(count) <= 10000:
        raise OptionError(f"lambda grid needs 2 to 10000 candidates, got {count}")


def check_fold_count(n_poses: int, k: int) -> None:
    """Raises OptionError unless k folds can split n_poses poses (2 <= k <= n_poses)."""
    if not 2 <= k <= n_poses:
        raise OptionError(f"cross-validation needs 2 <= folds <= number of poses "
                          f"({n_poses}), got folds={k}" + (
                              f" (--folds {n_poses} or fewer, or --lambda evidence)"
                              if n_poses >= 2 and k > n_poses else ""))


def make_folds(n_samples: int, k: int, seed: int, groups=None,
               strata=None) -> tuple[np.ndarray, ...]:
    """k folds of a seeded permutation of range(n_samples) (sorted within each fold).

    groups: (n_samples,) pose of each sample; the poses are permuted and split, so a pose's
    samples share a fold. None: every sample its own pose.
    strata: (n_samples,) measurement set of each sample: each set's poses are split into
    the k folds on their own, so every fold holds a share of every set. None: one set.
    """
    if strata is not None:
        strata = np.asarray(strata)
        groups = np.arange(n_samples) if groups is None else np.asarray(groups)
        parts = []
        for j, s in enumerate(np.unique(strata)):
            idx = np.flatnonzero(strata == s)
            parts.append([idx[f] for f in make_folds(len(idx), k, seed + j, groups[idx])])
        return tuple(np.sort(np.concatenate([p[f] for p in parts])) for f in range(k))
    groups = np.arange(n_samples) if groups is None else np.asarray(groups)
    poses, inverse = np.unique(groups, return_inverse=True)
    check_fold_count(len(poses), k)
    perm = np.random.default_rng(seed).permutation(len(poses))
    return tuple(np.flatnonzero(np.isin(inverse, f)) for f in np.array_split(perm, k))


def remembering(residual: Callable, keep: int = 2) -> Callable:
    """``residual`` remembering its last ``keep`` linearisations (r and J at u): a warm
    start begins where the previous fit ended, at the same u, so its first linearisation
    is the previous fit's last one, not evaluated again (the same numbers), and so is the
    solver's QR triangle of it (``factor(J, columns, make)``). The attributes of the
    streamed path (``blocks``, ``rows``, ``n_blocks``) are passed on."""
    seen: list = []  # (bytes of u, (r, J), {free columns: triangle of [J_free | -r]})

    def recall(u):
        """The remembered (r, J) at u (the same bits), or None."""
        key = np.asarray(u, dtype=float).tobytes()
        for v, out, _ in seen:
            if v == key:
                return out
        return None

    def keep_(u, out):
        seen.insert(0, (np.asarray(u, dtype=float).tobytes(), out, {}))
        del seen[keep:]

    def remembered(u, with_jacobian):
        if with_jacobian:
            out = recall(u)
            if out is not None:
                return out
        out = residual(u, with_jacobian)
        if with_jacobian:
            keep_(u, out)
        return out

    def factor(J, columns, make):
        """The solver's triangle of a remembered J (made by ``make`` once)."""
        for _, out, triangles in seen:
            if out[1] is J:
                key = columns.tobytes()
                if key not in triangles:
                    triangles[key] = make()
                return triangles[key]
        return make()

    setattr(remembered, "factor", factor)  # the solver looks for it (solver._data_triangle)
    setattr(remembered, "recall", recall)  # the folds evaluated together (fold_fitter)
    setattr(remembered, "keep", keep_)
    for name in ("blocks", "rows", "n_blocks"):
        if hasattr(residual, name):
            setattr(remembered, name, getattr(residual, name))
    return remembered


def fold_fitter(problem, free: np.ndarray, samples: np.ndarray | None = None) -> Callable:
    """``fit(train, lam, start)`` for :func:`cross_validate` on a calibration ``problem``
    (anything with ``options``, ``scale``, ``residual_function(rows)`` and ``fit``): each
    fold's training residual is built once and reused along the lambda path, and a warm
    start begins exactly at the previous solution (in the solver's units), whose
    linearisation is remembered (:func:`remembering`); fold fits use the looser
    ``cv_step_tol`` and show no progress. samples: the problem's rows the fold indices
    refer to (a subsample), or None for all."""
    o = problem.options
    options = replace(o.solver, step_tol=max(o.solver.step_tol, o.cv_step_tol), progress=None)
    cache: dict[bytes, Callable] = {}

    def fit(train, lam, start):
        train = train if samples is None else samples[train]
        key = train.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = remembering(problem.residual_function(train))
        return problem.fit(lam, train, free=free, residual=cache[key], options=options,
                           start_u=None if start is None else start.u)

    if together_possible(problem, samples):
        setattr(fit, "together", _together(problem, free, samples, options))
    return fit


def validation_error(problem, samples: np.ndarray) -> Callable:
    """``error(solution, val)`` for :func:`cross_validate` on a calibration ``problem``: the
    mean sample error [mm] (weighted by the sets' sigmas with several) on the rows
    ``samples[val]``; with ``together(solutions, vals)``, the folds' errors in one pass
    (one parameter vector per row) where :func:`together_possible`."""
    weighted = len(problem.kinds) > 1

    def error(sol, val):
        e = problem.sample_errors(sol.u * problem.scale, samples[val], weighted)
        return float(np.mean(np.concatenate([v for _, v in e])) / MM)

    def together(sols, vals):
        rows = [samples[v] for v in vals]
        X = np.repeat(np.stack([s.u * problem.scale for s in sols]), [len(r) for r in rows],
                      axis=0)
        e = np.concatenate([v for _, v in problem.sample_errors(X, np.concatenate(rows))])
        edges = np.cumsum([0] + [len(r) for r in rows])
        return [float(np.mean(e[a:b]) / MM) for a, b in zip(edges[:-1], edges[1:])]

    if together_possible(problem, samples):
        setattr(error, "together", together)
    return error


def together_possible(problem, samples: np.ndarray | None) -> bool:
    """Whether the folds' fits on the rows ``samples`` can be evaluated together
    (:func:`_together`): one set of measured points on an MD-H-family chain (whose
    evaluation takes one parameter vector per pose), without joint terms, and few enough
    samples that no fold's rows are streamed in blocks (the solver's dense path). samples:
    the problem's rows (None: all)."""
    kinds = problem.kinds
    return (len(kinds) == 1 and getattr(kinds[0], "kind", "") == "point"
            and problem.layout.n_terms == 0 and hasattr(kinds[0].error_model, "unpack")
            and getattr(problem.residual_function(samples), "n_blocks", 1) == 1)


def _together(problem, free: np.ndarray, samples: np.ndarray | None, options) -> Callable:
    """``together(trains, lams, warm_start, finished) -> solutions[m][f]``: the k folds'
    paths along the lambdas ``lams`` (in the order given) run side by side, each fold's fit
    its own solver (:func:`kincal.identification.solver.steps`, the same iterations and
    arithmetic as one at a time), warm-started from that fold's previous fit; at each step
    the linearisations every fold waits for are evaluated in one vectorised pass over their
    training rows, one parameter vector per row, instead of one pass per fold: the per-call
    overhead of the evaluation (about 200 numpy calls, most of a 60-pose fold fit's time) is
    paid once per step. A fold goes on to its next lambda as soon as its fit ends, without
    waiting for the others, so the passes are as many as the longest fold's path needs,
    not the sum over lambdas of the slowest fold's. The pass gives each row what the fold's
    own pass gives it (the rows do not mix). Each fold remembers its linearisations as
    :func:`remembering` does. finished(): called after each fold fit."""
    folds: dict[bytes, Callable] = {}  # training rows: the fold's remembering residual
    joint: dict[bytes, Callable] = {}  # the rows of several folds: their residual

    def rows_of(train):
        return train if samples is None else samples[train]

    def evaluate(trains, us):
        rows = [rows_of(t) for t in trains]
        allrows = np.concatenate(rows)
        key = allrows.tobytes()
        if key not in joint:
            joint[key] = problem.residual_function(allrows)
        U = np.repeat(np.stack(us), [len(r) for r in rows], axis=0)
        r, J = joint[key](U, True)
        out, at = [], 0
        for part in rows:
            n = part.size * (r.size // allrows.size)
            out.append((r[at:at + n], J[at:at + n]))
            at += n
        return out

    def together(trains, lams, warm_start=True, finished=None):
        k = len(trains)
        sols: list[list] = [[None] * k for _ in lams]
        at = [0] * k  # each fold's place on the lambda path
        rems = []
        for train in trains:
            key = rows_of(train).tobytes()
            if key not in folds:
                folds[key] = remembering(problem.residual_function(rows_of(train)))
            rems.append(folds[key])  # not streamed (together_possible): the solver yields

        def start(f):
            """Fold f's fit at its next lambda, as a generator, and its first point."""
            m = at[f]
            before = sols[m - 1][f] if m and warm_start else None
            run = problem.fit(lams[m], rows_of(trains[f]), free=free, residual=rems[f],
                              options=options, start_u=None if before is None else before.u,
                              driven=True)
            return run, next(run)

        def advance(f, out):
            """Send fold f's linearisation; go on while the next point is remembered (a
            warm start's first) and the next fit once one ends; its next point to
            evaluate, or None at the end of its path."""
            run = runs[f]
            while True:
                try:
                    u = run.send(out)
                except StopIteration as end:
                    sols[at[f]][f] = end.value
                    at[f] += 1
                    if finished is not None:
                        finished()
                    if at[f] == len(lams):
                        return None
                    run, u = start(f)
                    runs[f] = run
                out = rems[f].recall(u)
                if out is None:
                    return u

        runs: list = [None] * k
        pending = {}
        for f in range(k):
            runs[f], u = start(f)
            out = rems[f].recall(u)
            if out is None:
                pending[f] = u
            else:
                u = advance(f, out)
                if u is not None:
                    pending[f] = u
        while pending:
            outs = evaluate([trains[f] for f in pending], list(pending.values()))
            now, pending = pending, {}
            for (f, u), out in zip(now.items(), outs):
                rems[f].keep(u, out)
                nxt = advance(f, out)
                if nxt is not None:
                    pending[f] = nxt
        return sols

    return together


def cross_validate(fit: Callable, error: Callable, n_samples: int, lambdas: np.ndarray,
                   k: int = 5, seed: int = 0, warm_start: bool = True,
                   progress: Callable | None = None, groups=None,
                   strata=None) -> CrossValidation:
    """Run the CV sweep.

    fit(train_index, lam, start) -> solution: fit on the training samples, from ``start``
        (None = the problem's own start).
    error(solution, val_index) -> mean validation position error [mm].
    warm_start: solve each fold's lambdas from the largest down, each starting from the
        previous solution (same minimiser, far fewer iterations); False starts every fit
        from the nominal parameters, as the paper writes it.
    groups: (n_samples,) pose of each sample; strata: set of each sample (see make_folds).
    When ``fit`` has ``together(trains, lams, warm_start, finished) -> solutions[m][f]``
    and ``error`` has ``together(solutions, vals) -> errors`` (:func:`fold_fitter`,
    :func:`validation_error`), the folds' paths run side by side, evaluated together.
    """
    lambdas = np.asarray(lambdas, dtype=float)
    folds = make_folds(n_samples, k, seed, groups, strata)
    errors = np.empty((lambdas.size, k))
    order = np.argsort(-lambdas)
    total, done = lambdas.size * k, 0
    together = getattr(fit, "together", None)
    errors_together = getattr(error, "together", None)
    one_by_one = together is None or errors_together is None
    if together is not None and errors_together is not None:
        # the folds side by side, each on its own path as below; the validation errors of
        # all the fits in one pass at the end
        trains = [np.setdiff1d(np.arange(n_samples), val) for val in folds]

        def finished():
            nonlocal done
            done += 1
            if progress is not None:
                progress(done, total)

        sols = together(trains, [float(lambdas[m]) for m in order], warm_start, finished)
        errors[order] = np.reshape(errors_together([s for row in sols for s in row],
                                                   list(folds) * len(order)), (len(order), k))
    for f, val in enumerate(folds if one_by_one else ()):
        train = np.setdiff1d(np.arange(n_samples), val)
        start = None
        for m in order:
            sol = fit(train, float(lambdas[m]), start)
            errors[m, f] = error(sol, val)
            start = sol if warm_start else None
            done += 1
            if progress is not None:
                progress(done, total)
    mean = errors.mean(axis=1)
    best = int(np.argmin(mean))
    return CrossValidation(lambdas, errors, mean, best, float(lambdas[best]), folds, seed)


# The guard's thresholds. CV judges prediction inside the volume the data cover; when that
# volume is a small part of the workspace and CV prefers little pull toward nominal, or
# cannot tell the candidates apart, nothing in the data tells how the fit extrapolates.
# Set from the ten R-test-like seeds of scripts/estimators.py (extent / reach 0.013, the
# tracker-like sets 0.25-0.28): the two seeds where CV extrapolated worst (4.5x and 2.7x
# the evidence estimator's held-out error) left 0.68 and 0.67 of the parameters free,
# the other eight 0.11-0.52.
SMALL_VOLUME = 0.1  # data extent / reach below this: a small measurement volume
FLAT_CURVE = 0.02  # (max - min) / min of the CV curve below this: a flat curve
LITTLE_PULL = 0.6  # the penalty leaves at least this fraction of the parameters free


def free_fraction(J: np.ndarray, penalised: np.ndarray, lam: float) -> float:
    """Effective number of free penalised parameters over their number: 1 = no pull
    toward nominal, 0 = all held at nominal. J: (m, p) Jacobian of the free parameters
    (reporting units); penalised: (p,) bool; the effective number is the trace of the
    hat matrix (J^T J + lam P)^-1 J^T J less the unpenalised parameters."""
    if not penalised.any():
        return 1.0
    JtJ = J.T @ J
    try:
        hat = np.linalg.solve(JtJ + lam * np.diag(penalised.astype(float)), JtJ)
    except np.linalg.LinAlgError:
        return 1.0
    return float((np.trace(hat) - np.sum(~penalised)) / np.sum(penalised))


def small_volume_warning(cv: CrossValidation, extent_m: float, reach_m: float,
                         free_fraction: float) -> str:
    """A warning (or "") when CV's choice cannot be trusted to extrapolate.

    extent_m: largest distance of a measured position from their centroid [m];
    reach_m: largest distance of the tool point from the robot base [m];
    free_fraction: effective number of penalised parameters the fit leaves free (trace of
    the hat matrix, frames excepted) over their number: 1 = no pull toward nominal.
    Scale-free where lambda is not: what counts as a small lambda depends on the data.
    """
    ratio = extent_m / reach_m if reach_m > 0 else 0.0
    lo, hi = float(np.min(cv.mean_error)), float(np.max(cv.mean_error))
    flat = hi - lo <= FLAT_CURVE * lo
    near_zero = free_fraction >= LITTLE_PULL or cv.best_index == 0
    if ratio >= SMALL_VOLUME or not (flat or near_zero):
        return ""
    why = []
    if near_zero:
        why.append(f"it chose lambda = {cv.best_lambda:.3g}, which leaves "
                   f"{100 * free_fraction:.0f} % of the pulled parameters free (little "
                   "pull toward nominal)")
    if flat:
        why.append(f"its curve is flat (validation error {lo:.4g} to {hi:.4g} mm over "
                   f"lambda {cv.lambdas[0]:.3g} to {cv.lambdas[-1]:.3g})")
    return (f"cross-validation: {' and '.join(why)}, on data within {extent_m * 1e3:.1f} mm "
            f"of their centre, {100 * ratio:.1f} % of the arm's reach ({reach_m * 1e3:.0f} mm): "
            "CV judges prediction inside this small volume only and cannot see how the fit "
            "extrapolates. Use --lambda evidence (priors toward nominal chosen from the "
            "data), or give the tolerances (--lambda evidence --prior-mm --prior-deg), or "
            "measure poses spread over more of the workspace or with more tool tilt")
