"""The chain of any error model over a fixed set of poses: forward kinematics and the
motion each parameter causes, vectorised over poses.

Plain numpy. ``Chain(model, q, approach, backlash)`` computes the joint motions once;
``state(x, backlash_values)`` evaluates one parameter vector and keeps the frames before
and after every placement, from which :meth:`ChainState.point_columns` gives the analytic
derivative of any points rigidly attached to the tip and :meth:`ChainState.rotation_columns`
the derivative of the tip's orientation (as a small rotation in the base frame). No finite
differences.

Backlash terms (:mod:`kincal.models.backlash`) move joint i to q_i + b_i g_i, with g the
approach directions of the poses: their column is the joint's own motion (the turn about,
or slide along, its axis line) times g.
"""

from __future__ import annotations

import numpy as np

from kincal.models.base import ErrorModel


def rodrigues(w: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations by angles q (N,) about the unit axis w (3,)."""
    c = np.cos(q)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    # s K + (1 - c) w w^T, then c on the diagonal: the same sums as c I + s K + (1 - c) w w^T
    # (adding the zeros changes no bit) with two (N, 3, 3) arrays made instead of six
    R = np.multiply.outer(np.sin(q), K)
    R += np.multiply.outer(1.0 - c, np.outer(w, w))
    R[:, [0, 1, 2], [0, 1, 2]] += c[:, None]
    return R


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (np.cross is slow on small batches)."""
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


MOTION_CACHE_POSES = 1024  # poses up to which a chain keeps its joint motions
_GATHER_BUDGET = 4_000_000  # floats gathered at once for the kinematic columns (32 MB)


class Chain:
    """One error model's chain over N poses.

    model: the error model. joint_values: (N, n) [rad or m]. approach: (N, n) approach
    directions (+1/-1/0), needed with backlash terms. backlash: chain indices of the
    joints with a backlash term.
    """

    def __init__(self, model: ErrorModel, joint_values: np.ndarray,
                 approach: np.ndarray | None = None, backlash: tuple[int, ...] = ()):
        self.model = model
        self.q = np.asarray(joint_values, dtype=float)
        self.N = len(self.q)
        self.approach = None if approach is None else np.asarray(approach, dtype=float)
        self.backlash = tuple(int(i) for i in backlash)
        if self.backlash and (self.approach is None or self.approach.shape != self.q.shape):
            raise ValueError(f"backlash terms need approach directions of shape {self.q.shape}")
        self._backlash_of = {i: k for k, i in enumerate(self.backlash)}
        # the joint motions, (N, 4, 4) per joint, are kept for few poses (cheap to reuse
        # across evaluations); for many (MOTION_CACHE_POSES) they are made anew at each
        # evaluation: 128 bytes per pose and joint would otherwise stay for the whole fit
        self._motion = ([self.joint_motion(i, self.q[:, i]) for i in range(model.n)]
                        if self.N <= MOTION_CACHE_POSES else None)
        # each joint's parameters are contiguous in the vector: slices keep the writes cheap
        edges = np.searchsorted(model.joint_of, np.arange(model.n + 1))
        if np.any(np.diff(model.joint_of) < 0):
            raise ValueError("an error model must list its parameters joint by joint")
        self._by_joint = [slice(int(edges[i]), int(edges[i + 1])) for i in range(model.n)]

    def subset(self, rows) -> "Chain":
        return Chain(self.model, self.q[rows],
                     None if self.approach is None else self.approach[rows], self.backlash)

    def joint_motion(self, i: int, qi: np.ndarray) -> np.ndarray:
        """(N, 4, 4) motion of joint i by qi (N,), in its placed frame."""
        m = self.model
        w = m.screw_axes[i]
        M = np.zeros((len(qi), 4, 4))
        M[:, 3, 3] = 1.0
        if m.kinds[i] == "prismatic":
            M[:, :3, :3] = np.eye(3)
            M[:, :3, 3] = qi[:, None] * w
        else:  # a turn about the axis line through the screw point c: x -> R (x - c) + c
            R = rodrigues(w, qi)
            c = m.screw_points[i]
            M[:, :3, :3] = R
            M[:, :3, 3] = c - R @ c
        return M

    def state(self, x: np.ndarray, backlash: np.ndarray | None = None,
              keep: bool = True) -> "ChainState":
        """Evaluate kinematic parameters x (and backlash values) on every pose.

        keep=False keeps only the tip (cheaper when no derivative is wanted)."""
        m = self.model
        P = m.placements(x)
        G = np.broadcast_to(m.T_first, (self.N, 4, 4)) if keep else m.T_first
        before, placed = [], []
        for i in range(m.n):
            H = G @ P[i]
            if keep:
                before.append(G)
                placed.append(H)
            k = self._backlash_of.get(i)
            if k is None or backlash is None or backlash[k] == 0.0:
                G = H @ (self._motion[i] if self._motion is not None
                         else self.joint_motion(i, self.q[:, i]))
            else:
                assert self.approach is not None  # backlash terms have them (__init__)
                G = H @ self.joint_motion(i, self.q[:, i] + backlash[k] * self.approach[:, i])
        T = G @ m.T_last_tip
        if T.ndim == 2:
            T = np.broadcast_to(T, (self.N, 4, 4))
        return ChainState(self, x, T[:, :3, :3], T[:, :3, 3], before, placed)


class ChainState:
    """A chain evaluated at one parameter vector: the tip pose and, if kept, the frames
    before (``before[i]``) and after (``placed[i]``) joint i's placement, each (N, 4, 4)."""

    def __init__(self, chain: Chain, x, R_tip, p_tip, before, placed):
        self.chain, self.x = chain, x
        self.R_tip, self.p_tip = R_tip, p_tip
        self.before, self.placed = before, placed

    def point_columns(self, P: np.ndarray, generic: bool = False
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives of points P (N, 3) in the base frame, rigidly attached to the tip:
        (kinematic (N, 3, p), backlash (N, 3, n_backlash)). A model may offer a faster
        ``point_columns`` of its own (MD-H does); generic=True uses the twists anyway."""
        chain, m = self.chain, self.chain.model
        N = chain.N
        fast = None if generic else getattr(m, "point_columns", None)
        if fast is not None and self.before:
            K = fast(self.x, self.before, self.placed, P)
        elif self.before:
            K = np.empty((N, 3, m.size))
            G = np.stack(self.before)                             # (n, N, 4, 4)
            w, v = m.twists(self.x)
            jo = m.joint_of
            # vectorised over parameters, in row blocks to bound the (p, rows, 3, 3) gather
            step = max(1, _GATHER_BUDGET // max(1, 9 * m.size))
            for s in range(0, N, step):
                rows = slice(s, min(N, s + step))
                R = G[jo, rows, :3, :3]                           # (p, rows, 3, 3)
                W = np.matmul(R, w[:, None, :, None])[..., 0]     # (p, rows, 3) turn axes
                U = np.matmul(R, v[:, None, :, None])[..., 0]
                col = cross_rows(W, P[None, rows] - G[jo, rows, :3, 3]) + U
                K[rows] = col.transpose(1, 2, 0)
        else:
            K = np.empty((N, 3, m.size))
        B = np.empty((N, 3, len(chain.backlash)))
        for k, i in enumerate(chain.backlash):
            assert chain.approach is not None  # backlash terms have them (Chain.__init__)
            H = self.placed[i]
            axis = H[:, :3, :3] @ m.screw_axes[i]
            if m.kinds[i] == "prismatic":
                col = axis
            else:
                c = H[:, :3, 3] + H[:, :3, :3] @ m.screw_points[i]
                col = cross_rows(axis, P - c)
            B[:, :, k] = col * chain.approach[:, i, None]
        return K, B

    def rotation_columns(self) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives of the tip's orientation as small rotations in the base frame:
        (kinematic (N, 3, p), backlash (N, 3, n_backlash))."""
        chain, m = self.chain, self.chain.model
        w, _ = m.twists(self.x)
        K = np.empty((chain.N, 3, m.size))
        for i, idx in enumerate(chain._by_joint):
            if idx.start != idx.stop:
                K[:, :, idx] = self.before[i][:, :3, :3] @ w[idx].T
        B = np.empty((chain.N, 3, len(chain.backlash)))
        for k, i in enumerate(chain.backlash):
            assert chain.approach is not None  # backlash terms have them (Chain.__init__)
            axis = self.placed[i][:, :3, :3] @ m.screw_axes[i]
            B[:, :, k] = (0.0 if m.kinds[i] == "prismatic" else axis) * chain.approach[:, i, None]
        return K, B
