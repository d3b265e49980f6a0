"""Forward kinematics, Jacobians and damped least-squares steps of a chain, vectorised
over configurations.

The inverse kinematics of many targets needs the tip pose and the joint Jacobians for N
configurations at once (Pinocchio's Python API takes one configuration per call). kincal
has one vectorised chain (:mod:`kincal.models.chain`); its ``offsets`` error model at zero
offsets is the URDF chain itself, and the column of a joint's offset is exactly that
joint's motion, so the joint Jacobians are that model's columns. A tool point alone (the
plausibility gate's, at hundreds of configurations per fit) is carried through the joints'
motions written in the base frame instead, with no frame kept (:meth:`ChainKinematics.
tip_points`). Tests check them against :meth:`kincal.robot.Robot.tip_poses` /
:meth:`kincal.robot.Robot.tip_jacobian` (Pinocchio) and against central differences.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from kincal.models import offsets
from kincal.models.geometry import ChainGeometry
from kincal.rotations import rotation_log, turn_parts


BLOCK = 4096  # configurations (targets) its users take at once
_ROWS = 1024  # configurations evaluated at once: products small enough for one BLAS thread


@dataclass(frozen=True)
class ChainKinematics:
    """The chain of a ChainGeometry, ready for batched evaluation (its offsets model, made
    when first needed). One per geometry (:meth:`of`): what it prepares is kept."""

    geometry: ChainGeometry

    @classmethod
    def of(cls, geometry) -> "ChainKinematics":
        from kincal.models import per_geometry

        return per_geometry("chain kinematics", geometry, lambda: cls(geometry))

    @functools.cached_property
    def model(self) -> offsets.OffsetsModel:
        from kincal.models import build

        return build("offsets", self.geometry)

    @property
    def n(self) -> int:
        return self.geometry.n

    @property
    def placements(self) -> np.ndarray:
        """(n, 4, 4) pose of joint frame i at zero in joint frame i-1 (frame 0: B)."""
        return self.model.origins

    @property
    def prismatic(self) -> np.ndarray:
        return np.array([k == "prismatic" for k in self.geometry.kinds])

    @property
    def T_last_tip(self) -> np.ndarray:
        return self.model.T_last_tip

    def motions(self, q: np.ndarray) -> np.ndarray:
        """(n, 3, 1, N) the coefficients of each joint's motion at joint values q (N, n)
        [rad or m] in :meth:`tip_points`: (cos, sin, 1 - cos) of a revolute joint's value,
        (1, value, 0) of a prismatic one's; made once for joint values evaluated often (the
        plausibility gate's seeded configurations)."""
        q = np.atleast_2d(np.asarray(q, dtype=float)).T  # (n, N): each joint's row
        A = np.empty((len(q), 3, 1, q.shape[1]))
        np.cos(q, out=A[:, 0, 0])
        np.sin(q, out=A[:, 1, 0])
        np.subtract(1.0, A[:, 0, 0], out=A[:, 2, 0])
        slide = self.prismatic
        if slide.any():
            A[slide, 0, 0], A[slide, 1, 0], A[slide, 2, 0] = 1.0, q[slide], 0.0
        return A

    def tip_points(self, q: np.ndarray, tool=(0.0, 0.0, 0.0),
                   motions: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) the point ``tool`` (3,) of the tip frame [m], in B, for joint values q
        (N, n) [rad or m]; the point only, no frame, no Jacobian. motions: :meth:`motions`
        of these q, if made before.

        The chain as a product of joint motions in B, S_1(q_1) ... S_n(q_n) T_B_tip(0) (each
        a turn about, or slide along, its axis line through the joint frame at zero), carried
        from the tip to the base: each S_i x is three fixed linear maps of x (:attr:`_screws`)
        weighted by joint i's coefficients, one product over all configurations and a
        weighted sum along them; no product per configuration (numpy hands a stack of 4 x 4
        products to BLAS one matrix at a time)."""
        A = self.motions(q) if motions is None else motions
        x = np.ones((4, 1))
        x[:3, 0] = tool
        x = self.geometry.T_base_tip @ x
        out = np.ones((4, A.shape[-1]))  # columns [point; 1], one per configuration
        for i in range(self.n - 1, -1, -1):
            Y = (self._screws[i] @ x).reshape(3, 3, -1)  # the three parts of S_i x ...
            Y = Y * A[i]  # ... weighted by joint i's coefficients,
            np.add(Y[0], Y[1], out=out[:3])  # and summed
            out[:3] += Y[2]
            x = out  # (the first joint's parts are of one point: x is (4, 1) until then)
        return out[:3].T.copy()

    @functools.cached_property
    def _screws(self) -> np.ndarray:
        """(n, 9, 4): H_i @ x, for a point x = [p; 1] (a column) in B, gives three parts of
        joint i's motion S_i p whose sum weighted by :meth:`motions` is S_i p. A turn about
        the unit axis a through the point c (the joint frame's origin at zero), K the cross
        product matrix of a: S p = cos p + sin (K p - K c) + (1 - cos) (a a.p + c - a a.c)
        (:func:`kincal.rotations.turn_parts`); a slide along a: S p = p + q a."""
        g = self.geometry
        F = g.joint_frames
        n = len(F)
        a = np.einsum("nij,nj->ni", F[:, :3, :3], g.axes)  # the axes in B
        c = F[:, :3, 3]
        # joint, part, output, input (x, y, z, 1): the turn's parts about its line in B
        H = turn_parts(a, c)
        slide = self.prismatic
        if slide.any():
            H[slide, 1], H[slide, 2] = 0.0, 0.0
            H[slide, 1, :, 3] = a[slide]
        out = H.reshape(n, 9, 4)
        out.flags.writeable = False
        return out

    @functools.cached_property
    def _joints(self) -> list:
        """Per joint a fixed (4, 18) matrix G = P [E_cos E_sin E_(1-cos) E_1 | w | c]: the
        frame T = [R | t] (3, 4) before joint i's placement P times G gives at once the
        four parts of the frame after its motion M(q) = E_cos cos q + E_sin sin q +
        E_(1-cos) (1 - cos q) + E_1 (the turn about the line through c,
        :func:`kincal.rotations.turn_parts`, and E_1 the homogeneous row), the axis a =
        R P w and the point R P c + t of the axis line. A prismatic joint: E_cos = I,
        E_sin = 0, E_(1-cos) = 0, and the slide a q added to the translation."""
        m, out = self.model, []
        for i in range(m.n):
            w, c = m.screw_axes[i], m.screw_points[i]
            E = np.zeros((4, 4, 4))
            E[0, :3, :3] = np.eye(3)
            E[3, 3, 3] = 1.0
            if m.kinds[i] != "prismatic":
                E[:3, :3] = turn_parts(w, c)
            cols = np.hstack([E[0], E[1], E[2], E[3], np.r_[w, 0.0][:, None],
                              np.r_[c, 1.0][:, None]])
            out.append((m.origins[i] @ cols, m.kinds[i] == "prismatic"))
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
        if len(q) > _ROWS:  # in blocks of configurations: see _times
            parts = [self.evaluate(q[s:s + _ROWS], tool) for s in range(0, len(q), _ROWS)]
            return tuple(np.concatenate(p) for p in zip(*parts))
        m = self.model
        N = len(q)
        T = None  # [R | t] (N, 3, 4) so far; None: T_first, the same for every row
        axes, points = np.empty((N, 3, m.n)), np.empty((N, 3, m.n))
        for i, (G, prismatic) in enumerate(self._joints):
            # the constant frame before the first joint: one (3, 4) x (4, 18) product
            Y = (np.broadcast_to(m.T_first[:3] @ G, (N, 3, 18)) if T is None
                 else (T.reshape(-1, 4) @ G).reshape(N, 3, 18))
            axes[:, :, i] = Y[:, :, 16]
            if prismatic:
                T = Y[:, :, 0:4] + Y[:, :, 12:16]
                T[:, :, 3] += Y[:, :, 16] * q[:, i, None]
                continue
            points[:, :, i] = Y[:, :, 17]
            cos, sin = np.cos(q[:, i])[:, None, None], np.sin(q[:, i])[:, None, None]
            # cos Y0 + sin Y1 + (1 - cos) Y2 + Y3, the same sums in the same order, in place
            T = cos * Y[:, :, 0:4]
            T += sin * Y[:, :, 4:8]
            T += (1.0 - cos) * Y[:, :, 8:12]
            T += Y[:, :, 12:16]
        if T is None:
            T = np.broadcast_to(m.T_first[:3], (N, 3, 4))
        tip = (T.reshape(-1, 4) @ m.T_last_tip).reshape(N, 3, 4)
        R_tip = tip[:, :, :3]
        point = tip[:, :, 3] + _times(R_tip, np.asarray(tool, dtype=float))
        rev = ~self.prismatic
        a, d = (axes, point[:, :, None] - points) if rev.all() else (
            axes[:, :, rev], point[:, :, None] - points[:, :, rev])
        cross = np.stack([a[:, 1] * d[:, 2] - a[:, 2] * d[:, 1],  # a x (p - c)
                          a[:, 2] * d[:, 0] - a[:, 0] * d[:, 2],
                          a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0]], axis=1)
        if rev.all():  # every joint revolute (the common case): no gathers
            return R_tip, point, cross, axes
        J_point, J_rot = axes.copy(), np.zeros((N, 3, m.n))
        J_point[:, :, rev] = cross
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
        dq = damped_least_squares(A, e, 1e-8)
        return np.linalg.norm(e, axis=1), np.clip(q + dq, lower, upper)


def damped_least_squares(A: np.ndarray, e: np.ndarray, d2: float) -> np.ndarray:
    """(N, n) steps A^T (A A^T + d2 I)^-1 e of (N, m, n) Jacobians A and (N, m) errors e:
    the one damped least-squares step of kincal's inverse kinematics (this module's
    :meth:`ChainKinematics.damped_step`, :meth:`kincal.robot.Robot.inverse_kinematics`
    with N = 1, and :func:`damped_pinv`'s tasks in kincal.compensation.ik), by a solve of
    the m x m system, no inverse."""
    M = A @ np.swapaxes(A, 1, 2)
    M += d2 * np.eye(e.shape[1])
    return (np.swapaxes(A, 1, 2) @ np.linalg.solve(M, e[:, :, None]))[:, :, 0]


def damped_pinv(A: np.ndarray, d2: float) -> np.ndarray:
    """(N, n, m) damped pseudo-inverses A^T (A A^T + d2 I)^-1 of (N, m, n) matrices: the
    operator of :func:`damped_least_squares`, for prioritised tasks that also need its
    null-space projector I - A^+ A (kincal.compensation.ik).

    For m = 3 (a position or an orientation task) written out over the rows: the Cholesky
    factor L of the symmetric positive definite M = A A^T + d2 I (d2 > 0), M^-1 =
    L^-T L^-1 from it, then M^-1 A as whole-row operations (A^T M^-1 = (M^-1 A)^T): the
    batched LAPACK inverse costs more than this arithmetic on 3 x 3 matrices. Other m,
    and d2 = 0, by the inverse."""
    if A.shape[1] != 3 or not d2 > 0:
        At = np.swapaxes(A, 1, 2)
        return At @ np.linalg.inv(A @ At + d2 * np.eye(A.shape[1]))
    a = np.ascontiguousarray(np.swapaxes(A, 0, 1))  # (3, N, n): each row of A contiguous
    dot = lambda i, j: np.einsum("ij,ij->i", a[i], a[j])  # noqa: E731
    l00 = np.sqrt(dot(0, 0) + d2)
    l10, l20 = dot(1, 0) / l00, dot(2, 0) / l00
    l11 = np.sqrt(dot(1, 1) + d2 - l10 * l10)
    l21 = (dot(2, 1) - l20 * l10) / l11
    l22 = np.sqrt(dot(2, 2) + d2 - l20 * l20 - l21 * l21)
    m00, m11, m22 = 1.0 / l00, 1.0 / l11, 1.0 / l22  # L^-1, lower triangular
    m10 = -l10 * m00 * m11
    m21 = -l21 * m11 * m22
    m20 = -(l20 * m00 + l21 * m10) * m22
    s01, s02, s12 = m10 * m11 + m20 * m21, m20 * m22, m21 * m22  # M^-1 = L^-T L^-1
    inv = ((m00 * m00 + m10 * m10 + m20 * m20, s01, s02),
           (s01, m11 * m11 + m21 * m21, s12), (s02, s12, m22 * m22))
    X = np.empty(a.shape)
    for i, row in enumerate(inv):
        X[i] = row[0][:, None] * a[0]
        X[i] += row[1][:, None] * a[1]
        X[i] += row[2][:, None] * a[2]
    return X.transpose(1, 2, 0)


def _times(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A (N, 3, 3) times a fixed B (3, 3) or (3,): one matrix product over all N rows (for
    N up to :data:`_ROWS`: a larger one would go to BLAS's threads, slower on busy cores)."""
    return (A.reshape(-1, 3) @ B).reshape(A.shape[:2] + B.shape[1:])
