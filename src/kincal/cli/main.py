"""The ``kincal`` command line: a thin shell over the Python API.

``main(argv=None) -> int`` builds the parser from the command modules (each has
``register(subparsers)`` and ``run(args)``) and holds the policy they share: a
KincalError becomes one line on stderr and exit code 1 (usage errors: 2), with no
traceback and no file written; SIGINT and SIGTERM roll the outputs back; kincal's
warnings are printed as ``kincal: warning: ...`` lines. Every command computes
everything first and writes its outputs last, all or none.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from kincal import __version__
from kincal.cli import analyze, calibrate, compensate, demo, evaluate, plan, simulate
from kincal.errors import KincalError, KincalNote, KincalWarning

COMMANDS = (calibrate, evaluate, analyze, simulate, plan, compensate, demo)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="kincal", description="Kinematic calibration of serial "
                                 "robots from URDF (MD-H errors, L2 toward nominal, evidence "
                                 "or k-fold CV).")
    ap.add_argument("--version", action="version", version=f"kincal {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    return ap


class _Terminated(BaseException):
    """SIGTERM, raised like KeyboardInterrupt so that writes roll back on the way out."""


def _on_sigterm(signum, frame):
    raise _Terminated


def _timed(command: str) -> bool:
    """Whether a success of ``command`` ends with the ``kincal: done in N s`` line."""
    return next(m for m in COMMANDS if m.__name__.rsplit(".", 1)[1] == command).TIMED


def main(argv=None) -> int:
    import signal
    import threading
    import time

    t0 = time.perf_counter()
    parser = build_parser()
    args = parser.parse_args(argv)
    # SIGTERM unwinds like Ctrl-C (only the main thread may set handlers: main() called
    # from a worker thread keeps the default)
    sigterm = None
    if threading.current_thread() is threading.main_thread():
        sigterm = signal.signal(signal.SIGTERM, _on_sigterm)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", KincalWarning)
        try:
            from kincal.cli.checks import check_args

            check_args(args)
            code = args.run(args)
        except (KeyboardInterrupt, _Terminated) as exc:
            name, code = (("SIGINT", 130) if isinstance(exc, KeyboardInterrupt)
                          else ("SIGTERM", 143))
            print(f"kincal: error: interrupted ({name}); no output was written or changed",
                  file=sys.stderr)
            caught.clear()  # a half-run's warnings would only confuse
        except BrokenPipeError:  # output piped into head & co: stop quietly
            import os

            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            code = 0
        except KincalError as exc:
            message = " ".join(str(exc).split())  # one line
            print(f"kincal: error: {message}", file=sys.stderr)
            code = 1
        finally:
            for w in caught:
                if issubclass(w.category, KincalWarning):
                    kind = "note" if issubclass(w.category, KincalNote) else "warning"
                    print(f"kincal: {kind}: {w.message}", file=sys.stderr)
            if sigterm is not None:
                signal.signal(signal.SIGTERM, sigterm)
    if code == 0 and _timed(args.command):  # an error stays the one line it is
        print(f"kincal: done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
