"""Progress displays of the command line: drawn on a terminal, silent elsewhere."""

from __future__ import annotations

import sys


def progress_bar(stream=None, label="cross-validation", unit="fits"):
    """A progress callback ``(done, total)`` drawing a bar on a terminal, and None elsewhere."""
    stream = sys.stderr if stream is None else stream
    if not getattr(stream, "isatty", lambda: False)():
        return None

    import time

    t0 = time.perf_counter()

    def progress(done, total):
        width = 30
        filled = int(width * done / total)
        stream.write(f"\r  {label} [{'#' * filled}{'.' * (width - filled)}] "
                     f"{done}/{total} {unit}, {timing(time.perf_counter() - t0, done, total)}"
                     "\033[K")
        if done == total:
            stream.write("\n")
        stream.flush()

    return progress


def timing(elapsed: float, done: int, total: int) -> str:
    """"12.3 s, about 40 s left": the time so far and an estimate of the rest from the
    mean pace (none before the first step is done)."""
    text = f"{elapsed:.1f} s"
    if 0 < done < total:
        text += f", about {_span(elapsed / done * (total - done))} left"
    return text


def _span(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.0f} min"


class FitStatus:
    """A solver callback showing the iterations of a long fit on a terminal.

    Quiet for fits that end within ``after`` seconds (most do); a fit of many poses takes
    seconds per iteration, and then says where it is. ``close()`` ends the status line.
    """

    def __init__(self, stream=None, after: float = 2.0):
        import time

        self.stream = sys.stderr if stream is None else stream
        self.after, self.clock = after, time.perf_counter
        self.t0, self.drawn = self.clock(), False

    @classmethod
    def on_terminal(cls, stream=None) -> "FitStatus | None":
        stream = sys.stderr if stream is None else stream
        return cls(stream) if getattr(stream, "isatty", lambda: False)() else None

    def __call__(self, iteration, max_iterations):
        elapsed = self.clock() - self.t0
        if elapsed >= self.after:
            # an iteration count has no known end: the bound gives the worst case
            self.stream.write(f"\r  solving: iteration {iteration} (at most {max_iterations}), "
                              f"{elapsed:.1f} s, at most about "
                              f"{_span(elapsed / max(iteration, 1) * max_iterations)} in all"
                              "\033[K")
            self.stream.flush()
            self.drawn = True

    def close(self):
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()
            self.drawn = False
