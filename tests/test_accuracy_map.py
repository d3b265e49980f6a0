"""The predicted accuracy map against Monte Carlo re-calibrations, and its cube targets."""

import warnings

import numpy as np
import pytest

from kincal.errors import OptionError
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh
from kincal.planning.accuracy_map import (
    cube_grid,
    design_accuracy_map,
    result_accuracy_map,
)
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot

NOISE = 5e-5  # [m] per axis
DRAWS = 60


@pytest.fixture(scope="module")
def setup():
    rng = np.random.default_rng(3)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    lo, hi = np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi)
    q = rng.uniform(lo, hi, size=(60, g.n))        # calibration poses, the same in every draw
    q_targets = rng.uniform(lo, hi, size=(15, g.n))  # where the map is checked
    truth = Truth(planted_table(model, rng), np.array([1.0, 0.2, 0.1, 0.01, 0.02, 0.3]),
                  np.array([0.03, 0.0, 0.1]))
    return robot, model, q, q_targets, truth


def _calibrate(setup, options, draw):
    robot, model, q, _, truth = setup
    data = measure(model, truth, q, NOISE, np.random.default_rng(100 + draw))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = CalibrationProblem(robot, data, options)
        return problem, problem.solve()


def _monte_carlo_std(setup, options):
    """(M,) RMS 3-D scatter [m] of the predictions at the targets over re-calibrations with
    the same poses and new noise draws, and the first results."""
    q_targets = setup[3]
    preds, results = [], []
    for k in range(DRAWS):
        problem, res = _calibrate(setup, options, k)
        preds.append(res.predict(q_targets))
        results.append((problem, res))
    P = np.array(preds)
    return np.sqrt(np.mean(np.sum((P - P.mean(axis=0)) ** 2, axis=2), axis=0)), results


def test_least_squares_map_matches_monte_carlo(setup):
    mc, results = _monte_carlo_std(setup, CalibrationOptions(method="ls"))
    # the map of one calibration estimates the noise from its own residuals: average a few
    predicted = np.mean([result_accuracy_map(r, joint_values=setup[3]).std
                         for _, r in results[:5]], axis=0)
    ratio = predicted / mc
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio
    assert np.all(mc > 0.01e-3)  # not a trivially zero comparison


def test_fixed_lambda_design_map_matches_monte_carlo(setup):
    lam = 3.0  # strong enough to shrink the scatter visibly below least squares
    mc, results = _monte_carlo_std(setup, CalibrationOptions(method="l2", lam=lam))
    problem = results[0][0]
    design = design_accuracy_map(problem, NOISE, joint_values=setup[3], lam=lam)
    ratio = design.std / mc
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio
    ls = design_accuracy_map(problem, NOISE, joint_values=setup[3], lam=0.0)
    assert np.mean(ls.std) > np.mean(design.std)  # the penalty does shrink the variance
    # the calibration's own map is conservative with a penalty (its residuals carry the
    # pull toward nominal as well as noise), never optimistic
    own = result_accuracy_map(results[0][1], joint_values=setup[3]).std
    assert np.all(own / mc > 0.8)


def test_covariance_is_consistent_with_the_standard_errors(setup):
    _, res = _calibrate(setup, CalibrationOptions(method="ls"), 0)
    C = res.covariance
    assert C.shape == (res.space.size, res.space.size) and not C.flags.writeable
    assert np.allclose(C, C.T, rtol=0, atol=1e-12 * np.abs(C).max())
    se = np.array([p.std_error for p in res.parameters])
    ident = np.array([p.status == "identified" for p in res.parameters])
    assert np.allclose(np.sqrt(np.diag(C))[ident], se[ident], rtol=1e-12)
    assert not ident.all() and np.all(C[~ident] == 0) and np.all(C[:, ~ident] == 0)
    assert np.all(np.linalg.eigvalsh(C) > -1e-12 * np.abs(C).max())


def test_cube_points_are_reached_and_unreachable_ones_counted(setup):
    _, res = _calibrate(setup, CalibrationOptions(method="ls"), 0)
    center = np.array([0.45, 0.1, 0.35])
    amap = result_accuracy_map(res, cube=(center, 0.2), grid=3)
    assert len(amap.std) + len(amap.skipped) == 27 and len(amap.std) >= 20
    # each reached pose puts the identified tool point on its grid point (Pinocchio's
    # forward kinematics of the corrected robot, independent of the map's own model)
    T = res.corrected.tip_poses(amap.joint_values)
    reached = T[:, :3, 3] + T[:, :3, :3] @ res.tool
    grid = cube_grid(center, 0.2, 3)
    d = np.min(np.linalg.norm(reached[:, None] - grid[None], axis=2), axis=1)
    assert np.all(d < 1e-6)
    assert np.allclose(amap.positions, reached)
    assert np.all(amap.std > 0) and np.all(amap.worst_axis <= amap.std + 1e-15)
    far = result_accuracy_map(res, cube=(np.array([5.0, 0.0, 0.0]), 0.1), grid=2)
    assert len(far.std) == 0 and len(far.skipped) == 8
    assert "8 of 8 grid points skipped" in far.summary()


def test_bad_cube_is_refused():
    with pytest.raises(OptionError, match="edge"):
        cube_grid([0, 0, 0], -0.1)
    with pytest.raises(OptionError, match="grid"):
        cube_grid([0, 0, 0], 0.1, 0)
    with pytest.raises(OptionError, match="centre"):
        cube_grid([0, 0], 0.1)


def _pose_result():
    """A least-squares calibration of ec66 on 30 noisy tool poses (known frames)."""
    from kincal.measurements.pose import PoseData
    from kincal.rotations import base_rotation, rotation_exp

    rng = np.random.default_rng(7)
    robot = Robot.load("ec66")
    g = robot.geometry
    lo, hi = np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi)
    q = rng.uniform(lo, hi, size=(30, g.n))
    base, tool = np.array([0.4, -0.2, 0.1, 0.05, -0.1, 0.3]), np.array([0.01, -0.02, 0.08])
    Rb, Rt = base_rotation(*base[3:]), base_rotation(0.2, -0.1, 0.4)
    T = robot.tip_poses(q)
    p = (T[:, :3, 3] + T[:, :3, :3] @ tool) @ Rb.T + base[:3]
    R = rotation_exp(rng.normal(scale=np.radians(0.01), size=(30, 3))) @ Rb @ T[:, :3, :3] @ Rt
    data = PoseData(joint_names=robot.joint_names, joint_values=q, rotations=R,
                    positions=p + rng.normal(scale=NOISE, size=p.shape))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return CalibrationProblem(robot, [data], CalibrationOptions(method="ls")).solve(), rng


def test_pose_map_orientation_matches_finite_differences():
    """The orientation figure of a pose calibration's map: sqrt(trace T C T^T) with T the
    tool frame's small turn per parameter, here by central differences of the pose kind's
    residuals (not its Jacobian) over the whole parameter vector, with the calibration's
    covariance; to 1e-5. A factor, radians for degrees or the position rows fail it."""
    from kincal.measurements.pose import PoseData, PoseKind
    from kincal.rotations import base_rotation, rotation_log

    res, rng = _pose_result()
    g, lay = res.robot.geometry, res.layout
    q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(8, g.n))
    amap = result_accuracy_map(res, joint_values=q)
    assert amap.orientation_std is not None and amap.orientation_std.shape == (8,)
    f = lay.frames(res.x, 0)  # the tool frame at x, by Pinocchio on the corrected robot
    R_hat = (base_rotation(*f[3:6]) @ res.corrected.tip_poses(q)[:, :3, :3]
             @ base_rotation(*f[9:12]))
    km = PoseKind(res.error_model, PoseData(joint_names=res.robot.joint_names, joint_values=q,
                                            positions=np.zeros((8, 3)), rotations=R_hat,
                                            approach=np.zeros(q.shape)))
    c = km.data.ratio()[:, None]

    def turn(x):  # rows c log(R_hat R(x)^T): minus the turn of the tool frame, times c
        return km.residuals(*lay.split(x, 0))[:, 3:] / c

    assert np.abs(turn(res.x)).max() < 1e-9  # the engine and Pinocchio agree at x
    h = 1e-6
    D = np.stack([(turn(res.x + h * e) - turn(res.x - h * e)) / (2 * h)
                  for e in np.eye(lay.size)], axis=2)                   # (8, 3, p)
    S = np.einsum("mip,pq,mjq->mij", D, res.covariance, D)
    want = np.sqrt(np.trace(S, axis1=1, axis2=2))
    np.testing.assert_allclose(amap.orientation_std, want, rtol=1e-5)
    d = amap.as_dict()
    np.testing.assert_allclose(d["orientation_std_per_pose_deg"], np.degrees(want), rtol=1e-5)
    assert d["orientation_std_deg"]["max"] == pytest.approx(np.degrees(want).max(), rel=1e-5)
    assert f"max {np.degrees(want).max():.4f} deg" in amap.summary()
    assert "orientation std (tool frame)" in amap.summary()


def test_point_map_has_no_orientation(setup):
    _, res = _calibrate(setup, CalibrationOptions(method="ls"), 0)
    amap = result_accuracy_map(res)
    assert amap.orientation_std is None and "orientation" not in amap.summary()
    assert not any("orientation" in k for k in amap.as_dict())
