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
for the data. Suits: arms with irregular geometry, when the corrections should be read
directly as changes of the URDF origins, and tree paths (a base anywhere in the tree,
:mod:`kincal.robot`), which it fits naturally.

Tree paths. A reversed joint i (traversed from its child link up to its parent) has its
origin *after* its motion: the chain reads inverse(origin_i(x)) between joint i and the
next joint, so its six errors act on the next placement (the same errors of the same
URDF ``<origin>``, read as above). Two origins get no errors of their own, each with a
note: the top reversed joint's when a joint down follows (the transform through the
common ancestor link is then corrected as that first down joint's origin, which holds
every change of it, and the corrected URDF writes it there), or when none follows (its
origin lies between the last motion and the tip, the tool frame's part). The base frame's
own link (before the first reversed joint moves) is never corrected: no URDF origin holds it.

Several chains sharing joints (:mod:`kincal.identification.chains`): ``every_origin=True``
gives the top reversed joint's origin its six errors too when a joint down follows. Within
one chain they duplicate the first down joint's; across chains they do not (another chain
may climb through that origin, or descend through the same down joint from another
branch), and the rank-revealing selection removes what is redundant over the union.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.models.base import LENGTH, OFFSET, TWIST, ErrorModel
from kincal.rotations import base_rotation, base_turns, inverse, transform

FIELDS = ("tx", "ty", "tz", "rx", "ry", "rz")


@dataclass(frozen=True)
class PlacementModel(ErrorModel):
    """Six placement errors per joint origin (see the module notes). Placed frames are the
    URDF joint frames; each placement is P_k = left_k mid_k right_k, with right_k =
    origin_k(x) for a joint k traversed forward, left_k = inverse(origin_{k-1}(x)) after a
    reversed joint k-1 whose origin carries errors, identity otherwise.

    mid: (n, 4, 4) the fixed middle factors. origins: (n, 4, 4) nominal URDF origins.
    reversed: (n,) joints traversed against their URDF direction.
    has_errors: (n,) which joints' origins carry the six errors (in names order).
    """

    mid: np.ndarray
    origins: np.ndarray
    reversed: np.ndarray
    has_errors: np.ndarray

    def _origin(self, i: int | np.integer, e: np.ndarray) -> np.ndarray:
        R = base_rotation(e[3], e[4], e[5]) @ self.origins[i][:3, :3]
        return transform(R, self.origins[i][:3, 3] + e[:3])

    def _errors(self, x) -> np.ndarray:
        e = np.zeros((self.n, 6))
        e[self.has_errors] = np.asarray(x, float).reshape(-1, 6)
        return e

    def urdf_origins(self, x) -> dict[str, np.ndarray]:
        """{joint: (4, 4) its corrected URDF origin} for the joints whose origins carry
        errors [m]: what a corrected URDF writes, whatever chain traverses them."""
        e = self._errors(x)
        return {self.joint_names[i]: self._origin(i, e[i]) for i in np.flatnonzero(self.has_errors)}

    def placements(self, x) -> np.ndarray:
        e = self._errors(x)
        P = self.mid.copy()
        for i in np.flatnonzero(self.has_errors):
            if self.reversed[i]:
                P[i + 1] = inverse(self._origin(i, e[i])) @ P[i + 1]
            else:
                P[i] = P[i] @ self._origin(i, e[i])
        return P

    def twists(self, x) -> tuple[np.ndarray, np.ndarray]:
        e = self._errors(x)
        w, v = np.zeros((self.size, 3)), np.zeros((self.size, 3))
        for k, i in enumerate(np.flatnonzero(self.has_errors)):
            W = base_turns(e[i, 3], e[i, 4])  # columns: the rx, ry, rz axes in the link
            rows = slice(6 * k, 6 * k + 6)
            if self.reversed[i]:
                # inverse(origin) is the first factor: a change dO = d O moves a point X of
                # the frame before by -R^T (d applied at R X + p); the turns are about the
                # joint origin p, which is that frame's origin
                Rt = self._origin(i, e[i])[:3, :3].T
                v[rows][:3] = -Rt.T  # rows tx, ty, tz: -R^T e_k
                w[rows][3:] = -(Rt @ W).T
            else:
                L = self.mid[i]  # the parent link frame in the frame before
                if i and self.reversed[i - 1] and self.has_errors[i - 1]:
                    # the top reversed joint's inverse origin leads this placement
                    L = inverse(self._origin(i - 1, e[i - 1])) @ L
                R, o = L[:3, :3], L[:3, 3]
                c = o + R @ (self.origins[i][:3, 3] + e[i, :3])  # the joint origin, frame before
                axes = [R @ t for t in W.T]
                v[rows][:3] = R.T
                w[rows][3:] = axes
                v[rows][3:] = [np.cross(c, a) for a in axes]
        return w, v

    def point_columns(self, x, before, placed, P) -> np.ndarray:
        """(N, 3, p) derivatives of points P (N, 3) rigidly attached to the tip: the generic
        twists of kincal.models.chain written with this model's structure (the hot path):
        t slides along the parent link's axes, r turns about them through the joint
        origin (the origin of the placed frame). Chains with reversed joints take the
        generic twists."""
        if self.reversed.any():
            w, v = self.twists(x)
            G = np.asarray(before)[self.joint_of]                       # (p, N, 4, 4)
            W = (G[..., :3, :3] @ w[:, None, :, None])[..., 0]
            U = (G[..., :3, :3] @ v[:, None, :, None])[..., 0]
            return (np.cross(W, P[None] - G[..., :3, 3]) + U).transpose(1, 2, 0)
        e = np.asarray(x, float).reshape(self.n, 6)
        G, H = np.asarray(before), np.asarray(placed)                 # (n, N, 4, 4)
        F = G[:, :, :3, :3] @ self.mid[:, None, :3, :3]           # parent link axes
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


def _field_class(field: str, axis_in_parent: np.ndarray, kind: str) -> str:
    """The class of one placement error of a joint whose axis is ``axis_in_parent`` (unit,
    in its parent link frame): the turn about a revolute joint's own axis (or the slide
    along a prismatic joint's) is that joint's zero, an "offset" (it commutes with the
    joint's motion), when the axis lies along the error's axis; else a length or a twist."""
    k = "xyz".index(field[1])
    along = abs(float(axis_in_parent[k])) > 1.0 - 1e-9
    if field.startswith("t"):
        return OFFSET if (along and kind == "prismatic") else LENGTH
    return OFFSET if (along and kind == "revolute") else TWIST


def build(geometry, every_origin: bool = False) -> PlacementModel:
    """The placement model of a :class:`kincal.models.geometry.ChainGeometry`; every_origin: the top
    reversed joint's origin keeps its errors when a joint down follows (module notes)."""
    J = np.asarray(geometry.joint_frames, float)
    n = len(J)
    rev = geometry.is_reversed
    names = geometry.joint_names
    parents = np.asarray(geometry.parent_frames, float)
    origins = inverse(parents) @ J
    top = int(rev.sum()) - 1  # the last reversed joint, -1 if none
    has = ~rev
    has[:max(top + (every_origin and top < n - 1), 0)] = True
    # nominal P_k = inverse(frame before) . J_k, split around the origins with errors: the
    # frame before is reached through the previous joint's parent link when that joint's
    # inverse origin leads the placement, J_k through its parent link when k is forward
    before = np.concatenate([np.eye(4)[None], J[:-1]])
    led = np.concatenate([[False], (rev & has)[:-1]])
    left = inverse(np.where(led[:, None, None], np.concatenate([np.eye(4)[None], parents[:-1]]),
                            before))
    mid = left @ np.where(rev[:, None, None], J, parents)
    notes = [""] * n
    if top >= 0 and not has[top]:
        notes[top] = (f"reversed, its origin lies between {names[top]} and the tip: the tool "
                      "frame's part, no errors of its own" if top == n - 1 else
                      f"reversed at the common ancestor: its origin and {names[top + 1]}'s hold "
                      f"one transform, corrected as {names[top + 1]}'s origin")
    p = 6 * int(has.sum())
    joint_of = np.repeat(np.where(rev, np.arange(n) + 1, np.arange(n))[has], 6)
    classes = tuple(_field_class(f, origins[i][:3, :3] @ np.asarray(geometry.axes[i], float),
                                 geometry.kinds[i])
                    for i in range(n) if has[i] for f in FIELDS)
    return PlacementModel("placement", tuple(names), tuple(geometry.kinds),
                          tuple(f"{j}.{f}" for j, h in zip(names, has) if h for f in FIELDS),
                          np.zeros(p), np.array([f.startswith("t") for f in FIELDS] * (p // 6)),
                          classes,
                          joint_of, np.eye(4), np.asarray(geometry.axes, float),
                          np.zeros((n, 3)), np.broadcast_to(np.eye(4), (n, 4, 4)).copy(),
                          inverse(J[-1]) @ geometry.T_base_tip, tuple(notes),
                          mid, origins, rev, has)
