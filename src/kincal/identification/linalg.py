"""Dense linear algebra kernels of the identification: the QR triangle (LAPACK's dgeqrf, and
CholeskyQR2 for very tall matrices) and the minimum-norm least-squares solve (dgelsy),
called through scipy's compiled LAPACK wrappers without its checks and dispatch.

Plain numpy and scipy's LAPACK. A leaf of the identification: the solver, the selection of
identifiable parameters and the evidence take their factorisations from here.
"""

from __future__ import annotations

import numpy as np

NAMES = ("gelsy", "gelsy_lwork", "geqrf", "geqrf_lwork")  # the LAPACK routines used


def _routines() -> tuple:
    """(dgelsy, dgelsy_lwork, dgeqrf, dgeqrf_lwork): scipy's compiled LAPACK wrappers, the
    very functions ``scipy.linalg.lapack.get_lapack_funcs`` returns for float64. Before
    anything imports ``scipy.linalg``, its extension module (``_flapack``) is loaded from
    scipy's own file without the package import, which costs a command's start-up about
    0.15 s (its array-API layer imports numpy.f2py and numpy.testing) for a few LAPACK
    routines. Where scipy keeps that file elsewhere (another release's layout), the public
    import gives the same functions: only the start-up differs."""
    import importlib.util
    import os
    import sys

    if "scipy.linalg" not in sys.modules:
        import scipy

        folder = os.path.join(os.path.dirname(scipy.__file__), "linalg")
        files = sorted(f for f in os.listdir(folder) if f.startswith("_flapack.")
                       and f.endswith((".so", ".pyd")))
        spec = (importlib.util.spec_from_file_location("scipy.linalg._flapack",
                                                       os.path.join(folder, files[0]))
                if files else None)
        if spec is not None and spec.loader is not None:
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            if all(hasattr(module, "d" + name) for name in NAMES):
                return tuple(getattr(module, "d" + name) for name in NAMES)
    from scipy.linalg.lapack import get_lapack_funcs

    return tuple(get_lapack_funcs(NAMES, (np.zeros((1, 1)), np.zeros(1))))


_ROUTINES: tuple = ()  # (dgelsy, dgelsy_lwork, dgeqrf, dgeqrf_lwork), loaded at the first solve
_LWORK: dict = {}  # (m, n): LAPACK's optimal work size for gelsy
_QR_LWORK: dict = {}  # (m, n): the same for geqrf


def lapack() -> tuple:
    """(dgelsy, dgelsy_lwork, dgeqrf, dgeqrf_lwork), loaded once (:func:`_routines`)."""
    global _ROUTINES
    if not _ROUTINES:
        _ROUTINES = _routines()
    return _ROUTINES


_BELOW: dict = {}  # (rows, columns): indices below the diagonal


def qr_r(A: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """np.linalg.qr(A, mode="r"): LAPACK's dgeqrf with its optimal work size, as numpy
    and scipy.linalg.qr call it, through scipy's wrapper (:func:`lapack`), which costs half
    of numpy's call (its checks and the copy of the result cost as much as the
    factorisation of a fold fit's 144 x 28 matrix); scipy.linalg.qr's numbers to the bit,
    numpy's to rounding (with this project's numpy and scipy wheels the same bits). The part
    below the diagonal is zeroed through cached indices rather than np.triu's mask.
    overwrite: A (Fortran order) may be overwritten, which saves its copy."""
    _, _, geqrf, geqrf_lwork = _ROUTINES or lapack()
    m, n = A.shape
    if (m, n) not in _QR_LWORK:
        work, info = geqrf_lwork(m, n)
        if info != 0:
            raise ValueError(f"geqrf's work size query failed: {info}")
        _QR_LWORK[m, n] = max(1, int(work.real))
    h, _, _, info = geqrf(A, _QR_LWORK[m, n], overwrite)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of geqrf")
    R = np.ascontiguousarray(h[:min(m, n)])
    if R.shape not in _BELOW:
        _BELOW[R.shape] = np.tril_indices(R.shape[0], -1, R.shape[1])
    R[_BELOW[R.shape]] = 0.0
    return R


TALL = 50  # rows per column from which triangular_factor uses CholeskyQR2


def triangular_factor(A: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """R of A = Q R (upper triangular, n x n) for a tall A (m x n).

    Householder QR, except for very tall A (many poses), where CholeskyQR2 (two Cholesky
    passes, the second on A R1^-1) costs two Gram products instead; it is as accurate as
    QR while cond(A) stays below ~1e7, and falls back to QR beyond that. overwrite: A is
    a temporary QR may overwrite (in Fortran order, its copy is saved).
    """
    m, n = A.shape
    if m <= TALL * n:
        return qr_r(A, overwrite)
    try:
        R1 = np.linalg.cholesky(A.T @ A).T
        d = np.abs(np.diag(R1))
        if d.min() <= 1e-7 * d.max():
            raise np.linalg.LinAlgError("ill-conditioned")
        A1 = A @ np.linalg.inv(R1)  # small n x n inverse: much faster than a wide trsm
        return np.linalg.cholesky(A1.T @ A1).T @ R1
    except np.linalg.LinAlgError:
        return qr_r(A)


def lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The minimum-norm least-squares solution of A d = b (A (m, n) float64, b (m,)):
    LAPACK's gelsy (QR with column pivoting) with rcond 1e-15, the very call that
    ``scipy.linalg.lstsq(A, b, cond=1e-15, lapack_driver="gelsy", check_finite=False)``
    makes, without its checks and dispatch (a fold fit of Algorithm 1 solves a 45 x 45
    system, where they cost as much as the solve)."""
    gelsy, gelsy_lwork, _, _ = _ROUTINES or lapack()
    m, n = A.shape
    if m < n:
        b = np.concatenate([b, np.zeros(n - m)])
    if (m, n) not in _LWORK:
        work, info = gelsy_lwork(m, n, 1, 1e-15)
        if info != 0:
            raise ValueError(f"gelsy's work size query failed: {info}")
        _LWORK[m, n] = int(work.real)
    _, x, _, _, info = gelsy(A, b, np.zeros((n, 1), dtype=np.int32), 1e-15, _LWORK[m, n],
                             False, False)
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of gelsy")
    return x[:n]
