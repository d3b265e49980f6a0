"""The data rows of a least-squares problem reduced block by block to small matrices.

Plain numpy. Many poses give a tall Jacobian J (m x p, m = 3 N): at a million poses one J
is about 1 GB, and the dense path built it, a copy with the residual column and two more
for its factorisation at every iteration. Here the rows arrive in blocks of poses
(``blocks(u)`` yields ``(span, r_b, J_b)``, J_b in a buffer reused from block to block)
and only p x p quantities are kept:

- :func:`normal_equations`: the Gram matrix J^T J and J^T r summed over the blocks (one
  pass, one BLAS product per block). The solver's step needs the triangle R of J's free
  columns; R = chol(J_f^T J_f) (Cholesky-QR) is used when its diagonal ratio is above
  :data:`CHOLESKY_MIN_RATIO` (cond(J_f) below ~1e7, so the Gram matrix keeps at least
  ~2 significant digits: the step is then a few digits short of Householder's at worst,
  which costs at most an extra iteration, and the point the iterations converge to is
  where J^T r = 0, which both compute to working precision). Below that ratio it is
  refused and :func:`stacked_triangle` is used.
- :func:`stacked_triangle`: Householder R of [R; J_b] block after block (a tall-skinny QR):
  as accurate as one QR of the whole J, several times the Gram's cost; the identifiability
  analysis, whose rank decisions need full accuracy, uses it.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable, Protocol, cast

import numpy as np

from kincal.identification.layout import MM
from kincal.identification.selection import Identifiability, analyze, identifiable

CHOLESKY_MIN_RATIO = 1e-7  # smallest diag(R) / largest diag(R) accepted from the Gram


def stacked_triangle(blocks: Iterable[tuple[slice, np.ndarray, np.ndarray]],
                     columns: np.ndarray | None = None, with_residual: bool = False,
                     normal: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                     ) -> tuple[np.ndarray, int]:
    """(R (c, c) upper triangular, m): R^T R = A^T A for A the stacked J_b[:, columns]
    (with -r_b as a last column if ``with_residual``), and the number of rows m.

    normal: (r (m,), G (p, p), g (p,)) zeroed, summed into from the same blocks as
    :func:`normal_equations` does (one pass gives both: the analysis and the first
    linearisation of the fit that follows it at the same point)."""
    R: np.ndarray | None = None
    m = 0
    for span, r, J in blocks:
        if normal is not None:
            _add_normal(normal, span, r, J)
        A = J if columns is None else J[:, columns]
        if with_residual:
            A = np.column_stack([A, -r])
        m += A.shape[0]
        # numpy's stubs type qr(mode="r") as a QRResult; it returns the R array
        R = cast(np.ndarray, np.linalg.qr(A if R is None else np.vstack([R, A]), mode="r"))
    if R is None:
        raise ValueError("no rows to stack: the residual gave no blocks")
    return R, m


def _add_normal(normal, span, rb, Jb) -> None:
    r, G, g = normal
    r[span] = rb
    G += Jb.T @ Jb
    g += Jb.T @ rb


def normal_equations(blocks: Iterable[tuple[slice, np.ndarray, np.ndarray]], m: int,
                     p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r (m,), G = J^T J (p, p), g = J^T r (p,)) over the blocks."""
    normal = np.empty(m), np.zeros((p, p)), np.zeros(p)
    for span, rb, Jb in blocks:
        _add_normal(normal, span, rb, Jb)
    return normal


def triangle_from_gram(G: np.ndarray, g: np.ndarray, rr: float) -> np.ndarray | None:
    """The (k+1, k+1) triangle of [J | -r] from G = J^T J, g = J^T r and rr = r^T r, or
    None when G is too ill-conditioned for Cholesky-QR (see the module notes)."""
    k = G.shape[0]
    try:
        R = np.linalg.cholesky(G).T
    except np.linalg.LinAlgError:
        return None
    d = np.abs(np.diag(R))
    if k and d.min() <= CHOLESKY_MIN_RATIO * d.max():
        return None
    z = np.linalg.solve(R.T, -g) if k else np.zeros(0)  # R^T z = J^T (-r)
    out = np.zeros((k + 1, k + 1))
    out[:k, :k], out[:k, k] = R, z
    out[k, k] = np.sqrt(max(rr - float(z @ z), 0.0))
    return out


def linearise(blocks: Callable, u: np.ndarray, m: int, p: int, free_idx: np.ndarray,
              memo: dict | None = None):
    """(r (m,), G (p, p) = J^T J of every column, Rz (k+1, k+1) triangle of [J_free | -r])
    at u, from the blocks: one pass for the normal equations (or none: ``memo``, a
    residual's remembered pass at exactly this u, :func:`analyze_rows`), a second (stacked
    QR) only when they are too ill-conditioned."""
    kept = memo.pop(u.tobytes(), None) if memo else None
    r, G, g = kept if kept is not None else normal_equations(blocks(u), m, p)
    Rz = triangle_from_gram(G[np.ix_(free_idx, free_idx)], g[free_idx], float(r @ r))
    if Rz is None:
        Rz, _ = stacked_triangle(blocks(u), free_idx, with_residual=True)
    return r, G, Rz


def row_blocks(parts, layout, weights, scale, kinematic: bool = True,
               row_scale=None) -> Callable:
    """blocks(u, with_jacobian=True, out=None): the one traversal of the residual's rows
    (sets in order, each in its blocks of samples), yielding (rows, r_b [mm], J_b) per block
    at u = x / scale (or u (samples, p), one vector per sample: the folds of Algorithm 1
    together): the rows' weighted residuals and their Jacobian (None without
    with_jacobian). J_b is a view of ``out[rows]`` when ``out`` (m, p) is given (the dense
    Jacobian, :func:`residual_function`), else a buffer that the next block overwrites.
    parts: [(set index, kind model, global rows, [(local slice, block kind model)])];
    kinematic=False leaves the kinematic and backlash columns at zero. row_scale: None, or
    per set a (dim,) factor of each of a sample's rows (the noise levels of its kinds of
    row, :mod:`kincal.identification.evidence`), on top of the samples' weights."""
    buffers: dict = {}
    k, bl = layout.n_kinematic, layout.backlash_slice
    # every weight 1 (no sigmas, no noise levels): the products by the weights are left
    # out (a product by 1.0 changes no number)
    unit = row_scale is None and bool(np.all(weights == 1.0))

    def blocks(u, with_jacobian: bool = True, out: np.ndarray | None = None):
        x = u * scale
        at = first = 0
        for i, km, g, blocks_i in parts:
            if x.ndim == 1:
                kin, fr, b = layout.split(x, i)
            fs = layout.frame_slices[i]
            for sl, block in blocks_i:
                if x.ndim == 2:  # one vector per sample (u (samples, p))
                    kin, fr, b = layout.split(x[first + sl.start:first + sl.stop], i)
                w = None if unit else weights[g[sl]][:, None] * (
                    1.0 if row_scale is None else row_scale[i])
                span = slice(at + km.dim * sl.start, at + km.dim * sl.stop)
                if not with_jacobian:
                    rr = block.residuals(kin, fr, b)
                    yield span, (rr if w is None else rr * w).ravel() / MM, None
                    continue
                n = block.N * km.dim
                if out is not None:
                    J = out[span]
                else:
                    if n not in buffers:
                        buffers[n] = np.zeros((n, layout.size))
                    J = buffers[n]
                J[:] = 0.0
                rr, Jk, Jf, Jb = block.residuals(kin, fr, b, jacobian=True, kinematic=kinematic)
                if w is not None:
                    w3 = w[:, :, None]
                    rr, Jk, Jf, Jb = rr * w, Jk * w3, Jf * w3, Jb * w3
                J[:, :k] = Jk.reshape(n, -1)
                J[:, fs] = Jf.reshape(n, -1)
                if Jb.shape[2]:
                    J[:, bl] = Jb.reshape(n, -1)
                J *= scale / MM
                yield span, rr.ravel() / MM, J
            at += km.N * km.dim
            first += km.N

    return blocks


class BlockedResidual(Protocol):
    """A residual function that also streams its rows in blocks (:func:`residual_function`)."""

    blocks: Callable
    rows: int
    n_blocks: int
    memo: dict

    def __call__(self, u: np.ndarray, jacobian: bool = ...) -> Any: ...


def residual_function(parts, layout, weights, scale, kinematic: bool = True,
                      row_scale=None) -> BlockedResidual:
    """residual(u, with_jacobian) -> (r (m,) [mm], J (m, p) or None), the dense rows of
    :func:`row_blocks` (the same traversal, so the two cannot differ), with ``blocks``,
    ``rows`` (m) and ``n_blocks`` for the solver's streamed path."""
    blocks = row_blocks(parts, layout, weights, scale, kinematic, row_scale)
    m = sum(km.N * km.dim for _, km, _, _ in parts)

    def residual(u, with_jacobian):
        r = np.empty(m)
        J = np.empty((m, layout.size)) if with_jacobian else None
        for span, rb, _ in blocks(u, with_jacobian, J):
            r[span] = rb
        return r, J

    out = cast(BlockedResidual, residual)  # the attributes are set here
    out.blocks = blocks
    out.rows, out.n_blocks = m, sum(len(part[3]) for part in parts)
    out.memo = {}  # u bytes: of the pass made by the analysis (analyze_rows) at u, for the
    #                fit's first linearisation there: (r, J^T J, J^T r) streamed, (r, J) dense
    return out


def one_pass(whole: Callable, frames_only: Callable, u: np.ndarray, is_frame: np.ndarray
             ) -> None:
    """The start's one pass, for few samples (one block): the whole Jacobian at the start
    u, left in the memos of ``whole`` (for :func:`analyze_rows` there, then the fit's first
    linearisation) and of ``frames_only`` (its frame columns ``is_frame``, the rest zero:
    the frame fit's own Jacobian, for its analysis and first linearisation). The frame fit
    rarely moves from a point set's closed-form start (the frames' least-squares solution at
    the nominal kinematics), and then the analysis reads this pass instead of making its
    own; every kind's frame columns are the same numbers with or without the kinematic ones
    (tests/test_fixed_cost.py)."""
    if getattr(whole, "n_blocks", 1) > 1 or getattr(frames_only, "n_blocks", 1) > 1:
        return
    r, J = whole(u, True)
    Jf = J.copy()
    Jf[:, ~is_frame] = 0.0
    for f, rJ in ((whole, (r, J)), (frames_only, (r, Jf))):
        memo = cast(BlockedResidual, f).memo
        memo.clear()
        memo[u.tobytes()] = rJ


def analyze_rows(residual: Callable, u: np.ndarray, column_scale: np.ndarray, names,
                 n_kinematic: int, free: np.ndarray, rank_tol: float,
                 samples: int | None = None, joints=()) -> Identifiability:
    """:func:`kincal.identification.selection.analyze` of the Jacobian at u with its columns
    scaled by ``column_scale`` (:func:`_analysed_matrix`); samples: the samples of its rows;
    joints: the joints' order of preference (several chains)."""
    A, m = _analysed_matrix(residual, u)
    return analyze(A * column_scale, names, n_kinematic, free, rank_tol, m=m, samples=samples,
                   joints=joints)


def identifiable_rows(residual: Callable, u: np.ndarray, column_scale: np.ndarray, names,
                      n_kinematic: int, free: np.ndarray, rank_tol: float, joints=()
                      ) -> tuple[str, ...]:
    """The names :func:`analyze_rows` keeps, without its report
    (:func:`kincal.identification.selection.identifiable`)."""
    A, m = _analysed_matrix(residual, u)
    return identifiable(A * column_scale, names, n_kinematic, free, rank_tol, m=m,
                        joints=joints)


def _analysed_matrix(residual: Callable, u: np.ndarray) -> tuple[np.ndarray, int | None]:
    """(the Jacobian at u, None); for rows streamed in blocks (many poses), (its QR triangle
    (the same column norms, projections and singular values), built without the whole J,
    the number of rows), in a pass that also sums the normal equations at u and leaves them
    in the residual's ``memo`` for the fit's first linearisation (:func:`linearise`), which
    starts there."""
    if getattr(residual, "n_blocks", 1) <= 1:
        memo = getattr(residual, "memo", None)
        kept = memo.get(u.tobytes()) if memo else None  # a pass made at u already
        r, J = residual(u, True) if kept is None else kept
        if memo is not None:  # the fit that starts at u takes (r, J) from here (linearise)
            memo.clear()
            memo[u.tobytes()] = (r, J)
        return J, None
    blocked = cast(BlockedResidual, residual)
    p = u.size
    normal = np.empty(blocked.rows), np.zeros((p, p)), np.zeros(p)
    R, m = stacked_triangle(blocked.blocks(u), normal=normal)
    blocked.memo.clear()
    blocked.memo[u.tobytes()] = normal
    return R, m
