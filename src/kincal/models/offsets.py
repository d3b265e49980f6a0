"""The ``offsets`` error model: joint offsets only (the common "zero calibration").

One parameter per joint, its zero: ``<joint>.theta`` [rad] for a revolute joint (a turn
about its own axis), ``<joint>.d`` [m] for a prismatic one (a slide along it), nominally
0, written into the URDF as that joint's origin turned (or moved) along its axis. Every
other parameter of the chain stays nominal; the measurement frame and tool are fitted as
always. Few parameters and well conditioned: suits a robot whose geometry is trusted
(after re-mastering, a motor swap, a collision) and few or poorly spread poses. It cannot
correct link lengths or axis tilts: with large geometric errors the residual stays large.
With position-only data the last joint's offset is identifiable only with a tool point
off its axis.

Tree paths (a base anywhere in the tree): suits them. A reversed joint's offset is a turn
about its chain axis (the URDF axis negated) before its motion; the two commute, and
:meth:`kincal.robot.Robot.with_joint_frames` writes it into that joint's own origin, so
the offset means the same as on a forward joint: true joint value = reading + offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.models.base import OFFSET, ErrorModel
from kincal.rotations import axis_rotation, inverse, transform


@dataclass(frozen=True)
class OffsetsModel(ErrorModel):
    """Joint offsets (see the module notes); placed frames are the URDF joint frames and
    ``origins`` (n, 4, 4) their nominal placements in the frame before; ``urdf`` (n, 4, 4)
    the nominal URDF origins (None: a geometry made without its URDF parent frames) and ``urdf_axes`` (n, 3) the URDF axes (chain axes, negated
    for reversed joints)."""

    origins: np.ndarray
    urdf: np.ndarray | None
    urdf_axes: np.ndarray

    def urdf_origins(self, x) -> dict[str, np.ndarray]:
        """{joint: (4, 4) its corrected URDF origin} [m]: the origin turned about (slid
        along) the URDF axis by the offset, forward or reversed alike (module notes)."""
        if self.urdf is None:
            raise ValueError("this offsets model was built from a geometry without its URDF "
                             "parent frames: it has no URDF origins")
        x = np.asarray(x, float).ravel()
        out = {}
        for i, name in enumerate(self.joint_names):
            w = self.urdf_axes[i]
            if self.kinds[i] == "prismatic":
                M = transform(None, w * x[i])
            else:
                M = transform(axis_rotation(w, x[i]), None)
            out[name] = self.urdf[i] @ M
        return out

    def _offset(self, i: int, value: float) -> np.ndarray:
        w = self.screw_axes[i]
        if self.kinds[i] == "prismatic":
            return transform(None, w * value)
        return transform(axis_rotation(w, value), None)

    def placements(self, x) -> np.ndarray:
        x = np.asarray(x, float).ravel()
        if not x.any():  # zero offsets (the URDF chain itself, ChainKinematics): each offset
            return self.origins.copy()  # is the identity, so the origins as they are
        return np.array([self.origins[i] @ self._offset(i, x[i]) for i in range(self.n)])

    def twists(self, x) -> tuple[np.ndarray, np.ndarray]:
        w, v = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for i in range(self.n):
            R, c = self.origins[i][:3, :3], self.origins[i][:3, 3]
            axis = R @ self.screw_axes[i]
            if self.kinds[i] == "prismatic":
                v[i] = axis
            else:
                w[i], v[i] = axis, np.cross(c, axis)
        return w, v


def build(geometry) -> OffsetsModel:
    """The offsets model of a :class:`kincal.models.geometry.ChainGeometry`."""
    J = np.asarray(geometry.joint_frames, float)
    n = len(J)
    before = np.concatenate([np.eye(4)[None], J[:-1]])
    names = tuple(f"{j}.{'d' if k == 'prismatic' else 'theta'}"
                  for j, k in zip(geometry.joint_names, geometry.kinds))
    return OffsetsModel("offsets", tuple(geometry.joint_names), tuple(geometry.kinds), names,
                        np.zeros(n), np.array([k == "prismatic" for k in geometry.kinds]),
                        (OFFSET,) * n, np.arange(n), np.eye(4), np.asarray(geometry.axes, float),
                        np.zeros((n, 3)), np.broadcast_to(np.eye(4), (n, 4, 4)).copy(),
                        inverse(J[-1]) @ geometry.T_base_tip, ("",) * n, inverse(before) @ J,
                        None if geometry.parent_frames is None
                        else inverse(np.asarray(geometry.parent_frames, float)) @ J,
                        np.where(geometry.is_reversed[:, None], -1.0, 1.0)
                        * np.asarray(geometry.axes, float))
