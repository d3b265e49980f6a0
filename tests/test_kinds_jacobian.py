"""Every measurement kind's analytic Jacobian against central differences, with every
error model, backlash terms included."""

import numpy as np
import pytest
from conftest import random_joint_values

from kincal import models
from kincal.measurements.data import Measurements
from kincal.measurements.distance import DistanceData, DistanceKind
from kincal.measurements.flush import FlushData, FlushKind
from kincal.measurements.plane import PlaneData, PlaneKind
from kincal.measurements.point import PointKind
from kincal.measurements.pose import PoseData, PoseKind, right_jacobian_inverse
from kincal.robot import Robot
from kincal.rotations import base_rotation, rotation_log


def make_kind(kind, model, q, rng, names):
    n = len(q)
    if kind == "point":
        data = Measurements(names, q, rng.normal(size=(n, 3)))
        return PointKind(model, data, backlash=(1, model.n - 1))
    if kind == "pose":
        R = np.stack([base_rotation(*a) for a in rng.uniform(-2, 2, size=(n, 3))])
        data = PoseData(joint_names=names, joint_values=q, positions=rng.normal(size=(n, 3)),
                        rotations=R, sigma_deg=rng.uniform(0.01, 0.1, n))
        return PoseKind(model, data, backlash=(1, model.n - 1))
    if kind == "distance":
        data = DistanceData(joint_names=names, joint_values=q, distances=rng.uniform(0.5, 1, n))
        return DistanceKind(model, data, backlash=(1, model.n - 1))
    if kind == "flush":
        data = FlushData(joint_names=names, joint_values=q, planes=np.arange(n) % 2,
                         labels=("1", "2"), sigma=rng.uniform(0.01, 0.1, n) * 1e-3,
                         sigma_deg=rng.uniform(0.01, 0.1, n))
        return FlushKind(model, data, backlash=(1, model.n - 1))
    data = PlaneData(joint_names=names, joint_values=q, planes=np.arange(n) % 3,
                     labels=("1", "2", "3"))
    return PlaneKind(model, data, backlash=(1, model.n - 1))


@pytest.mark.parametrize("robot_name,tip", [("ec66", "flange"), ("ur10", "tool0")])
@pytest.mark.parametrize("model_name", models.MODELS)
@pytest.mark.parametrize("kind", ["point", "pose", "distance", "plane", "flush"])
def test_kind_jacobian_matches_central_differences(kind, model_name, robot_name, tip, rng):
    robot = Robot.load(robot_name, tip=tip)
    model = models.build(model_name, robot.geometry)
    q = random_joint_values(robot.geometry, rng, 12)
    q[0] = 0.0  # q = 0 on purpose
    km = make_kind(kind, model, q, rng, robot.joint_names)
    kin = model.nominal + rng.normal(size=model.size) * 1e-2
    frames = rng.normal(size=km.n_frames) * 0.3
    b = rng.normal(size=2) * 1e-2
    x = np.concatenate([kin, frames, b])
    k, f = model.size, km.n_frames

    def res(x):
        return km.residuals(x[:k], x[k:k + f], x[k + f:])

    r, Jk, Jf, Jb = km.residuals(kin, frames, b, jacobian=True)
    assert np.allclose(r, res(x))
    if kind == "pose":  # a joint's play turns the tool: the orientation rows see it
        assert np.abs(Jb[:, 3:, :]).max() > 1e-3
    J = np.concatenate([Jk, Jf, Jb], axis=2)
    h = 1e-6
    for c in range(x.size):
        e = np.zeros_like(x)
        e[c] = h
        fd = (res(x + e) - res(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        assert np.abs(J[:, :, c] - fd).max() / scale < 1e-6, (kind, c)
    # frame-only Jacobian: the same frame columns, zero kinematic ones
    _, Jk0, Jf0, Jb0 = km.residuals(kin, frames, b, jacobian=True, kinematic=False)
    assert np.allclose(Jf0, Jf) and not Jk0.any() and not Jb0.any()


def test_right_jacobian_inverse_near_zero_and_large(rng):
    # angles below pi (log wraps beyond it)
    phi = np.vstack([rng.uniform(-1.5, 1.5, size=(5, 3)), [[1e-9, 0, 0], [0, 0, 0], [0, 2.9, 0.1]]])
    Ji = right_jacobian_inverse(phi)
    from scipy.spatial.transform import Rotation

    h = 1e-6
    for n in range(len(phi)):
        E = Rotation.from_rotvec(phi[n]).as_matrix()
        for c in range(3):
            e = np.zeros(3)
            e[c] = h
            up = rotation_log((E @ Rotation.from_rotvec(e).as_matrix())[None])[0]
            dn = rotation_log((E @ Rotation.from_rotvec(-e).as_matrix())[None])[0]
            assert np.allclose((up - dn) / (2 * h), Ji[n, :, c], atol=1e-6)


def test_pose_residual_sees_a_frame_turned_half_round(rng):
    """A measured orientation 180 deg from the model's (a flipped frame) is an orientation
    residual of pi (times the rows' weight ratio), not of nearly nothing: the pose kind's
    logarithm is rotation_log, whose axis near pi comes from the symmetric part."""
    robot = Robot.load("ec66", tip="flange")
    model = models.build("complete", robot.geometry)
    q = random_joint_values(robot.geometry, rng, 4)
    flipped = robot.tip_poses(q)[:, :3, :3] @ base_rotation(np.pi, 0.0, 0.0)
    data = PoseData(joint_names=robot.joint_names, joint_values=q,
                    positions=np.zeros((4, 3)), rotations=flipped, sigma_deg=np.full(4, 0.05))
    kind = PoseKind(model, data)
    r = kind.residuals(model.nominal, np.zeros(kind.n_frames), None)  # base and tool: identity
    assert np.allclose(np.linalg.norm(r[:, 3:], axis=1), np.pi * data.ratio(), rtol=1e-9)
