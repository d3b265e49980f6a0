"""The ``kincal`` command line: a thin shell over the Python API.

``main(argv=None) -> int`` builds the parser from the command modules (each has
``register(subparsers)`` and ``run(args)``) and holds the policy they share: a
KincalError becomes one line on stderr and exit code 1 (usage errors: 2), with no
traceback and no file written; SIGINT and SIGTERM roll the outputs back; kincal's
warnings are printed as ``kincal: warning: ...`` lines. An OS error no boundary named
(a path too long, the working folder deleted, stdout on a full disk) is one line too.
Every command computes everything first, says its last words, then commits its outputs,
all or none (:mod:`kincal.cli.console`).
"""

from __future__ import annotations

import argparse
import sys
import warnings

from kincal import __version__
from kincal.cli import analyze, calibrate, compensate, demo, evaluate, fleet, plan, simulate
from kincal.cli.console import Terminated, quiet_stdout, say, stdout_to_null
from kincal.cli.usage import UsageParser
from kincal.errors import KincalError, KincalNote, KincalWarning

COMMANDS = (calibrate, evaluate, analyze, simulate, plan, compensate, demo, fleet)
# the commands whose summary --json gives as one JSON object on stdout
JSON_COMMANDS = ("calibrate", "evaluate", "analyze", "simulate", "plan", "compensate", "fleet")


def build_parser() -> argparse.ArgumentParser:
    ap = UsageParser(prog="kincal", description="Kinematic calibration of robots "
                                 "from URDF: any chain of the tree, several chains sharing "
                                 "joints; complete error models, a penalty toward nominal "
                                 "(evidence or k-fold CV), a plausibility gate.")
    ap.add_argument("--version", action="version", version=f"kincal {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    from kincal.cli.options import add_console

    for name, p in sub.choices.items():  # the console options, the same on every command
        add_console(p, json_summary=name in JSON_COMMANDS)
    return ap


def _on_sigterm(signum, frame):
    raise Terminated


def _standard_streams() -> None:
    """Open a closed stdin/stdout/stderr (``2>&-``) on /dev/null: otherwise the next file
    opened takes descriptor 2 and C libraries' messages would land in it; and make a
    console that cannot encode a path print it escaped rather than fail."""
    import os

    for fd, name in ((0, "stdin"), (1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDONLY if fd == 0 else os.O_WRONLY)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
            if getattr(sys, name) is None:
                setattr(sys, name, open(fd, "r" if fd == 0 else "w", closefd=False))
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)  # a TextIOWrapper's, not a capture's
        try:
            if reconfigure is not None:
                reconfigure(errors="backslashreplace")
        except ValueError:
            pass


def _matplotlib_home() -> str | None:
    """A scratch MPLCONFIGDIR when matplotlib's own folders cannot be written (a read-only
    HOME): matplotlib would print "mkdir -p failed" lines on stderr. Returns the folder
    to remove, or None."""
    import os

    if os.environ.get("MPLCONFIGDIR") or "matplotlib" in sys.modules:
        return None
    home = os.path.expanduser("~")
    for base in (os.environ.get("XDG_CONFIG_HOME") or os.path.join(home, ".config"),
                 os.environ.get("XDG_CACHE_HOME") or os.path.join(home, ".cache")):
        folder = os.path.join(base, "matplotlib")
        while not os.path.exists(folder) and os.path.dirname(folder) != folder:
            folder = os.path.dirname(folder)
        if not (os.path.isdir(folder) and os.access(folder, os.W_OK | os.X_OK)):
            import tempfile

            os.environ["MPLCONFIGDIR"] = tempfile.mkdtemp(prefix="kincal-matplotlib-")
            return os.environ["MPLCONFIGDIR"]
    return None


def _drain_stdout() -> None:
    """Flush what a refused run printed; what stdout cannot take is dropped, not retried
    (and failed again, with a traceback) at exit."""
    try:
        sys.stdout.flush()
    except (OSError, ValueError):
        stdout_to_null()


def _os_error_line(exc: OSError) -> str:
    """One line for an OS error no boundary turned into a KincalError."""
    import os

    try:
        os.getcwd()
    except OSError:
        return ("the working folder no longer exists (deleted while kincal was running?); "
                "no output was written or changed")
    import errno

    # files are written through safe_write, whose errors name their path: a nameless "disk
    # full" is the console's (stdout redirected to a full disk)
    if exc.filename is None and exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO):
        return (f"cannot write to the standard output ({exc.strerror or exc}); no output "
                "was written or changed")
    name = exc.filename if exc.filename is not None else ""
    name = str(name) if len(str(name)) <= 80 else str(name)[:60] + "..."
    return f"{name}{': ' if name else ''}{exc.strerror or exc}"


def main(argv=None) -> int:
    import signal
    import threading
    import time

    t0 = time.perf_counter()
    _standard_streams()
    parser = build_parser()
    args = parser.parse_args(argv)
    args.command_line = ["kincal", *(sys.argv[1:] if argv is None else argv)]
    # SIGTERM unwinds like Ctrl-C (only the main thread may set handlers: main() called
    # from a worker thread keeps the default)
    sigterm = None
    if threading.current_thread() is threading.main_thread():
        sigterm = signal.signal(signal.SIGTERM, _on_sigterm)
    scratch = _matplotlib_home()
    failed = False  # a refused run: its one error line, and warnings that may explain it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", KincalWarning)
        try:
            from kincal.cli.checks import check_args

            if args.verbose:  # first, also before an option's refusal
                print(f"kincal {__version__}: {' '.join(args.command_line)}", file=sys.stderr)
            check_args(args)
            with quiet_stdout(args.quiet):
                code = args.run(args)
            say([])  # flush: a full disk behind stdout fails here (one line), not at exit
        except (KeyboardInterrupt, Terminated) as exc:
            name, code = (("SIGINT", 130) if isinstance(exc, KeyboardInterrupt)
                          else ("SIGTERM", 143))
            print(f"kincal: error: interrupted ({name}); no output was written or changed",
                  file=sys.stderr)
            caught.clear()  # a half-run's warnings would only confuse
        except BrokenPipeError:  # output piped into head & co: stop quietly
            stdout_to_null()
            code = 0
        except (KincalError, OSError) as exc:
            message = " ".join((str(exc) if isinstance(exc, KincalError)
                                else _os_error_line(exc)).split())  # one line
            if args.verbose:
                message += f" [{type(exc).__name__}]"
            print(f"kincal: error: {message}", file=sys.stderr)
            code, failed = 1, True
            _drain_stdout()
        finally:
            said = set()  # a warning raised again (a second fit of the same data) says nothing new
            for w in caught:
                if issubclass(w.category, KincalWarning) and not (
                        failed and issubclass(w.category, KincalNote)):  # how an input was
                    kind = "note" if issubclass(w.category, KincalNote) else "warning"  # read
                    line = f"kincal: {kind}: {w.message}"
                    if line not in said:
                        said.add(line)
                        print(line, file=sys.stderr)
            if sigterm is not None:
                signal.signal(signal.SIGTERM, sigterm)
            if scratch is not None:
                import os
                import shutil

                shutil.rmtree(scratch, ignore_errors=True)
                os.environ.pop("MPLCONFIGDIR", None)
    if code == 0:  # an error stays the one line it is
        print(f"kincal: done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
