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
  in the EC66 table). Plain MD-H cannot express a tilt of a parallel axis within their
  common plane; the measurement model still reproduces the URDF exactly (see C below),
  and Hayati's beta (below, the ``complete`` model) adds the missing direction.
- coincident axes: no normal at all; x_i is the URDF joint x axis projected onto the
  plane normal to z_i, frame i at the URDF joint origin. Exact, but not complete: a shift
  of axis i+1 along y_i has no parameter (theta_i and d_i move along the common line), in
  MD-H and with Hayati's beta alike; the ``placement`` model has it (docs/method.md).
- prismatic joints: the axis has a direction only; its line is taken through the URDF
  joint origin. The joint value adds to d_i.
- the first axis in general position: frame 0 is a fixed frame of the base with z_0 on
  axis 1 (origin at the foot of the perpendicular from the base origin, x_0 from the
  base x axis), so a_0 = alpha_0 = 0; when axis 1 is the base z axis, frame 0 is the base.
- the last frame n has no next axis: it sits at the URDF joint origin with x_n from the
  URDF joint x axis.

Hayati's beta (``extract(geometry, beta_below=...)``, the ``complete`` model): for a pair
of axes within the angle whose sine is ``beta_below`` of parallel, row i+1 becomes

    A_{i+1} = Tx(a_i) Rx(alpha_i) Ry(beta_i) Rz(theta_{i+1}) Tz(d_{i+1})

(beta about the y axis of frame i after its twist, as Hayati's beta follows alpha), and
frame i's x axis points from frame i's origin (the URDF joint origin) to the point where
axis i+1 pierces the plane normal to axis i there. That point moves smoothly with the
axes, so the parameters stay continuous as the axes approach, reach and pass parallel
(MD-H's common normal runs off to infinity instead). The pair's two angles are alpha
(out of the common plane) and beta (within it); d_i becomes redundant with d_{i+1} and
the rank-revealing selection drops one. Beta is named ``<joint>.beta`` for joint i+1,
beside its ``.a`` and ``.alpha``.

Exactness: a fixed offset C_i = F_i^-1 J_i between MD-H frame i (from the product of
the nominal table) and the URDF joint frame J_i keeps every link rigidly attached to its
MD-H frame. Zero errors therefore reproduce the URDF placements to machine precision,
even where a nominal axis is parallel only to within PARALLEL_TOL.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from kincal.errors import OptionError
from kincal.models.base import LENGTH, OFFSET, TWIST, ErrorModel
from kincal.models.chain import equal_runs
from kincal.rotations import cross_rows, inverse, tilt_angles, transform

PARALLEL_TOL = 1e-6  # |sin| of the angle between axes below which they count as parallel
TOOL_AXIS_WARNING = 5e-3  # [m] a tool point nearer the last joint axis: warn (last_axis_distance)
_ZERO = 1e-12  # [m] or [-], what counts as zero length in the geometric construction

FIELDS = ("a", "alpha", "d", "theta")  # column order of an MD-H table in kincal
LENGTH_FIELDS = ("a", "d")
_CLASS = {"a": LENGTH, "alpha": TWIST, "beta": TWIST, "d": LENGTH, "theta": OFFSET}


def mdh_transform(a: float, alpha: float, d: float, theta: float, beta: float = 0.0) -> np.ndarray:
    """A = Tx(a) Rx(alpha) Ry(beta) Rz(theta) Tz(d) as a 4x4 array [m, rad] (Craig's
    Rx(alpha) Tx(a) Rz(theta) Tz(d) when beta = 0)."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    if beta == 0.0:
        return np.array([[ct, -st, 0.0, a],
                         [ca * st, ca * ct, -sa, -sa * d],
                         [sa * st, sa * ct, ca, ca * d],
                         [0.0, 0.0, 0.0, 1.0]])
    cb, sb = np.cos(beta), np.sin(beta)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    Ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    Rz = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
    R = Rx @ Ry @ Rz
    return transform(R, np.array([a, 0.0, 0.0]) + R[:, 2] * d)


def mdh_parameters(T: np.ndarray) -> tuple[float, float, float, float]:
    """(a, alpha, d, theta) of a transform of MD-H form (inverse of :func:`mdh_transform`)."""
    R, p = T[:3, :3], T[:3, 3]
    alpha = float(np.arctan2(-R[1, 2], R[2, 2]))
    theta = float(np.arctan2(-R[0, 1], R[0, 0]))
    d = float(-np.sin(alpha) * p[1] + np.cos(alpha) * p[2])
    return float(p[0]), alpha, d, theta


def hayati_parameters(T: np.ndarray) -> tuple[float, float, float, float, float]:
    """(a, alpha, d, theta, beta) of a transform Tx(a) Rx(alpha) Ry(beta) Rz(theta) Tz(d)
    whose origin lies on the line through (a, 0, 0) along its z axis."""
    R, p = T[:3, :3], T[:3, 3]
    z = R[:, 2]
    alpha, beta = map(float, tilt_angles(z))
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    Rxy = np.array([[cb, 0.0, sb], [sa * sb, ca, -sa * cb], [-ca * sb, sa, ca * cb]])
    Rz = Rxy.T @ R
    theta = float(np.arctan2(Rz[1, 0], Rz[0, 0]))
    d = float((p[1] * z[1] + p[2] * z[2]) / (z[1] ** 2 + z[2] ** 2))
    return float(p[0] - d * z[0]), alpha, d, theta, beta


@dataclass(frozen=True)
class MdhModel(ErrorModel):
    """A chain in MD-H form (optionally with Hayati's beta), exact for its URDF.

    The kinematic parameters of joint i are, in this order, ``<joint>.a`` (a_{i-1} [m]),
    ``.alpha`` (alpha_{i-1} [rad]), ``.beta`` (beta_{i-1} [rad], only where has_beta),
    ``.d`` (d_i [m]) and ``.theta`` (theta_oi [rad]).

    table: (n, 4) nominal [a, alpha, d, theta] per joint [m, rad].
    beta: (n,) nominal beta (0 where has_beta is False).
    has_beta: (n,) which joints carry a beta parameter.
    The placed frames are the MD-H frames; T_first is the fixed frame 0 in the base frame,
    joint_offsets the C_i, screw_axes/points joint i's axis in MD-H frame i (e_z and the
    origin up to PARALLEL_TOL), T_last_tip the tip in MD-H frame n.
    """

    table: np.ndarray
    beta: np.ndarray
    has_beta: np.ndarray

    @classmethod
    def build(cls, name, joint_names, kinds, table, beta, has_beta, T_first, joint_offsets,
              screw_axes, screw_points, T_last_tip, notes) -> "MdhModel":
        names, nominal, is_length, classes, joint_of = [], [], [], [], []
        for i, j in enumerate(joint_names):
            a, alpha, d, theta = table[i]
            fields = [("a", a), ("alpha", alpha)] + ([("beta", beta[i])] if has_beta[i] else []) \
                + [("d", d), ("theta", theta)]
            for f, v in fields:
                names.append(f"{j}.{f}")
                nominal.append(v)
                is_length.append(f in LENGTH_FIELDS)
                classes.append(_CLASS[f])
                joint_of.append(i)
        # a prismatic joint's zero is its d: that d is its offset
        classes = [OFFSET if (nm.endswith(".d") and kinds[jo] == "prismatic") else c
                   for nm, c, jo in zip(names, classes, joint_of)]
        return cls(name, tuple(joint_names), tuple(kinds), tuple(names), np.array(nominal),
                   np.array(is_length, dtype=bool), tuple(classes), np.array(joint_of, dtype=int),
                   T_first, screw_axes, screw_points, joint_offsets, T_last_tip, tuple(notes),
                   np.asarray(table, float), np.asarray(beta, float), np.asarray(has_beta, bool))

    # compatibility names of the MD-H description
    @property
    def T_base_0(self) -> np.ndarray:
        return self.T_first

    @property
    def offsets(self) -> np.ndarray:
        return self.joint_offsets

    @property
    def T_n_tip(self) -> np.ndarray:
        return self.T_last_tip

    def unpack(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(table (n, 4), beta (n,)) of a kinematic vector x (or of a (n, 4) table when the
        model has no beta); (tables (N, n, 4), betas (N, n)) of one vector per pose (N, p)."""
        x = np.asarray(x, dtype=float)
        if x.ndim == 2:
            if x.shape[1] != self.size:
                raise ValueError(f"{self.size} kinematic parameters expected, got {x.shape[1]}")
            betas = np.zeros((len(x), self.n))
            betas[:, self.has_beta] = x[:, self._field_index[2]]
            return x[:, self._table_index], betas
        x = x.ravel()
        if x.size != self.size:
            raise ValueError(f"{self.size} kinematic parameters expected, got {x.size}")
        if not self.has_beta.any():
            return x.reshape(self.n, 4), np.zeros(self.n)
        beta = np.zeros(self.n)  # gathered at once: this runs every iteration
        beta[self.has_beta] = x[self._field_index[2]]
        return x[self._table_index], beta

    def pack(self, table, beta=None) -> np.ndarray:
        """The kinematic vector of a table (n, 4) and beta (n,) (nominal beta if None)."""
        table = np.asarray(table, float).reshape(self.n, 4)
        beta = self.beta if beta is None else np.asarray(beta, float)
        out = []
        for i in range(self.n):
            out += list(table[i, :2]) + ([beta[i]] if self.has_beta[i] else []) + list(table[i, 2:])
        return np.array(out)

    def placements(self, x) -> np.ndarray:
        """(n, 4, 4) A_i = Tx(a) Rx(alpha) Ry(beta) Rz(theta) Tz(d), vectorised over joints;
        (n, N, 4, 4) for one vector per pose x (N, p), made once per run of equal rows (the
        folds of Algorithm 1 evaluated together: a few vectors over many poses)."""
        if np.ndim(x) == 2 and len(x) > 1:
            runs = equal_runs(np.asarray(x, dtype=float))
            if len(runs) < len(x):
                A = self.placements(np.asarray(x)[[a for a, _ in runs]])
                return np.repeat(A, [b - a for a, b in runs], axis=1)
        table, beta = self.unpack(x)
        a, alpha, d, theta = table.T  # (n,) each, or (n, N) per pose
        beta = beta.T
        ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
        ct, st = np.cos(theta), np.sin(theta)
        if a.ndim == 1:  # one vector: entry by entry (below), not ~40 calls on n-element arrays
            return _placements_of(a, d, ca, sa, cb, sb, ct, st)
        A = np.zeros(a.shape + (4, 4))
        for r, row in enumerate(_rows(a, d, ca, sa, cb, sb, ct, st)):
            for c, v in enumerate(row):
                A[..., r, c] = v
        A[..., 3, 3] = 1.0
        return A

    def twists(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Twists in frame i-1 (see kincal.models.base): a slides along x, alpha turns about
        x, beta about Rx(alpha) y through (a, 0, 0), theta about the new z axis through
        (a, 0, 0), d slides along it. Vectorised over joints (this runs every iteration)."""
        table, beta = self.unpack(x)
        a, alpha = table[:, 0], table[:, 1]
        ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
        z = np.column_stack([sb, -sa * cb, ca * cb])             # new z axis, frame i-1
        c_cross_z = np.column_stack([np.zeros(self.n), -a * z[:, 2], a * z[:, 1]])
        ia, ial, ib, idd, ith = self._field_index
        w, v = np.zeros((self.size, 3)), np.zeros((self.size, 3))
        v[ia, 0] = 1.0                                            # a
        w[ial, 0] = 1.0                                           # alpha
        if ib.size:                                               # beta
            hb = self.has_beta
            w[ib, 1], w[ib, 2] = ca[hb], sa[hb]
            v[ib, 1], v[ib, 2] = -a[hb] * sa[hb], a[hb] * ca[hb]
        v[idd] = z                                                # d
        w[ith], v[ith] = z, c_cross_z                             # theta
        return w, v

    def point_columns(self, x, before, placed, P) -> np.ndarray:
        """(N, 3, p) derivatives of points P (N, 3) rigidly attached to the tip, from the
        frames before (G) and after (H) each placement: the same numbers as the generic
        twists of :mod:`kincal.models.chain`, written with MD-H's structure because this is
        the identification's hot path (a slides along x_G, alpha turns about it, d slides
        along z_H, theta turns about it, beta about Rx(alpha) y_G through o_G + a x_G)."""
        G, H = np.asarray(before), np.asarray(placed)                 # (n, N, 4, 4)
        xg, zh = G[:, :, :3, 0], H[:, :, :3, 2]
        rg, rh = P - G[:, :, :3, 3], P - H[:, :, :3, 3]
        ia, ial, ib, idd, ith = self._field_index
        K = np.empty((self.size, len(P), 3))  # parameter first: whole-block writes
        K[ia], K[idd] = xg, zh
        # the alpha and theta columns in one cross product (the same products, fewer calls)
        turns = cross_rows(np.concatenate([xg, zh]), np.concatenate([rg, rh]))
        K[ial], K[ith] = turns[:self.n], turns[self.n:]
        if ib.size:
            hb = self.has_beta
            table, _ = self.unpack(x)
            a, alpha = table.T[0][hb], table.T[1][hb]  # (n_beta,), or (n_beta, N) per pose
            a, alpha = a.reshape(len(a), -1, 1), alpha.reshape(len(alpha), -1, 1)
            Gb = G[hb]
            y1 = (np.cos(alpha) * Gb[:, :, :3, 1] + np.sin(alpha) * Gb[:, :, :3, 2])
            c = Gb[:, :, :3, 3] + a * Gb[:, :, :3, 0]
            K[ib] = cross_rows(y1, P - c)
        return K.transpose(1, 2, 0)

    @cached_property
    def _table_index(self) -> np.ndarray:
        """(n, 4) positions of a, alpha, d, theta in the vector."""
        ia, ial, _, idd, ith = self._field_index
        return np.column_stack([ia, ial, idd, ith])

    @cached_property
    def _field_index(self) -> tuple[np.ndarray, ...]:
        """Positions of a, alpha, beta (joints with beta only), d, theta in the vector."""
        has = self.has_beta.astype(int)
        start = np.concatenate([[0], np.cumsum(4 + has)[:-1]])
        return start, start + 1, (start + 2)[self.has_beta], start + 2 + has, start + 3 + has

    def frames(self, x=None) -> np.ndarray:
        """(n, 4, 4) MD-H frames F_i at zero joint values in the base frame."""
        P = self.placements(self.nominal if x is None else x)
        out, F = np.empty((self.n, 4, 4)), self.T_first
        for i in range(self.n):
            F = F @ P[i]
            out[i] = F
        return out


def _rows(a, d, ca, sa, cb, sb, ct, st) -> tuple:
    """The top three rows of A = Tx(a) Rx(alpha) Ry(beta) Rz(theta) Tz(d), written out, from
    a, d and the cosines and sines of alpha, beta, theta: numbers or arrays alike (the same
    elementwise IEEE operations in the same order, so the same numbers)."""
    r12, r22 = -sa * cb, ca * cb
    return ((cb * ct, -cb * st, sb, sb * d + a),
            (ca * st + sa * sb * ct, ca * ct - sa * sb * st, r12, r12 * d),
            (sa * st - ca * sb * ct, sa * ct + ca * sb * st, r22, r22 * d))


def _placements_of(*columns) -> np.ndarray:
    """(n, 4, 4) :meth:`MdhModel.placements` of one vector from its columns (a, d, cos and
    sin of alpha, beta, theta; (n,) each) in Python numbers (:func:`_rows`): fewer calls
    than ~40 numpy operations on n-element arrays."""
    out: list = []
    for values in zip(*(c.tolist() for c in columns)):
        for row in _rows(*values):
            out += row
        out += (0.0, 0.0, 0.0, 1.0)
    return np.array(out).reshape(-1, 4, 4)


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


def extract(geometry, beta_below: float | None = None, name: str | None = None) -> MdhModel:
    """The MD-H model of a :class:`kincal.models.geometry.ChainGeometry` (see the module notes).

    beta_below: None for plain MD-H; else the sine of the angle below which a pair of
    consecutive axes counts as nearly parallel and gets Hayati's beta.
    A tree path whose first joints are reversed (a base off the tip's branch) is refused
    (OptionError): MD-H rows start at the base, and the first row's a and alpha would move
    the first axis within the base frame's own link, a change no URDF origin holds.
    """
    rev = getattr(geometry, "reversed", None)
    if rev is not None and np.any(rev):
        raise OptionError(
            f"error model {name or ('mdh' if beta_below is None else 'complete')!r} cannot "
            f"describe a tree path ({int(np.sum(rev))} joints traversed upward from the base): "
            f"its first MD-H row would move the axis of {geometry.joint_names[0]} within the "
            "base frame's own link, which no URDF origin holds; use the 'placement' or "
            "'offsets' model")
    J = np.asarray(geometry.joint_frames, dtype=float)
    n = len(J)
    z = np.array([_unit(J[i, :3, :3] @ geometry.axes[i]) for i in range(n)])
    o = J[:, :3, 3]
    hints = [_x_hint(J[i], geometry.axes[i]) for i in range(n)]
    names = geometry.joint_names
    geo, notes = [], []
    has_beta = np.zeros(n, dtype=bool)
    for i in range(n):
        zi, oi = z[i], o[i]
        note = ""
        if i == n - 1:
            origin = oi
            x = _perp(hints[i], zi)
        else:
            c = np.cross(zi, z[i + 1])
            delta = o[i + 1] - oi
            nearly = beta_below is not None and np.linalg.norm(c) < beta_below
            if nearly and i + 1 < n:
                # Hayati: x toward the point where axis i+1 pierces the plane normal to axis i
                has_beta[i + 1] = True
                origin = oi
                s = -(delta @ zi) / (z[i + 1] @ zi)
                perp = delta + s * z[i + 1]
                if np.linalg.norm(perp) > _ZERO:
                    x = _signed_toward(_unit(perp), hints[i], perp)
                    what = "are parallel" if np.linalg.norm(c) <= PARALLEL_TOL else \
                        f"are nearly parallel ({np.degrees(np.arcsin(min(float(np.linalg.norm(c)), 1.0))):.3g} deg)"
                    note = (f"axes of {names[i]} and {names[i + 1]} {what}: frame kept at the "
                            f"URDF joint origin, {names[i + 1]}.beta added (Hayati)")
                else:
                    x = _perp(hints[i], zi)
                    note = (f"axes of {names[i]} and {names[i + 1]} meet on the normal plane: "
                            f"x from the URDF joint frame, {names[i + 1]}.beta added (Hayati)")
            elif np.linalg.norm(c) > PARALLEL_TOL:
                cn = _unit(c)
                # closest point on axis i to axis i+1
                w = np.cross(z[i + 1], cn)
                t = (delta @ w) / (zi @ w)
                origin = oi + t * zi
                dist = delta @ cn
                x = _signed_toward(cn, hints[i], cn * (dist if abs(dist) > _ZERO else 1.0))
                if abs(dist) <= _ZERO:
                    note = f"axes of {names[i]} and {names[i + 1]} intersect"
            else:
                origin = oi
                perp = _perp(delta, zi)
                if np.linalg.norm(perp) > _ZERO:
                    x = _signed_toward(_unit(perp), hints[i], perp)
                    note = (f"axes of {names[i]} and {names[i + 1]} are "
                            "parallel: frame kept at the URDF joint origin")
                else:
                    x = _perp(hints[i], zi)
                    note = (f"axes of {names[i]} and {names[i + 1]} "
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
    table, beta = np.empty((n, 4)), np.zeros(n)
    prev = T_base_0
    for i in range(n):
        T = inverse(prev) @ geo[i]
        if has_beta[i]:
            a, alpha, d, theta, beta[i] = hayati_parameters(T)
            table[i] = a, alpha, d, theta
        else:
            table[i] = mdh_parameters(T)
        prev = geo[i]
    table[0, 0] = table[0, 1] = 0.0  # exact by construction of frame 0
    name = name or ("mdh" if beta_below is None else "complete")
    eye, zeros = np.eye(4), np.zeros((n, 3))
    model = MdhModel.build(name, names, geometry.kinds, table, beta, has_beta, T_base_0,
                           np.zeros((n, 4, 4)), zeros, zeros, eye, notes)
    F = model.frames()
    offsets = inverse(F) @ J
    screw = np.einsum("nij,nj->ni", offsets[:, :3, :3], np.asarray(geometry.axes, dtype=float))
    T_n_tip = inverse(F[-1]) @ geometry.T_base_tip
    return MdhModel.build(name, names, geometry.kinds, table, beta, has_beta, T_base_0, offsets,
                          screw / np.linalg.norm(screw, axis=1, keepdims=True),
                          offsets[:, :3, 3].copy(), T_n_tip, notes)
