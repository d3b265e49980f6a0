"""How many threads the BLAS library may use while kincal computes.

kincal's matrices are narrow (tens of columns; the poses are folded in by QR), so a
multithreaded BLAS gains nothing on them, and on a machine whose cores are busy with
other work its threads wait for each other: on this project's 2-core machine with both
cores loaded, one LS fit of 10,000 poses took 1.73 s with OpenBLAS's default threads and
0.82 s with one thread (0.60 s and 0.59 s on an idle machine). So a calibration runs with
one BLAS thread by default (``CalibrationOptions.blas_threads``), through threadpoolctl;
the previous setting is restored afterwards. None leaves BLAS as it is.
"""

from __future__ import annotations

import contextlib
import functools

from threadpoolctl import ThreadpoolController


@functools.lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    """The BLAS libraries loaded in this process, found once (a scan costs ~1 ms, as
    much as 8 % of a small fit). The solver's LAPACK (scipy's, with an OpenBLAS of its own
    beside numpy's) is loaded first: loaded later, at a fit's first step, it was not among
    them, so it ran with its default threads whatever the limit, and the new worker thread
    it started busy-waited ~0.1 s after the process's first fit (counted as CPU time)."""
    from kincal.identification import linalg

    linalg.lapack()
    return ThreadpoolController()


_active: list[int] = []  # the limits in force in this process, innermost last


@contextlib.contextmanager
def limited(threads: int | None):
    """A context in which BLAS uses at most ``threads`` threads (None: unchanged). Inside
    one of the same limit (solve's, around the analysis's) it changes nothing: threadpoolctl's
    limit queries, sets and restores every library each time (~0.4 % of a 60-pose fit)."""
    if threads is None or (_active and _active[-1] == int(threads)):
        yield
        return
    with _controller().limit(limits=int(threads), user_api="blas"):
        _active.append(int(threads))
        try:
            yield
        finally:
            _active.pop()
