"""kincal fleet on many simulated units: wall time with 2 workers against 1, the CPU time and
the peak memory of each worker process (issue 21's acceptance).

First Dask's own cost per task (no-op jobs through kincal's engine), one unit per task and
as the engine batches them. Then writes --units simulated EC66 tracker files
(kincal.fleet.simulated) into a temporary folder, runs ``kincal fleet ... --workers N`` for
N in --workers (--repeats times each, the fastest kept), and samples the CPU time and
resident memory (RSS) of the command and of its worker processes (psutil, a dependency of
distributed) every 0.2 s. Dask's LocalCluster caps a worker at
kincal.fleet.engine.WORKER_MEMORY. The load average is printed, and the cores the run had
(its CPU time over its wall time): on a shared machine a second worker only helps when it
gets a core of its own (Linux's autogroup scheduler shares the CPU between sessions, not
processes: the command and its workers are one session).

    python scripts/bench_fleet.py                # 200 units (minutes)
    python scripts/bench_fleet.py --units 10     # quick
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

from kincal.fleet.simulated import FleetModel
from kincal.robot import Robot


def make_files(folder: Path, units: int, poses: int) -> list[str]:
    fm = FleetModel.of(Robot.load("ec66", tip="flange"), 0)
    return fm.tracker_files(folder, units, np.random.default_rng(0), n=poses, width=3)


def run(files, workers: int, out: Path) -> tuple[float, float, dict, dict]:
    """(wall time [s], the command's own CPU time [s], {worker pid: peak resident memory
    [MB]}, {worker pid: CPU time [s]}); the workers are the command's child processes that
    multiprocessing spawned, sampled every 0.2 s."""
    cmd = [sys.executable, "-m", "kincal", "fleet", "ec66", *files, "--tip", "flange",
           "--tool-offset", "0", "0", "0.045", "--out-dir", str(out), "--workers",
           str(workers), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    me, peak, cpu, own = psutil.Process(proc.pid), {}, {}, 0.0
    while proc.poll() is None:
        try:
            t = me.cpu_times()
            own = t.user + t.system
            for child in me.children(recursive=True):
                try:
                    if "spawn_main" not in " ".join(child.cmdline()):
                        continue  # a worker is spawned by multiprocessing (not its tracker)
                    t = child.cpu_times()
                    peak[child.pid] = max(peak.get(child.pid, 0), child.memory_info().rss)
                    cpu[child.pid] = t.user + t.system
                except psutil.Error:
                    pass
        except psutil.Error:
            pass
        time.sleep(0.2)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"kincal fleet failed: {proc.stderr.read()}")
    return wall, own, {k: v / 2 ** 20 for k, v in peak.items()}, cpu


def _noop(job):
    return job


def task_overhead(n: int = 400) -> list[tuple[int, float, float]]:
    """Dask's own cost of a task, measured on no-op jobs through kincal's engine (one local
    worker): (jobs per task, CPU per job of the command [ms], of the worker [ms]); jobs per
    task 1, then what the engine chooses for a fleet of n units on 2 workers."""
    from kincal.cli.options import Chain
    from kincal.fleet.engine import Engine, batch_size

    def cpu(p):
        t = p.cpu_times()
        return t.user + t.system

    me, out = psutil.Process(), []
    with Engine(1) as engine:
        workers = [c for c in me.children(recursive=True)
                   if "spawn_main" in " ".join(c.cmdline())]
        jobs = [(Chain("ec66", "flange"), i) for i in range(n)]  # a unit job's size
        for b in (1, batch_size(n, 2)):
            c0, w0 = cpu(me), sum(cpu(w) for w in workers)
            engine.run(_noop, jobs, lambda r: None, None, b)
            out.append((b, (cpu(me) - c0) / n * 1e3,
                        (sum(cpu(w) for w in workers) - w0) / n * 1e3))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=200)
    ap.add_argument("--poses", type=int, default=40, help="tracker poses per unit")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=1,
                    help="runs per worker count; the minimum wall time is printed")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        files = make_files(Path(tmp), a.units, a.poses)
        print(f"{a.units} units, {a.poses} tracker poses each; {psutil.cpu_count()} CPUs; "
              f"load average before: {os.getloadavg()[0]:.2f}")
        for b, own, worker in task_overhead():
            print(f"Dask's overhead per unit at {b} units per task: {own:.2f} ms CPU in the "
                  f"command, {worker:.2f} ms in the worker", flush=True)
        base = None
        for w in a.workers:
            runs = []
            for r in range(a.repeats):
                out = Path(tmp) / f"out{w}-{r}"
                runs.append(run(files, w, out))
                shutil.rmtree(out)
            wall, own, mem, cpu = min(runs, key=lambda r: r[0])
            base = base or wall
            total = own + sum(cpu.values())
            print(f"--workers {w}: {wall:.1f} s wall ({base / wall:.2f}x the speed of the "
                  f"first; {a.units / wall:.1f} units/s, min of {a.repeats}); CPU time: the "
                  f"command {own:.1f} s, its workers "
                  f"{' + '.join(f'{v:.1f}' for v in cpu.values())} s, in all {total:.1f} s, "
                  f"so the run had {total / wall:.2f} cores; peak memory per worker process: "
                  f"{', '.join(f'{m:.0f}' for m in mem.values())} MB; load average now: "
                  f"{os.getloadavg()[0]:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
