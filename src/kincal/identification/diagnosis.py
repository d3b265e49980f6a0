"""Residual diagnosis: a pattern a missing term would explain, named with its size.

After any fit (``--model`` chosen or given), the residuals of the point sets (several files
together: the kinematic parameters shared, each set's frames its own) are tested
against what each joint's missing term would leave: backlash (the joint off by +-b with
its approach direction), a scale error of a prismatic joint (off by k * q), a periodic
error of a revolute joint (off by c * cos q + s * sin q), a compliance of a revolute joint
(off by c * tau, tau the gravity torque it carries, from the URDF's inertials: only where
they give it one, :mod:`kincal.gravity`). Each pattern is the joint's own
motion ``dP/dq_j`` times that function of the samples, with what the fitted parameters
can already absorb projected out; the pattern with the largest F statistic is reported
when its p-value, times the number of patterns tried (Bonferroni), is below ``ALPHA``.
Plain numpy over the result's arrays; the Jacobian comes from the point model. The F
distribution's tail is computed here (:func:`f_sf`, the regularised incomplete beta
function by its continued fraction) rather than by ``scipy.stats``, whose import costs a
command that prints a summary 0.4-1.2 s (tests/test_diagnosis_compliance.py compares the
two).
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
    at the samples' RMS gravity torque [deg]; rms_mm: (now, with the term) sample RMS
    [mm]; p_value: Bonferroni-corrected."""

    joint: str
    cause: str
    size: float
    rms_mm: tuple[float, float]
    p_value: float
    given: tuple[str, ...] = ()  # the joints the fit already has this kind of term for

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
                f"would go from {self.rms_mm[0]:.3g} to {self.rms_mm[1]:.3g} mm "
                f"(p = {self.p_value:.2g})")

    def as_dict(self) -> dict:
        unit = "%" if self.cause == "scale" else "deg"
        return {"joint": self.joint, "cause": self.cause, f"size_{unit}": self.size,
                "rms_now_mm": self.rms_mm[0], "rms_with_term_mm": self.rms_mm[1],
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
    """The strongest significant pattern in the point sets' residuals, or None (also when
    a set is of another kind, or with several chains). Several point sets (files) are
    tested together: one term per joint, seen by every set through its own approach
    directions, with the kinematic parameters shared and each set's frames its own."""
    if any(s.kind != "point" for s in result.sets) or (
            result.chains is not None and result.chains.several):
        return None
    from kincal.models.compliance import torque_rms

    em = result.error_model
    joints = tuple(em.joint_names)
    have = [joints.index(j) for j in result.layout.backlash if j in joints]
    stiff = [joints.index(j) for j in result.layout.compliance if j in joints]
    blocks = [_set_block(result, s, -(-MAX_POSES // len(result.sets))) for s in result.sets]
    q, g, r, Jq, K = (np.concatenate([b[i] for b in blocks]) for i in range(5))
    # each set's frame columns its own: block-diagonal beside the shared kinematic ones
    own = np.zeros((len(r), sum(b[5].shape[1] for b in blocks)))
    row = col = 0
    for b in blocks:
        own[row:row + len(b[5]), col:col + b[5].shape[1]] = b[5]
        row, col = row + len(b[5]), col + b[5].shape[1]
    tau = _torques(result.robot, q, em.kinds)
    A = np.column_stack([K, own]
                        + [(Jq[:, :, j] * g[:, j:j + 1]).reshape(-1, 1) for j in have]
                        + [(Jq[:, :, j] * tau[:, j:j + 1]).reshape(-1, 1) for j in stiff])
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
            if j not in stiff and tau[:, j].any():
                tests.append((name, "compliance", [tau[:, j]], j))
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
        p = nested_p(gain, rss - gain, dof, k, len(tests))
        if p < ALPHA and (best is None or F > best[0]):
            N = len(q)
            size = (100 * coef[0] if cause == "scale" else
                    math.degrees(float(np.hypot(*coef))) if cause == "periodic"
                    else math.degrees(coef[0] * torque_rms(fs[0])) if cause == "compliance"
                    else math.degrees(coef[0]))
            rms = (math.sqrt(float(r @ r) / N) * 1e3,
                   math.sqrt(max(float(r @ r) - gain, 0.0) / N) * 1e3)
            given = {"backlash": have, "compliance": stiff}.get(cause, [])
            best = (F, Finding(name, cause, float(size), rms, p,
                               tuple(joints[i] for i in given)))
    return None if best is None else best[1]


def _set_block(result, s, max_poses: int) -> tuple:
    """One point set's part of the test, on at most ``max_poses`` of its poses: (q (N, n),
    approach (N, n), residual (3N,) [m], the measured point's motion per joint (N, 3, n),
    the kinematic columns (3N, k), the set's frame columns (3N, f))."""
    from kincal.measurements.point import MeasurementModel

    em = result.error_model
    n, k = em.n, result.kinematic.size
    d = s.data.for_chain(em.joint_names)
    # Beyond max_poses the test runs on that many poses evenly spaced in file order (their
    # approach directions from the whole sequence): a pattern that matters is plain at
    # thousands of poses, and the Jacobian, its SVD and the gravity torques then cost what
    # a summary may (at 100,000 poses they cost more than the fit).
    keep = (slice(None) if len(d) <= max_poses
            else np.unique(np.linspace(0, len(d) - 1, max_poses).round().astype(int)))
    q, g = d.joint_values[keep], d.approach[keep]
    r = np.asarray(s.residuals, float).reshape(len(d), -1)[keep].reshape(-1)  # measured - predicted
    b, t = s.frame_names.index("base.x"), s.frame_names.index("tool.x")
    x = np.concatenate([result.kinematic, s.frames[b:b + 6],
                        s.frames[t:t + 3 * d.n_points], np.zeros(n)])
    _, J = MeasurementModel(em, q, np.ones_like(q), em.joint_names, np.asarray(d.points)[keep],
                            d.n_points).jacobian(x)
    J = J.reshape(len(r), -1)
    return q, g, r, J[:, -n:].reshape(len(q), 3, n), J[:, :k], J[:, k:-n]


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
