"""I-optimal pose selection: the smallest mean predicted position variance over a volume.

Plain numpy, beside :mod:`kincal.planning.pose_selection` (which builds the normalised
Jacobians and reports). With the information matrix M = J_S^T J_S of the chosen poses
and A = mean over the target poses t of J_t^T J_t (the same columns), the mean predicted
variance of the measured point over the targets, per unit noise variance, is

    V(S) = trace(M^-1 A) / 3        [mm^2 per mm^2 of noise, per axis]

I-optimality minimises V: it cares about how well the calibrated model predicts where
the robot will work (the target volume), not about the parameters as such, so it does
not spend poses on parameter combinations that barely move the point there.

The measurement frame and tool point are registered again wherever the robot is used (a
new instrument, a new tool; the paper's validation refits them), so an error that a
rigid frame and a tool point absorb over the targets costs nothing there. A therefore
counts only what is left of the kinematic columns after that refit: with the targets'
stacked Jacobian split into kinematic columns K and frame columns F (``base.*``,
``tool.*``),

    A = K^T (I - P_F) K / T   (zero in the frame rows and columns),

P_F the projection onto the span of F. This is what trace(M^-1 A) must weigh when the
validation refits the frames, and it is what made I-optimal poses better than D-optimal
ones in a 20 mm cube (docs/results.md, "The default beyond its twin"): without it, the
criterion spends poses on the frame parameters and on the kinematic combinations that
the frames absorb anyway.

Search, as for D: greedy forward selection from the ridge RIDGE * I, each step scoring
every candidate k at once by the rank-3 update

    trace(M^-1 A) - trace((M + J_k^T J_k)^-1 A) = trace((I + B_k J_k^T)^-1 B_k A B_k^T),
    B_k = J_k M^-1,

then exchanges: each chosen pose in turn is taken out (rank-3 downdate) and the best
candidate put in its place if that lowers V by more than a relative EXCHANGE_RTOL; sweeps
repeat until one makes no swap or ``max_swaps`` is reached. Deterministic (ties go to the
lower index). A local optimum for single swaps, not in general the global one.
"""

from __future__ import annotations

import numpy as np

from kincal.planning.d_optimal import CHUNK

RIDGE = 1e-6  # as in pose_selection: the first greedy picks see a finite objective
EXCHANGE_RTOL = 1e-9  # a swap must lower V by more than this fraction
SINGULAR = 1e-12


def target_moment(Jt: np.ndarray, frames: np.ndarray | None = None,
                  count: int | None = None) -> np.ndarray:
    """(p, p) A for target Jacobians (T, 3, p): the mean of J_t^T J_t, or with ``frames``
    ((p,) bool, the frame and tool columns) the kinematic part left after refitting those
    over the targets (see the module notes). Only J^T J enters: the triangle R of the
    stacked rows (as (1, p, p)) gives the same A, with ``count`` the number of targets."""
    T, _, p = Jt.shape
    T = T if count is None else count
    if frames is None or not frames.any():
        return np.einsum("kip,kiq->pq", Jt, Jt) / T
    S = Jt.reshape(-1, p)
    K = S[:, ~frames]
    U, sv, _ = np.linalg.svd(S[:, frames], full_matrices=False)
    Q = U[:, sv > SINGULAR ** 0.5 * sv[0]]  # an orthonormal basis of the span of F
    R = K - Q @ (Q.T @ K)
    A = np.zeros((p, p))
    A[np.ix_(~frames, ~frames)] = R.T @ R / T
    return A


def mean_variance(Minv: np.ndarray, A: np.ndarray) -> float:
    """V = trace(M^-1 A) / 3 (see the module notes)."""
    return float(np.einsum("pq,qp->", Minv, A)) / 3.0


def mean_variances(Jn: np.ndarray, A: np.ndarray, subsets: np.ndarray) -> np.ndarray:
    """(K,) V of each subset (K, n) of candidate rows; inf where its M is singular."""
    X = Jn[subsets].reshape(len(subsets), -1, Jn.shape[2])
    out = np.full(len(subsets), np.inf)
    for k, Xk in enumerate(X):
        Minv = _exact_inverse(Xk.T @ Xk)
        if Minv is not None:
            out[k] = mean_variance(Minv, A)
    return out


def _gains(Jn: np.ndarray, Minv: np.ndarray, A: np.ndarray) -> np.ndarray:
    """(M,) decrease of 3 V when each candidate is added to the set of M^-1 (CHUNK
    candidates at a time: their (c, 3, p) products, not the whole set's, are held)."""
    out = np.empty(len(Jn))
    for s in range(0, len(Jn), CHUNK):
        J = Jn[s:s + CHUNK]
        B = J @ Minv                                                # (c, 3, p)
        C = np.eye(3) + B @ J.transpose(0, 2, 1)                    # (c, 3, 3)
        Q = (B @ A) @ B.transpose(0, 2, 1)                          # (c, 3, 3)
        out[s:s + CHUNK] = np.trace(np.linalg.solve(C, Q), axis1=1, axis2=2)
    return out


def _add(Minv: np.ndarray, Jk: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """M^-1 after M += sign J_k^T J_k (Woodbury, rank 3)."""
    W = Jk @ Minv
    out = Minv - W.T @ np.linalg.solve(sign * np.eye(3) + W @ Jk.T, W)
    return 0.5 * (out + out.T)


def _exact_inverse(G: np.ndarray) -> np.ndarray | None:
    w = np.linalg.eigvalsh(G)
    if w[0] <= SINGULAR * w[-1]:
        return None
    return np.linalg.inv(G)


def greedy(Jn: np.ndarray, n: int, keep: list[int], A: np.ndarray):
    """Forward selection; returns (chosen, M^-1, ridge still on)."""
    M, _, p = Jn.shape
    chosen = list(keep)
    G = RIDGE * np.eye(p) + np.einsum("kip,kiq->pq", Jn[chosen], Jn[chosen])
    Minv, ridge = np.linalg.inv(G), True
    available = np.ones(M, dtype=bool)
    available[chosen] = False
    while True:
        if ridge and 3 * len(chosen) >= p:
            S = Jn[chosen].reshape(-1, p)
            exact = _exact_inverse(S.T @ S)
            if exact is not None:
                Minv, ridge = exact, False
        if len(chosen) == n:
            return chosen, Minv, ridge
        gain = _gains(Jn, Minv, A)
        gain[~available] = -np.inf
        k = int(np.argmax(gain))
        Minv = _add(Minv, Jn[k])
        chosen.append(k)
        available[k] = False


def exchange(Jn: np.ndarray, chosen: list[int], n_keep: int, Minv: np.ndarray, A: np.ndarray,
             max_swaps: int):
    """Swap sweeps (see the module notes); returns (chosen, M^-1, swaps, converged)."""
    chosen = list(chosen)
    swaps = 0
    while True:
        swapped = False
        for i in range(n_keep, len(chosen)):
            V = mean_variance(Minv, A)
            out = chosen[i]
            try:
                Mi = _add(Minv, Jn[out], sign=-1.0)
            except np.linalg.LinAlgError:
                continue  # the set without this pose is singular: it cannot leave
            if not np.all(np.isfinite(Mi)) or np.min(np.linalg.eigvalsh(Mi)) <= 0:
                continue
            gain = _gains(Jn, Mi, A)
            gain[chosen] = -np.inf
            gain[out] = -np.inf
            k = int(np.argmax(gain))
            V_new = mean_variance(Mi, A) - gain[k] / 3.0
            if V_new < V * (1 - EXCHANGE_RTOL):
                if swaps == max_swaps:
                    return chosen, Minv, swaps, False
                Minv = _add(Mi, Jn[k])
                chosen[i] = k
                swaps += 1
                swapped = True
        if not swapped:
            return chosen, Minv, swaps, True
