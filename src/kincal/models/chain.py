"""The chain of any error model over a fixed set of poses: forward kinematics and the
motion each parameter causes, vectorised over poses.

Plain numpy. ``Chain(model, q, approach, backlash)`` computes the joint motions once;
``state(x, backlash_values)`` evaluates one parameter vector and keeps the frames before
and after every placement, from which :meth:`ChainState.point_columns` gives the analytic
derivative of any points rigidly attached to the tip and :meth:`ChainState.rotation_columns`
the derivative of the tip's orientation (as a small rotation in the base frame). No finite
differences.

Joint terms move joint i to q_i + v f_i, one coefficient v over the poses and a known
factor f_i per pose: backlash terms (:mod:`kincal.models.backlash`, v = b half the play,
f = g the approach directions) and compliance terms (:mod:`kincal.models.compliance`,
v = c the compliance, f = tau the gravity torque the joint carries). A term's column is
the joint's own motion (the turn about, or slide along, its axis line) times f. The
terms' values come in one vector: the backlash terms, then the compliance terms.
"""

from __future__ import annotations

import numpy as np

from kincal.models.base import ErrorModel
from kincal.rotations import cross_rows, turn_parts


def axis_cross(i: int, v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """e_i x v for rows v (N, 3): cross_rows(e_i, v) without its multiplications by 0 and 1
    (the same numbers, up to the sign of a zero), into ``out`` (N, 3) if given (a
    Jacobian's column block)."""
    j, k = (i + 1) % 3, (i + 2) % 3
    if out is None:
        out = np.empty(v.shape)
    out[:, i] = 0.0
    out[:, k] = v[:, j]
    np.negative(v[:, k], out=out[:, j])
    return out


def equal_runs(x: np.ndarray) -> list[tuple[int, int]]:
    """[(start, stop)] of the runs of equal consecutive rows of x (N, p): one parameter
    vector per pose, as the folds of Algorithm 1 evaluated together give it (a few
    vectors, each over many poses), is evaluated once per run where that is cheaper."""
    first = np.ones(len(x), dtype=bool)
    np.any(x[1:] != x[:-1], axis=1, out=first[1:])
    starts = np.flatnonzero(first).tolist()
    return list(zip(starts, starts[1:] + [len(x)]))


def motion_basis(w: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(3, 12): the top rows [R | c - R c] of a turn by q about the unit axis w (3,) through
    the point c (3,), flattened, are (cos q, sin q, 1 - cos q) times this matrix
    (:func:`kincal.rotations.turn_parts`), kept per axis line."""
    key = (w.tobytes(), np.asarray(c, float).tobytes())
    B = _BASES.get(key)
    if B is None:
        if len(_BASES) > 256:
            _BASES.clear()
        B = _BASES[key] = turn_parts(w, c).reshape(3, 12)
    return B


_BASES: dict = {}  # (axis, point) bytes: motion_basis


MOTION_CACHE_POSES = 1024  # poses up to which a chain keeps its joint motions
KEPT_FIRST = 2  # a chain of so few poses keeps its first states (and its last)
FRAMES_POSES = 256  # and the frames of its first state, up to this many poses (230 kB at 7
#                     joints: a few of the CV folds' chains are kept at once)
TIP_BLOCK_POSES = 4096  # poses evaluated together by Chain.tip
_GATHER_BUDGET = 4_000_000  # floats gathered at once for the kinematic columns (32 MB)


class Chain:
    """One error model's chain over N poses.

    model: the error model. joint_values: (N, n) [rad or m]. approach: (N, n) approach
    directions (+1/-1/0), needed with backlash terms. backlash: chain indices of the
    joints with a backlash term. torque: (N, n) gravity torque per joint [N m], needed
    with compliance terms; compliance: chain indices of the joints with one.
    """

    def __init__(self, model: ErrorModel, joint_values: np.ndarray,
                 approach: np.ndarray | None = None, backlash: tuple[int, ...] = (),
                 torque: np.ndarray | None = None, compliance: tuple[int, ...] = ()):
        self.model = model
        self.q = np.asarray(joint_values, dtype=float)
        self.N = len(self.q)
        self.approach = None if approach is None else np.asarray(approach, dtype=float)
        self.torque = None if torque is None else np.asarray(torque, dtype=float)
        self.backlash = tuple(int(i) for i in backlash)
        self.compliance = tuple(int(i) for i in compliance)
        if self.backlash and (self.approach is None or self.approach.shape != self.q.shape):
            raise ValueError(f"backlash terms need approach directions of shape {self.q.shape}")
        if self.compliance and (self.torque is None or self.torque.shape != self.q.shape):
            raise ValueError(f"compliance terms need gravity torques of shape {self.q.shape}")
        # every joint term: its joint and its factor per pose (backlash, then compliance)
        self.terms = self.backlash + self.compliance
        g, t = self.approach, self.torque  # checked above where the terms need them
        self.factors = np.column_stack(
            [g[:, i] for i in self.backlash if g is not None]
            + [t[:, i] for i in self.compliance if t is not None]
        ) if self.terms else np.zeros((self.N, 0))
        self._terms_of: dict[int, list[int]] = {}
        for k, i in enumerate(self.terms):
            self._terms_of.setdefault(i, []).append(k)
        # the joint motions, (N, 4, 4) per joint, are kept for few poses (cheap to reuse
        # across evaluations); for many (MOTION_CACHE_POSES) they are made anew at each
        # evaluation: 128 bytes per pose and joint would otherwise stay for the whole fit
        self._motion = self._motions() if self.N <= MOTION_CACHE_POSES else None
        # few poses: [(values' bytes, R_tip, p_tip, (before, placed) or None)] of the first
        # KEPT_FIRST states evaluated (at distinct values), then of the last (Chain.state);
        # the frames of the very first only
        self._kept: list = []
        # each joint's parameters are contiguous in the vector: slices keep the writes cheap
        edges = np.searchsorted(model.joint_of, np.arange(model.n + 1))
        if np.any(np.diff(model.joint_of) < 0):
            raise ValueError("an error model must list its parameters joint by joint")
        self._by_joint = [slice(int(edges[i]), int(edges[i + 1])) for i in range(model.n)]

    def subset(self, rows) -> "Chain":
        return Chain(self.model, self.q[rows],
                     None if self.approach is None else self.approach[rows], self.backlash,
                     None if self.torque is None else self.torque[rows], self.compliance)

    def _motions(self) -> list:
        """[(N, 4, 4)] every joint's motion at its joint values: the revolute joints'
        together (:meth:`_turns`), ~6 numpy calls per chain instead of per joint."""
        m = self.model
        rev = [i for i in range(m.n) if m.kinds[i] != "prismatic"]
        out = [None if i in rev else self.joint_motion(i, self.q[:, i]) for i in range(m.n)]
        if rev:
            for i, M in zip(rev, self._turns(rev, self.q.T[rev])):
                out[i] = M
        return out

    def joint_motion(self, i: int, qi: np.ndarray) -> np.ndarray:
        """(N, 4, 4) motion of joint i by qi (N,), in its placed frame."""
        m = self.model
        if m.kinds[i] != "prismatic":
            return self._turns([i], qi[None])[0]
        M = np.empty((len(qi), 4, 4))
        M[:, 3] = (0.0, 0.0, 0.0, 1.0)
        M[:, :3, :3] = np.eye(3)
        M[:, :3, 3] = qi[:, None] * m.screw_axes[i]
        return M

    def _turns(self, joints: list, Q: np.ndarray) -> np.ndarray:
        """(len(joints), N, 4, 4) the motions of the revolute ``joints`` by values Q
        (len(joints), N): a turn about the axis line through the screw point c, x -> R (x - c)
        + c, with R = c I + s K + (1 - c) w w^T; all twelve entries of [R | c - R c] as one
        product of (cos, sin, 1 - cos) with each joint's constant basis
        (:func:`motion_basis`), stacked over the joints (a product per joint, the same
        numbers whether one joint or many)."""
        m, (k, N) = self.model, Q.shape
        A = np.empty((k, N, 3))
        np.cos(Q, out=A[:, :, 0])
        np.sin(Q, out=A[:, :, 1])
        np.subtract(1.0, A[:, :, 0], out=A[:, :, 2])
        B = np.stack([motion_basis(m.screw_axes[i], m.screw_points[i]) for i in joints])
        M = np.empty((k, N, 4, 4))
        M[:, :, 3] = (0.0, 0.0, 0.0, 1.0)
        M[:, :, :3] = np.matmul(A, B).reshape(k, N, 3, 4)
        return M

    def tip(self, x: np.ndarray, backlash: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
        """(R (N, 3, 3), p (N, 3)) of the tip: :meth:`state` without the kept frames, for
        many poses in blocks of TIP_BLOCK_POSES (the same numbers, row by row), so that its
        (N, 4, 4) temporaries do not grow with the whole set."""
        if self.N <= TIP_BLOCK_POSES:
            s = self.state(x, backlash, keep=False)
            return s.R_tip, s.p_tip
        R, p = np.empty((self.N, 3, 3)), np.empty((self.N, 3))
        for rows, s in self._tip_blocks(x, backlash):
            R[rows], p[rows] = s.R_tip, s.p_tip
        return R, p

    def tip_point(self, x: np.ndarray, point: np.ndarray,
                  backlash: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) the point ``point`` (3,) of the tip frame in the base frame, p + R point
        of :meth:`tip` (the same numbers) without its (N, 3, 3) rotations."""
        out = np.empty((self.N, 3))
        for rows, s in self._tip_blocks(x, backlash):
            out[rows] = s.p_tip + s.R_tip @ point
        return out

    def _tip_blocks(self, x, backlash):
        for a in range(0, self.N, TIP_BLOCK_POSES):
            rows = slice(a, a + TIP_BLOCK_POSES)
            yield rows, (self if self.N <= TIP_BLOCK_POSES else self.subset(rows)).state(
                x, backlash, keep=False)

    def state(self, x: np.ndarray, backlash: np.ndarray | None = None,
              keep: bool = True) -> "ChainState":
        """Evaluate kinematic parameters x (and the joint terms' values: backlash, then
        compliance) on every pose; x (N, p): one kinematic vector per pose (the folds of
        Algorithm 1 evaluated together, :mod:`kincal.identification.cross_validation`).

        keep=False keeps only the tip (cheaper when no derivative is wanted)."""
        m, N = self.model, self.N
        # few poses: the first states (KEPT_FIRST) and the last are kept (read-only), for
        # evaluations at the same values: a frame fit moves only the frames (its every
        # evaluation is at the same kinematics), and the start's kinematics come back for the
        # result's residuals before calibration and, on a robot's seeded poses, at every fit
        # (the structural analysis); the nominal values and the start's (u = x / scale, whose
        # product back may differ in the last bit) are two. The same numbers, whether the
        # frames were kept or not
        key = (np.asarray(x, float).tobytes(), None if backlash is None or not np.any(backlash)
               else np.asarray(backlash, float).tobytes()) if self._motion is not None else None
        if key is not None:
            for values, R_tip, p_tip, frames in self._kept:
                if values == key and (frames is not None or not keep):
                    return ChainState(self, x, R_tip, p_tip, *(frames if keep else ([], [])))
        P = m.placements(x)
        # the frames before and after each placement, written in place when kept (one
        # (n, N, 4, 4) array each, so the columns need no stacking); a constant frame times
        # a placement is one (4 N, 4) x (4, 4) product
        before = np.empty((m.n, N, 4, 4)) if keep else None
        placed = np.empty((m.n, N, 4, 4)) if keep else None
        G = m.T_first
        for i in range(m.n):
            if G.ndim == 2:
                H = G @ P[i]
                if placed is not None:
                    placed[i] = H
            elif P.ndim == 4:  # one placement per pose
                H = placed[i] if placed is not None else np.empty((N, 4, 4))
                np.matmul(G, P[i], out=H)
            else:
                H = placed[i] if placed is not None else np.empty((N, 4, 4))
                np.matmul(G.reshape(-1, 4), P[i], out=H.reshape(-1, 4))
            if before is not None and i == 0:  # the others were made in place (below)
                before[i] = G
            ks = [k for k in self._terms_of.get(i, ()) if backlash is not None
                  and backlash[k] != 0.0]
            if not ks:
                M = (self._motion[i] if self._motion is not None
                     else self.joint_motion(i, self.q[:, i]))
            else:
                assert backlash is not None  # ks is empty without the terms' values
                qi = self.q[:, i] + sum(backlash[k] * self.factors[:, k] for k in ks)
                M = self.joint_motion(i, qi)
            # kept frames: the product made where the next joint's "before" is kept
            G = (np.matmul(H, M, out=before[i + 1]) if before is not None and i + 1 < m.n
                 else np.matmul(H, M))
        T = G @ m.T_last_tip if G.ndim == 2 else np.matmul(G.reshape(-1, 4), m.T_last_tip
                                                           ).reshape(N, 4, 4)
        if T.ndim == 2:
            T = np.broadcast_to(T, (N, 4, 4))
        if key is not None:  # read-only: shared by the states it serves
            T.flags.writeable = False
            kept = self._kept
            # a first one again (now with its frames), or the last; frames are kept for the
            # very first state only (the one a robot's seeded poses come back to: the
            # structural analysis evaluates them with derivatives at the start)
            at = next((i for i, e in enumerate(kept[:KEPT_FIRST]) if e[0] == key),
                      min(len(kept), KEPT_FIRST))
            frames = None
            if at == 0 and before is not None and placed is not None and N <= FRAMES_POSES:
                before.flags.writeable = placed.flags.writeable = False
                frames = (before, placed)
            entry = (key, T[:, :3, :3], T[:, :3, 3], frames)
            self._kept = kept[:at] + [entry] + kept[at + 1:KEPT_FIRST + 1]
        return ChainState(self, x, T[:, :3, :3], T[:, :3, 3],
                          [] if before is None else before, [] if placed is None else placed)


class ChainState:
    """A chain evaluated at one parameter vector: the tip pose and, if kept, the frames
    before (``before[i]``) and after (``placed[i]``) joint i's placement, each (N, 4, 4)
    (``before`` and ``placed``: (n, N, 4, 4) arrays; empty lists when not kept)."""

    def __init__(self, chain: Chain, x, R_tip, p_tip, before, placed):
        self.chain, self.x = chain, x
        self.R_tip, self.p_tip = R_tip, p_tip
        self.before, self.placed = before, placed

    def point_columns(self, P: np.ndarray, generic: bool = False
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives of points P (N, 3) in the base frame, rigidly attached to the tip:
        (kinematic (N, 3, p), joint terms (N, 3, n_terms)). A model may offer a faster
        ``point_columns`` of its own (MD-H does); generic=True uses the twists anyway."""
        chain, m = self.chain, self.chain.model
        N = chain.N
        fast = None if generic else getattr(m, "point_columns", None)
        if fast is not None and len(self.before):
            K = fast(self.x, self.before, self.placed, P)
        elif len(self.before):
            K = np.empty((N, 3, m.size))
            G = np.asarray(self.before)                           # (n, N, 4, 4)
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
        B = np.empty((N, 3, len(chain.terms)))
        for k, i in enumerate(chain.terms):
            H = self.placed[i]
            axis = H[:, :3, :3] @ m.screw_axes[i]
            if m.kinds[i] == "prismatic":
                col = axis
            else:
                c = H[:, :3, 3] + H[:, :3, :3] @ m.screw_points[i]
                col = cross_rows(axis, P - c)
            B[:, :, k] = col * chain.factors[:, k, None]
        return K, B

    def rotation_columns(self) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives of the tip's orientation as small rotations in the base frame:
        (kinematic (N, 3, p), joint terms (N, 3, n_terms))."""
        chain, m = self.chain, self.chain.model
        w, _ = m.twists(self.x)
        K = np.empty((chain.N, 3, m.size))
        for i, idx in enumerate(chain._by_joint):
            if idx.start != idx.stop:
                K[:, :, idx] = self.before[i][:, :3, :3] @ w[idx].T
        B = np.empty((chain.N, 3, len(chain.terms)))
        for k, i in enumerate(chain.terms):
            axis = self.placed[i][:, :3, :3] @ m.screw_axes[i]
            B[:, :, k] = (0.0 if m.kinds[i] == "prismatic" else axis) * chain.factors[:, k, None]
        return K, B
