"""Modified Denavit-Hartenberg (Craig) description of a chain, and its error layer.

Frame i relative to frame i-1 (row i of a table, parameters of joint i):

    A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_oi) Tz(d_i)

and joint i moves frame i about (revolute) or along (prismatic) its z axis. The four
parameters of joint i are named ``<joint>.a`` (a_{i-1} [m]), ``<joint>.alpha``
(alpha_{i-1} [rad]), ``<joint>.d`` (d_i [m]) and ``<joint>.theta`` (theta_oi [rad]).

Extraction from any URDF (the URDF frames need not be MD-H frames). The z axis of
frame i is joint i's axis, oriented as the URDF axis so joint values keep their sign.
For i < n, frame i sits on axis i at the foot of the common normal to axis i+1, with
x_i along that normal. Degenerate cases, each a deliberate choice:

- intersecting axes (a = 0): the normal's direction is z_i x z_{i+1}; its sign is the
  one closest to the URDF joint frame's x axis, so an MD-H URDF gives back its own table.
- parallel axes (|z_i x z_{i+1}| < PARALLEL_TOL): the normal's position along the axis is
  free; frame i keeps the URDF joint origin (so d values are the designer's offsets, as
  in the EC66 table). MD-H cannot express a tilt of a parallel axis within their common
  plane; the measurement model still reproduces the URDF exactly (see C below).
- coincident axes: no normal at all; x_i is the URDF joint x axis projected onto the
  plane normal to z_i, frame i at the URDF joint origin.
- prismatic joints: the axis has a direction only; its line is taken through the URDF
  joint origin. The joint value adds to d_i.
- the first axis in general position: frame 0 is a fixed frame of the base with z_0 on
  axis 1 (origin at the foot of the perpendicular from the base origin, x_0 from the
  base x axis), so a_0 = alpha_0 = 0; when axis 1 is the base z axis, frame 0 is the base.
- the last frame n has no next axis: it sits at the URDF joint origin with x_n from the
  URDF joint x axis.

Exactness: a fixed offset C_i = F_i^-1 J_i between MD-H frame i (from the product of
the nominal table) and the URDF joint frame J_i keeps every link rigidly attached to its
MD-H frame. Zero errors therefore reproduce the URDF placements to machine precision,
even where a nominal axis is parallel only to within PARALLEL_TOL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.rotations import inverse, transform

PARALLEL_TOL = 1e-6  # |sin| of the angle between axes below which they count as parallel
TOOL_AXIS_WARNING = 5e-3  # [m] a tool point nearer the last joint axis: warn (last_axis_distance)
_ZERO = 1e-12  # [m] or [-], what counts as zero length in the geometric construction

FIELDS = ("a", "alpha", "d", "theta")  # column order of an MD-H table in kincal
LENGTH_FIELDS = ("a", "d")


def mdh_transform(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """A = Rx(alpha) Tx(a) Rz(theta) Tz(d) as a 4x4 array [m, rad]."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array([[ct, -st, 0.0, a],
                     [ca * st, ca * ct, -sa, -sa * d],
                     [sa * st, sa * ct, ca, ca * d],
                     [0.0, 0.0, 0.0, 1.0]])


def mdh_parameters(T: np.ndarray) -> tuple[float, float, float, float]:
    """(a, alpha, d, theta) of a transform of MD-H form (inverse of :func:`mdh_transform`)."""
    R, p = T[:3, :3], T[:3, 3]
    alpha = float(np.arctan2(-R[1, 2], R[2, 2]))
    theta = float(np.arctan2(-R[0, 1], R[0, 0]))
    d = float(-np.sin(alpha) * p[1] + np.cos(alpha) * p[2])
    return float(p[0]), alpha, d, theta


@dataclass(frozen=True)
class MdhModel:
    """A chain in MD-H form, exact for the URDF it came from.

    joint_names, kinds: as in the chain ("revolute" or "prismatic").
    table: (n, 4) nominal [a, alpha, d, theta] per joint [m, rad].
    T_base_0: (4, 4) fixed pose of MD-H frame 0 in the base frame B.
    offsets: (n, 4, 4) C_i, pose of the URDF joint frame i in MD-H frame i.
    screw_axes: (n, 3) joint i's axis in MD-H frame i (= C_i axis_i; e_z up to PARALLEL_TOL).
    screw_points: (n, 3) a point of joint i's axis line in MD-H frame i (the URDF joint
        origin; on the z axis up to PARALLEL_TOL). The joint turns about this line, so the
        model is exact even where MD-H frame i is not exactly on the joint axis.
    T_n_tip: (4, 4) pose of the tip frame in MD-H frame n.
    notes: one line per joint naming the degenerate case met, if any.
    """

    joint_names: tuple[str, ...]
    kinds: tuple[str, ...]
    table: np.ndarray
    T_base_0: np.ndarray
    offsets: np.ndarray
    screw_axes: np.ndarray
    T_n_tip: np.ndarray
    notes: tuple[str, ...]
    screw_points: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.joint_names)

    def frames(self, table: np.ndarray | None = None) -> np.ndarray:
        """(n, 4, 4) MD-H frames F_i at zero joint values in the base frame."""
        table = self.table if table is None else np.asarray(table, dtype=float)
        F = self.T_base_0
        out = np.empty((self.n, 4, 4))
        for i, row in enumerate(table):
            F = F @ mdh_transform(*row)
            out[i] = F
        return out

    def joint_frames(self, table: np.ndarray | None = None) -> np.ndarray:
        """(n, 4, 4) URDF joint frames T_B_Ji at zero joint values for an MD-H table.

        The table of the nominal model gives back the URDF's own joint frames.
        """
        return self.frames(table) @ self.offsets

    def last_axis_distance(self, tool) -> float | None:
        """Distance [m] of the tool point (tip frame) from the last joint's axis line, or
        None if the last joint is prismatic. Near 0, turning that joint barely moves the
        point: its theta (and the tilt of its axis) are weak or unidentifiable."""
        if self.kinds[-1] != "revolute":
            return None
        p = self.T_n_tip[:3, :3] @ np.asarray(tool, float) + self.T_n_tip[:3, 3]  # frame n
        c = np.zeros(3) if self.screw_points is None else self.screw_points[-1]
        return float(np.linalg.norm(np.cross(p - c, self.screw_axes[-1])))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _x_hint(J: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The URDF joint frame's x axis, or y if x is (nearly) the joint axis, in B."""
    k = 0 if abs(axis[0]) < 0.9 else 1
    return J[:3, k]


def _perp(v: np.ndarray, z: np.ndarray) -> np.ndarray:
    return v - (v @ z) * z


def _signed_toward(n: np.ndarray, hint: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """``n`` or ``-n``, whichever agrees with ``hint`` (else with ``fallback``)."""
    s = n @ hint
    if abs(s) < 1e-6:
        s = n @ fallback
    return n if s >= 0 else -n


def extract(geometry) -> MdhModel:
    """The MD-H model of a :class:`kincal.robot.ChainGeometry` (see the module notes)."""
    J = np.asarray(geometry.joint_frames, dtype=float)
    n = len(J)
    z = np.array([_unit(J[i, :3, :3] @ geometry.axes[i]) for i in range(n)])
    o = J[:, :3, 3]
    hints = [_x_hint(J[i], geometry.axes[i]) for i in range(n)]
    geo, notes = [], []
    for i in range(n):
        zi, oi = z[i], o[i]
        note = ""
        if i == n - 1:
            origin = oi
            x = _perp(hints[i], zi)
        else:
            c = np.cross(zi, z[i + 1])
            delta = o[i + 1] - oi
            if np.linalg.norm(c) > PARALLEL_TOL:
                cn = _unit(c)
                # closest point on axis i to axis i+1
                w = np.cross(z[i + 1], cn)
                t = (delta @ w) / (zi @ w)
                origin = oi + t * zi
                dist = delta @ cn
                x = _signed_toward(cn, hints[i], cn * (dist if abs(dist) > _ZERO else 1.0))
                if abs(dist) <= _ZERO:
                    note = f"axes of {geometry.joint_names[i]} and {geometry.joint_names[i + 1]} intersect"
            else:
                origin = oi
                perp = _perp(delta, zi)
                if np.linalg.norm(perp) > _ZERO:
                    x = _signed_toward(_unit(perp), hints[i], perp)
                    note = (f"axes of {geometry.joint_names[i]} and {geometry.joint_names[i + 1]} are "
                            "parallel: frame kept at the URDF joint origin")
                else:
                    x = _perp(hints[i], zi)
                    note = (f"axes of {geometry.joint_names[i]} and {geometry.joint_names[i + 1]} "
                            "coincide: x from the URDF joint frame")
        x = _unit(_perp(x, zi))
        R = np.column_stack([x, np.cross(zi, x), zi])
        geo.append(transform(R, origin))
        if geometry.kinds[i] == "prismatic":
            note = (note + "; " if note else "") + "prismatic: axis line through the URDF joint origin"
        notes.append(note)
    # frame 0: z on axis 1, origin at the foot of the perpendicular from the base origin
    z0 = z[0]
    origin0 = o[0] - (o[0] @ z0) * z0
    x0 = _perp(np.array([1.0, 0.0, 0.0]), z0)
    if np.linalg.norm(x0) < 1e-6:
        x0 = _perp(np.array([0.0, 1.0, 0.0]), z0)
    x0 = _unit(x0)
    T_base_0 = transform(np.column_stack([x0, np.cross(z0, x0), z0]), origin0)
    if np.linalg.norm(origin0) > _ZERO or abs(z0[2] - 1.0) > 1e-12:
        notes[0] = (notes[0] + "; " if notes[0] else "") + \
            "first axis is not the base z axis: fixed frame 0 placed on it"
    table = np.empty((n, 4))
    prev = T_base_0
    for i in range(n):
        table[i] = mdh_parameters(inverse(prev) @ geo[i])
        prev = geo[i]
    table[0, 0] = table[0, 1] = 0.0  # exact by construction of frame 0
    model = MdhModel(tuple(geometry.joint_names), tuple(geometry.kinds), table, T_base_0,
                     np.zeros((n, 4, 4)), np.zeros((n, 3)), np.eye(4), tuple(notes))
    F = model.frames()
    offsets = inverse(F) @ J
    screw = np.einsum("nij,nj->ni", offsets[:, :3, :3], np.asarray(geometry.axes, dtype=float))
    T_n_tip = inverse(F[-1]) @ geometry.T_base_tip
    return MdhModel(model.joint_names, model.kinds, table, T_base_0, offsets,
                    screw / np.linalg.norm(screw, axis=1, keepdims=True), T_n_tip, model.notes,
                    offsets[:, :3, 3].copy())
