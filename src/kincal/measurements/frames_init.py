"""Closed-form first guess of the measurement frame and the tool point.

Plain numpy. With the nominal kinematics the tip poses (R_k, p_k) in the base frame are
known; the measured points P_k satisfy P_k = R_b (p_k + R_k t) + t_b. Two starts are
tried and the better kept, so no user guess is needed:

- pivot start: if the measured point moved little (R-test, a sphere seated in a cup),
  p_k + R_k t is nearly constant, which is linear in (t, c): a pivot calibration;
- given start: the user's tool guess (default: the tip frame origin).

From each start, rigid registration (Kabsch) of the predicted points gives (R_b, t_b);
with R_b fixed, (t, t_b) follow from a linear least-squares solve; a few rounds of the
two settle the guess. Further measured points on the tool then follow, each by a linear
solve with that frame (:func:`point_in_tip`). The caller refines all by Gauss-Newton.
"""

from __future__ import annotations

import numpy as np

from kincal.rotations import kabsch, kabsch_rotation


def pivot_tool(R_tip: np.ndarray, p_tip: np.ndarray) -> np.ndarray:
    """Tool point t [m] in the tip frame that keeps p_k + R_k t most nearly fixed."""
    N = len(R_tip)
    A = np.concatenate([R_tip, np.broadcast_to(-np.eye(3), (N, 3, 3))], axis=2).reshape(3 * N, 6)
    sol, *_ = np.linalg.lstsq(A, -p_tip.reshape(-1), rcond=None)
    return sol[:3]


def alternate(R_tip, p_tip, P, tools, rounds: int = 8, sums: tuple | None = None) -> list:
    """Alternate Kabsch for (R_b, t_b) and a linear solve for (t, t_b) from each start of
    ``tools`` (S, 3), the starts' rounds together.

    Returns per start (R_b (3, 3), t_b (3,), tool (3,), rms [m]). sums: :func:`round_sums`
    of these poses (default: made here).

    Each round's work is 3 x 3 arithmetic on sums over the poses made once (a round costs
    the same whatever the number of poses): Kabsch's cross-covariance of the predicted
    points x_k = p_k + R_k t with the centred measured ones is H = sum p_k Pc_k^T +
    sum_j t_j sum_k R_k e_j Pc_k^T, and the linear solve's normal equations
    [[N I, (R_b S)^T], [R_b S, N I]] (S = sum R_k) reduce by the Schur complement to
    (N I - S^T S / N) t = r_1 - S^T R_b^T r_2 / N, a matrix the same in every round. The
    starts still going are stacked, so a round is a few numpy calls (one SVD) for all of
    them, each start's numbers those of its rounds alone. When that matrix is
    ill-conditioned (tip orientations nearly all alike: t and t_b barely separable) the
    rounds take numpy's least squares of the stacked rows (3N, 6) instead, whose
    minimum-norm answer the normal equations cannot give."""
    T = np.array(tools, dtype=float).reshape(-1, 3)
    sums = round_sums(R_tip, p_tip, P) if sums is None else sums
    if not sums:
        return [_alternate_rows(R_tip, p_tip, P, t, rounds) for t in T]
    N, S, w, V, H0, HT, W, c0, P_sum, p_sum = sums
    going = list(range(len(T)))
    for _ in range(rounds):
        t = T[going]
        # products of stacks of one matrix by one vector each (matmul's per-matrix
        # products: the bits of one start's own, which products of t (L, 3) by a matrix
        # at once round otherwise)
        Rb = kabsch_rotation(H0 + np.matmul(t[:, None, :], HT).reshape(-1, 3, 3))
        r2 = P_sum - Rb @ p_sum
        r1 = np.einsum("ijl,blj->bi", W, Rb) - c0
        y = r1 - np.matmul(S.T, np.swapaxes(Rb, 1, 2) @ r2[:, :, None])[:, :, 0] / N
        sol = np.matmul(V, np.matmul(V.T, y[:, :, None]) / w[:, None])[:, :, 0]
        T[going] = sol
        # Gauss-Newton refines it after; the largest change in Python numbers (the same
        # differences, fewer numpy calls)
        going = [k for k, a, b in zip(going, sol.tolist(), t.tolist())
                 if max(abs(u - v) for u, v in zip(a, b)) > 1e-9]
        if not going:
            break
    return _finish(R_tip, p_tip, P, T)


def round_sums(R_tip, p_tip, P) -> tuple:
    """The sums over the poses that :func:`alternate`'s rounds work on (its notes), the
    same from every start: (N, S, the eigenpairs (w, V) of N I - S^T S / N, H0, HT, W, c0,
    the sums of P and p); () when that matrix is ill-conditioned (the rounds then take the
    stacked rows)."""
    N = len(P)
    S = R_tip.sum(axis=0)
    C = N * np.eye(3) - S.T @ S / N
    w, V = np.linalg.eigh(C)
    if w[0] <= 1e-6 * max(w[-1], 1e-300):
        return ()
    Pc = P - P.mean(axis=0)
    H0 = p_tip.T @ Pc  # sum p_k Pc_k^T
    HT = np.einsum("kaj,kb->jab", R_tip, Pc).reshape(3, 9)  # [j] = sum R_k e_j Pc_k^T
    W = np.einsum("kji,kl->ijl", R_tip, P)  # r_1 = W : R_b - sum R_k^T p_k
    c0 = np.einsum("kji,kj->i", R_tip, p_tip)
    return N, S, w, V, H0, HT, W, c0, P.sum(axis=0), p_tip.sum(axis=0)


def _finish(R_tip, p_tip, P, tools) -> list:
    """Per tool point of ``tools`` (S, 3): (R_b, t_b) by Kabsch of its predicted points onto
    P, it, and the rms [m] of the fit; the starts together (:func:`kincal.rotations.kabsch`
    of a stack: each one's numbers those of its own call)."""
    T = np.asarray(tools, dtype=float).reshape(-1, 3)
    x = p_tip + np.matmul(R_tip, T[:, None, :, None])[..., 0]  # (S, N, 3)
    Rb, tb = kabsch(x, P)
    fit = np.matmul(x, np.swapaxes(Rb, 1, 2)) + tb[:, None]
    rms = np.sqrt(np.mean(np.sum((P - fit) ** 2, axis=2), axis=1)).tolist()
    return list(zip(Rb, tb, T, rms))


def _alternate_rows(R_tip, p_tip, P, t, rounds):
    """:func:`alternate` on the stacked rows, for tip orientations nearly all alike."""
    N = len(P)
    for _ in range(rounds):
        x = p_tip + R_tip @ t
        Rb, tb = kabsch(x, P)
        A = np.concatenate([Rb @ R_tip, np.broadcast_to(np.eye(3), (N, 3, 3))], axis=2)
        b = P - p_tip @ Rb.T
        sol, *_ = np.linalg.lstsq(A.reshape(3 * N, 6), b.reshape(-1), rcond=None)
        if np.max(np.abs(sol[:3] - t)) <= 1e-9:  # Gauss-Newton refines it after
            t = sol[:3]
            break
        t = sol[:3]
    return _finish(R_tip, p_tip, P, [t])[0]


def initial_frames(R_tip, p_tip, P, tool_guess=None):
    """Best of the pivot and given starts: (R_b, t_b, tool, rms [m], start name)."""
    starts = {"given": np.zeros(3) if tool_guess is None else np.asarray(tool_guess, float),
              "pivot": pivot_tool(R_tip, p_tip)}
    best = None
    for name, found in zip(starts, alternate(R_tip, p_tip, P, list(starts.values()))):
        if best is None or found[3] < best[3]:
            best = (*found, name)
    return best


def point_in_tip(R_tip, p_tip, P, Rb, tb) -> np.ndarray:
    """(3,) the tool point t that best gives P_k = R_b (p_k + R_k t) + t_b, frame known."""
    A = np.asarray(R_tip).reshape(-1, 3)
    b = ((np.asarray(P) - tb) @ Rb - p_tip).reshape(-1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    return sol
