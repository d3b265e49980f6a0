"""Forward kinematics and Jacobians of a chain, vectorised over configurations.

Plain numpy over a :class:`kincal.robot.ChainGeometry` (the joint frames at zero joint
values, expressed in the base frame B): the same product of joint placements and joint
motions that Pinocchio evaluates, but for N configurations at once, which the inverse
kinematics of many targets needs (Pinocchio's Python API takes one configuration per
call). Tests check it against :meth:`kincal.robot.Robot.tip_poses` and
:meth:`kincal.robot.Robot.tip_jacobian` (Pinocchio) and against central differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.rotations import inverse


def _rotations(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations about the unit ``axis`` (3,) by ``angles`` (N,) [rad]."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


@dataclass(frozen=True)
class ChainKinematics:
    """The chain of a ChainGeometry as relative placements, ready for batched evaluation.

    placements: (n, 4, 4) pose of joint frame i at zero in joint frame i-1 (frame 0: B).
    axes: (n, 3) unit axis of joint i in its own frame. prismatic: (n,) bool.
    T_last_tip: (4, 4) the tip frame in the last joint frame.
    """

    placements: np.ndarray
    axes: np.ndarray
    prismatic: np.ndarray
    T_last_tip: np.ndarray

    @classmethod
    def of(cls, geometry) -> "ChainKinematics":
        J = np.asarray(geometry.joint_frames, dtype=float)
        prev = np.concatenate([np.eye(4)[None], J[:-1]])
        return cls(inverse(prev) @ J, np.asarray(geometry.axes, dtype=float),
                   np.array([k == "prismatic" for k in geometry.kinds]),
                   inverse(J[-1]) @ np.asarray(geometry.T_base_tip, dtype=float))

    @property
    def n(self) -> int:
        return len(self.axes)

    def evaluate(self, q: np.ndarray, tool=(0.0, 0.0, 0.0)):
        """Tip pose and Jacobians for joint values ``q`` (N, n) [rad or m].

        Returns (R_tip (N, 3, 3), p_point (N, 3), J_point (N, 3, n), J_rot (N, 3, n)): the
        tip orientation in B, the position in B of the point ``tool`` (3,) given in the
        tip frame [m], and the Jacobians of that point's position [m per rad or m] and of
        the tip frame's orientation (angular velocity in B axes per joint velocity).
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        N = len(q)
        R = np.broadcast_to(np.eye(3), (N, 3, 3))
        p = np.zeros((N, 3))
        z = np.empty((N, self.n, 3))  # joint axes in B
        o = np.empty((N, self.n, 3))  # a point of each axis in B
        for i in range(self.n):
            P = self.placements[i]
            p = p + R @ P[:3, 3]
            R = R @ P[:3, :3]
            z[:, i] = R @ self.axes[i]
            o[:, i] = p
            if self.prismatic[i]:
                p = p + z[:, i] * q[:, i, None]
            else:
                R = R @ _rotations(self.axes[i], q[:, i])
        p_tip = p + R @ self.T_last_tip[:3, 3]
        R_tip = R @ self.T_last_tip[:3, :3]
        point = p_tip + R_tip @ np.asarray(tool, dtype=float)
        lever = point[:, None, :] - o
        J_point = np.where(self.prismatic[None, :, None], z, np.cross(z, lever))
        J_rot = np.where(self.prismatic[None, :, None], 0.0, z)
        return R_tip, point, np.swapaxes(J_point, 1, 2), np.swapaxes(J_rot, 1, 2)
