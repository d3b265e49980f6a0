"""Predicted measurements and the analytic identification Jacobian, vectorised over poses.

Plain numpy. For N poses with chain joint values q (N, n), and the parameter vector x of
:mod:`kincal.parameters`, the predicted tool point in the measurement frame is

    P_k = R_base (p_tip(q_k; table) + R_tip(q_k; table) t_tool) + t_base       [m]

computed with the exact MD-H model of :mod:`kincal.mdh` (the same numbers Pinocchio gives
for the corrected URDF). Derivatives are closed form: a change of alpha_{i-1} turns
everything after frame i-1 about its x axis, a_{i-1} slides it along that axis, theta_i
turns it about axis i, d_i slides it along axis i. No finite differences.

Backlash terms (:mod:`kincal.backlash`) move joint i to q_i + b_i g_i, with g the
approach directions of the poses: their column is the joint's own motion (the turn about,
or slide along, its true axis line) times g.

With several measured points per pose (K tool points), each sample names its point; the
sample sees its own t_tool, and only that point's tool columns are non-zero.
"""

from __future__ import annotations

import math

import numpy as np

from kincal.errors import DataError
from kincal.identification.parameters import ParameterSpace
from kincal.models.mdh import MdhModel
from kincal.rotations import base_rotation, rotx, roty, rotz


def _rodrigues(w: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations by angles q (N,) about the unit axis w (3,)."""
    c, s = np.cos(q)[:, None, None], np.sin(q)[:, None, None]
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return c * np.eye(3) + s * K + (1.0 - c) * np.outer(w, w)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (np.cross is slow on small batches)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis of equally shaped arrays."""
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _mdh4(a, alpha, d, theta) -> np.ndarray:
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return np.array([[ct, -st, 0.0, a], [ca * st, ca * ct, -sa, -sa * d],
                     [sa * st, sa * ct, ca, ca * d], [0.0, 0.0, 0.0, 1.0]])


class MeasurementModel:
    """Forward model and Jacobian of one MD-H chain over a fixed set of poses.

    mdh: the chain. joint_values: (N, n) [rad or m], one row per sample. backlash: chain
    joints with a backlash term; approach: (N, n) approach directions of the samples
    (needed with backlash terms). points: (N,) index of the measured point of each sample
    (default all 0) among n_points (default: as many as the indices name). The joint
    motions are computed once here, so evaluating many parameter vectors on the same
    poses is cheap.
    """

    def __init__(self, mdh: MdhModel, joint_values: np.ndarray, approach: np.ndarray | None = None,
                 backlash=(), points: np.ndarray | None = None, n_points: int | None = None):
        self.mdh = mdh
        try:
            q = np.asarray(joint_values, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"joint_values must be an (N, {mdh.n}) array of numbers ({exc})") from None
        if q.ndim != 2 or q.shape[1] != mdh.n:
            raise DataError(f"joint_values must be (N, {mdh.n}), got {q.shape}")
        self.points = (np.zeros(len(q), dtype=int) if points is None
                       else np.asarray(points, dtype=int))
        if self.points.shape != (len(q),) or (len(q) and self.points.min() < 0):
            raise DataError(f"points must be ({len(q)},) indices >= 0")
        if n_points is None:
            n_points = int(self.points.max()) + 1 if len(q) else 1
        self.space = ParameterSpace.of_chain(mdh.joint_names, mdh.kinds, backlash, n_points)
        if len(q) and self.points.max() >= n_points:
            raise DataError(f"a point index is >= n_points = {n_points}")
        if self.space.n_backlash and (approach is None or np.shape(approach) != q.shape):
            raise DataError(f"backlash terms need approach directions of shape {q.shape}")
        self.q = q
        self.approach = None if approach is None else np.asarray(approach, dtype=float)
        self.N = len(q)
        self._backlash_of = dict(zip(self.space.backlash_joint_index, range(self.space.n_backlash)))
        # joint motions as (N, 4, 4) transforms, computed once for these poses
        self._motion = [self._joint_motion(i, q[:, i]) for i in range(mdh.n)]

    def _joint_motion(self, i: int, qi: np.ndarray) -> np.ndarray:
        """(N, 4, 4) motion of joint i by qi (N,), in MD-H frame i before it moves."""
        kind, w = self.mdh.kinds[i], self.mdh.screw_axes[i]
        M = np.zeros((len(qi), 4, 4))
        M[:, 3, 3] = 1.0
        if kind == "prismatic":
            M[:, :3, :3] = np.eye(3)
            M[:, :3, 3] = qi[:, None] * w
        else:  # a turn about the axis line through the screw point c: x -> R (x - c) + c
            R = _rodrigues(w, qi)
            M[:, :3, :3] = R
            if self.mdh.screw_points is not None:
                c = self.mdh.screw_points[i]
                M[:, :3, 3] = c - R @ c
        return M

    def subset(self, rows) -> "MeasurementModel":
        return MeasurementModel(self.mdh, self.q[rows],
                                None if self.approach is None else self.approach[rows],
                                self.space.backlash, self.points[rows], self.space.n_points)

    def _measured_points(self, x: np.ndarray, R_tip: np.ndarray, p_tip: np.ndarray) -> np.ndarray:
        """(N, 3) each sample's measured point in the base frame."""
        tools = self.space.tools(x)
        if len(tools) == 1:
            return p_tip + R_tip @ tools[0]
        return p_tip + np.einsum("nij,nj->ni", R_tip, tools[self.points])

    def tip_poses(self, table: np.ndarray, backlash: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """(R (N, 3, 3), p (N, 3)) of the tip frame in the base frame."""
        R, p, _ = self._chain(table, backlash, keep=False)
        return R, p

    def _chain(self, table, backlash, keep: bool):
        G = np.broadcast_to(self.mdh.T_base_0, (self.N, 4, 4)) if keep else self.mdh.T_base_0
        stages = []
        for i in range(self.mdh.n):
            H = G @ _mdh4(*table[i])  # frame i before its joint moves
            if keep:
                stages.append((G, H))
            k = self._backlash_of.get(i)
            if k is None or backlash is None or backlash[k] == 0.0:
                G = H @ self._motion[i]
            else:
                G = H @ self._joint_motion(i, self.q[:, i] + backlash[k] * self.approach[:, i])
        T = G @ self.mdh.T_n_tip
        return T[:, :3, :3], T[:, :3, 3], stages

    def predict(self, x: np.ndarray) -> np.ndarray:
        """(N, 3) predicted tool-point positions in the measurement frame [m]."""
        table, base, _ = self.space.split(x)
        R_tip, p_tip, _ = self._chain(table, self.space.backlash_values(x), keep=False)
        P = self._measured_points(x, R_tip, p_tip)
        return P @ base_rotation(*base[3:]).T + base[:3]

    def jacobian(self, x: np.ndarray, kinematic: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(prediction (N, 3), Jacobian (N, 3, p)) of the predicted positions w.r.t. x.

        kinematic=False leaves the MD-H and backlash columns at zero (cheaper, for frame-only
        fits).
        """
        table, base, _ = self.space.split(x)
        backlash = self.space.backlash_values(x)
        R_tip, p_tip, stages = self._chain(table, backlash, keep=kinematic)
        P = self._measured_points(x, R_tip, p_tip)
        n, N = self.mdh.n, self.N
        J = np.empty((N, 3, self.space.size))
        if not kinematic:
            J[:, :, :4 * n] = 0.0
            J[:, :, 4 * n + self.space.n_frames:] = 0.0
            return self._frame_columns(J, P, R_tip, base)
        G = np.stack([g for g, _ in stages])  # (n, N, 4, 4)
        H = np.stack([h for _, h in stages])
        xg, zh = G[:, :, :3, 0], H[:, :, :3, 2]                            # (n, N, 3)
        rg, rh = P - G[:, :, :3, 3], P - H[:, :, :3, 3]
        cols = np.empty((n, 4, N, 3))
        cols[:, 0] = xg                                                    # a_{i-1}
        cols[:, 1] = _cross3(xg, rg)                                       # alpha_{i-1}
        cols[:, 2] = zh                                                    # d_i
        cols[:, 3] = _cross3(zh, rh)                                       # theta_i
        J[:, :, :4 * n] = cols.reshape(4 * n, N, 3).transpose(1, 2, 0)
        for k, i in enumerate(self.space.backlash_joint_index):
            # the joint's own motion: about (along) its axis line w through c, in frame H_i
            Hr, Ht = H[i, :, :3, :3], H[i, :, :3, 3]
            w = Hr @ self.mdh.screw_axes[i]
            if self.mdh.kinds[i] == "prismatic":
                col = w
            else:
                c = (Ht if self.mdh.screw_points is None
                     else Ht + Hr @ self.mdh.screw_points[i])
                col = _cross(w, P - c)
            J[:, :, 4 * n + self.space.n_frames + k] = col * self.approach[:, i, None]
        return self._frame_columns(J, P, R_tip, base, rotate_kinematic=True)

    def _frame_columns(self, J, P, R_tip, base, rotate_kinematic=False):
        """Fill the base and tool columns (and turn the MD-H ones into the measurement frame)."""
        N, k, f = self.N, self.space.n_kinematic, self.space.n_frames
        rx, ry, rz = base[3:]
        Rx, Ry, Rz = rotx(rx), roty(ry), rotz(rz)
        Rb = Rx @ Ry @ Rz
        if rotate_kinematic:
            J[:, :, :k] = np.matmul(Rb, J[:, :, :k])
            J[:, :, k + f:] = np.matmul(Rb, J[:, :, k + f:])
        Pm = P @ Rb.T + base[:3]
        J[:, :, k:k + 3] = np.eye(3)
        ex, ey, ez = np.eye(3)
        J[:, :, k + 3] = _cross(np.broadcast_to(ex, (N, 3)), Pm - base[:3])
        J[:, :, k + 4] = _cross(np.broadcast_to(ey, (N, 3)), P @ (Ry @ Rz).T) @ Rx.T
        J[:, :, k + 5] = _cross(np.broadcast_to(ez, (N, 3)), P @ Rz.T) @ (Rx @ Ry).T
        # a sample moves with its own point only: its block gets R_b R_tip, the others 0
        J[:, :, k + 6:k + 6 + 3 * self.space.n_points] = 0.0
        rows, first = np.arange(N), k + 6 + 3 * self.points
        for c in range(3):
            J[rows, :, first + c] = np.matmul(Rb, R_tip[:, :, c, None])[:, :, 0]
        return Pm, J
