"""Residual diagnosis: a pattern a missing term would explain, named with its size.

After any fit (``--model`` chosen or given), the residuals of every set (several files,
any kinds, several chains together: the kinematic parameters shared, each set's frames its
own) are tested against what each joint's missing term would leave: backlash (the joint
off by +-b with its approach direction), a scale error of a prismatic joint (off by k * q),
a periodic error of a revolute joint (off by c * cos q + s * sin q), a compliance of a
revolute joint (off by c * tau, tau the gravity torque it carries, from the URDF's
inertials: only where they give it one, :mod:`kincal.gravity`). Each pattern is the
residual's motion with the joint's value ``dr/dq_j`` (the kind's own analytic Jacobian:
a backlash term on every joint with every approach +1) times that function of the
samples, with what the fitted parameters can already absorb projected out, the rows
weighed as the fit weighs them (orientation rows of poses and tilts of flush touches
scaled by their sigma ratio, sets by their stated sigmas); the pattern with the largest F
statistic is reported when its p-value, times the number of patterns tried (Bonferroni),
is below ``ALPHA``. Plain numpy over the result's arrays. The F distribution's tail is
computed here (:func:`f_sf`, the regularised incomplete beta function by its continued
fraction) rather than by ``scipy.stats``, whose import costs a command that prints a
summary 0.4-1.2 s (tests/test_diagnosis_compliance.py compares the two).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ALPHA = 1e-3  # family-wise false-alarm rate of a reported pattern
MAX_POSES = 5000  # poses the test looks at: evenly spaced in file order beyond this many


@dataclass(frozen=True)
class Finding:
    """A pattern in the residuals. cause: "backlash", "scale", "periodic" or "compliance";
    size: half the play [deg], the scale error [%], the amplitude [deg] or the deflection
    at the samples' RMS gravity torque [deg]; rms_mm: (now, with the term) RMS of the
    samples' errors [mm] (position, distance, height above a plane: each kind's own);
    rms_deg: the same of their orientation errors [deg] (poses, flush tilts), None without
    them; p_value: Bonferroni-corrected."""

    joint: str
    cause: str
    size: float
    rms_mm: tuple[float, float]
    p_value: float
    given: tuple[str, ...] = ()  # the joints the fit already has this kind of term for
    rms_deg: tuple[float, float] | None = None

    def line(self) -> str:
        option = " ".join((*self.given, self.joint))  # the option replaces the joints given
        what = {"backlash": f"backlash of about {abs(self.size):.3g} deg half-play "
                            f"(--backlash {option})",
                "scale": f"a scale error of about {self.size:+.3g} % of its travel",
                "periodic": f"a periodic error of about {self.size:.3g} deg amplitude "
                            "(once per turn)",
                "compliance": f"a compliance of about {self.size:+.3g} deg at the RMS "
                              f"gravity torque (--compliance {option})"}[self.cause]
        return (f"diagnosis: the residuals follow {self.joint}: {what}; modelled, the RMS "
                f"would go from {self.rms_mm[0]:.3g} to {self.rms_mm[1]:.3g} mm"
                + ("" if self.rms_deg is None else
                   f", the orientation's from {self.rms_deg[0]:.3g} to {self.rms_deg[1]:.3g} deg")
                + f" (p = {self.p_value:.2g})")

    def as_dict(self) -> dict:
        unit = "%" if self.cause == "scale" else "deg"
        return {"joint": self.joint, "cause": self.cause, f"size_{unit}": self.size,
                "rms_now_mm": self.rms_mm[0], "rms_with_term_mm": self.rms_mm[1],
                **({} if self.rms_deg is None else {"rms_now_deg": self.rms_deg[0],
                                                    "rms_with_term_deg": self.rms_deg[1]}),
                "p_value": self.p_value}


def nested_p(gain: float, rss: float, dof: int, k: int = 1, tests: int = 1) -> float:
    """The p-value of adding k columns to a least-squares fit (F test with k and dof
    degrees of freedom), times ``tests`` (Bonferroni over the patterns tried), at most 1.
    gain: the drop of the residual sum of squares the columns bring (what the fit could
    already absorb projected out of them); rss: the sum after adding them; dof: rows minus
    the rank of the fit with them. Exact for a linear model with i.i.d. Gaussian noise."""
    if dof <= 0 or rss <= 0:
        return 1.0
    return min(1.0, f_sf((gain / k) / (rss / dof), k, dof) * tests)


def diagnose(result) -> Finding | None:
    """The strongest significant pattern in the residuals of every set, or None. The sets
    are tested together, whatever their kinds and chains: one term per joint, seen by every
    set through its own approach directions, with the kinematic parameters shared (a joint
    on several chains has one term) and each set's frames its own."""
    from kincal.models.compliance import torque_rms

    em = result.error_model
    joints = tuple(em.joint_names)
    have = [joints.index(j) for j in result.layout.backlash if j in joints]
    stiff = [joints.index(j) for j in result.layout.compliance if j in joints]
    blocks = [_SetBlock.of(result, i, -(-MAX_POSES // len(result.sets)))
              for i in range(len(result.sets))]
    q, g, tau = (np.concatenate([getattr(b, f) for b in blocks]) for f in ("q", "g", "tau"))
    Jq, r = np.concatenate([b.Jq for b in blocks]), np.concatenate([b.r for b in blocks])
    at = np.concatenate([b.sample + k for b, k in zip(blocks, _firsts(blocks))])  # row's sample
    own = np.zeros((len(r), sum(b.own.shape[1] for b in blocks)))
    row = col = 0
    for b in blocks:  # each set's frame columns its own: block-diagonal beside the shared
        own[row:row + len(b.own), col:col + b.own.shape[1]] = b.own
        row, col = row + len(b.own), col + b.own.shape[1]
    w = _row_weights(blocks)  # as the fit weighs the sets (their stated sigmas)
    A = np.column_stack([np.concatenate([b.K for b in blocks]), own]
                        + [Jq[:, j] * g[at, j] for j in have]
                        + [Jq[:, j] * tau[at, j] for j in stiff]) * w[:, None]
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    U = U[:, sv > 1e-9 * sv[0]]
    rank = U.shape[1]
    resid = r * w - U @ (U.T @ (r * w))  # the fit already absorbed its own directions
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
            if j not in stiff and tau[:, j].any():
                tests.append((name, "compliance", [tau[:, j]], j))
    best = None
    m = len(r)
    for name, cause, fs, j in tests:
        C = np.column_stack([Jq[:, j] * f[at] * w for f in fs])
        C = C - U @ (U.T @ C)
        if np.linalg.norm(C) <= 1e-12 * max(float(np.linalg.norm(A)), 1e-300):
            continue
        coef, *_ = np.linalg.lstsq(C, resid, rcond=None)
        gain = float(np.sum((C @ coef) ** 2))
        k, dof = len(fs), m - rank - len(fs)
        if dof <= 0 or rss - gain <= 0:
            continue
        F = (gain / k) / ((rss - gain) / dof)
        p = nested_p(gain, rss - gain, dof, k, len(tests))
        if p < ALPHA and (best is None or F > best[0]):
            # the residual rows with the term and every fitted parameter refitted (the
            # linearised refit: the part the fit absorbs, projected off, less the term's);
            # r - C coef / w kept what a penalised fit had left of its own directions, and
            # said 0.73 mm where modelling the term gave 0.075 (a TIAGo Pro torso's scale)
            after = (resid - C @ coef) / w
            mm, deg = _rms(blocks, r, after)
            if not _lowers_every(mm, deg):
                continue  # a trade between the kinds of error, not a term they all miss
            size = (100 * coef[0] if cause == "scale" else
                    math.degrees(float(np.hypot(*coef))) if cause == "periodic"
                    else math.degrees(coef[0] * torque_rms(fs[0])) if cause == "compliance"
                    else math.degrees(coef[0]))
            given = {"backlash": have, "compliance": stiff}.get(cause, [])
            best = (F, Finding(name, cause, float(size), mm, p,
                               tuple(joints[i] for i in given), deg))
    return None if best is None else best[1]


@dataclass(frozen=True)
class _SetBlock:
    """One set's part of the test, in the union's joints (zero where its chain has none):
    q, approach g, gravity torques tau (N, n) of its samples; per residual row (the set's
    rows sample by sample): the residual r [m; angle rows as the fit scales them], its
    sample, its motion per joint value Jq (rows, n), the kinematic columns K (rows, k) and
    the set's frame columns own (rows, f); the kind model (what its rows mean) and the
    samples' stated sigmas [m] (None: none stated)."""

    q: np.ndarray
    g: np.ndarray
    tau: np.ndarray
    r: np.ndarray
    sample: np.ndarray
    Jq: np.ndarray
    K: np.ndarray
    own: np.ndarray
    kind_model: object
    sigma: np.ndarray | None

    @classmethod
    def of(cls, result, i: int, max_poses: int) -> "_SetBlock":
        """Set ``i`` of ``result`` on at most ``max_poses`` of its samples: beyond that
        many, evenly spaced in file order (their approach directions from the whole
        sequence): a pattern that matters is plain at thousands of poses, and the Jacobian,
        its SVD and the gravity torques then cost what a summary may (at 100,000 poses they
        cost more than the fit)."""
        from dataclasses import replace

        from kincal.measurements.sets import kind_model

        s = result.sets[i]
        union = tuple(result.error_model.joint_names)
        em, idx = ((result.error_model, np.arange(result.kinematic.size))
                   if result.chains is None else result.chains.chain_of(i))
        robot = result.robot if result.chains is None else result.chains.robots[i]
        d = s.data.for_chain(em.joint_names)
        keep = (np.arange(len(d)) if len(d) <= max_poses
                else np.unique(np.linspace(0, len(d) - 1, max_poses).round().astype(int)))
        d = d.subset(keep)
        q, g = np.asarray(d.joint_values, float), np.asarray(d.approach, float)
        N, n = q.shape
        # a backlash term on every joint, every approach +1: its column is the residual's
        # motion per joint value (the kind's own analytic derivative)
        km = kind_model(em, replace(d, approach=np.ones_like(q)), tuple(range(n)))
        _, dK, dF, dq = km.residuals(np.asarray(result.kinematic)[idx], s.frames,
                                     np.zeros(n), jacobian=True)
        rows = N * km.dim
        cols = [union.index(j) for j in em.joint_names]
        wide = [np.zeros((N, len(union))) for _ in range(3)]
        for a, v in zip(wide, (q, g, _torques(robot, q, em.kinds))):
            a[:, cols] = v
        Jq = np.zeros((rows, len(union)))
        Jq[:, cols] = -dq.reshape(rows, n)  # the prediction's motion (r = measured - it)
        K = np.zeros((rows, result.kinematic.size))
        K[:, idx] = dK.reshape(rows, -1)
        return cls(q=wide[0], g=wide[1], tau=wide[2],
                   r=np.asarray(s.residuals, float)[keep].reshape(-1),
                   sample=np.repeat(np.arange(N), km.dim), Jq=Jq, K=K,
                   own=dF.reshape(rows, -1), kind_model=km,
                   sigma=None if d.sigma is None else np.asarray(d.sigma, float))


def _row_weights(blocks) -> np.ndarray:
    """(rows,) each residual row's weight: its sample's, as the fit weighs the sets
    (:func:`kincal.measurements.kind.sample_weights`)."""
    from kincal.measurements.kind import sample_weights

    w = sample_weights([b.sigma for b in blocks], [len(b.q) for b in blocks])
    return w[np.concatenate([b.sample + k for b, k in zip(blocks, _firsts(blocks))])]


def _firsts(blocks) -> np.ndarray:
    """(B,) the index of each block's first sample among all the blocks' samples."""
    return np.cumsum([0] + [len(b.q) for b in blocks[:-1]])


def _lowers_every(mm: tuple[float, float], deg: tuple[float, float] | None) -> bool:
    """Whether modelling a pattern lowers the RMS of every kind of error the line reports.
    The test weighs position and angle rows together, so a pattern can gain by turning one
    kind's error into the other's: poses read in the wrong angle convention "explained" by
    a compliance of 258 deg that took the positions from 5.76 to 25.5 mm (a simulated
    EC66, rpy-zyx read as rpy-xyz). A term the data miss lowers both."""
    return mm[1] < mm[0] and (deg is None or deg[1] < deg[0])


def _rms(blocks, before: np.ndarray, after: np.ndarray) -> tuple:
    """((RMS now, with the term) of the samples' errors [mm] (position, distance, height:
    the kind's own), and of their orientation errors [deg] or None when no set has one)."""
    from kincal.identification.statistics import angle_errors

    out: dict = {"mm": ([], []), "deg": ([], [])}
    row = 0
    for b in blocks:
        km, N = b.kind_model, len(b.q)
        for k, r in enumerate((before, after)):
            part = r[row:row + N * km.dim].reshape(N, km.dim)
            out["mm"][k].append(km.sample_errors(part) * 1e3)
            angles = angle_errors(km, part)
            if angles is not None:
                out["deg"][k].append(np.degrees(angles))
        row += N * km.dim

    def rms(parts):
        return math.sqrt(float(np.mean(np.concatenate(parts) ** 2)))

    return (tuple(rms(p) for p in out["mm"]),
            tuple(rms(p) for p in out["deg"]) if out["deg"][0] else None)


def _torques(robot, q: np.ndarray, kinds) -> np.ndarray:
    """(N, n) the gravity torques a compliance pattern multiplies [N m]: zero columns for
    the joints no compliance term can describe (:func:`kincal.models.compliance.loaded`)."""
    from kincal.models.compliance import loaded

    tau = np.asarray(robot.gravity_torques(q), float)
    tau[:, ~loaded(kinds, tau)] = 0.0
    return tau


def f_sf(F: float, d1: float, d2: float) -> float:
    """P(X > F) for X following the F distribution with (d1, d2) degrees of freedom: the
    regularised incomplete beta function I_x(d2/2, d1/2) at x = d2 / (d2 + d1 F)."""
    if not F > 0:
        return 1.0
    if math.isinf(F):
        return 0.0
    return _betainc(d2 / 2, d1 / 2, d2 / (d2 + d1 * F))


def _betainc(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b), 0 <= x <= 1, from its continued
    fraction, on the side of x where the fraction converges fast (I_x(a, b) = 1 -
    I_{1-x}(b, a)); its prefactor in logarithms, so tails down to 1e-300 are kept."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
                 + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1) / (a + b + 2):
        return math.exp(log_front) * _beta_fraction(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_fraction(b, a, 1.0 - x) / b


def _beta_fraction(a: float, b: float, x: float, steps: int = 500) -> float:
    """The continued fraction 1 / (1 + d1 / (1 + d2 / (1 + ...))) of the incomplete beta
    function, d_{2m+1} = -(a+m)(a+b+m) x / ((a+2m)(a+2m+1)), d_{2m} = m(b-m) x /
    ((a+2m-1)(a+2m)), evaluated by the modified Lentz method."""
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, steps + 1):
        for num in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                    -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            return h
    raise ArithmeticError(f"the incomplete beta function's continued fraction did not "
                          f"converge at a={a:g}, b={b:g}, x={x:g}")
