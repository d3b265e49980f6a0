"""Forward kinematics and Jacobians of a chain, vectorised over configurations.

The inverse kinematics of many targets needs the tip pose and the joint Jacobians for N
configurations at once (Pinocchio's Python API takes one configuration per call). kincal
has one vectorised chain (:mod:`kincal.models.chain`); its ``offsets`` error model at zero
offsets is the URDF chain itself, and the column of a joint's offset is exactly that
joint's motion, so the joint Jacobians are that model's columns. Tests check them against
:meth:`kincal.robot.Robot.tip_poses` / :meth:`kincal.robot.Robot.tip_jacobian`
(Pinocchio) and against central differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.models import offsets
from kincal.models.chain import Chain


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

    def evaluate(self, q: np.ndarray, tool=(0.0, 0.0, 0.0)):
        """Tip pose and Jacobians for joint values ``q`` (N, n) [rad or m].

        Returns (R_tip (N, 3, 3), p_point (N, 3), J_point (N, 3, n), J_rot (N, 3, n)): the
        tip orientation in B, the position in B of the point ``tool`` (3,) given in the
        tip frame [m], and the Jacobians of that point's position [m per rad or m] and of
        the tip frame's orientation (angular velocity in B axes per joint velocity).
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        state = Chain(self.model, q).state(np.zeros(self.model.n))
        point = state.p_tip + state.R_tip @ np.asarray(tool, dtype=float)
        J_point, _ = state.point_columns(point)
        J_rot, _ = state.rotation_columns()
        return state.R_tip, point, J_point, J_rot
