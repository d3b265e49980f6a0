"""Kinematics of many configurations at once: tool point, tip axis, Jacobians, and IK.

Plain numpy over the chain geometry of :class:`kincal.robot.Robot` (exact for the URDF),
for :mod:`kincal.planning.volume_candidates`, which solves thousands of small IK problems
at a time (Pinocchio's Python API takes one configuration per call). Jacobians are
analytic (each joint's axis line at the configuration) and tested against Pinocchio's
forward kinematics and central differences.

The IK task puts the tool point at a target and the tip z axis along a unit direction u:
residual (P - target, (z - u) L), L the arm's reach so that both parts weigh alike. The
spin about z is left free (5 conditions, 6 residuals): damped Gauss-Newton steps are
then minimum-norm, and keep the spin of the start.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kincal.models.kinematics import ChainKinematics

if TYPE_CHECKING:
    from kincal.robot import Robot

IK_ITERATIONS = 60
IK_TOL = 1e-9  # [m] on the point and [-] on the z axis: converged
MAX_STEP = 0.3  # [rad or m] largest joint step per iteration (keeps the branch)


class BatchKinematics:
    """Forward kinematics and Jacobians of the chain for N configurations at once.

    Built from the robot's :class:`kincal.models.geometry.ChainGeometry` (joint frames at zero in
    the base frame B): the same product of joint placements and joint motions that
    Pinocchio evaluates, for many configurations per call. tool: (3,) the point of
    interest in the tip frame [m].
    """

    def __init__(self, robot: "Robot", tool):
        g = robot.geometry
        self.n = g.n
        self.lo, self.hi = g.ranges()
        self.tool = np.asarray(tool, float)
        J = np.asarray(g.joint_frames, float)
        self._chain = ChainKinematics.of(g)  # kincal's one vectorised chain (models.chain)
        origins = np.concatenate([J[:, :3, 3], g.T_base_tip[None, :3, 3]])
        # the arm's reach: it makes the linear part of the Jacobian comparable to the angular
        self.reach = max(float(np.linalg.norm(np.diff(origins, axis=0), axis=1).sum()), 1e-3)

    def jacobians(self, Q):
        """(R (N, 3, 3), P (N, 3), Jp (N, 3, n), Jw (N, 3, n)): tip rotation, tool point,
        and the joint Jacobians of the tool point [m per rad or m] and of the tip rotation
        [rad per rad or m], all in the base frame (analytic)."""
        return self._chain.evaluate(np.atleast_2d(np.asarray(Q, float)), self.tool)

    def poses(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tip rotation (N, 3, 3), tool point (N, 3)) in the base frame."""
        R, P, _, _ = self.jacobians(Q)
        return R, P

    def task(self, Q):
        """(residual (N, 6), Jacobian (N, 6, n), R, P) of the point and z-axis task."""
        R, P, Jp, Jw = self.jacobians(Q)
        z = R[:, :, 2]
        Jz = -np.cross(z[:, :, None], Jw, axis=1)  # dz = w x z dq
        F = np.concatenate([P, z * self.reach], axis=1)
        return F, np.concatenate([Jp, Jz * self.reach], axis=1), R, P

    def sigma_min(self, Q) -> np.ndarray:
        """(N,) smallest singular value of the 6 x n tip Jacobian (linear part / reach)."""
        _, _, Jp, Jw = self.jacobians(Q)
        J = np.concatenate([Jp / self.reach, Jw], axis=1)                  # (N, 6, n)
        return np.linalg.svd(J, compute_uv=False)[:, -1]

    def solve(self, targets, directions, start):
        """Damped Gauss-Newton from ``start`` (N, n); returns (Q, converged (N,))."""
        Q = np.clip(np.array(start, float), self.lo, self.hi)
        goal = np.concatenate([targets, directions * self.reach], axis=1)
        done = np.zeros(len(Q), dtype=bool)
        for _ in range(IK_ITERATIONS):
            act = np.flatnonzero(~done)
            if act.size == 0:
                break
            F, J, _, _ = self.task(Q[act])
            r = F - goal[act]
            ok = np.max(np.abs(r), axis=1) < IK_TOL
            done[act[ok]] = True
            act, r, J = act[~ok], r[~ok], J[~ok]
            JtJ = J.transpose(0, 2, 1) @ J
            mu = 1e-6 * (np.trace(JtJ, axis1=1, axis2=2)[:, None, None] + 1e-12)
            g = J.transpose(0, 2, 1) @ r[..., None]
            dq = -np.linalg.solve(JtJ + mu * np.eye(self.n), g)[..., 0]
            big = np.max(np.abs(dq), axis=1, keepdims=True)
            dq *= np.minimum(1.0, MAX_STEP / np.maximum(big, 1e-300))
            Q[act] = np.clip(Q[act] + dq, self.lo, self.hi)
        return Q, done
