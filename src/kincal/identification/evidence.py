"""Bayesian choice of the pull toward nominal: per-class prior scales and the noise level
by maximising the marginal likelihood (type-II maximum likelihood, empirical Bayes).

Plain numpy. Linearised at the current parameters, the calibration is the linear Gaussian
model (reporting units: residuals in mm, parameters in mm or deg)

    y = J d + e,   e ~ N(0, sigma^2 I),   d_i ~ N(0, s_c(i)^2)  (penalised parameters),

with d the parameters' offsets from nominal and a flat prior on the measurement frame and
tool points (as the paper's penalty leaves them free). The hyperparameters, one scale
s_c per parameter class (lengths, twists, joint offsets, backlash; :func:`prior_class`)
and the noise sigma, maximise the evidence p(y | s, sigma) with d integrated out. In
those units the posterior mode is the L2 fit with one weight per parameter,
lambda_i = sigma^2 / s_c(i)^2, so the nonlinear fit is the usual solver; the calibration
relinearises and re-estimates until the hyperparameters settle (kincal.calibration).

The maximiser: MacKay's fixed point (fast) with an EM step instead whenever MacKay's
would lower the evidence; EM never lowers it, so the iteration is monotone. Everything
is p x p (p free parameters): J enters through the triangle R of J = Q R and z = Q^T y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np

from kincal.identification.solver import triangular_factor

# suffix of a parameter name -> its prior class (kinematic error models of every kind)
_SUFFIX_CLASS = {"a": "length", "d": "length", "tx": "length", "ty": "length",
                 "tz": "length", "alpha": "twist", "beta": "twist", "rx": "twist",
                 "ry": "twist", "rz": "twist", "theta": "offset", "backlash": "backlash"}
# "fleet": the parameters a fleet prior covers, one scale on the fleet's covariance
# (kincal.identification.prior); its scale is a multiple of that covariance [1]
CLASSES = ("length", "twist", "offset", "backlash", "fleet")
# scales stay within [SCALE_MIN, SCALE_MAX] reporting units (mm or deg): a class the data
# show at exactly nominal would otherwise drive its scale to 0 only asymptotically
SCALE_MIN, SCALE_MAX = 1e-7, 1e4


def prior_class(name: str, penalised: bool = True) -> str | None:
    """The prior class of parameter ``name`` ("joint_3.a" -> "length"), None if it has a
    flat prior (``penalised`` False: measurement frame and tool points)."""
    if not penalised:
        return None
    suffix = name.rsplit(".", 1)[-1]
    try:
        return _SUFFIX_CLASS[suffix]
    except KeyError:
        raise ValueError(f"no prior class for parameter {name!r} (suffix {suffix!r}); "
                         f"known suffixes: {', '.join(_SUFFIX_CLASS)}") from None


@dataclass(frozen=True)
class EvidenceFit:
    """Hyperparameters of the priors toward nominal, chosen (or given) by evidence.

    classes: the prior classes present (in CLASSES order). scales: (c,) prior standard
    deviation per class [mm for lengths, deg for angles; backlash in deg, or mm for a
    prismatic joint]. counts: (c,) free parameters per class. given: (c,) True where the
    user gave the scale. noise_mm: standard deviation of one residual component [mm] (of
    a unit-weight sample); noise_given: whether the user gave it. log_evidence: per
    outer iteration (relinearisation) at the chosen hyperparameters [nats]. iterations:
    outer iterations; converged: whether the hyperparameters settled.
    """

    classes: tuple[str, ...]
    scales: np.ndarray
    counts: np.ndarray
    given: np.ndarray
    noise_mm: float
    noise_given: bool
    log_evidence: np.ndarray
    iterations: int
    converged: bool

    def scale_of(self, cls: str) -> float:
        return float(self.scales[self.classes.index(cls)])

    def weights(self, class_of: tuple[str | None, ...]) -> np.ndarray:
        """(p,) L2 weights lambda_i = sigma^2 / s_c(i)^2 (0 where the prior is flat)."""
        w = np.zeros(len(class_of))
        for i, c in enumerate(class_of):
            if c is not None and c in self.classes:
                w[i] = self.noise_mm ** 2 / self.scale_of(c) ** 2
        return w

    def line(self) -> str:
        unit = {"length": "mm", "twist": "deg", "offset": "deg", "backlash": "",
                "fleet": "x the fleet's scatter"}
        parts = [f"{c} {s:.3g} {unit[c]}".rstrip() + (" (given)" if g else "")
                 for c, s, g in zip(self.classes, self.scales, self.given)]
        return (f"prior scales {', '.join(parts)}; noise {self.noise_mm:.3g} mm"
                + (" (given)" if self.noise_given else ""))

    def as_dict(self) -> dict:
        return {"prior_scales": {c: {"scale": float(s), "unit": "mm" if c == "length" else
                                     ("deg" if c in ("twist", "offset") else
                                      "x fleet" if c == "fleet" else "mm or deg"),
                                     "parameters": int(n), "given": bool(g)}
                                 for c, s, n, g in zip(self.classes, self.scales, self.counts,
                                                       self.given)},
                "noise_mm": self.noise_mm, "noise_given": self.noise_given,
                "log_evidence": self.log_evidence.tolist(), "iterations": self.iterations,
                "converged": self.converged}


@dataclass(frozen=True)
class LinearEvidence:
    """The linear Gaussian problem y = J d + e in the compressed form of J = Q R.

    R: (p, p) triangle, z: (p,) Q^T y, rest2: ||y||^2 - ||z||^2 (the part of y no
    parameter can fit), m: number of residuals (any; m <= p leaves rows of R zero).
    groups: (p,) class index per parameter, -1 = flat.
    """

    R: np.ndarray
    z: np.ndarray
    rest2: float
    m: int
    groups: np.ndarray

    @classmethod
    def of(cls, J: np.ndarray, y: np.ndarray, groups) -> "LinearEvidence":
        p = J.shape[1]
        Rz = triangular_factor(np.column_stack([J, y]))  # no Q: one pass over the rows
        if Rz.shape[0] < p + 1:  # fewer residuals than parameters: the prior decides
            Rz = np.vstack([Rz, np.zeros((p + 1 - Rz.shape[0], p + 1))])
        return cls(Rz[:p, :p], Rz[:p, p], float(Rz[p, p] ** 2), J.shape[0],
                   np.asarray(groups, int))

    def posterior(self, alpha: np.ndarray, beta: float):
        """(mean (p,), diag of covariance (p,), ||R (R_H^-1)||_F^2, log|H|, E_D) with prior
        precision alpha per class (index by groups) and noise precision beta."""
        # (p,) prior precisions, 0 where flat (indexing only the penalised: with no
        # penalised parameter free, alpha is empty)
        a = np.zeros(self.groups.size)
        pen = self.groups >= 0
        a[pen] = np.asarray(alpha, float)[self.groups[pen]]
        sb = math.sqrt(beta)
        # H = beta R^T R + diag(a) = R_H^T R_H, from one QR of the stacked square roots
        # numpy's stubs type qr(mode="r") as a QRResult; it returns the R array
        RH = cast(np.ndarray, np.linalg.qr(np.vstack([sb * self.R, np.diag(np.sqrt(a))]),
                                           mode="r"))
        RHi = np.linalg.solve(RH, np.eye(RH.shape[0]))
        w = beta * (RHi @ (RHi.T @ (self.R.T @ self.z)))
        diag = np.einsum("ij,ij->i", RHi, RHi)
        fit = self.z - self.R @ w
        E_D = float(fit @ fit) + self.rest2
        trace = float(np.sum((self.R @ RHi) ** 2))
        logdetH = 2.0 * float(np.sum(np.log(np.abs(np.diag(RH)))))
        return w, diag, trace, logdetH, E_D, a

    def log_evidence(self, alpha: np.ndarray, beta: float) -> float:
        """log p(y | alpha, beta) [nats], up to the constant of the flat priors."""
        w, _, _, logdetH, E_D, a = self.posterior(alpha, beta)
        pen = self.groups >= 0
        return float(0.5 * self.m * math.log(beta) + 0.5 * np.sum(np.log(a[pen]))
                     - 0.5 * logdetH - 0.5 * beta * E_D - 0.5 * float(np.sum(a * w * w))
                     - 0.5 * self.m * math.log(2.0 * math.pi))


def maximise(problem: LinearEvidence, n_classes: int, alpha0: np.ndarray, beta0: float,
             alpha_fixed: np.ndarray | None = None, beta_fixed: bool = False,
             max_iterations: int = 500, tol: float = 1e-10):
    """Maximise the evidence over the class precisions alpha = 1/s^2 and beta = 1/sigma^2.

    alpha_fixed: (n_classes,) True where alpha is given and kept; beta_fixed likewise.
    Returns (alpha, beta, history of log evidence per iteration, converged).
    """
    g = problem.groups
    fixed = np.zeros(n_classes, bool) if alpha_fixed is None else np.asarray(alpha_fixed)
    a_lo, a_hi = 1.0 / SCALE_MAX ** 2, 1.0 / SCALE_MIN ** 2
    alpha = np.clip(np.asarray(alpha0, float).copy(), a_lo, a_hi)
    beta = float(beta0)
    counts = np.bincount(g[g >= 0], minlength=n_classes).astype(float)
    history = [problem.log_evidence(alpha, beta)]
    converged = False
    for _ in range(max_iterations):
        w, diag, trace, _, E_D, a = problem.posterior(alpha, beta)
        gamma = 1.0 - a * diag  # how well the data determine each parameter (1: flat prior)
        w2 = np.bincount(g[g >= 0], weights=w[g >= 0] ** 2, minlength=n_classes)
        s2 = np.bincount(g[g >= 0], weights=diag[g >= 0], minlength=n_classes)
        gam = np.bincount(g[g >= 0], weights=gamma[g >= 0], minlength=n_classes)
        with np.errstate(divide="ignore", invalid="ignore"):
            mackay_a = np.where(w2 > 0, gam / w2, a_hi)
        mackay_b = (problem.m - float(np.sum(gamma))) / max(E_D, 1e-300)
        em_a = counts / np.maximum(w2 + s2, 1e-300)
        em_b = problem.m / max(E_D + trace, 1e-300)
        best = None
        for new_a, new_b in ((mackay_a, mackay_b), (em_a, em_b)):
            new_a = np.where(fixed | (counts == 0), alpha, np.clip(new_a, a_lo, a_hi))
            new_b = beta if beta_fixed else float(new_b)
            if not (np.all(np.isfinite(new_a)) and math.isfinite(new_b) and new_b > 0):
                continue
            value = problem.log_evidence(new_a, new_b)
            if value >= history[-1] - 1e-12 * abs(history[-1]):
                best = (new_a, new_b, value)
                break
        if best is None:  # neither step helps: at the maximum to working precision
            converged = True
            break
        alpha, beta, value = best
        history.append(value)
        if abs(history[-1] - history[-2]) <= tol * max(1.0, abs(history[-1])):
            converged = True
            break
    return alpha, beta, np.array(history), converged


def estimate(fit, linearise, u_start: np.ndarray, u_prior: np.ndarray, free: np.ndarray,
             class_of: tuple[str | None, ...], given_scales: dict[str, float] | None = None,
             given_noise_mm: float | None = None, max_outer: int = 20, rtol: float = 1e-3,
             step_tol: float = 1e-6, shape: np.ndarray | None = None):
    """Hyperparameters and fit together: linearise, maximise the evidence, refit, repeat.

    fit(weights (p,), u_start) -> SolveSummary: the L2 fit with per-parameter weights.
    linearise(u) -> (r (m,), J (m, p)): weighted residuals [mm] and dr/du at u.
    u_start, u_prior: (p,) start and nominal values (reporting units); free: (p,) bool.
    class_of: (p,) prior class per parameter, None for a flat prior (see prior_class).
    given_scales: class -> scale the user gave (mm or deg), kept; given_noise_mm likewise.
    Stops when no hyperparameter moves by more than ``rtol`` (relative) between two
    relinearisations, or when the fit itself no longer moves (no parameter by more than
    ``step_tol`` mm or deg): a class the data show at nominal has its scale shrink toward
    0 round after round while its parameters stay pinned, and nothing else changes.
    shape: (p, p) the fleet prior's precision (kincal.identification.prior), used for the
    parameters of class "fleet": their prior is N(0, s^2 shape^-1) with one scale s, so the
    evidence is taken in whitened coordinates (J times V diag(w)^-1/2 of shape = V diag(w) V^T),
    and the
    fit's weight for them, alpha / beta, multiplies that precision (the fit's penalty).
    Returns (SolveSummary of the last fit, EvidenceFit).
    """
    given_scales = given_scales or {}
    idx = np.flatnonzero(free)
    present = [c for c in CLASSES if any(class_of[i] == c for i in idx)]
    groups = np.array([-1 if (cls := class_of[i]) is None else present.index(cls)
                       for i in idx], dtype=np.intp)
    n = len(present)
    fixed_a = np.array([c in given_scales for c in present], bool)
    alpha = np.array([1.0 / given_scales[c] ** 2 if c in given_scales else 1.0 for c in present])
    u, sol, history = np.asarray(u_start, float), None, []
    r, _ = linearise(u)
    beta = (1.0 / given_noise_mm ** 2 if given_noise_mm is not None
            else r.size / max(float(r @ r), 1e-300))
    converged = False
    white = None  # columns of the fleet class: d = L^-T z, z ~ N(0, s^2 I)
    if shape is not None and "fleet" in present:
        c = np.flatnonzero(groups == present.index("fleet"))
        w, V = np.linalg.eigh(shape[np.ix_(idx[c], idx[c])])  # shape = V diag(w) V^T
        white = (c, V / np.sqrt(np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))))
    for it in range(1, max_outer + 1):
        r, J = linearise(u)
        Jf = J[:, idx]
        if white is not None:
            Jf = Jf.copy()
            Jf[:, white[0]] = Jf[:, white[0]] @ white[1]
        shift = np.where(groups >= 0, (u_prior - u)[idx], 0.0)  # flat: centred where we are
        y = -(r + J[:, idx] @ shift)
        problem = LinearEvidence.of(Jf, y, groups)
        new_alpha, new_beta, h, _ = maximise(problem, n, alpha, beta, fixed_a,
                                             given_noise_mm is not None)
        history.append(h[-1])
        moved = max(np.max(np.abs(np.log(new_alpha / alpha)), initial=0.0),
                    abs(math.log(new_beta / beta)))
        alpha, beta = new_alpha, new_beta
        weights = np.zeros(u.size)
        pen = groups >= 0
        weights[idx[pen]] = alpha[groups[pen]] / beta
        sol = fit(weights, u)
        step = float(np.max(np.abs(sol.u - u)))
        u = sol.u
        if it > 1 and (moved <= rtol or step <= step_tol):
            converged = True
            break
    counts = np.bincount(groups[groups >= 0], minlength=n)
    result = EvidenceFit(tuple(present), 1.0 / np.sqrt(alpha), counts, fixed_a,
                         1.0 / math.sqrt(beta), given_noise_mm is not None,
                         np.array(history), it, converged)
    return sol, result
