"""kincal fleet on many simulated units: wall time with 2 workers against 1, and the peak
memory of each worker process (issue 21's acceptance).

Writes --units simulated EC66 tracker files (kincal.fleet.simulated) into a temporary
folder, runs ``kincal fleet ... --workers N`` for N in --workers, and samples the resident
memory of the command's worker processes (psutil) every 0.2 s. Dask's LocalCluster caps a
worker at kincal.fleet.engine.WORKER_MEMORY.

    python scripts/bench_fleet.py                # 200 units (minutes)
    python scripts/bench_fleet.py --units 10     # quick
"""

from __future__ import annotations

import argparse
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
    robot = Robot.load("ec66", tip="flange")
    fm = FleetModel.of(robot, 0)
    rng = np.random.default_rng(0)
    files = []
    for u in range(units):
        path = folder / f"u{u + 1:03d}.csv"
        path.write_text(fm.tracker(fm.unit(rng), rng, n=poses).to_csv_text())
        files.append(str(path))
    return files


def run(files, workers: int, out: Path) -> tuple[float, list[float]]:
    """(wall time [s], peak resident memory per worker process [MB])."""
    cmd = [sys.executable, "-m", "kincal", "fleet", "ec66", *files, "--tip", "flange",
           "--tool-offset", "0", "0", "0.045", "--out-dir", str(out), "--workers",
           str(workers), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    me, peak = psutil.Process(proc.pid), {}
    while proc.poll() is None:
        try:
            for child in me.children(recursive=True):
                try:
                    if "worker" in " ".join(child.cmdline()) or child.name().startswith(
                            "python"):
                        peak[child.pid] = max(peak.get(child.pid, 0), child.memory_info().rss)
                except psutil.Error:
                    pass
        except psutil.Error:
            pass
        time.sleep(0.2)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"kincal fleet failed: {proc.stderr.read()}")
    return wall, sorted((v / 2 ** 20 for v in peak.values()), reverse=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=200)
    ap.add_argument("--poses", type=int, default=40, help="tracker poses per unit")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        files = make_files(Path(tmp), a.units, a.poses)
        print(f"{a.units} units, {a.poses} tracker poses each; {psutil.cpu_count()} CPUs")
        base = None
        for w in a.workers:
            wall, mem = run(files, w, Path(tmp) / f"out{w}")
            base = base or wall
            print(f"--workers {w}: {wall:.1f} s ({base / wall:.2f}x of the first), "
                  f"{a.units / wall:.1f} units/s; peak memory of its {len(mem)} child "
                  f"processes [MB]: {', '.join(f'{m:.0f}' for m in mem[:w + 2])}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
