"""Algorithm 1 with the folds evaluated together (one vectorised pass per step over the
folds' training rows, one parameter vector per row) gives what the folds fitted one at a
time give: the same chosen lambda and the curve to 1e-9 (bit for bit on some BLAS kernels), on tracker-like data in a 400 mm cube, R-test-like data in a 20 mm cube (whose
small-lambda fits creep under damping, so their end depends on every bit of the path) and
random poses."""

from __future__ import annotations

import numpy as np
import pytest

from kincal.identification.cross_validation import (cross_validate, fold_fitter,
                                                    lambda_grid, validation_error)
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh
from kincal.planning.simulation import Truth, cube_poses, measure, planted_table
from kincal.robot import Robot

ROBOT = Robot.load("ec66")


def _data(seed, size=None, n=60):
    """Poses in a cube of ``size`` m (tilt 15 deg below 0.1 m, else 30), or random joints."""
    rng = np.random.default_rng(seed)
    model = mdh.extract(ROBOT.geometry)
    tool = np.array([0.02, 0.01, 0.12])
    g = ROBOT.geometry
    if size is None:
        q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(n, g.n))
    else:
        q = cube_poses(ROBOT, n, [0.4, 0.0, 0.25], size, tool, rng,
                       max_tilt=np.radians(15 if size < 0.1 else 30))
    truth = Truth(planted_table(model, rng), np.array([0.8, 0.3, -0.2, 0.02, -0.03, 1.2]),
                  tool + [0.001, -0.001, 0.002])
    return measure(model, truth, q, 5e-5, rng)


def _both(problem):
    """(together, one fold at a time) CV curves of ``problem``."""
    o = problem.options
    grid = lambda_grid(o.lambda_min, o.lambda_max, o.n_lambdas)
    samples = np.arange(problem.n_samples)
    groups = problem.kinds[0].data.poses
    out = []
    for together in (True, False):
        fit = fold_fitter(problem, problem.free_mask(), samples)
        error = validation_error(problem, samples)
        assert hasattr(fit, "together") and hasattr(error, "together")
        if not together:
            del fit.together  # cross_validate then fits each fold on its own
        out.append(cross_validate(fit, error, len(samples), grid, o.fold_count, o.seed,
                                  groups=groups))
    return out


@pytest.mark.parametrize("seed,size,model", [(0, 0.4, "complete"), (1, 0.02, "complete"),
                                             (2, 0.02, "complete"), (3, None, "complete"),
                                             (4, 0.02, "mdh"), (5, 0.4, "mdh")])
def test_folds_together_give_the_folds_one_at_a_time(seed, size, model):
    problem = CalibrationProblem(ROBOT, _data(seed, size),
                                 CalibrationOptions(method="l2", lam="cv", model=model))
    fast, slow = _both(problem)
    assert fast.best_index == slow.best_index
    assert np.abs(fast.fold_errors / slow.fold_errors - 1).max() < 1e-9
    assert np.abs(fast.mean_error / slow.mean_error - 1).max() < 1e-9


def test_one_vector_per_row_gives_each_folds_own_rows():
    """The residual and Jacobian of two folds' rows at their own parameters, in one call,
    equal each fold's own (to 1e-12 of their largest entry)."""
    problem = CalibrationProblem(ROBOT, _data(7, 0.02), CalibrationOptions(method="l2"))
    rows = [np.arange(0, 48), np.arange(12, 60)]
    u0 = problem.start() / problem.scale
    us = [u0 + 1e-3 * np.random.default_rng(s).standard_normal(u0.size) for s in range(2)]
    joint = problem.residual_function(np.concatenate(rows))
    r, J = joint(np.repeat(np.stack(us), [len(x) for x in rows], axis=0), True)
    at = 0
    for x, u in zip(rows, us):
        r1, J1 = problem.residual_function(x)(u, True)
        n = r1.size
        assert np.abs(r[at:at + n] - r1).max() <= 1e-12 * np.abs(r1).max()
        assert np.abs(J[at:at + n] - J1).max() <= 1e-12 * np.abs(J1).max()
        at += n


def test_folds_are_fitted_one_at_a_time_with_joint_terms():
    """A chain with backlash terms evaluates one parameter vector at a time: no
    ``together`` (cross_validate fits the folds one by one)."""
    from kincal.identification.cross_validation import together_possible

    data = _data(8, 0.4)
    plain = CalibrationProblem(ROBOT, data, CalibrationOptions(method="l2"))
    assert together_possible(plain, np.arange(plain.n_samples))
    joints = ROBOT.geometry.joint_names
    terms = CalibrationProblem(ROBOT, data, CalibrationOptions(method="l2",
                                                               backlash=(joints[1],)))
    assert terms.layout.n_terms == 1 and not together_possible(terms, np.arange(60))


def test_folds_streamed_in_blocks_are_fitted_one_at_a_time():
    """Folds of more samples than a block (the solver's streamed path) are not evaluated
    together: their fits stay the streamed ones."""
    from kincal.identification.cross_validation import together_possible
    from kincal.identification.problem import BLOCK_SAMPLES

    n = BLOCK_SAMPLES + 100
    problem = CalibrationProblem(ROBOT, _data(9, None, n), CalibrationOptions(method="l2"))
    assert together_possible(problem, np.arange(100))
    assert not together_possible(problem, np.arange(n))


@pytest.mark.parametrize("n", [7, 8])
def test_folds_with_fewer_rows_than_parameters(n):
    """Few poses: each fold's training rows (3 per pose) are fewer than the free parameters,
    so the data's triangle is shorter than the linear problem (a regression: the solver
    wrote it into a square block and failed). Algorithm 1 runs, the folds together give the
    folds one at a time, and each fold fit lowers its penalised objective. The curves agree
    to 1e-5, not 1e-9: only the penalty holds some directions of these fits (condition up
    to lambda^-1), so the last bits of the BLAS move them, and those differ between CPUs'
    kernels (up to 6e-7 on OpenBLAS's Haswell kernels, 0 on its SkylakeX ones)."""
    problem = CalibrationProblem(ROBOT, _data(10 + n, 0.4, n),
                                 CalibrationOptions(method="l2", lam="cv"))
    assert 3 * n * 4 // 5 < int(problem.free_mask().sum())
    fast, slow = _both(problem)
    assert fast.best_index == slow.best_index
    assert np.all(np.isfinite(fast.mean_error))
    assert np.abs(fast.mean_error / slow.mean_error - 1).max() < 1e-5
    rows = np.arange(3 * (n - 2))  # the first n - 2 poses' rows
    sol = problem.fit(1e-2, rows)
    assert sol.cost[-1] < sol.cost[0]
    result = problem.solve()
    assert result.cv is not None and np.isfinite(result.cv.best_lambda)
