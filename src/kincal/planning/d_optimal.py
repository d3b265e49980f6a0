"""D-optimal pose selection: greedy forward choice, then Fedorov exchange, on log det of the
information matrix sum_k J_k^T J_k of per-sample Jacobians (k, d, p) in reporting units.

Plain numpy; :mod:`kincal.planning.pose_selection` builds the Jacobians and reports, this
module only chooses (its I-optimal sibling is :mod:`kincal.planning.i_optimal`). Rank
updates keep every step cheap: the Woodbury identity for each pick and each swap, a
batched d x d determinant for every candidate at once.
"""

from __future__ import annotations

import numpy as np

RIDGE = 1e-6  # start of the greedy search, in units of the average pose's information
EXCHANGE_TOL = 1e-9  # a swap must raise log det by more than this to be made
SINGULAR = 1e-12  # reciprocal condition below which an information matrix counts as singular
CHUNK = 2048  # candidates scored at once (bounds memory)


def _det3(A: np.ndarray) -> np.ndarray:
    """Determinants of (..., d, d) arrays: closed form for d = 3 (points), else LAPACK
    (poses give 6 rows per sample, distances and plane contacts 1)."""
    if A.shape[-1] != 3:
        return np.linalg.det(A)
    return (A[..., 0, 0] * (A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1])
            - A[..., 0, 1] * (A[..., 1, 0] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 0])
            + A[..., 0, 2] * (A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0]))


def _log(x: np.ndarray) -> np.ndarray:
    """ln x, -inf where x <= 0 (a determinant that rounding made non-positive)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x > 0, np.log(np.where(x > 0, x, 1.0)), -np.inf)


def _quad(J: np.ndarray, Minv: np.ndarray) -> np.ndarray:
    """(k, 3, 3) J_k M^-1 J_k^T for (k, 3, p) Jacobians, CHUNK at a time (the (k, 3, p)
    product of all candidates would take as much memory as their Jacobians)."""
    out = np.empty((len(J), J.shape[1], J.shape[1]))
    for s in range(0, len(J), CHUNK):
        Jc = J[s:s + CHUNK]
        out[s:s + CHUNK] = (Jc @ Minv) @ Jc.transpose(0, 2, 1)
    return out


def _exact_inverse(G: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(G^-1, ln det G) of a symmetric information matrix, or None if it is singular."""
    w = np.linalg.eigvalsh(G)
    if w[0] <= SINGULAR * w[-1]:
        return None
    L = np.linalg.cholesky(G)
    Linv = np.linalg.inv(L)
    return Linv.T @ Linv, float(2.0 * np.sum(np.log(np.diag(L))))


def greedy(Jn: np.ndarray, n: int, keep: list[int]):
    """Forward selection from RIDGE * I; returns (chosen, M^-1, log det, ridge still on)."""
    M, d, p = Jn.shape
    chosen = list(keep)
    G = RIDGE * np.eye(p) + np.einsum("kip,kiq->pq", Jn[chosen], Jn[chosen])
    Minv, log_det = np.linalg.inv(G), float(np.linalg.slogdet(G)[1])
    ridge = True
    available = np.ones(M, dtype=bool)
    available[chosen] = False
    while True:
        if ridge and d * len(chosen) >= p:
            S = Jn[chosen].reshape(-1, p)
            exact = _exact_inverse(S.T @ S)
            if exact is not None:
                (Minv, log_det), ridge = exact, False
        if len(chosen) == n:
            return chosen, Minv, log_det, ridge
        gain = _log(_det3(np.eye(d) + _quad(Jn, Minv)))  # all candidates: one batched product
        gain[~available] = -np.inf
        k = int(np.argmax(gain))
        Jk = Jn[k]
        W = Jk @ Minv                                                   # (3, p)
        Minv = Minv - W.T @ np.linalg.solve(np.eye(d) + W @ Jk.T, W)    # Woodbury
        Minv = 0.5 * (Minv + Minv.T)
        log_det += float(gain[k])
        chosen.append(k)
        available[k] = False


def _best_swap(Jn, chosen, removable, Minv):
    """(log-det gain, position in chosen, candidate) of the best single swap."""
    M, d, p = Jn.shape
    JS = Jn[chosen]
    WS = JS @ Minv
    A_ii = WS @ JS.transpose(0, 2, 1)                                  # (n, 3, 3)
    free_rows = np.setdiff1d(np.arange(M), chosen)
    best = (-np.inf, -1, -1)
    for start in range(0, free_rows.size, CHUNK):
        rows = free_rows[start:start + CHUNK]
        JU = Jn[rows]
        I_A = np.eye(d) + _quad(JU, Minv)                               # (c, 3, 3)
        A_ij = (WS.reshape(-1, p) @ JU.reshape(-1, p).T).reshape(
            len(chosen), d, len(rows), d).transpose(0, 2, 1, 3)         # (n, c, 3, 3)
        # det(M - J_i'J_i + J_j'J_j) / det M = det(I + A_jj) det(I - A_ii + A_ij (I + A_jj)^-1 A_ji)
        D = np.eye(d) - A_ii[:, None] + A_ij @ np.linalg.inv(I_A)[None] @ A_ij.transpose(0, 1, 3, 2)
        gain = _log(_det3(I_A))[None, :] + _log(_det3(D))
        gain[~removable] = -np.inf
        i, j = np.unravel_index(int(np.argmax(gain)), gain.shape)
        if gain[i, j] > best[0]:
            best = (float(gain[i, j]), int(i), int(rows[j]))
    return best


def exchange(Jn, chosen, n_keep, Minv, log_det, max_swaps):
    """Fedorov exchange; returns (chosen, M^-1, log det, swaps, converged)."""
    removable = np.arange(len(chosen)) >= n_keep
    swaps = 0
    while True:
        if len(chosen) == Jn.shape[0] or not removable.any():
            return chosen, Minv, log_det, swaps, True
        gain, i, j = _best_swap(Jn, chosen, removable, Minv)
        if not gain > EXCHANGE_TOL:
            return chosen, Minv, log_det, swaps, True
        if swaps == max_swaps:
            return chosen, Minv, log_det, swaps, False
        U = np.concatenate([Jn[j], Jn[chosen[i]]])                     # (6, p)
        W = U @ Minv
        d = Jn.shape[1]
        K = W @ U.T + np.diag(np.r_[np.ones(d), -np.ones(d)])          # C^-1 + U M^-1 U'
        Minv = Minv - W.T @ np.linalg.solve(K, W)                      # Woodbury, rank 6
        Minv = 0.5 * (Minv + Minv.T)
        log_det += gain
        chosen = chosen[:i] + [j] + chosen[i + 1:]
        swaps += 1
