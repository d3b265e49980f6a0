"""Time `kincal plan ec66 --in-cube ... --max-tilt 60 --poses 60` from a few thousand candidates.

Prints, per candidate count, the wall-clock and CPU time of the whole command (load,
candidate generation, the default working volume's 1000 target poses, I-optimal
selection, writing) and of its three stages, median of
--repeats runs, with the load average at the start (the machine may be shared).

Usage: python scripts/bench_volume_plan.py [--candidates 2000 3000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from kincal.cli.main import main as kincal
from kincal.identification.blas_threads import limited
from kincal.planning.pose_selection import select_poses
from kincal.planning.volume_candidates import (Volume, VolumeSpec, volume_candidates,
                                               working_volume)
from kincal.robot import Robot

TOOL = (0.03, 0.02, 0.12)  # [m]


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, nargs="+", default=[2000, 3000])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    print(f"load average at start: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    robot = Robot.load("ec66")
    spec = VolumeSpec(Volume.cube((0.4, 0.0, 0.25), 0.02), TOOL, math.radians(60))
    print("| candidates | whole command, wall (CPU) [s] | generation [s] | targets [s] | "
          "selection [s] |")
    print("|---|---|---|---|---|")
    for m in args.candidates:
        whole, gen, tgt, sel = [], [], [], []
        for r in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                argv = ["plan", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--max-tilt",
                        "60", "--random", str(m), "--poses", "60", "--tool-offset",
                        *map(str, TOOL), "--seed", str(r), "--out", str(Path(tmp) / "c.csv")]
                with contextlib.redirect_stdout(io.StringIO()):
                    code, w, c = _timed(lambda: kincal(argv))
                assert code == 0
                whole.append((w, c))
            cands, w1, c1 = _timed(lambda: volume_candidates(robot, spec, m, seed=r))
            work, w3, c3 = _timed(lambda: volume_candidates(
                robot, working_volume(spec, cands.home), 1000, seed=r + 1))
            with limited(1):  # as kincal plan does
                _, w2, c2 = _timed(lambda: select_poses(robot, cands.joint_values, 60, tool=TOOL,
                                                        method="I", targets=work.joint_values))
            gen.append((w1, c1))
            tgt.append((w3, c3))
            sel.append((w2, c2))

        def cell(x):
            a = np.median(np.array(x), axis=0)
            return f"{a[0]:.2f} ({a[1]:.2f})"

        print(f"| {m} | {cell(whole)} | {cell(gen)} | {cell(tgt)} | {cell(sel)} |")


if __name__ == "__main__":
    main()
