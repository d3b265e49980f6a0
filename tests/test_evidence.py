"""The evidence estimator: per-class prior scales and noise by maximum marginal likelihood."""

import json
import math

import numpy as np
import pytest
import scipy.optimize
from conftest import random_joint_values

from kincal.errors import OptionError
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.identification.cross_validation import CrossValidation, small_volume_warning
from kincal.identification.evidence import LinearEvidence, maximise, prior_class
from kincal.identification.solver import SolverOptions, solve
from kincal.models import mdh
from kincal.planning.simulation import Truth, measure, planted_table, true_positions
from kincal.robot import Robot


def _linear(seed, m=300, per_class=(15, 15, 15), flat=4, scales=(0.3, 0.05, 1.0), noise=0.1):
    """y = J d + e with d_i ~ N(0, scale of its class^2), flat-prior columns last."""
    rng = np.random.default_rng(seed)
    groups = np.concatenate([np.full(n, c) for c, n in enumerate(per_class)]
                            + [np.full(flat, -1)])
    J = rng.normal(size=(m, groups.size)) * rng.uniform(0.3, 3.0, size=groups.size)
    d = np.where(groups >= 0, np.asarray(scales)[np.maximum(groups, 0)], 10.0)
    d = d * rng.normal(size=groups.size)
    y = J @ d + rng.normal(size=m) * noise
    return J, y, groups


def _direct_log_evidence(J, y, groups, scales, noise, flat_var=1e6):
    """log N(y; 0, noise^2 I + J S J^T) by the m x m covariance, flat priors as a huge
    variance with its log-normaliser removed (the limit the estimator uses; the error
    is O(1 / flat_var), and much larger variances lose the m x m determinant to rounding)."""
    var = np.where(groups >= 0, np.asarray(scales, float)[np.maximum(groups, 0)] ** 2,
                   flat_var)
    C = noise ** 2 * np.eye(len(y)) + (J * var) @ J.T
    _, logdet = np.linalg.slogdet(C)
    n_flat = int(np.sum(groups < 0))
    return float(-0.5 * (y @ np.linalg.solve(C, y) + logdet + len(y) * math.log(2 * math.pi))
                 + 0.5 * n_flat * math.log(flat_var))


def test_log_evidence_matches_the_direct_gaussian_marginal():
    J, y, groups = _linear(0, m=120, per_class=(6, 5, 4), flat=3)
    scales, noise = np.array([0.2, 0.07, 0.5]), 0.08
    fast = LinearEvidence.of(J, y, groups).log_evidence(1 / scales ** 2, 1 / noise ** 2)
    assert fast == pytest.approx(_direct_log_evidence(J, y, groups, scales, noise), abs=1e-3)
    # without flat parameters the two are the same formula, to rounding
    keep = groups >= 0
    fast = LinearEvidence.of(J[:, keep], y, groups[keep]).log_evidence(1 / scales ** 2,
                                                                        1 / noise ** 2)
    exact = _direct_log_evidence(J[:, keep], y, groups[keep], scales, noise)
    assert fast == pytest.approx(exact, rel=1e-10, abs=1e-8)


def test_maximiser_is_the_brute_force_maximum_and_monotone():
    J, y, groups = _linear(1, m=90, per_class=(6, 6, 6), flat=3)
    problem = LinearEvidence.of(J, y, groups)
    alpha, (beta,), history, converged = maximise(problem, 3, np.ones(3), 1.0)
    assert converged
    # every iteration raised (never lowered) the evidence
    assert np.all(np.diff(history) >= -1e-9 * abs(history[-1]))
    assert history[-1] > history[0] + 1.0

    # independent: a grid over log scales and log noise on the m x m formula, then
    # Nelder-Mead from the best grid point (from a poor start it stalls: not concave)
    def negative(v):
        return -_direct_log_evidence(J, y, groups, np.exp(v[:3]), np.exp(v[3]))

    axis = np.log(np.logspace(-2, 1, 7))
    grid = np.array(np.meshgrid(axis, axis, axis, axis)).reshape(4, -1).T
    start = grid[np.argmin([negative(v) for v in grid])]
    simplex = start + 0.3 * np.vstack([np.zeros(4), np.eye(4)])  # one grid step
    brute = scipy.optimize.minimize(negative, start, method="Nelder-Mead",
                                    options=dict(xatol=1e-6, fatol=1e-9, maxiter=4000,
                                                 maxfev=4000, initial_simplex=simplex))
    assert np.exp(brute.x[:3]) == pytest.approx(1 / np.sqrt(alpha), rel=2e-3)
    assert np.exp(brute.x[3]) == pytest.approx(1 / math.sqrt(beta), rel=2e-3)
    assert -brute.fun == pytest.approx(history[-1], abs=1e-3)


def test_recovers_known_prior_scales_and_noise():
    scales, noise = np.array([0.3, 0.05, 1.0]), 0.1
    J, y, groups = _linear(2, m=1500, per_class=(50, 50, 50), flat=6, scales=scales,
                           noise=noise)
    alpha, (beta,), _, converged = maximise(LinearEvidence.of(J, y, groups), 3, np.ones(3), 1.0)
    assert converged
    # 50 draws per class: a scale is known to ~1/sqrt(100), 10 %
    assert 1 / np.sqrt(alpha) == pytest.approx(scales, rel=0.3)
    assert 1 / math.sqrt(beta) == pytest.approx(noise, rel=0.05)


def test_given_hyperparameters_stay_put():
    J, y, groups = _linear(3, m=200)
    alpha0 = np.array([4.0, 100.0, 1.0])
    alpha, (beta,), history, _ = maximise(LinearEvidence.of(J, y, groups), 3, alpha0, 50.0,
                                       alpha_fixed=np.array([True, False, True]),
                                       beta_fixed=True)
    assert alpha[0] == 4.0 and alpha[2] == 1.0 and beta == 50.0
    assert alpha[1] != 100.0
    assert np.all(np.diff(history) >= -1e-9 * abs(history[-1]))


@pytest.mark.parametrize("name, cls", [
    ("joint_3.a", "length"), ("joint_3.d", "length"), ("arm_2_joint.tx", "length"),
    ("j.ty", "length"), ("j.tz", "length"), ("joint_3.alpha", "twist"),
    ("joint_3.beta", "twist"), ("j.rx", "twist"), ("j.ry", "twist"), ("j.rz", "twist"),
    ("joint_3.theta", "offset"), ("joint_6.backlash", "backlash")])
def test_prior_class_by_suffix(name, cls):
    assert prior_class(name) == cls


def test_prior_class_flat_and_unknown():
    assert prior_class("base.rz", penalised=False) is None
    with pytest.raises(ValueError, match="no prior class.*'foo'"):
        prior_class("joint_3.foo")


def test_per_parameter_weights_give_the_closed_form():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(40, 6))
    b = rng.normal(size=40)
    u0 = rng.normal(size=6)
    pen = np.array([1, 1, 1, 1, 0, 0], dtype=bool)
    lam = np.array([0.1, 3.0, 30.0, 0.0, 99.0, 99.0])  # off-penalised entries unused
    sol = solve(lambda u, jac: (A @ u - b, A if jac else None), u0, np.ones(6, bool),
                lam=lam, penalised=pen, prior=u0, options=SolverOptions(step_tol=1e-14))
    L = np.diag(np.where(pen, lam, 0.0))
    expected = np.linalg.solve(A.T @ A + L, A.T @ b + L @ u0)
    assert np.abs(sol.u - expected).max() < 1e-9


def _ec66_data(seed, n=60, noise=1e-5):
    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, n)
    truth = Truth(planted_table(model, rng), np.array([0.6, 0.2, -0.1, 0.01, 0.02, 0.5]),
                  np.array([0.03, 0.02, 0.12]))
    return robot, model, truth, measure(model, truth, q, noise, rng)


def test_calibration_with_evidence_recovers_planted_errors():
    robot, model, truth, data = _ec66_data(5)
    res = CalibrationProblem(robot, data, CalibrationOptions(lam="evidence")).solve()
    ev = res.evidence
    assert ev is not None and ev.converged and math.isnan(res.lam)
    # the noise (0.01 mm per axis) is found, and the fit leaves only noise behind
    assert ev.noise_mm == pytest.approx(0.01, rel=0.2)
    assert res.after.rms < 0.02
    # planted errors of 0.3 mm / 0.03 deg (redundant ones absorbed by the kept ones, so
    # compare predictions): on 200 new poses the model predicts the true robot to within
    # the noise, as plain least squares does on these well-spread poses
    q = random_joint_values(robot.geometry, np.random.default_rng(50), 200)
    true = true_positions(model, truth, q)
    err = np.linalg.norm(res.predict(q) - true, axis=1).mean()
    ls = CalibrationProblem(robot, data, CalibrationOptions(method="ls")).solve()
    err_ls = np.linalg.norm(ls.predict(q) - true, axis=1).mean()
    nominal = CalibrationProblem(robot, data, CalibrationOptions(method="frames")).solve()
    err_nominal = np.linalg.norm(nominal.predict(q) - true, axis=1).mean()
    assert err < 0.01e-3 and err < 1.2 * err_ls and err < 0.05 * err_nominal
    assert "chosen by maximum evidence" in res.summary()
    assert "prior scales length" in res.summary()


def test_given_priors_and_noise_are_used_and_reported():
    robot, _, _, data = _ec66_data(6, n=30)
    res = CalibrationProblem(robot, data, CalibrationOptions(
        lam="evidence", prior_mm=0.5, prior_deg=0.05, noise_mm=0.02)).solve()
    ev = res.evidence
    assert ev.noise_mm == 0.02 and ev.noise_given and ev.given.all()
    assert ev.scale_of("length") == 0.5 and ev.scale_of("offset") == 0.05
    # the same fit as the L2 solve with those per-class weights
    from kincal.export.report import result_dict
    d = result_dict(res)
    assert d["evidence"]["prior_scales"]["twist"]["scale"] == 0.05
    assert d["lambda"] is None
    assert "given" in res.summary().splitlines()[0]


def test_evidence_settings_need_the_evidence_estimator():
    with pytest.raises(OptionError,
                       match=r"prior_mm \(--prior-mm\) is a setting of the evidence estimator"):
        CalibrationOptions(lam="cv", prior_mm=0.1).validated()
    with pytest.raises(OptionError, match=r"noise_mm \(--noise-mm\).*got method ls"):
        CalibrationOptions(method="ls", noise_mm=0.1).validated()
    with pytest.raises(OptionError, match=r"noise_mm \(--noise-mm\) must be between"):
        CalibrationOptions(lam="evidence", noise_mm=-1.0).validated()
    with pytest.raises(OptionError, match="'cv', 'evidence' or a number"):
        CalibrationOptions(lam="bayes").validated()


def _cv(mean, lambdas=None):
    lambdas = np.logspace(-6, 3, len(mean)) if lambdas is None else lambdas
    mean = np.asarray(mean, float)
    best = int(np.argmin(mean))
    return CrossValidation(lambdas, mean[:, None], mean, best, float(lambdas[best]), (), 0)


def test_cv_guard_warns_on_small_volume_with_near_zero_or_flat_curve():
    near_zero = _cv([0.10, 0.11, 0.12, 0.2, 0.4])
    flat = _cv([0.101, 0.100, 0.1005, 0.1009, 0.1010])
    clear = _cv([0.30, 0.2, 0.1, 0.2, 0.4])
    note = small_volume_warning(near_zero, 0.017, 0.9, 0.99)
    assert "lambda = 1e-06" in note and "17.0 mm" in note and "1.9 %" in note
    assert "99 % of the pulled parameters free" in note and "--lambda evidence" in note
    assert "flat" in small_volume_warning(flat, 0.017, 0.9, 0.5)
    assert small_volume_warning(clear, 0.017, 0.9, 0.5) == ""  # a clear interior minimum
    # an interior minimum that still leaves almost everything free
    assert "95 %" in small_volume_warning(clear, 0.017, 0.9, 0.95)
    assert small_volume_warning(near_zero, 0.35, 0.9, 0.99) == ""  # data over the workspace


@pytest.fixture(scope="module")
def rtest_csv(tmp_path_factory):
    from kincal.cli.main import main

    d = tmp_path_factory.mktemp("rtest")
    assert main(["simulate", "ec66", "--design", "rtest", "--out", str(d / "rt.csv"),
                 "--seed", "1"]) == 0
    return d / "rt.csv"


def test_cli_evidence_summary_and_report(rtest_csv, tmp_path, capsys):
    from kincal.cli.main import main

    capsys.readouterr()
    assert main(["calibrate", "ec66", str(rtest_csv), "--out", str(tmp_path / "c.urdf"),
                 "--lambda", "evidence", "--report", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "chosen by maximum evidence" in out and "noise" in out
    report = json.loads((tmp_path / "r.json").read_text())
    ev = report["evidence"]
    assert set(ev["prior_scales"]) == {"length", "twist", "offset"}
    assert 0.01 < ev["noise_mm"] < 0.2 and report["cross_validation"] is None
    assert report["options"]["lambda"] == "evidence"


def test_cli_given_tolerances_and_misuse(rtest_csv, tmp_path, capsys):
    from kincal.cli.main import main

    assert main(["calibrate", "ec66", str(rtest_csv), "--out", str(tmp_path / "c.urdf"),
                 "--lambda", "evidence", "--prior-mm", "0.3", "--prior-deg", "0.03",
                 "--noise-mm", "0.05"]) == 0
    out = capsys.readouterr().out
    assert "length 0.3 mm (given)" in out and "noise 0.05 mm (given)" in out
    code = main(["calibrate", "ec66", str(rtest_csv), "--out", str(tmp_path / "d.urdf"),
                 "--lambda", "cv", "--prior-mm", "0.3"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and not (tmp_path / "d.urdf").exists()
    assert [line for line in err if line.startswith("kincal: error:")] == [
        "kincal: error: prior_mm (--prior-mm) is a setting of the evidence estimator: use it "
        "with method l2 and lambda 'evidence' (got method l2, lambda 'cv')"]


@pytest.mark.parametrize("extra, says", [
    (["--model", "offsets", "--prior-mm", "0.3"],
     "error model offsets has none on this chain"),
    (["--model", "offsets", "--prior-mm", "0.3", "--prior-deg", "0.03"],
     "error model offsets has none on this chain"),
    (["--fix", "*.a", "*.d", "--prior-mm", "0.3"], "none of them is free here"),
])
def test_a_tolerance_of_a_class_the_fit_lacks_is_refused(rtest_csv, tmp_path, capsys, extra,
                                                         says):
    """Audit of issue 12: --prior-mm on the offsets model (no lengths on a revolute arm) or
    with every length held was kept and used nowhere, the calibration written without a
    word; now one line naming the classes that are free, and nothing written."""
    from kincal.cli.main import main

    out = tmp_path / "c.urdf"
    code = main(["calibrate", "ec66", str(rtest_csv), "--out", str(out), "--lambda",
                 "evidence", *extra])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 1 and not out.exists()
    errors = [line for line in err if line.startswith("kincal: error:")]
    assert len(errors) == 1 and "prior_mm (--prior-mm) 0.3 mm" in errors[0], err
    assert says in errors[0] and "used nowhere" in errors[0]


def test_cv_guard_reaches_the_user_on_small_volume_data(rtest_csv):
    from kincal.measurements.data import Measurements

    robot = Robot.load("ec66")
    data = Measurements.from_csv(rtest_csv, robot.joint_names)
    # a grid of tiny lambdas only: CV must pick almost no penalty on 20 mm-cube data
    options = CalibrationOptions(lam="cv", lambda_min=1e-6, lambda_max=1e-4, n_lambdas=3)
    with pytest.warns(UserWarning, match=r"cross-validation: it chose lambda = .* of the arm's "
                                          r"reach .* --lambda evidence"):
        CalibrationProblem(robot, data, options).solve()


def test_fewer_residuals_than_parameters():
    """5 poses, 15 equations for 25 parameters: the priors make it solvable."""
    J, y, groups = _linear(7, m=12, per_class=(5, 5, 5), flat=3)
    problem = LinearEvidence.of(J, y, groups)
    scales, noise = np.array([0.2, 0.07, 0.5]), 0.08
    assert problem.log_evidence(1 / scales ** 2, 1 / noise ** 2) == pytest.approx(
        _direct_log_evidence(J, y, groups, scales, noise), abs=1e-3)
    _, _, history, _ = maximise(problem, 3, np.ones(3), 1.0)
    assert np.all(np.diff(history) >= -1e-9 * abs(history[-1]))
    robot, _, _, data = _ec66_data(8, n=5)
    res = CalibrationProblem(robot, data, CalibrationOptions(lam="evidence")).solve()
    assert res.evidence is not None and np.all(np.isfinite(res.x))


def test_estimators_script_runs_in_a_reduced_size():
    """scripts/estimators.py (the estimator table of docs/results.md) cannot rot: one tracker-like
    seed through each estimator, and its table."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "estimators.py"
    spec = importlib.util.spec_from_file_location("estimators_script", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    row = dict(script.simulated(0, "tracker"), seed=0)
    # wide, accurate data: every estimator predicts within 15 % of the true parameters
    for name in ("ls", "cv", "evidence"):
        assert row[name] < 1.15 * row["truth"], (name, row)
    table = script._table("title", [row], True)
    assert table[1].startswith("| case | ls | cv | evidence | auto | truth") and "x)" in table[3]


def test_free_fraction_of_the_penalty():
    from kincal.identification.cross_validation import free_fraction

    J = np.diag([1.0, 2.0, 3.0])
    pen = np.array([True, True, False])
    assert free_fraction(J, pen, 0.0) == pytest.approx(1.0)
    # hat diagonal s^2 / (s^2 + lam) per penalised column: 1/2 and 4/5
    assert free_fraction(J, pen, 1.0) == pytest.approx((0.5 + 0.8) / 2)
    assert free_fraction(J, pen, 1e12) == pytest.approx(0.0, abs=1e-9)


def test_evidence_with_several_measurement_sets(tmp_path):
    """Two data files in one calibration: the evidence priors are fitted over both sets."""
    from kincal import Measurements, Robot, calibrate
    from kincal.cli.main import main as kmain

    files = []
    for seed in (1, 2):
        path = tmp_path / f"s{seed}.csv"
        assert kmain(["simulate", "ec66", "--out", str(path), "--seed", str(seed),
                      "--poses", "40", "--truth-seed", "5"]) == 0
        files.append(path)
    robot = Robot.load("ec66")
    sets = [Measurements.from_csv(f, robot.joint_names) for f in files]
    ev = calibrate(robot, sets, lam="evidence")
    cv = calibrate(robot, sets, lam="cv")
    assert ev.evidence is not None and math.isnan(ev.lam) and "evidence" in ev.summary()
    assert cv.evidence is None and cv.cv is not None
    # both fit each set to about the simulated noise (0.05 mm per axis)
    for res in (ev, cv):
        assert all(s.after.mean < 0.12 for s in res.sets), res.summary()


def test_auto_with_several_sets_judges_the_measured_volume(tmp_path):
    """lambda 'auto' on two sets from a 20 mm cube takes the evidence; on wide sets, CV."""
    from kincal import Measurements, Robot, calibrate
    from kincal.cli.main import main as kmain

    robot = Robot.load("ec66")
    for design, expected in (("rtest", "evidence"), ("tracker", "cv")):
        sets = []
        for seed in (1, 2):
            path = tmp_path / f"{design}{seed}.csv"
            assert kmain(["simulate", "ec66", "--out", str(path), "--seed", str(seed),
                          "--poses", "30", "--design", design, "--truth-seed", "5"]) == 0
            sets.append(Measurements.from_csv(path, robot.joint_names))
        res = calibrate(robot, sets)
        assert res.penalty_choice.startswith(f"{expected}, chosen automatically"), res.summary()
        assert (res.evidence is not None) == (expected == "evidence")


def test_variance_components_recover_two_planted_noise_levels_and_the_direct_evidence():
    """Rows in two noise groups (0.1 and 2.0: a flush touch's heights and tilts, two
    instruments): the log evidence is the direct Gaussian marginal with a diagonal noise
    covariance, and the maximiser recovers each group's noise (one sigma for all could not:
    it lies between the two)."""
    rng = np.random.default_rng(7)
    J, y, groups = _linear(3, m=600, noise=0.0)
    rows = np.arange(600) % 3 == 0  # a third of the rows in group 1
    noise = np.where(rows, 2.0, 0.1)
    y = y + rng.normal(size=600) * noise
    problem = LinearEvidence.of(J, y, groups, rows.astype(int))
    scales = np.array([0.3, 0.05, 1.0])
    var = np.where(groups >= 0, scales[np.maximum(groups, 0)] ** 2, 1e6)
    C = np.diag(noise ** 2) + (J * var) @ J.T
    direct = float(-0.5 * (y @ np.linalg.solve(C, y) + np.linalg.slogdet(C)[1]
                           + 600 * math.log(2 * math.pi)) + 0.5 * 4 * math.log(1e6))
    assert problem.log_evidence(1 / scales ** 2, 1 / np.array([0.1, 2.0]) ** 2) == \
        pytest.approx(direct, abs=1e-3)
    alpha, beta, history, converged = maximise(problem, 3, np.ones(3), np.ones(2))
    assert converged and np.all(np.diff(history) >= -1e-9 * np.abs(history[1:]))
    assert 1 / np.sqrt(beta) == pytest.approx([0.1, 2.0], rel=0.15)
    (one,) = maximise(LinearEvidence.of(J, y, groups), 3, np.ones(3), 1.0)[1]
    assert 0.3 < 1 / math.sqrt(one) < 1.5  # one sigma for all: neither
    # a group's noise given is kept
    _, kept, _, _ = maximise(problem, 3, np.ones(3), np.array([4.0, 1.0]),
                             beta_fixed=np.array([True, False]))
    assert kept[0] == 4.0 and 1 / math.sqrt(kept[1]) == pytest.approx(2.0, rel=0.15)


@pytest.mark.parametrize("n, how", [(7, "evidence"), (9, "evidence"), (10, "cv")])
def test_auto_penalty_needs_two_poses_per_fold_for_cv(n, how):
    """Lambda "auto" on positions from a large volume chooses CV only with at least two poses
    per fold (5 folds: 10 poses); fewer, the evidence, and the summary says why."""
    from test_cv_together import ROBOT, _data  # random joint values: a large volume

    from kincal.identification.penalty_choice import automatic

    problem = CalibrationProblem(ROBOT, _data(1, None, n),
                                 CalibrationOptions(method="l2", model="complete"))
    chosen, why = automatic(problem)
    assert chosen == how
    assert ("too few for 5-fold cross-validation" in why) is (how == "evidence")


def test_auto_penalty_keeps_the_folds_the_user_gave():
    """Lambda "auto" with the folds given: the user's k is not a reason to choose the
    evidence. A k the poses can meet (even one pose per fold) leaves the choice to the volume
    (CV here); a k beyond the poses is an error naming the counts, as with --lambda cv."""
    from test_cv_together import ROBOT, _data  # random joint values: a large volume

    from kincal.identification.penalty_choice import automatic

    def choice(n, k):
        return automatic(CalibrationProblem(ROBOT, _data(1, None, n), CalibrationOptions(
            method="l2", model="complete", folds=k)))[0]

    assert choice(9, 9) == "cv"
    assert choice(9, None) == "evidence"
    with pytest.raises(OptionError, match=r"number of poses \(9\), got folds=10 \(--folds 9"):
        choice(9, 10)


def _four_poses(tmp_path):
    """four.csv: four simulated EC66 poses at given joint values (simulate's own draws
    depend on the BLAS kernels' last bits, and on other draws the evidence finds an inner
    optimum: a noise of 0.23 mm, calibrated)."""
    from kincal.cli.main import main

    poses, data = tmp_path / "poses.csv", tmp_path / "four.csv"
    poses.write_text("joint_1,joint_2,joint_3,joint_4,joint_5,joint_6\n"
                     "-0.1576202695,4.2919315843,1.7726804687,-1.7160761253,1.4768494959,-1.6286561854\n"
                     "0.1373103116,4.8143225599,1.7495826771,-1.8470586944,1.4888098272,-1.4150198869\n"
                     "-0.3680690702,4.9882860479,1.8318732527,-1.7526453938,1.5109518663,-1.7377819389\n"
                     "-0.6001756830,4.2732722918,1.8925881611,-1.2176136959,1.2457383425,-2.4411475372\n")
    assert main(["simulate", "ec66", "--poses-file", str(poses), "--seed", "1", "--out",
                 str(data)]) == 0
    return data


def test_evidence_refuses_a_fit_through_every_point(tmp_path, capsys):
    """Four simulated poses (12 equations) for 12 identifiable parameters, where the
    evidence puts the noise near zero (3e-6 mm) and the fit through every point: refused
    with both counts, nothing written; with the noise stated, calibrated."""
    from kincal.cli.main import main

    data, out = _four_poses(tmp_path), tmp_path / "cal.urdf"
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert ("kincal: error: 4 poses give 12 equations for 12 identifiable parameters and the "
            "fit passes through every one") in err
    assert not out.exists()
    assert main(["calibrate", "ec66", str(data), "--out", str(out), "--noise-mm", "0.05"]) == 0
    assert out.exists()
    # written, with the warning that nothing is left over to judge the fit by
    err = capsys.readouterr().err
    assert ("kincal: warning: 4 poses give 12 equations for 12 identifiable parameters: none "
            "is left over, so the errors after calibration say nothing of its accuracy") in err
    # whatever chooses the penalty: a lambda given
    assert main(["calibrate", "ec66", str(data), "--out", str(out), "--overwrite",
                 "--lambda", "0.1"]) == 0
    assert ("4 poses give 12 equations for 12 identifiable parameters: none is left over"
            in capsys.readouterr().err)
    # kincal analyze says it before any fit, as a note of the identifiability
    assert main(["analyze", "ec66", str(data)]) == 0
    assert ("note: 12 equations for 12 identifiable parameters: none is left over"
            in capsys.readouterr().out)
    assert main(["simulate", "ec66", "--poses", "5", "--seed", "1", "--out", str(data),
                 "--overwrite"]) == 0  # 15 equations for 15 parameters: still none left
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data), "--out", str(out), "--overwrite"]) == 0
    assert ("5 poses give 15 equations for 15 identifiable parameters: none is left over"
            in capsys.readouterr().err)
    assert main(["simulate", "ec66", "--poses", "12", "--seed", "1", "--out", str(data),
                 "--overwrite"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data), "--out", str(out), "--overwrite"]) == 0
    assert "equations for" not in capsys.readouterr().err  # 36 equations: some to spare


def test_cv_on_fewer_poses_than_folds_names_the_options(tmp_path, capsys):
    """--lambda cv on 4 poses with the default 5 folds: one error line naming the options
    that would run (fewer folds, or the evidence); nothing written."""
    from kincal.cli.main import main

    data, out = _four_poses(tmp_path), tmp_path / "cal.urdf"
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data), "--out", str(out), "--lambda", "cv"]) == 1
    err = capsys.readouterr().err
    assert ("kincal: error: cross-validation needs 2 <= folds <= number of poses (4), got "
            "folds=5 (--folds 4 or fewer, or --lambda evidence)") in err
    assert not out.exists()


def test_exact_direction_is_found_only_where_one_direction_fits_the_residual():
    """J d = r exactly with more rows than columns: the unit direction (found on a subset
    of the rows, checked on all); a residual with noise beside it, or too few rows: None."""
    from kincal.identification.evidence import exact_direction

    rng = np.random.default_rng(0)
    J = rng.normal(size=(900, 12))
    d = rng.normal(size=12)
    found = exact_direction(J, J @ d)
    assert found is not None and abs(abs(found @ d) / np.linalg.norm(d) - 1.0) < 1e-12
    assert exact_direction(J, J @ d + 1e-6 * rng.normal(size=900)) is None
    looked = set(np.unique(np.linspace(0, 899, 20 * 13).astype(int)).tolist())
    k = next(i for i in range(900) if i not in looked)
    bent = J @ d
    bent[k] += 1e-3  # exact on the rows the search looks at, not on every row
    assert exact_direction(J, bent) is None
    assert exact_direction(J[:13], J[:13] @ d) is None  # no row to spare: every r fits


@pytest.mark.parametrize("kind", ["plane", "flush"])
def test_contacts_calibrate_with_their_scale_left_to_the_prior(tmp_path, capsys, kind):
    """3,000 simulated EC66 plane contacts or flush touches: a contact's distance (a
    touch's height) is homogeneous in the lengths and the plane offsets, so the robot
    shrunk toward its base fits those rows exactly; the evidence drove their noise to 0
    along it and the gate refused (629-656 mm corrections). Now that direction is left to
    the prior: calibrated, the noise near the simulated 0.05 mm (and 0.05 deg), and the
    summary says so. Point data have no such direction."""
    import json

    from kincal.cli.main import main

    data = tmp_path / f"{kind}.csv"
    assert main(["simulate", "ec66", "--kind", kind, "--poses", "3000", "--seed", "0",
                 "--out", str(data), "--quiet"]) == 0
    capsys.readouterr()
    flush = ["--flush"] if kind == "flush" else []
    assert main(["calibrate", "ec66", str(data), "--on-plane", *flush, "--tool-offset", "0",
                 "0", "0.12", "--out", str(tmp_path / "c.urdf"), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)["evidence"]
    assert ev["exact_direction_to_prior"]
    noise = [g["sigma"] for g in ev["noise_groups"]] or [ev["noise_mm"]]
    assert all(0.04 < s < 0.06 for s in noise), ev
    points = tmp_path / "points.csv"
    assert main(["simulate", "ec66", "--poses", "60", "--seed", "0", "--out", str(points),
                 "--quiet"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(points), "--lambda", "evidence", "--out",
                 str(tmp_path / "p.urdf"), "--json"]) == 0
    assert not json.loads(capsys.readouterr().out)["evidence"]["exact_direction_to_prior"]


def test_many_poses_estimate_the_hyperparameters_on_a_subsample(tmp_path, capsys, monkeypatch):
    """A set of more than EVIDENCE_MAX_POSES poses: the evidence linearises a seeded random
    subsample of them (each round's dense Jacobian of every row took 1.5 GB at 300,000
    poses), every pose of a smaller set beside it, and the fit uses every pose: said in the
    summary and the JSON; the noise groups of a flush set (heights, tilts) and of the small
    point set found alike; the hyperparameters and the prediction close to those of every
    pose."""
    from kincal.cli import main
    from kincal.identification import penalty_choice

    files = []
    for kind, seed, n in (("flush", 1, 150), ("point", 2, 40)):
        path = tmp_path / f"{kind}.csv"
        assert main(["simulate", "ec66", "--kind", kind, "--poses", str(n), "--seed", str(seed),
                     "--out", str(path)]) == 0
        files.append(str(path))
    capsys.readouterr()
    runs = {}
    for cap in (10 ** 9, 100):
        monkeypatch.setattr(penalty_choice, "EVIDENCE_MAX_POSES", cap)
        out = tmp_path / f"c{cap}.urdf"
        assert main(["calibrate", "ec66", *files, "--on-plane", "--flush", "--lambda",
                     "evidence", "--out", str(out), "--json"]) == 0
        runs[cap] = json.loads(capsys.readouterr().out)
    whole, sub = runs[10 ** 9]["evidence"], runs[100]["evidence"]
    assert whole["subsample_poses"] is None and sub["subsample_poses"] == [140, 190]  # 100 + all 40
    assert [g["rows"] for g in sub["noise_groups"]] == [g["rows"] for g in whole["noise_groups"]]
    assert len(whole["noise_groups"]) == 3  # flush heights, flush tilts, points
    for a, b in zip(sub["noise_groups"], whole["noise_groups"]):
        assert a["sigma"] == pytest.approx(b["sigma"], rel=0.3)
    for c in whole["prior_scales"]:
        assert sub["prior_scales"][c]["scale"] == pytest.approx(
            whole["prior_scales"][c]["scale"], rel=0.6)
    monkeypatch.setattr(penalty_choice, "EVIDENCE_MAX_POSES", 100)
    assert main(["calibrate", "ec66", *files, "--on-plane", "--flush", "--lambda",
                 "evidence", "--out", str(tmp_path / "d.urdf")]) == 0
    assert "estimated on a random 140 of the 190 poses, the fit on all" in capsys.readouterr().out
    # the corrected robots predict alike: within 15 um, under a third of the 50 um noise
    # (190 poses of 0.05 mm leave about 15 um of uncertainty in each)
    robot = Robot.load("ec66")
    q = random_joint_values(robot.geometry, np.random.default_rng(3), 100)
    tips = [Robot.load(str(tmp_path / f"c{cap}.urdf"), tip="flange").tip_poses(q)[:, :3, 3]
            for cap in (10 ** 9, 100)]
    assert np.abs(tips[0] - tips[1]).max() < 15e-6
