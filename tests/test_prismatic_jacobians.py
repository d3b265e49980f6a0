"""Every measurement kind's analytic Jacobian against central differences on random chains
with prismatic joints and backlash terms on them (EC66 and UR10, where the other kind tests
run, have no prismatic joint: a wrong orientation column of a prismatic backlash term would
pass there)."""

import numpy as np
import pytest
from chains import random_chain
from conftest import random_joint_values

from kincal import models
from kincal.measurements.distance import DistanceData, DistanceKind
from kincal.measurements.plane import PlaneData, PlaneKind
from kincal.measurements.point import PointKind
from kincal.measurements.data import Measurements
from kincal.measurements.pose import PoseData, PoseKind
from kincal.models.chain import Chain
from kincal.robot import Robot
from kincal.rotations import base_rotation

KINDS = ("point", "pose", "distance", "plane")
TOLERANCE = 1e-6  # largest |analytic - central difference| / largest |column entry|


def _chain_with_prismatic(tmp_path, seed):
    """A random chain with at least one prismatic joint that is not the last one (the
    last joint of a chain is revolute for the error models), and its robot."""
    rng = np.random.default_rng(seed)
    for attempt in range(200):
        text, cases = random_chain(rng, n=int(rng.integers(4, 7)),
                                   cases=("general", "prismatic", "parallel", "prismatic"))
        path = tmp_path / f"chain_{seed}_{attempt}.urdf"
        path.write_text(text)
        robot = Robot.load(path, tip="tip")
        kinds = robot.geometry.kinds
        if "prismatic" in kinds[:-1] and kinds[-1] == "revolute":
            return robot, rng
    raise AssertionError("no random chain with a prismatic joint")  # pragma: no cover


def _kind(kind, model, q, rng, names, backlash):
    n = len(q)
    if kind == "point":
        return PointKind(model, Measurements(names, q, rng.normal(size=(n, 3))), backlash=backlash)
    if kind == "pose":
        R = np.stack([base_rotation(*a) for a in rng.uniform(-2, 2, size=(n, 3))])
        data = PoseData(joint_names=names, joint_values=q, positions=rng.normal(size=(n, 3)),
                        rotations=R, sigma_deg=rng.uniform(0.01, 0.1, n))
        return PoseKind(model, data, backlash=backlash)
    if kind == "distance":
        data = DistanceData(joint_names=names, joint_values=q, distances=rng.uniform(0.5, 1, n))
        return DistanceKind(model, data, backlash=backlash)
    data = PlaneData(joint_names=names, joint_values=q, planes=np.arange(n) % 3,
                     labels=("1", "2", "3"))
    return PlaneKind(model, data, backlash=backlash)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("model_name", models.MODELS)
@pytest.mark.parametrize("kind", KINDS)
def test_kind_jacobian_with_prismatic_backlash_matches_central_differences(
        kind, model_name, seed, tmp_path):
    robot, rng = _chain_with_prismatic(tmp_path, seed)
    model = models.build(model_name, robot.geometry)
    kinds = robot.geometry.kinds
    prismatic = [i for i, k in enumerate(kinds) if k == "prismatic"]
    revolute = [i for i, k in enumerate(kinds) if k == "revolute"]
    backlash = tuple(sorted(set(prismatic) | {revolute[0]}))  # every prismatic joint
    q = random_joint_values(robot.geometry, rng, 10)
    q[0] = 0.0  # q = 0 on purpose
    km = _kind(kind, model, q, rng, robot.joint_names, backlash)
    kin = model.nominal + rng.normal(size=model.size) * 1e-2
    frames = rng.normal(size=km.n_frames) * 0.3
    b = rng.normal(size=len(backlash)) * 1e-2
    k, f = model.size, km.n_frames
    x = np.concatenate([kin, frames, b])

    def res(x):
        return km.residuals(x[:k], x[k:k + f], x[k + f:])

    r, Jk, Jf, Jb = km.residuals(kin, frames, b, jacobian=True)
    assert np.allclose(r, res(x))
    J = np.concatenate([Jk, Jf, Jb], axis=2)
    names = ([f"kinematic {c}" for c in range(k)] + [f"frame {c}" for c in range(f)]
             + [f"backlash of joint {robot.joint_names[i]} ({kinds[i]})" for i in backlash])
    h = 1e-6
    for c in range(x.size):
        e = np.zeros_like(x)
        e[c] = h
        fd = (res(x + e) - res(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        err = np.abs(J[:, :, c] - fd).max() / scale
        assert err < TOLERANCE, (f"{kind} Jacobian column {names[c]} differs from central "
                                 f"differences by {err:.2g} (model {model_name}, seed {seed})")


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("model_name", models.MODELS)
def test_prismatic_backlash_moves_the_joint_as_pinocchio_does(model_name, seed, tmp_path):
    """The value the Jacobians differentiate: a backlash term b with approach g is the
    joint's own motion q + b g (metres on a prismatic joint), so the chain's tip pose
    equals Pinocchio's on the corrected robot at those joint values."""
    robot, rng = _chain_with_prismatic(tmp_path, seed)
    model = models.build(model_name, robot.geometry)
    backlash = tuple(i for i, k in enumerate(robot.geometry.kinds) if k == "prismatic")
    q = random_joint_values(robot.geometry, rng, 20)
    g = rng.choice([-1.0, 0.0, 1.0], size=q.shape)
    kin = model.nominal + rng.normal(size=model.size) * 1e-3
    b = rng.normal(size=len(backlash)) * 1e-2
    s = Chain(model, q, g, backlash).state(kin, b)
    q_eff = q.copy()
    for k, i in enumerate(backlash):
        q_eff[:, i] += b[k] * g[:, i]
    T = robot.with_joint_frames(model.joint_frames(kin)).tip_poses(q_eff)
    assert np.abs(T[:, :3, 3] - s.p_tip).max() < 1e-12, "tip position with prismatic backlash"
    assert np.abs(T[:, :3, :3] - s.R_tip).max() < 1e-12, "tip orientation with prismatic backlash"
