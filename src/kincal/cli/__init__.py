"""The ``kincal`` command line (``main(argv=None) -> int``), a thin shell over the API.

A command runs BLAS with one thread: OpenBLAS, as numpy and scipy load it, starts a pool of
worker threads per library that spin while waiting for work, and a command's small
matrices never give them any (kincal's fits already run with one BLAS thread,
:mod:`kincal.identification.blas_threads`). So, unless the user has set it, the command
line sets ``OPENBLAS_NUM_THREADS=1`` before anything loads numpy: the 60-pose
``kincal calibrate --method ls`` took 0.47 s of CPU with the pools, 0.28 s without them
(docs/results.md "Speed"). The Python API leaves the environment alone.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from kincal.cli.main import main  # noqa: E402

__all__ = ["main"]
