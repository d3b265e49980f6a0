"""The console side of a command's output: said before the files are committed.

A command's last words ("wrote PATH") are written and flushed to stdout after its files
are staged and before they take their names (:func:`say_and_write`): a stdout that cannot
take them (``> /dev/full``, a closed pipe) fails the run with nothing written, so the
files on disk always agree with the exit code.
"""

from __future__ import annotations

import sys

from kincal.errors import ExportError


def say(lines) -> None:
    """Write ``lines`` to stdout and flush; ExportError if stdout cannot take them."""
    text = "".join(f"{line}\n" for line in lines)
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except BrokenPipeError:  # the reader stopped listening (| head): not a failure of the run
        stdout_to_null()
    except (OSError, ValueError) as exc:  # ValueError: an encoding error, a closed stream
        reason = getattr(exc, "strerror", None) or exc.__class__.__name__
        raise ExportError(f"cannot write to the standard output ({reason}); no output was "
                          "written or changed") from None


def stdout_to_null() -> None:
    """Send what stdout still holds, and will get, to /dev/null (its reader is gone)."""
    import os

    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):  # not a file (captured in tests)
        pass


def say_and_write(files, lines, *, overwrite: bool, protect, dirs=()) -> list:
    """:func:`kincal.export.safe_write.write_all` with ``lines(targets)`` said between
    staging and commit; returns the written paths."""
    from kincal.export.safe_write import write_all

    return write_all(files, overwrite=overwrite, protect=protect, dirs=dirs,
                     before_commit=lambda targets: say(lines(targets)))


class _NullOut:
    """stdout of a --quiet run: takes everything, keeps nothing."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False


def quiet_stdout(on: bool):
    """With --quiet, stdout goes nowhere while the command runs (one place for every
    command: they say what they say, and nobody hears it)."""
    import contextlib

    return contextlib.redirect_stdout(_NullOut()) if on else contextlib.nullcontext()
