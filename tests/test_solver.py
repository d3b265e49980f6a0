"""The Gauss-Newton / Levenberg-Marquardt solver and the L2 penalty."""

import numpy as np
import pytest
from conftest import random_joint_values

from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.identification.solver import SolverOptions, solve
from kincal.models import mdh
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot


def _problem(seed, noise=2e-5, n=40, **options):
    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = random_joint_values(robot.geometry, rng, n)
    truth = Truth(planted_table(model, rng), np.array([0.6, 0.2, -0.1, 0.01, 0.02, 0.5]),
                  np.array([0.03, 0.02, 0.12]))
    return CalibrationProblem(robot, measure(model, truth, q, noise, rng),
                              CalibrationOptions(**options))


@pytest.mark.parametrize("lam", [0.0, 0.3, 20.0])
def test_first_step_is_the_tikhonov_closed_form(lam):
    p = _problem(0)
    x0 = p.start()
    free = p.free_mask()
    # independent closed form in SI: residual in mm, penalty lam * ||dx / s||^2
    pred, J = p.kinds[0].model.jacobian(x0)  # the point engine, not the problem's stacking
    r = (p.kinds[0].data.positions - pred).ravel() / 1e-3
    Jm = J.reshape(-1, x0.size)[:, free] / 1e-3
    S2inv = np.diag(np.where(p.space.is_kinematic[free], 1.0 / p.scale[free] ** 2, 0.0))
    dx = np.linalg.solve(Jm.T @ Jm + lam * S2inv, Jm.T @ r)
    sol = p.fit(lam, options=SolverOptions(max_iterations=1))
    step = (sol.u * p.scale - x0)[free]
    assert sol.damping[0] == 0.0  # the undamped step was accepted
    assert np.abs(step - dx).max() <= 1e-9 * np.abs(dx).max()


def test_linear_problem_converges_to_the_regularised_solution():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(30, 6))
    A[:, 5] = A[:, 4] + 1e-6 * rng.normal(size=30)  # nearly collinear columns
    b = rng.normal(size=30)
    u0 = rng.normal(size=6)
    pen = np.array([1, 1, 1, 1, 1, 0], dtype=bool)
    lam = 0.7
    sol = solve(lambda u, jac: (A @ u - b, A if jac else None), u0, np.ones(6, bool), lam=lam,
                penalised=pen, prior=u0)
    P = np.diag(pen.astype(float))
    expected = np.linalg.solve(A.T @ A + lam * P, A.T @ b + lam * P @ u0)
    assert np.abs(sol.u - expected).max() < 1e-8
    assert sol.converged


@pytest.mark.parametrize("seed", range(5))
def test_accepted_steps_never_raise_the_objective(seed):
    # far start: a bad tool guess, large noise, tiny lambda (an ill-conditioned problem)
    p = _problem(seed, noise=5e-4, n=15, method="l2", lam=1e-6, tool_guess=(0.3, -0.2, 0.0))
    sol = p.fit(1e-6)
    assert np.all(np.diff(sol.cost) <= 1e-12 * sol.cost[0])
    assert sol.cost[-1] < sol.cost[0]


def test_iteration_limit_is_reported_not_hidden():
    import warnings

    from kincal.errors import KincalWarning

    p = _problem(2, noise=1e-4, method="ls", solver=SolverOptions(max_iterations=1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = p.solve()
    assert not res.converged and res.solve.reason == "iteration limit"
    assert any(issubclass(w.category, KincalWarning) and "did not converge" in str(w.message)
               for w in caught)
    assert "NOT CONVERGED" in res.summary()


@pytest.mark.parametrize("m,deficient", [(100, False), (5000, False), (5000, True)])
def test_triangular_factor_matches_householder(m, deficient):
    from kincal.identification.linalg import triangular_factor

    rng = np.random.default_rng(m)
    A = rng.normal(size=(m, 20)) * np.logspace(0, 3, 20)  # columns of very different size
    if deficient:
        A[:, 7] = A[:, 3] - 2 * A[:, 5]
    R = triangular_factor(A)
    assert np.allclose(R.T @ R, A.T @ A, rtol=1e-10, atol=1e-8 * np.abs(A.T @ A).max())
    R_qr = np.linalg.qr(A, mode="r")
    assert np.allclose(np.abs(np.diag(R)), np.abs(np.diag(R_qr)), rtol=1e-6, atol=1e-6 * np.abs(R_qr).max())
