"""The geometry of a chain at zero joint values: the value every error model and batched
kinematics is built from (:class:`kincal.robot.Robot` makes it from its URDF, the one
Pinocchio boundary; plain numpy here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ChainGeometry:
    """The chain at zero joint values, expressed in the base frame B.

    joint_names: the n movable chain joints in path order (from the base).
    kinds: "revolute" (revolute or continuous) or "prismatic", per joint.
    joint_frames: (n, 4, 4) T_B_Ji, pose of joint frame i (= its child link frame) [m].
    axes: (n, 3) unit joint axis of joint i in its own frame, in the chain's direction:
        the URDF axis, negated for a reversed joint. A positive joint value turns (slides)
        the tip side about (along) it, whichever way the joint is traversed; joint values
        keep the URDF's sign.
    T_base_tip: (4, 4) pose of the tip frame at zero joint values [m].
    lower, upper: (n,) joint limits [rad or m]; +-inf when the URDF gives none.
    parent_frames: (n, 4, 4) pose of each joint's URDF parent link frame (the frame its
        ``<origin>`` is written in) at zero joint values [m]. For a reversed joint that
        link is on the tip side of it: origin_i = inverse(parent_frames[i]) @ joint_frames[i].
    reversed: (n,) True for the joints traversed against their URDF direction (the path
        from the base up to the common ancestor); None means none (a chain below its base).
    """

    joint_names: tuple[str, ...]
    kinds: tuple[str, ...]
    joint_frames: np.ndarray
    axes: np.ndarray
    T_base_tip: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    parent_frames: np.ndarray | None = None
    reversed: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.joint_names)

    @property
    def is_reversed(self) -> np.ndarray:
        """(n,) bool: which joints are traversed against their URDF direction."""
        return (np.zeros(self.n, dtype=bool) if self.reversed is None
                else np.asarray(self.reversed, dtype=bool))

    def ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) (n,) [rad or m]: the joint limits, +-pi where the URDF gives none
        (a continuous joint): the range that poses are drawn from and steps clipped to."""
        return (np.where(np.isfinite(self.lower), self.lower, -np.pi),
                np.where(np.isfinite(self.upper), self.upper, np.pi))


def chain_length(joint_frames: np.ndarray, T_base_tip: np.ndarray) -> float:
    """[m] summed distances first joint -> ... -> last joint -> tip frame, at zero values."""
    pts = np.vstack([joint_frames[:, :3, 3], T_base_tip[:3, 3]])
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
