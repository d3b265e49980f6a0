"""The console side of a command's output: said before the files are committed.

A command's last words ("wrote PATH") are written and flushed to stdout after its files
are staged and before they take their names (:func:`say_and_write`): a stdout that cannot
take them (``> /dev/full``, a closed pipe) fails the run with nothing written, so the
files on disk always agree with the exit code.
"""

from __future__ import annotations

import sys

from kincal.errors import ExportError


class AfterStdout(str):
    """A line for stderr that :func:`say` writes once stdout has taken its lines (a --json
    run's "kincal: wrote PATH"): said before, it claimed files that a stdout on a full disk
    then kept from being written."""


def say(lines) -> None:
    """Write ``lines`` to stdout and flush, then the :class:`AfterStdout` among them to
    stderr; ExportError if stdout cannot take them."""
    text = "".join(f"{line}\n" for line in lines if not isinstance(line, AfterStdout))
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except BrokenPipeError:  # the reader stopped listening (| head): not a failure of the run
        stdout_to_null()
    except (OSError, ValueError) as exc:  # ValueError: an encoding error, a closed stream
        reason = getattr(exc, "strerror", None) or exc.__class__.__name__
        raise ExportError(f"cannot write to the standard output ({reason}); no output was "
                          "written or changed") from None
    for line in lines:
        if isinstance(line, AfterStdout):
            print(line, file=sys.stderr)


def stdout_to_null() -> None:
    """Send what stdout still holds, and will get, to /dev/null (its reader is gone)."""
    import os

    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):  # not a file (captured in tests)
        pass



class Terminated(BaseException):
    """SIGTERM, raised like KeyboardInterrupt so that writes roll back on the way out
    (``kincal.cli.main`` installs the handler; a command that can leave finished work, as
    ``kincal fleet``, catches both to say what is complete)."""

def say_and_write(files, lines, *, provenance, overwrite: bool, protect, dirs=()) -> list:
    """The one writer (:func:`kincal.export.outputs.write_files`: ``files`` are its
    File values, each stamped with ``provenance``) with ``lines(targets)`` said between
    staging and commit; returns the written paths."""
    from kincal.export.outputs import write_files

    return write_files(files, provenance, overwrite=overwrite, protect=protect, dirs=dirs,
                       before_commit=lambda targets: say(lines(targets)))


def summary_lines(json_out: bool, human, summary: dict, written=(),
                  wrote=lambda path: f"  wrote {path}") -> list[str]:
    """What a command says at its end: its ``human`` lines and one ``wrote`` line per
    written file (wrote None: none, the human lines name them); with ``--json`` (json_out) the ``summary`` alone, as one JSON object
    (SI units; the paths written under "written"), the written files said on stderr
    instead (once stdout took the JSON: :func:`say`), so that stdout holds nothing but the
    JSON."""
    if not json_out:
        return list(human) + ([] if wrote is None else [wrote(path) for path in written])
    from kincal import __version__
    from kincal.export.report import dumps

    return [dumps({"format": "kincal-summary-1", "kincal_version": __version__, **summary,
                   "written": [str(p) for p in written]}).rstrip("\n")] + [
        AfterStdout(f"kincal: wrote {path}") for path in written]


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
