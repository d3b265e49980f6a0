"""Bayesian choice of the pull toward nominal: per-class prior scales and the noise level
by maximising the marginal likelihood (type-II maximum likelihood, empirical Bayes).

Plain numpy. Linearised at the current parameters, the calibration is the linear Gaussian
model (reporting units: residuals in mm, parameters in mm or deg)

    y = J d + e,   e_j ~ N(0, sigma_g(j)^2),   d_i ~ N(0, s_c(i)^2)  (penalised parameters),

with d the parameters' offsets from nominal and a flat prior on the measurement frame and
tool points (as the paper's penalty leaves them free). The hyperparameters, one scale
s_c per parameter class (lengths, twists, joint offsets, backlash; :func:`prior_class`)
and the noise sigma_g of each group of rows (variance components: a flush touch's height
[m] and tilts [rad], two files from two instruments, have unrelated noise levels; one
group when the user stated the noise), maximise the evidence p(y | s, sigma) with d
integrated out. In those units the posterior mode is the L2 fit with one weight per
parameter, lambda_i = sigma^2 / s_c(i)^2, and the rows of group g weighted by
sigma / sigma_g, so the nonlinear fit is the usual solver; the calibration relinearises
and re-estimates until the hyperparameters settle (kincal.calibration).

The maximiser: MacKay's fixed point (fast) with an EM step instead whenever MacKay's
would lower the evidence; EM never lowers it, so the iteration is monotone. Everything
is p x p (p free parameters): J enters through the triangle R of J = Q R and z = Q^T y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from kincal.identification.linalg import triangular_factor

# suffix of a parameter name -> its prior class (kinematic error models of every kind)
_SUFFIX_CLASS = {"a": "length", "d": "length", "tx": "length", "ty": "length",
                 "tz": "length", "alpha": "twist", "beta": "twist", "rx": "twist",
                 "ry": "twist", "rz": "twist", "theta": "offset", "backlash": "backlash",
                 "compliance": "compliance"}
# "fleet": the parameters a fleet prior covers, one scale on the fleet's covariance
# (kincal.identification.prior); its scale is a multiple of that covariance [1]
CLASSES = ("length", "twist", "offset", "backlash", "compliance", "fleet")
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
    outer iterations; converged: whether the hyperparameters settled. row_noise: (G,) the
    noise of each row group in the weighted rows [mm] (variance components; one group:
    noise_mm); noise_groups: per group (rows, sigma, unit), in the rows' own units (mm of
    height, deg of tilt; :func:`kincal.identification.penalty_choice.fit_evidence`).
    gauged: whether the data's residual was exactly a direction of the parameters (see
    :func:`exact_direction`), left to the prior. subsample: (poses, poses in the data) when
    the hyperparameters were estimated on a seeded random subsample of the poses (the fit
    itself on every one), else None.
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
    row_noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    noise_groups: tuple[tuple[str, float, str], ...] = ()
    gauged: bool = False
    subsample: tuple[int, int] | None = None

    def scale_of(self, cls: str) -> float:
        return float(self.scales[self.classes.index(cls)])

    def weights(self, class_of: tuple[str | None, ...]) -> np.ndarray:
        """(p,) L2 weights lambda_i = sigma^2 / s_c(i)^2 (0 where the prior is flat)."""
        w = np.zeros(len(class_of))
        for i, c in enumerate(class_of):
            if c is not None and c in self.classes:
                w[i] = self.noise_mm ** 2 / self.scale_of(c) ** 2
        return w

    def scale_text(self, cls: str) -> str:
        """Class ``cls``'s prior scale as the summary writes it ("offset 4.92 deg")."""
        unit = {"length": "mm", "twist": "deg", "offset": "deg",
                "backlash": "deg half-play (mm if prismatic)",
                "compliance": "deg at the RMS torque", "fleet": "x the fleet's scatter"}
        return f"{cls} {self.scale_of(cls):.3g} {unit[cls]}".rstrip()

    def line(self) -> str:
        parts = [self.scale_text(c) + (" (given)" if g else "")
                 for c, g in zip(self.classes, self.given)]
        noise = (f"noise {self.noise_mm:.3g} mm" + (" (given)" if self.noise_given else "")
                 if len(self.noise_groups) < 2 else "noise per row group " + ", ".join(
                     f"{rows} {s:.3g} {unit}" for rows, s, unit in self.noise_groups))
        gauge = ("; one direction fits any residual exactly (distances to planes, contact "
                 "heights: the robot shrunk toward its base), left to the prior"
                 if self.gauged else "")
        sub = (f"; estimated on a random {self.subsample[0]:,} of the {self.subsample[1]:,} "
               "poses, the fit on all" if self.subsample else "")
        return f"prior scales {', '.join(parts)}; {noise}{gauge}{sub}"

    def as_dict(self) -> dict:
        return {"prior_scales": {c: {"scale": float(s), "unit": "mm" if c == "length" else
                                     ("deg" if c in ("twist", "offset") else
                                      "x fleet" if c == "fleet" else "mm or deg"),
                                     "parameters": int(n), "given": bool(g)}
                                 for c, s, n, g in zip(self.classes, self.scales, self.counts,
                                                       self.given)},
                "noise_mm": self.noise_mm, "noise_given": self.noise_given,
                "noise_groups": [{"rows": rows, "sigma": s, "unit": unit}
                                 for rows, s, unit in self.noise_groups],
                "log_evidence": self.log_evidence.tolist(), "iterations": self.iterations,
                "converged": self.converged, "exact_direction_to_prior": self.gauged,
                "subsample_poses": None if self.subsample is None else list(self.subsample)}


@dataclass(frozen=True)
class LinearEvidence:
    """The linear Gaussian problem y = J d + e in the compressed form of J = Q R, the rows in
    G noise groups (variance components: group g's noise sigma_g = beta_g^-1/2).

    R: (G, p, p) triangle of each group's rows, z: (G, p) Q_g^T y_g, rest2: (G,)
    ||y_g||^2 - ||z_g||^2 (the part of y_g no parameter can fit), m: (G,) rows per group
    (any; m_g <= p leaves rows of R_g zero). groups: (p,) class index per parameter, -1 =
    flat.
    """

    R: np.ndarray
    z: np.ndarray
    rest2: np.ndarray
    m: np.ndarray
    groups: np.ndarray

    @classmethod
    def of(cls, J: np.ndarray, y: np.ndarray, groups, rows=None) -> "LinearEvidence":
        """rows: (m,) noise group of each row (0..G-1); None: one group."""
        p = J.shape[1]
        rows = np.zeros(J.shape[0], int) if rows is None else np.asarray(rows, int)
        parts = []
        for g in range(int(rows.max()) + 1 if rows.size else 1):
            on = rows == g
            Rz = triangular_factor(np.column_stack([J[on], y[on]]))  # no Q: one pass
            if Rz.shape[0] < p + 1:  # fewer residuals than parameters: the prior decides
                Rz = np.vstack([Rz, np.zeros((p + 1 - Rz.shape[0], p + 1))])
            parts.append((Rz[:p, :p], Rz[:p, p], float(Rz[p, p] ** 2), int(on.sum())))
        R, z, rest2, m = zip(*parts)
        return cls(np.array(R), np.array(z), np.array(rest2), np.array(m), np.asarray(groups, int))

    def posterior(self, alpha: np.ndarray, beta):
        """(mean (p,), diag of covariance (p,), ||R_g R_H^-1||_F^2 per group (G,), log|H|,
        E_D per group (G,), prior precisions (p,)) with prior precision alpha per class
        (index by groups) and noise precision beta (G,) per row group."""
        # (p,) prior precisions, 0 where flat (indexing only the penalised: with no
        # penalised parameter free, alpha is empty)
        a = np.zeros(self.groups.size)
        pen = self.groups >= 0
        a[pen] = np.asarray(alpha, float)[self.groups[pen]]
        sb = np.sqrt(np.broadcast_to(np.asarray(beta, float), self.m.shape))
        # H = sum_g beta_g R_g^T R_g + diag(a) = R_H^T R_H, from one QR of the square roots
        # numpy's stubs type qr(mode="r") as a QRResult; it returns the R array
        RH = cast(np.ndarray, np.linalg.qr(np.vstack([*(sb[:, None, None] * self.R),
                                                      np.diag(np.sqrt(a))]), mode="r"))
        RHi = np.linalg.solve(RH, np.eye(RH.shape[0]))
        w = RHi @ (RHi.T @ np.einsum("g,gij,gi->j", sb ** 2, self.R, self.z))
        diag = np.einsum("ij,ij->i", RHi, RHi)
        fit = self.z - np.einsum("gij,j->gi", self.R, w)
        E_D = np.sum(fit * fit, axis=1) + self.rest2
        trace = np.sum(np.einsum("gij,jk->gik", self.R, RHi) ** 2, axis=(1, 2))
        logdetH = 2.0 * float(np.sum(np.log(np.abs(np.diag(RH)))))
        return w, diag, trace, logdetH, E_D, a

    def log_evidence(self, alpha: np.ndarray, beta) -> float:
        """log p(y | alpha, beta) [nats], up to the constant of the flat priors; beta: the
        noise precision of each row group (G,), or one for all."""
        w, _, _, logdetH, E_D, a = self.posterior(alpha, beta)
        b = np.broadcast_to(np.asarray(beta, float), self.m.shape)
        pen = self.groups >= 0
        return float(0.5 * np.sum(self.m * np.log(b)) + 0.5 * np.sum(np.log(a[pen]))
                     - 0.5 * logdetH - 0.5 * float(b @ E_D) - 0.5 * float(np.sum(a * w * w))
                     - 0.5 * float(np.sum(self.m)) * math.log(2.0 * math.pi))


def maximise(problem: LinearEvidence, n_classes: int, alpha0: np.ndarray, beta0,
             alpha_fixed: np.ndarray | None = None, beta_fixed=False,
             max_iterations: int = 500, tol: float = 1e-10):
    """Maximise the evidence over the class precisions alpha = 1/s^2 and the noise
    precisions beta = 1/sigma^2, one per row group (variance components).

    beta0: (G,) or one value; alpha_fixed: (n_classes,) True where alpha is given and
    kept; beta_fixed likewise, (G,) or one flag. The steps per group are MacKay's
    beta_g = (m_g - gamma_g) / E_D,g, with gamma_g = beta_g tr(J_g H^-1 J_g^T) the
    parameters group g's rows determine, or EM's m_g / (E_D,g + tr(J_g H^-1 J_g^T)).
    Returns (alpha, beta (G,), history of log evidence per iteration, converged).
    """
    g = problem.groups
    fixed = np.zeros(n_classes, bool) if alpha_fixed is None else np.asarray(alpha_fixed)
    b_fixed = np.broadcast_to(np.asarray(beta_fixed, bool), problem.m.shape)
    a_lo, a_hi = 1.0 / SCALE_MAX ** 2, 1.0 / SCALE_MIN ** 2
    alpha = np.clip(np.asarray(alpha0, float).copy(), a_lo, a_hi)
    beta = np.broadcast_to(np.asarray(beta0, float), problem.m.shape).copy()
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
        E = np.maximum(E_D, 1e-300)
        mackay_b = (problem.m - beta * trace) / E
        em_a = counts / np.maximum(w2 + s2, 1e-300)
        em_b = problem.m / np.maximum(E_D + trace, 1e-300)
        best = None
        for new_a, new_b in ((mackay_a, mackay_b), (em_a, em_b)):
            new_a = np.where(fixed | (counts == 0), alpha, np.clip(new_a, a_lo, a_hi))
            new_b = np.where(b_fixed, beta, new_b)
            if not (np.all(np.isfinite(new_a)) and np.all(np.isfinite(new_b))
                    and np.all(new_b > 0)):
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


EXACT = 1e-9  # a residual fitted to this fraction of its norm by one direction: exactly


def exact_direction(J: np.ndarray, r: np.ndarray, on: np.ndarray | None = None
                    ) -> np.ndarray | None:
    """(p,) the unit direction d with J d = r exactly (to EXACT of |r|) on the rows ``on``
    (indices; None: all) when they outnumber the columns, else None. Such a direction fits
    any residual, noise included: plane contacts alone are one (each contact's distance is
    homogeneous of degree one in every length, the planes' offsets among them, so the robot
    shrunk toward its base touches every plane; a known length, a distance or a point set
    breaks it). Maximising the evidence along it drives the noise to zero and the lengths
    to the collapsed robot (3,000 simulated EC66 plane contacts: 6 of 6 refused by the
    gate, corrections of 656 mm); :func:`estimate` leaves it to the prior: the evidence is
    taken on the other directions, and the fit's penalty holds the lengths near nominal
    along it."""
    m, p = J.shape
    on = np.arange(m) if on is None else np.asarray(on)
    if on.size <= p + 1 or not np.any(r[on]):
        return None
    # found on at most 20 (p + 1) evenly spaced rows (exact on all rows, exact on those; the
    # least-norm solution: a group's rows may not see every column, a flush touch's height
    # not the face's tilt), then checked on every row with one product: a bounded cost, and
    # no copy of J (a million rows)
    some = on[np.unique(np.linspace(0, on.size - 1, min(on.size, 20 * (p + 1))).astype(int))]
    d, _, rank, _ = np.linalg.lstsq(J[some], r[some], rcond=None)
    if rank >= some.size - 1 or not np.any(d):
        return None  # no row to spare there: every residual fits
    miss = (J @ d - r)[on]
    if not float(miss @ miss) <= EXACT ** 2 * float(r[on] @ r[on]):
        return None
    return d / np.linalg.norm(d)


def exact_directions(J: np.ndarray, r: np.ndarray, rows: np.ndarray) -> list[np.ndarray]:
    """Orthonormal directions, each fitting one noise group's residual exactly
    (:func:`exact_direction` per group of ``rows``): with a noise per group the evidence
    drives that group's noise to zero along it (flush touches: the heights are homogeneous
    in the lengths, the tilts do not see them; 3,000 simulated EC66 touches collapsed)."""
    out: list[np.ndarray] = []
    groups = np.unique(rows)
    for g in groups:
        d = exact_direction(J, r, None if groups.size == 1 else np.flatnonzero(rows == g))
        if d is None:
            continue
        for e in out:
            d = d - (d @ e) * e
        if np.linalg.norm(d) > 1e-6:
            out.append(d / np.linalg.norm(d))
    return out


def estimate(fit, linearise, u_start: np.ndarray, u_prior: np.ndarray, free: np.ndarray,
             class_of: tuple[str | None, ...], given_scales: dict[str, float] | None = None,
             given_noise_mm: float | None = None, max_outer: int = 20, rtol: float = 1e-3,
             step_tol: float = 1e-6, shape: np.ndarray | None = None,
             rows: np.ndarray | None = None):
    """Hyperparameters and fit together: linearise, maximise the evidence, refit, repeat.

    fit(weights (p,), u_start, row_scale (G,)) -> SolveSummary: the L2 fit with
    per-parameter weights, the rows of group g multiplied by row_scale[g].
    linearise(u) -> (r (m,), J (m, p)): weighted residuals [mm] and dr/du at u.
    u_start, u_prior: (p,) start and nominal values (reporting units); free: (p,) bool.
    class_of: (p,) prior class per parameter, None for a flat prior (see prior_class).
    given_scales: class -> scale the user gave (mm or deg), kept; given_noise_mm likewise
    (the noise of every row: one group, kept).
    rows: (m,) noise group of each residual row (0..G-1; None: one): each group's noise is
    a variance component of its own, maximising the evidence with the rest. The fit weighs
    group g's rows by row_scale_g = sigma / sigma_g, sigma^-2 the rows' mean precision
    (the scales' mean square over the rows is 1), and the parameters by
    lambda_i = sigma^2 / s_c(i)^2 (EvidenceFit.noise_mm is that sigma).
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
    rows = np.zeros(r.size, int) if rows is None or given_noise_mm is not None else \
        np.asarray(rows, int)
    m_g = np.bincount(rows, minlength=int(rows.max()) + 1).astype(float)
    r2 = np.bincount(rows, weights=r * r, minlength=m_g.size)
    beta = (np.full(m_g.size, 1.0 / given_noise_mm ** 2) if given_noise_mm is not None
            else m_g / np.maximum(r2, 1e-300))
    converged = False
    white = None  # columns of the fleet class: d = L^-T z, z ~ N(0, s^2 I)
    if shape is not None and "fleet" in present:
        c = np.flatnonzero(groups == present.index("fleet"))
        w, V = np.linalg.eigh(shape[np.ix_(idx[c], idx[c])])  # shape = V diag(w) V^T
        white = (c, V / np.sqrt(np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))))
    gauged = False
    for it in range(1, max_outer + 1):
        r, J = linearise(u)
        Jf = J[:, idx]
        if white is not None:
            Jf = Jf.copy()
            Jf[:, white[0]] = Jf[:, white[0]] @ white[1]
        for g in exact_directions(Jf, r, rows) if white is None else ():
            # a direction that fits any residual (of a noise group): to the prior, not the data
            Jf, gauged = Jf - np.outer(Jf @ g, g), True
        shift = np.where(groups >= 0, (u_prior - u)[idx], 0.0)  # flat: centred where we are
        y = -(r + J[:, idx] @ shift)
        problem = LinearEvidence.of(Jf, y, groups, rows)
        new_alpha, new_beta, h, _ = maximise(problem, n, alpha, beta, fixed_a,
                                             given_noise_mm is not None)
        history.append(h[-1])
        moved = max(np.max(np.abs(np.log(new_alpha / alpha)), initial=0.0),
                    float(np.max(np.abs(np.log(new_beta / beta)))))
        alpha, beta = new_alpha, new_beta
        beta_ref = float(m_g @ beta / m_g.sum())  # the rows' mean precision
        weights = np.zeros(u.size)
        pen = groups >= 0
        weights[idx[pen]] = alpha[groups[pen]] / beta_ref
        sol = fit(weights, u, np.sqrt(beta / beta_ref))
        step = float(np.max(np.abs(sol.u - u)))
        u = sol.u
        if it > 1 and (moved <= rtol or step <= step_tol):
            converged = True
            break
    counts = np.bincount(groups[groups >= 0], minlength=n)
    result = EvidenceFit(tuple(present), 1.0 / np.sqrt(alpha), counts, fixed_a,
                         1.0 / math.sqrt(beta_ref), given_noise_mm is not None,
                         np.array(history), it, converged, row_noise=1.0 / np.sqrt(beta),
                         gauged=gauged)
    return sol, result
