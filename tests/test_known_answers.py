"""Known answers where a silent error would hurt most: the parameter selection on a badly
scaled Jacobian, the gate's length check in both signs, the penalty's units, the
cross-validation folds, the evidence optimum, its weights and the standard errors.

Each test computes the right answer on its own (closed forms, finite differences, sets)
and does not compare against numbers the code printed before.
"""

import math

import numpy as np
import pytest
from conftest import random_joint_values

from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.identification.cross_validation import cross_validate, make_folds
from kincal.identification.evidence import (SCALE_MIN, EvidenceFit, LinearEvidence, estimate,
                                            maximise)
from kincal.identification.plausibility import Evidence, Thresholds, judge
from kincal.identification.selection import analyze
from kincal.identification.solver import SolverOptions, solve
from kincal.models import mdh
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot

MM, DEG = 1e-3, math.pi / 180.0  # the documented reporting units, written out here


# ------------------------------------------------------------- selection (rank tolerance)
def _badly_scaled():
    """Four columns (preference order j4, j3, j2, j1) whose norms span 1e5, and the known
    answer: j3 is small and nearly parallel to j4 but has an own part of 1e-3 of its norm
    (kept), j2 is an exact combination of j4 and j3 (dropped), j1 is independent (kept)."""
    m = 12
    e = np.eye(m)
    j4 = 1e4 * e[0]
    j3 = 0.1 * (e[0] + 1e-3 * e[1])
    j2 = 2.0 * j4 - 3.0 * j3
    j1 = 1.0 * e[2] + 0.5 * e[3]
    J = np.column_stack([j1, j2, j3, j4])
    names = ("j1.a", "j2.a", "j3.a", "j4.a")
    return J, names, {"j1.a", "j3.a", "j4.a"}, {"j2.a"}


def test_selection_tolerance_is_relative_to_each_columns_own_norm():
    J, names, kept, dropped = _badly_scaled()
    ident = analyze(J, names, n_kinematic=4)
    assert set(ident.kept) == kept and set(ident.dropped) == dropped, (
        f"the selection on a badly scaled Jacobian kept {ident.kept} and dropped "
        f"{ident.dropped}; expected kept {sorted(kept)}: j3.a has 1e-3 of its own norm "
        "independent of j4.a, far above the rank tolerance 1e-7 of its own norm (a tolerance "
        "relative to the largest column drops it)")


@pytest.mark.parametrize("seed", range(5))
def test_selection_does_not_change_when_columns_are_rescaled(seed):
    # the unit of a parameter must not decide whether it is identifiable (within the
    # range where no column is negligible next to the largest: 1e-7 of its norm)
    J, names, kept, dropped = _badly_scaled()
    rng = np.random.default_rng(seed)
    factors = 10.0 ** rng.uniform(-0.5, 0.5, size=J.shape[1])
    ident = analyze(J * factors, names, n_kinematic=4)
    assert set(ident.kept) == kept and set(ident.dropped) == dropped, (
        f"rescaling the columns by {factors} changed the selection to kept {ident.kept}: "
        "the rank tolerance must be relative to each column's own norm")


# ------------------------------------------------------------ gate: length correction
def _evidence(correction_mm):
    # a clean calibration of a 1 m arm but for one length correction
    return Evidence(reach_m=1.0, residual_median_mm=0.05, residual_rms_mm=0.06,
                    before_rms_mm=2.0, spread_mm=300.0, change_rms_mm=1.0, change_max_mm=2.0,
                    corrections=(("joint_2.a", correction_mm, "mm"), ("joint_3.alpha", 0.1, "deg")))


@pytest.mark.parametrize("value", [600.0, -600.0])
def test_gate_refuses_a_length_correction_over_half_the_reach_in_either_sign(value):
    verdict = judge(_evidence(value), Thresholds())
    kinds = [f.kind for f in verdict.findings]
    assert "length_correction" in kinds and not verdict.plausible, (
        f"a {value:+g} mm correction of a 1000 mm arm (over the 50 % threshold) passed the "
        f"gate (findings {kinds}): the length check must compare |correction|")


@pytest.mark.parametrize("value", [400.0, -400.0])
def test_gate_accepts_a_length_correction_under_half_the_reach_in_either_sign(value):
    verdict = judge(_evidence(value), Thresholds())
    assert verdict.plausible, [f.message for f in verdict.findings]


# ------------------------------------------------------------------- penalty units
def _ec66_problem(lam, n=40, seed=2):
    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, n)
    truth = Truth(planted_table(model, rng, length_sd=1e-3, angle_sd=np.radians(0.2)),
                  np.array([0.6, 0.2, -0.1, 0.01, 0.02, 0.5]), np.array([0.03, 0.02, 0.12]))
    data = measure(model, truth, q, 1e-5, rng)
    options = CalibrationOptions(lam=lam, solver=SolverOptions(step_tol=1e-13, rel_tol=1e-16))
    return CalibrationProblem(robot, data, options)


def test_l2_penalty_is_in_mm_and_degrees():
    """At the L2 solution the gradient of F(u) = ||r_mm||^2 + lam ||u_k - u0_k||^2 is zero,
    with u in mm for lengths and degrees for angles (the documented units, written out
    here). Derivatives by central differences of the SI position errors."""
    lam = 3.0
    problem = _ec66_problem(lam)
    result = problem.solve()
    sp = result.space
    unit = np.where(sp.is_length, MM, DEG)  # one reporting unit of each parameter, in SI
    x = result.x
    free = np.array([p.status == "identified" for p in result.parameters])
    pen = np.asarray(sp.is_penalised) & free
    u, u0 = x / unit, problem.start() / unit

    def r_mm(u):
        return (problem.residuals(u * unit, 0) / MM).ravel()  # set 1: positions [m]

    r = r_mm(u)
    h = 1e-5  # [mm or deg]
    angles_checked = 0
    for i in np.flatnonzero(pen):
        e = np.zeros_like(u)
        e[i] = h
        J_i = (r_mm(u + e) - r_mm(u - e)) / (2 * h)
        g_data = 2.0 * J_i @ r
        g_pen = 2.0 * lam * (u[i] - u0[i])
        size = max(abs(g_data), abs(g_pen))
        if size < 1e-6:  # the parameter sits at its nominal value: nothing to compare
            continue
        angles_checked += not sp.is_length[i]
        assert abs(g_data + g_pen) < 1e-3 * size, (
            f"{sp.names[i]}: the L2 solution is not stationary in reporting units "
            f"(data gradient {g_data:.4g}, penalty gradient {g_pen:.4g} per "
            f"{'mm' if sp.is_length[i] else 'deg'}): the penalty must measure lengths in mm "
            "and angles in degrees")
    assert angles_checked >= 3


# ------------------------------------------------------------ cross-validation folds
@pytest.mark.parametrize("k", [2, 3, 5])
def test_cv_folds_are_disjoint_complete_and_keep_poses_together(k):
    rng = np.random.default_rng(k)
    poses = np.repeat(np.arange(23), rng.integers(1, 4, size=23))  # 1 to 3 samples a pose
    n = poses.size
    seen = []

    def fit(train, lam, start):
        seen.append(["train", np.array(train)])
        return None

    def error(sol, val):
        seen[-1] += ["val", np.array(val)]
        return 1.0

    cv = cross_validate(fit, error, n, np.array([0.1, 1.0]), k=k, seed=7, groups=poses)
    all_samples = np.arange(n)
    # the folds partition the samples
    joined = np.sort(np.concatenate(cv.folds))
    assert np.array_equal(joined, all_samples), "the validation folds do not partition the samples"
    assert len(seen) == 2 * k
    for _, train, _, val in seen:
        overlap = np.intersect1d(train, val)
        assert overlap.size == 0, f"validation samples {overlap} are also in the training set"
        missing = np.setdiff1d(all_samples, np.union1d(train, val))
        assert missing.size == 0, f"samples {missing} are in neither training nor validation"
        split = set(poses[train]) & set(poses[val])
        assert not split, f"poses {sorted(split)} have samples on both sides of a fold"


def test_cv_folds_within_each_set():
    strata = np.repeat([0, 1, 2], [10, 14, 9])
    folds = make_folds(strata.size, 3, 0, strata=strata)
    assert np.array_equal(np.sort(np.concatenate(folds)), np.arange(strata.size))
    for f in folds:  # every fold holds a share of every set
        assert set(strata[f]) == {0, 1, 2}


# ------------------------------------------------------------------------ evidence
def _linear(seed, m=80, per_class=(5, 4, 3), scales=(0.3, 0.05, 1.0), noise=0.1):
    rng = np.random.default_rng(seed)
    groups = np.concatenate([np.full(n, c) for c, n in enumerate(per_class)])
    J = rng.normal(size=(m, groups.size)) * rng.uniform(0.3, 3.0, size=groups.size)
    d = np.asarray(scales)[groups] * rng.normal(size=groups.size)
    y = J @ d + rng.normal(size=m) * noise
    return J, y, groups


def _log_marginal(J, y, groups, scales, noise):
    """log N(y; 0, noise^2 I + J S J^T), S = diag(scale of each parameter's class^2)."""
    C = noise ** 2 * np.eye(len(y)) + (J * np.asarray(scales)[groups] ** 2) @ J.T
    _, logdet = np.linalg.slogdet(C)
    return float(-0.5 * (y @ np.linalg.solve(C, y) + logdet + len(y) * math.log(2 * math.pi)))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("scales", [(0.3, 0.05, 1.0), (0.3, 0.0, 1.0)])
def test_evidence_optimum_is_stationary(scales, seed):
    """d log p(y) / d log(scale_c) and d / d log(noise) vanish at the returned optimum
    (central differences of the m x m Gaussian marginal, written out here). With a class
    the data show at nominal (true scale 0), the slow EM steps cannot hide a wrong MacKay
    noise update (m instead of m - gamma, the effective number of parameters): the
    iteration then stops short of the maximum."""
    J, y, groups = _linear(seed, scales=scales)
    alpha, (beta,), _, converged = maximise(LinearEvidence.of(J, y, groups), 3, np.ones(3), 1.0)
    assert converged
    v = np.concatenate([-0.5 * np.log(alpha), [-0.5 * math.log(beta)]])  # log scales, log noise

    def f(v):
        return _log_marginal(J, y, groups, np.exp(v[:3]), math.exp(v[3]))

    h = 1e-4
    names = ("scale of class 0", "scale of class 1", "scale of class 2", "noise")
    for i in range(4):
        e = np.zeros(4)
        e[i] = h
        grad = (f(v + e) - f(v - e)) / (2 * h)
        if i < 3 and v[i] < np.log(SCALE_MIN) + 1.0:  # at the lower bound: must push down
            assert grad <= 1e-3, f"{names[i]} stopped at its bound, yet the evidence rises"
            continue
        assert abs(grad) < 1e-3, (f"the log evidence still changes with log({names[i]}) at "
                                  f"the returned optimum (derivative {grad:.3g}): not a maximum "
                                  "(the noise update must use m - gamma)")


def test_evidence_weights_are_noise_over_scale_squared():
    fit = EvidenceFit(("length", "twist", "offset"), np.array([0.2, 0.05, 0.5]),
                      np.array([2, 2, 1]), np.zeros(3, bool), 0.01, False, np.zeros(1), 1, True)
    classes = ("length", None, "twist", "offset", "length", None)
    expected = [(0.01 / 0.2) ** 2, 0.0, (0.01 / 0.05) ** 2, (0.01 / 0.5) ** 2,
                (0.01 / 0.2) ** 2, 0.0]
    assert fit.weights(classes) == pytest.approx(expected, rel=1e-12)


def test_evidence_fit_uses_the_weights_of_its_own_hyperparameters():
    """estimate(): the final fit is made with weights (noise / scale)^2 of the returned
    hyperparameters, and is the closed-form posterior mean of the linear problem."""
    J, y, groups = _linear(5, m=60)
    classes = tuple(("length", "twist", "offset")[g] for g in groups) + (None, None)
    rng = np.random.default_rng(0)
    A = np.column_stack([J, rng.normal(size=(60, 2))])  # two flat-prior columns
    b = y + A[:, -2:] @ np.array([3.0, -2.0])
    u0 = np.zeros(A.shape[1])
    calls = []

    def fit(weights, u_start, row_scale):
        calls.append(weights.copy())
        return solve(lambda u, jac: (A @ u - b, A if jac else None), u_start,
                     np.ones(A.shape[1], bool), lam=weights, penalised=weights > 0, prior=u0,
                     options=SolverOptions(step_tol=1e-14))

    sol, ev = estimate(fit, lambda u: (A @ u - b, A), u0, u0, np.ones(A.shape[1], bool),
                       classes)
    s = dict(zip(ev.classes, ev.scales))
    expected = np.array([(ev.noise_mm / s[c]) ** 2 if c else 0.0 for c in classes])
    assert calls[-1] == pytest.approx(expected, rel=1e-9), (
        "the final fit's weights are not (noise / scale)^2 of the returned hyperparameters")
    L = np.diag(expected)
    mean = np.linalg.solve(A.T @ A + L, A.T @ b)
    assert np.abs(sol.u - mean).max() < 1e-8


def test_evidence_posterior_is_the_closed_form_on_a_linear_case():
    """The posterior of y = J d + e, e ~ N(0, sigma^2), d_i ~ N(0, s_c(i)^2), flat priors on
    two columns: mean beta H^-1 J^T y and covariance H^-1, H = beta J^T J + diag(alpha_i)
    (alpha 0 where flat); the variances feed MacKay's gamma and the noise update."""
    J, y, groups = _linear(7, m=25)
    rng = np.random.default_rng(1)
    J = np.column_stack([J, rng.normal(size=(25, 2))])
    groups = np.concatenate([groups, [-1, -1]])
    alpha, beta = np.array([4.0, 300.0, 0.5]), 90.0
    a = np.where(groups >= 0, alpha[np.maximum(groups, 0)], 0.0)
    H = beta * J.T @ J + np.diag(a)
    cov = np.linalg.inv(H)
    mean = beta * cov @ J.T @ y
    w, var, *_ = LinearEvidence.of(J, y, groups).posterior(alpha, beta)
    assert np.abs(w - mean).max() < 1e-10 * np.abs(mean).max()
    assert var == pytest.approx(np.diag(cov), rel=1e-9), "posterior variances"


def test_evidence_standard_errors_against_the_closed_form():
    """A calibration with evidence priors: each identified parameter's standard error is
    the sandwich s^2 H^-1 J^T J H^-1 of the linearised problem, H = J^T J + diag(w),
    w = (noise / scale)^2 of the evidence fit, s^2 = RSS / (m - tr(H^-1 J^T J)), in
    reporting units (mm, deg), converted to SI; in the small-noise limit of a well
    determined parameter it is the posterior standard deviation noise * sqrt(H^-1)."""
    rng = np.random.default_rng(5)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, 60)
    truth = Truth(planted_table(model, rng), np.array([0.6, 0.2, -0.1, 0.01, 0.02, 0.5]),
                  np.array([0.03, 0.02, 0.12]))
    data = measure(model, truth, q, 1e-5, rng)
    res = CalibrationProblem(robot, data, CalibrationOptions(lam="evidence")).solve()
    ev = res.evidence
    sp = res.space
    free = np.array([p.status == "identified" for p in res.parameters])
    scale = dict(zip(ev.classes, ev.scales))
    suffix_class = {"a": "length", "d": "length", "alpha": "twist", "beta": "twist",
                    "theta": "offset"}
    w = np.array([(ev.noise_mm / scale[suffix_class[n.rsplit(".", 1)[1]]]) ** 2
                  if sp.is_penalised[i] else 0.0 for i, n in enumerate(sp.names)])
    J = res.solve.jacobian[:, free]  # mm per mm or deg
    r = res.solve.residual
    H = J.T @ J + np.diag(w[free])
    Hi = np.linalg.inv(H)
    dof = np.trace(Hi @ J.T @ J)
    s2 = float(r @ r) / (J.shape[0] - dof)
    cov = s2 * Hi @ J.T @ J @ Hi
    unit = np.where(sp.is_length, MM, DEG)[free]
    expected = np.sqrt(np.diag(cov)) * unit
    got = np.array([p.std_error for p in res.parameters])[free]
    assert got == pytest.approx(expected, rel=1e-6), (
        f"evidence standard errors differ from the closed form by a factor up to "
        f"{np.max(np.maximum(got / expected, expected / got)):.3g}")
    # the noise the evidence found is the noise planted (0.01 mm), and the standard errors
    # are those of a posterior with that noise where the data decide (within 20 %)
    assert ev.noise_mm == pytest.approx(0.01, rel=0.2)
    posterior = ev.noise_mm * np.sqrt(np.diag(Hi)) * unit
    strong = np.diag(Hi @ J.T @ J) > 0.9  # the data, not the prior, determine these
    assert strong.sum() >= 5
    assert got[strong] == pytest.approx(posterior[strong], rel=0.2)
