"""The ``placement`` error model: six small errors of every joint's placement.

The URDF ``<origin>`` of joint i (its pose in its parent link frame L) becomes

    origin_i(x) = [ Rx(rx) Ry(ry) Rz(rz) R_o  |  p_o + (tx, ty, tz) ]

with the six errors ``<joint>.tx .ty .tz`` [m] and ``.rx .ry .rz`` [rad] along and about
the axes of the parent link frame, the turns about the joint origin (so translations and
rotations stay decoupled). Nominal values are 0. This is the model FIGAROH calls "full
placement errors". It is complete by construction (any rigid error of a link is a change of
its joint's placement) but far from minimal: each revolute joint's turn about its own axis
and slide along it duplicate parts of the next placement, and the measurement frame and
tool absorb more. The rank-revealing selection (:mod:`kincal.identification.selection`)
keeps one of every redundant group (from the tip back), so the identified set is minimal
for the data. Suits: arms with irregular geometry, or when the corrections should be read
directly as changes of the URDF origins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.models.base import LENGTH, TWIST, ErrorModel
from kincal.rotations import inverse, rotx, roty, rotz, transform

FIELDS = ("tx", "ty", "tz", "rx", "ry", "rz")


@dataclass(frozen=True)
class PlacementModel(ErrorModel):
    """Six placement errors per joint (see the module notes). Placed frames are the URDF
    joint frames; ``parent_in_before`` (n, 4, 4) is each joint's parent link frame in the
    frame before its placement, ``origins`` (n, 4, 4) the nominal URDF origins."""

    parent_in_before: np.ndarray = None
    origins: np.ndarray = None

    def _origin(self, i: int, e: np.ndarray) -> np.ndarray:
        R = rotx(e[3]) @ roty(e[4]) @ rotz(e[5]) @ self.origins[i][:3, :3]
        return transform(R, self.origins[i][:3, 3] + e[:3])

    def placements(self, x) -> np.ndarray:
        e = np.asarray(x, float).reshape(self.n, 6)
        return np.array([self.parent_in_before[i] @ self._origin(i, e[i]) for i in range(self.n)])

    def twists(self, x) -> tuple[np.ndarray, np.ndarray]:
        e = np.asarray(x, float).reshape(self.n, 6)
        w, v = np.zeros((self.size, 3)), np.zeros((self.size, 3))
        for i in range(self.n):
            L = self.parent_in_before[i]
            R, o = L[:3, :3], L[:3, 3]
            c = o + R @ (self.origins[i][:3, 3] + e[i, :3])  # the joint origin, frame before
            Rx, Ry = rotx(e[i, 3]), roty(e[i, 4])
            axes = [R[:, 0], R @ Rx[:, 1], R @ Rx @ Ry[:, 2]]
            for k in range(3):
                v[6 * i + k] = R[:, k]
                w[6 * i + 3 + k] = axes[k]
                v[6 * i + 3 + k] = np.cross(c, axes[k])
        return w, v


    def point_columns(self, x, before, placed, P) -> np.ndarray:
        """(N, 3, p) derivatives of points P (N, 3) rigidly attached to the tip: the generic
        twists of kincal.models.chain written with this model's structure (the hot path):
        t slides along the parent link's axes, r turns about them through the joint
        origin (the origin of the placed frame)."""
        e = np.asarray(x, float).reshape(self.n, 6)
        G, H = np.stack(before), np.stack(placed)                 # (n, N, 4, 4)
        F = G[:, :, :3, :3] @ self.parent_in_before[:, None, :3, :3]  # parent link axes
        c, s = np.cos(e[:, 3]), np.sin(e[:, 3])
        cy, sy = np.cos(e[:, 4]), np.sin(e[:, 4])
        u_y = np.stack([np.zeros(self.n), c, s], axis=1)           # Rx(rx) e_y
        u_z = np.stack([sy, -s * cy, c * cy], axis=1)              # Rx(rx) Ry(ry) e_z
        r = P - H[:, :, :3, 3]                                     # (n, N, 3) from the origin
        cols = np.empty((self.n, 6, len(P), 3))
        cols[:, 0], cols[:, 1], cols[:, 2] = F[..., 0], F[..., 1], F[..., 2]
        for k, axis in enumerate((F[..., 0], (F @ u_y[:, None, :, None])[..., 0],
                                  (F @ u_z[:, None, :, None])[..., 0])):
            cols[:, 3 + k] = np.cross(axis, r)
        return cols.reshape(6 * self.n, len(P), 3).transpose(1, 2, 0)


def build(geometry) -> PlacementModel:
    """The placement model of a :class:`kincal.robot.ChainGeometry`."""
    J = np.asarray(geometry.joint_frames, float)
    n = len(J)
    parents = np.asarray(geometry.parent_frames, float)
    before = np.concatenate([np.eye(4)[None], J[:-1]])       # frame before each placement
    parent_in_before = inverse(before) @ parents
    origins = inverse(parents) @ J
    names = tuple(f"{j}.{f}" for j in geometry.joint_names for f in FIELDS)
    return PlacementModel("placement", tuple(geometry.joint_names), tuple(geometry.kinds), names,
                        np.zeros(6 * n), np.array([f.startswith("t") for f in FIELDS] * n),
                        tuple((LENGTH if f.startswith("t") else TWIST) for _ in range(n)
                              for f in FIELDS),
                        np.repeat(np.arange(n), 6), np.eye(4), np.asarray(geometry.axes, float),
                        np.zeros((n, 3)), np.broadcast_to(np.eye(4), (n, 4, 4)).copy(),
                        inverse(J[-1]) @ geometry.T_base_tip, ("",) * n,
                        parent_in_before, origins)
