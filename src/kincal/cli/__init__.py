"""The ``kincal`` command line (``main(argv=None) -> int``), a thin shell over the API."""

from kincal.cli.main import main

__all__ = ["main"]
