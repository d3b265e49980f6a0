"""Forward kinematics, Jacobians and damped least-squares steps of a chain, vectorised
over configurations.

The inverse kinematics of many targets needs the tip pose and the joint Jacobians for N
configurations at once (Pinocchio's Python API takes one configuration per call). kincal
has one vectorised chain (:mod:`kincal.models.chain`); its ``offsets`` error model at zero
offsets is the URDF chain itself, and the column of a joint's offset is exactly that
joint's motion, so the joint Jacobians are that model's columns. Tests check them against
:meth:`kincal.robot.Robot.tip_poses` / :meth:`kincal.robot.Robot.tip_jacobian`
(Pinocchio) and against central differences.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from kincal.models import offsets
from kincal.models.chain import Chain
from kincal.rotations import rotation_log


BLOCK = 4096  # configurations evaluated at once


@dataclass(frozen=True)
class ChainKinematics:
    """The chain of a ChainGeometry, ready for batched evaluation (its offsets model)."""

    model: offsets.OffsetsModel

    @classmethod
    def of(cls, geometry) -> "ChainKinematics":
        return cls(offsets.build(geometry))

    @property
    def n(self) -> int:
        return self.model.n

    @property
    def placements(self) -> np.ndarray:
        """(n, 4, 4) pose of joint frame i at zero in joint frame i-1 (frame 0: B)."""
        return self.model.origins

    @property
    def prismatic(self) -> np.ndarray:
        return np.array([k == "prismatic" for k in self.model.kinds])

    @property
    def T_last_tip(self) -> np.ndarray:
        return self.model.T_last_tip

    def tip_points(self, q: np.ndarray, tool=(0.0, 0.0, 0.0)) -> np.ndarray:
        """(N, 3) the point ``tool`` (3,) of the tip frame [m], in B, for joint values q
        (N, n) [rad or m]; the tip pose only, no Jacobian."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        state = Chain(self.model, q).state(np.zeros(self.model.n), keep=False)
        return state.p_tip + state.R_tip @ np.asarray(tool, dtype=float)

    @functools.cached_property
    def _joints(self) -> list:
        """Per joint: (origin, axis w, axis point c, [w]x, c - w (w . c), w x c), the last
        three None for a prismatic joint."""
        m, out = self.model, []
        for i in range(m.n):
            w, c = m.screw_axes[i], m.screw_points[i]
            K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
            out.append((m.origins[i], w, c) + ((None, None, None) if m.kinds[i] == "prismatic"
                                               else (K, c - w * (w @ c), K @ c)))
        return out

    def tool_poses(self, q: np.ndarray, tool=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """(R_tip (N, 3, 3), p_point (N, 3)) of :meth:`evaluate`, without keeping the
        Jacobians (made block by block and dropped)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        R, p = np.empty((len(q), 3, 3)), np.empty((len(q), 3))
        for s in range(0, len(q), BLOCK):
            R[s:s + BLOCK], p[s:s + BLOCK] = self.evaluate(q[s:s + BLOCK], tool)[:2]
        return R, p

    def evaluate(self, q: np.ndarray, tool=(0.0, 0.0, 0.0)):
        """Tip pose and Jacobians for joint values ``q`` (N, n) [rad or m].

        Returns (R_tip (N, 3, 3), p_point (N, 3), J_point (N, 3, n), J_rot (N, 3, n)): the
        tip orientation in B, the position in B of the point ``tool`` (3,) given in the
        tip frame [m], and the Jacobians of that point's position [m per rad or m] and of
        the tip frame's orientation (angular velocity in B axes per joint velocity).

        The chain's product T_first P_1 M_1(q_1) ... P_n M_n(q_n) T_last_tip as rotations
        and translations (the offsets model at zero: P_i its origins), each product by a
        fixed matrix one product over all rows; joint i's columns are its axis line's
        motion: a x (p - c) and a for a revolute joint (axis a through c, in B), a and 0
        for a prismatic one.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if len(q) > BLOCK:  # in blocks of configurations: see _times
            parts = [self.evaluate(q[s:s + BLOCK], tool) for s in range(0, len(q), BLOCK)]
            return tuple(np.concatenate(p) for p in zip(*parts))
        m = self.model
        N = len(q)
        R = np.broadcast_to(m.T_first[:3, :3], (N, 3, 3))
        t = np.broadcast_to(m.T_first[:3, 3], (N, 3))
        axes, points = np.empty((N, 3, m.n)), np.empty((N, 3, m.n))
        for i, (O, w, c, K, u, v) in enumerate(self._joints):
            HR, Ht = _times(R, O[:3, :3]), _times(R, O[:3, 3]) + t  # joint i's placed frame
            a = axes[:, :, i] = _times(HR, w)
            if K is None:  # prismatic
                R, t = HR, Ht + a * q[:, i, None]
                continue
            # the turn M = cos I + sin K + (1 - cos) w w^T about the line through c, K = [w]x:
            # HR M = cos HR + sin HR K + (1 - cos) a w^T; c - M c = (1 - cos) u - sin v
            # with u = c - w (w . c) and v = w x c
            cos, sin = np.cos(q[:, i])[:, None], np.sin(q[:, i])[:, None]
            points[:, :, i] = _times(HR, c) + Ht
            R = cos[:, :, None] * HR + sin[:, :, None] * _times(HR, K) + (
                1.0 - cos)[:, :, None] * (a[:, :, None] * w)
            t = (1.0 - cos) * _times(HR, u) - sin * _times(HR, v) + Ht
        R_tip = _times(R, m.T_last_tip[:3, :3])
        point = _times(R, m.T_last_tip[:3, 3]) + t + _times(R_tip, np.asarray(tool, dtype=float))
        rev = ~self.prismatic
        J_point, J_rot = axes.copy(), np.zeros((N, 3, m.n))
        a, d = axes[:, :, rev], point[:, :, None] - points[:, :, rev]
        J_point[:, :, rev] = np.stack([a[:, 1] * d[:, 2] - a[:, 2] * d[:, 1],  # a x (p - c)
                                       a[:, 2] * d[:, 0] - a[:, 0] * d[:, 2],
                                       a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0]], axis=1)
        J_rot[:, :, rev] = a
        return R_tip, point, J_point, J_rot

    def damped_step(self, q: np.ndarray, tool, positions: np.ndarray, rotations, lower,
                    upper) -> tuple[np.ndarray, np.ndarray]:
        """One damped least-squares step toward the targets, for N configurations at once:
        the step of :meth:`kincal.robot.Robot.inverse_kinematics`, on the vectorised chain.

        q: (N, n) joint values; positions: (N, 3) wanted positions of the point ``tool``
        (3,) of the tip frame, in B [m]; rotations: (N, 3, 3) wanted tip orientations in B,
        or None (position only); lower, upper: (n,) finite joint limits. Returns (|e| (N,),
        the next q (N, n)): the norm of the error [m and rad stacked] at q and
        q + A^T (A A^T + 1e-8 I)^-1 e clipped to the limits, A the Jacobian of the error.
        """
        R, p, J_point, J_rot = self.evaluate(q, tool)
        e, A = np.asarray(positions, dtype=float) - p, J_point
        if rotations is not None:
            e = np.concatenate([e, rotation_log(rotations @ np.swapaxes(R, 1, 2))], axis=1)
            A = np.concatenate([J_point, J_rot], axis=1)
        M = A @ np.swapaxes(A, 1, 2)
        M += 1e-8 * np.eye(e.shape[1])
        dq = (np.swapaxes(A, 1, 2) @ np.linalg.solve(M, e[:, :, None]))[:, :, 0]
        return np.linalg.norm(e, axis=1), np.clip(q + dq, lower, upper)


def _times(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A (N, 3, 3) times a fixed B (3, 3) or (3,): one matrix product over all N rows (for
    N up to :data:`BLOCK`: a larger one would go to BLAS's threads, slower on busy cores)."""
    return (A.reshape(-1, 3) @ B).reshape(A.shape[:2] + B.shape[1:])
