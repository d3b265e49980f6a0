"""Gauss-Newton with Levenberg-Marquardt damping and an L2 pull toward nominal values.

Plain numpy. The problem is posed in *reporting units*: residuals in mm, parameters in
mm or degrees (u = x / scale), so that a penalty weight lambda means the same as in the
paper (whose tables use mm and degrees). The objective is

    F(u) = || w * r(u) ||^2 + lambda * || u_k - u0_k ||^2     [mm^2]

over the free parameters, where u_k are the penalised (kinematic) ones. A step is taken
only if it lowers F; otherwise the damping grows and the step is tried again.

Stopping: F grows with the number of samples, so an absolute tolerance on its change (the
paper's 1e-5 mm^2) is strict at 60 poses and out of reach at 200,000 ones, where each
iteration of a slowly converging fit still gains more than that. The default rule is
therefore relative: stop when the Gauss-Newton model predicts that a full undamped step
would lower F by less than ``rel_tol * F`` (the Gauss-Newton decrement d^T (J^T J + P) d,
computed as a sum of squares, so free of cancellation). Duplicating every sample doubles
both sides and leaves the step unchanged: the rule does not depend on N. The paper's rule
stays available (``SolverOptions(rule="paper")``) for the reproduction of its tables.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from kincal.errors import OptionError
from kincal.identification.linalg import TALL, lstsq, triangular_factor


RULES = ("relative", "paper")


@dataclass(frozen=True)
class SolverOptions:
    """Stopping rules and damping.

    rule: "relative" (default, scale-free in the number of samples): stop when the
        Gauss-Newton step would lower the objective by less than rel_tol times it, or
        when it fell by less than cost_rtol times itself over cost_window iterations;
        "paper": the paper's absolute rule, cost_tol over cost_window iterations.
        Both also stop on step_tol, when no step lowers the objective, and at
        max_iterations (not converged).
    rel_tol: [1] relative predicted decrease below which the relative rule stops.
    cost_rtol: [1] relative objective change per iteration that counts as no progress:
        the paper's 1e-5 mm^2 is 2.5e-5 to 1e-4 of the objective of a paper-sized data set
        (0.1 to 0.4 mm^2 at 30 to 60 poses, 0.05 mm noise), so an ill-conditioned fit
        crawling along a flat valley (plain LS on small-volume data, a tool point on the
        last axis) stops about where the paper's rule stops it there, and at the same
        relative progress at 200,000 poses, where the paper's rule would let it run to the
        iteration limit. A well-posed fit stops before, on rel_tol, at full precision.
    max_iterations: accepted or rejected steps at most (paper: 100).
    cost_tol: [mm^2] (rule "paper") the objective changed by less than this ...
    cost_window: ... over this many consecutive iterations (paper: 1e-5 over 5).
    step_tol: [mm or deg] largest component of an accepted step below which we stop.
    initial_damping: damping tried after a rejected Gauss-Newton step, as a multiple
        of diag(J^T J) (Marquardt scaling).
    progress: callback(iteration, max_iterations) after each iteration, or None.
    """

    rule: str = "relative"
    rel_tol: float = 1e-12
    cost_rtol: float = 1e-4
    max_iterations: int = 100
    cost_tol: float = 1e-5
    cost_window: int = 5
    step_tol: float = 1e-10
    initial_damping: float = 1e-4
    progress: Callable | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.rule not in RULES:
            raise OptionError(f"unknown stopping rule {self.rule!r}; expected one of "
                              f"{', '.join(RULES)}")
        for name in ("rel_tol", "cost_rtol", "cost_tol", "step_tol"):
            value = getattr(self, name)
            if not (isinstance(value, numbers.Real) and not isinstance(value, bool)
                    and math.isfinite(value) and value >= 0):
                raise OptionError(f"{name} must be a finite number >= 0, got {value!r}")


@dataclass(frozen=True)
class SolveSummary:
    """Outcome of one solve, with its history.

    u: parameters at the end (reporting units, all parameters, fixed ones untouched).
    cost: objective per iteration [mm^2], starting with the initial value.
    damping: damping used at each iteration (0 = plain Gauss-Newton step).
    converged: whether a stopping rule other than the iteration limit fired.
    reason: which rule stopped the solve.
    """

    u: np.ndarray
    cost: np.ndarray
    data_cost: float
    penalty: float
    damping: np.ndarray
    iterations: int
    converged: bool
    reason: str
    jacobian: np.ndarray | None = field(repr=False)  # (m, p) at the solution, reporting
    # units; None when the rows were streamed in blocks (many poses): then ``gram`` holds
    # J^T J, which is all the statistics need
    residual: np.ndarray = field(repr=False)  # (m,) at the solution [mm]
    gram: np.ndarray | None = field(default=None, repr=False)  # (p, p) J^T J, streamed fits

    def normal_matrix(self, free: np.ndarray) -> np.ndarray:
        """(k, k) J^T J of the columns ``free`` (mask or indices) at the solution."""
        if self.jacobian is None:
            idx = np.flatnonzero(free) if np.asarray(free).dtype == bool else np.asarray(free)
            assert self.gram is not None  # a streamed fit carries J^T J
            return self.gram[np.ix_(idx, idx)]
        J = self.jacobian[:, free]
        return J.T @ J

    def jacobian_root(self, free: np.ndarray) -> np.ndarray:
        """A matrix B with B^T B = J^T J over the columns ``free``: the Jacobian's columns
        themselves, or (streamed fits) a square root of the Gram matrix."""
        if self.jacobian is not None:
            return self.jacobian[:, free]
        w, V = np.linalg.eigh(self.normal_matrix(free))
        return np.sqrt(np.maximum(w, 0.0))[:, None] * V.T


def _data_triangle(residual: Callable, r: np.ndarray, J: np.ndarray,
                   free_idx: np.ndarray) -> np.ndarray:
    """The triangle of [J_free | -r] (:func:`triangular_factor`), or the one a residual that
    remembers its linearisations (``factor``, kincal.identification.cross_validation.
    remembering) kept for this J: a warm start's first iteration factors the matrix the
    previous fit's last iteration did."""
    def make():
        m, n = len(r), free_idx.size + 1  # QR's in Fortran order: factored in place
        A = np.empty((m, n), order="F" if m <= TALL * n else "C")
        A[:, :-1] = J[:, free_idx]
        np.negative(r, out=A[:, -1])
        return triangular_factor(A, overwrite=True)

    kept = getattr(residual, "factor", None)
    return make() if kept is None else kept(J, free_idx, make)


def solve(residual: Callable, u0: np.ndarray, free: np.ndarray, lam: float | np.ndarray = 0.0,
          penalised: np.ndarray | None = None, prior: np.ndarray | None = None,
          options: SolverOptions = SolverOptions()) -> SolveSummary:
    """Minimise F from ``u0`` over the parameters where ``free`` is True (:func:`steps`
    driven by ``residual``).

    residual(u, with_jacobian) -> (r (m,), J (m, p) or None): weighted residuals [mm]
        and their Jacobian with respect to u (measured minus predicted has J = -dP/du;
        either sign convention works as long as J = dr/du).
    penalised: (p,) bool, parameters pulled toward ``prior`` with weight lam.
    lam: one weight for every penalised parameter, or (p,) weights, one per parameter
        (per-class priors, kincal.identification.evidence; entries off ``penalised`` unused),
        or a (p, p) symmetric positive semidefinite matrix Lam: the penalty
        (u - prior)^T Lam (u - prior) over the penalised parameters (a fleet prior,
        kincal.identification.prior); its entries between free and fixed parameters must
        be zero (the fixed ones' offsets would otherwise pull the free ones).
    """
    run = steps(residual, u0, free, lam, penalised, prior, options)
    memo = getattr(residual, "memo", None)  # the analysis's pass at a point, if any
    try:
        u = next(run)
        while True:
            kept = memo.pop(u.tobytes(), None) if memo else None
            u = run.send(residual(u, True) if kept is None else kept)
    except StopIteration as done:
        return done.value


def steps(residual: Callable, u0: np.ndarray, free: np.ndarray, lam: float | np.ndarray = 0.0,
          penalised: np.ndarray | None = None, prior: np.ndarray | None = None,
          options: SolverOptions = SolverOptions()):
    """:func:`solve` as a generator: it yields each point u where it needs the dense
    linearisation and is sent (r, J) there; it returns the SolveSummary. Whoever drives it
    evaluates the points, so several solves can be evaluated together (the folds of
    Algorithm 1 in one vectorised pass, kincal.identification.cross_validation); a residual
    streamed in blocks (``n_blocks`` > 1) is linearised here and nothing is yielded. The
    residual's ``factor`` (a remembered triangle) is used as by :func:`solve`."""
    p = u0.size
    free_idx = np.flatnonzero(free)
    pen = np.zeros(p, dtype=bool) if penalised is None else np.asarray(penalised, dtype=bool)
    prior = u0.copy() if prior is None else np.asarray(prior, dtype=float)
    pen_f = pen[free_idx]
    # what every iteration uses, made once: the penalised entries' indices (gathers by
    # index rather than by mask: the same numbers, a fold fit's iterations are short)
    ndim, pen_idx, fp_idx = np.ndim(lam), np.flatnonzero(pen), free_idx[pen_f]
    prior_pen, prior_fp = prior[pen_idx], prior[fp_idx]
    root: np.ndarray | None = None  # the penalty's root on the free rows, if not diagonal
    if ndim == 2:  # a matrix (a fleet prior's precision)
        Lam = np.asarray(lam, dtype=float)
        w, V = np.linalg.eigh(Lam[np.ix_(fp_idx, fp_idx)])
        root = np.sqrt(np.maximum(w, 0.0))[:, None] * V.T  # root^T root = Lam_ff
        sq_f = np.ones(root.shape[0])
        weight: float | np.ndarray = Lam[np.ix_(pen, pen)]
    elif ndim == 1:  # one weight per parameter: the root's diagonal
        lam_p = np.broadcast_to(np.asarray(lam, dtype=float), (p,))
        sq_f, weight = np.sqrt(np.maximum(lam_p[fp_idx], 0.0)), lam_p[pen]
    else:
        sq_f = np.full(fp_idx.size, math.sqrt(max(float(lam), 0.0)))
        weight = float(lam)

    def objective(u, r):
        d = u[pen_idx] - prior_pen
        if ndim == 0:  # the paper's single weight: the original arithmetic
            return float(r @ r), float(weight * (d @ d))
        if ndim == 2:
            return float(r @ r), float(d @ weight @ d)
        return float(r @ r), float(weight @ (d * d))

    streamed = getattr(residual, "n_blocks", 1) > 1

    def linearise(u):
        """(r, None, G, Rz): streamed in blocks for many poses
        (:mod:`kincal.identification.reduction`)."""
        from kincal.identification.reduction import linearise as reduce

        r, G, Rz = reduce(residual.blocks, u, residual.rows, p, free_idx,
                          getattr(residual, "memo", None))
        return r, None, G, Rz

    u = u0.astype(float).copy()
    if streamed:
        r, J, G, Rz = linearise(u)
    else:
        (r, J), G, Rz = (yield u), None, None
    data, penalty = objective(u, r)
    costs, damps = [data + penalty], []
    # Levenberg-Marquardt with Nielsen's damping update: mu scales diag(J^T J); a step
    # is kept only if it lowers F, and the gain ratio rho (actual / predicted decrease)
    # steers mu, so well-conditioned problems take plain Gauss-Newton steps.
    mu, nu = 0.0, 2.0
    small = 0
    reason, converged = "iteration limit", False
    # the linear problem's matrix A0 = [R; P] and right-hand side b0 = [z; -root (u -
    # prior)], filled in place at each iteration: the penalty's rows P, the same at every
    # iteration, are written once
    k = free_idx.size
    n_pen = int(pen_f.sum()) if sq_f.size and (sq_f > 0).any() else 0
    A0, b0 = np.zeros((k + n_pen, k)), np.zeros(k + n_pen)
    if n_pen and root is None:
        A0[k + np.arange(n_pen), np.flatnonzero(pen_f)] = sq_f
    elif n_pen:
        A0[k:, np.flatnonzero(pen_f)] = root
    # -root (u - prior): a diagonal root's product is the elementwise one, the same bits
    minus = -sq_f if root is None else -root
    it = 0
    while it < options.max_iterations:
        it += 1
        # One QR of [J | -r] reduces the data rows to a k x k triangle R and z = Q^T (-r):
        # ||J d + r||^2 = ||R d - z||^2 + rho^2, so every damping attempt below solves a
        # small system whatever the number of poses.
        if not streamed:
            Rz = _data_triangle(residual, r, J, free_idx)
        h = min(Rz.shape[0], k)  # fewer data rows than free parameters: a shorter triangle
        A0[:h], b0[:h] = Rz[:h, :k], Rz[:h, k]
        rho2 = float(Rz[k, k] ** 2) if Rz.shape[0] > k else 0.0
        if n_pen:
            b0[k:] = (minus * (u[fp_idx] - prior_fp) if root is None else
                      minus @ (u[fp_idx] - prior_fp))
        colnorm2 = None  # Marquardt's scaling, made when a step is damped
        if options.rule == "relative":
            # the Gauss-Newton decrement ||A0 d||^2 = F(u) - min of the linear model
            gn = lstsq(A0, b0)
            a_gn = A0 @ gn
            decrement = float(np.add.reduce(a_gn ** 2))  # np.sum's own sum, without its wrapper
            if decrement <= options.rel_tol * costs[-1]:
                it -= 1  # no step taken
                reason, converged = (f"predicted decrease below {options.rel_tol:g} of the "
                                     "objective"), True
                break
        else:
            gn = None
        accepted = False
        while True:
            if mu > 0:
                if colnorm2 is None:
                    colnorm2 = np.maximum(np.einsum("ij,ij->j", A0, A0), 1e-30)
                A = np.vstack([A0, np.diag(np.sqrt(mu * colnorm2))])
                b = np.concatenate([b0, np.zeros(free_idx.size)])
                step = lstsq(A, b)
            elif gn is not None:  # the undamped step is the decrement's solve above
                step = gn
            else:
                step = lstsq(A0, b0)
            u_new = u.copy()
            u_new[free_idx] += step
            # with the Jacobian at once: most steps are accepted, and then it is needed
            if streamed:
                r_new, J_new, G_new, Rz_new = linearise(u_new)
            else:
                (r_new, J_new), G_new, Rz_new = (yield u_new), None, None
            d_new, p_new = objective(u_new, r_new)
            lin = (a_gn if step is gn else A0 @ step) - b0
            predicted = costs[-1] - float(lin @ lin) - rho2
            actual = costs[-1] - (d_new + p_new)
            if actual >= 0 and math.isfinite(d_new):
                accepted = True
                rho = actual / predicted if predicted > 0 else 1.0
                if mu > 0:
                    mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                    if mu < options.initial_damping * 1e-3:
                        mu = 0.0
                nu = 2.0
                break
            mu = options.initial_damping if mu == 0 else mu * nu
            nu *= 2.0
            if mu > 1e10:
                break
        damps.append(mu)
        if not accepted:
            reason, converged = "no step lowers the objective (local minimum)", True
            break
        u, r, J, G, Rz = u_new, r_new, J_new, G_new, Rz_new
        data, penalty = d_new, p_new
        costs.append(data + penalty)
        if np.abs(step).max() < options.step_tol:
            reason, converged = "step below step_tol", True
            break
        if options.progress is not None:
            options.progress(it, options.max_iterations)
        if options.rule == "paper":
            small = small + 1 if actual < options.cost_tol else 0
        else:  # the same test relative to the objective, so it does not depend on N
            small = small + 1 if actual <= options.cost_rtol * costs[-1] else 0
        if small >= options.cost_window:
            what = (f"{options.cost_tol:g} mm^2" if options.rule == "paper" else
                    f"{options.cost_rtol:g} of the objective")
            reason, converged = (f"objective change below {what} over "
                                 f"{options.cost_window} iterations"), True
            break
    return SolveSummary(u, np.array(costs), data, penalty, np.array(damps), it, converged,
                        reason, J, r, G)
