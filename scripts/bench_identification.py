"""Speed and memory of kincal's identification on this machine; prints its figures.

EC66, tracker-like poses in a 400 mm cube (and an R-test-like 20 mm cube for the CV),
0.05 mm noise:
- one least-squares fit on 60 poses (median of repeats),
- the whole Algorithm 1 on 60 poses (50 lambdas x 5 folds + final fit), L2 + CV,
- one least-squares fit on 1,000 / 10,000 / 200,000 poses, with the peak memory
  (tracemalloc) of the fit, to show it grows linearly with the number of poses;
- the default L2 + CV on 200,000 poses (lambda by CV on a random 2,000 of them, see
  CalibrationOptions.cv_max_poses), with wall and CPU time and the load average, since
  the machine is shared;
- the 10,000-pose fit again with both cores kept busy by two spinning processes, with
  kincal's default of one BLAS thread and with BLAS left at its own threads
  (CalibrationOptions.blas_threads = 1 / None; skipped with --no-busy);
- the command line as a user meets it, wall time of a new process (start-up and imports
  included): `kincal --help` and `kincal calibrate --method ls` on the 60 poses
  (targets 0.3 s and 0.8 s; --cli-only runs just these).

Usage: python scripts/bench_identification.py [--repeats 5] [--no-busy] [--cli-only] [--no-200k]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tracemalloc
import warnings

import numpy as np

from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import DEFAULT, MODELS, mdh
from kincal.planning.simulation import Truth, cube_poses, measure, planted_table
from kincal.robot import Robot


def _data(robot, model, n, size, rng, tilt=30):
    tool = np.array([0.02, 0.01, 0.12])
    if n <= 200:
        q = cube_poses(robot, n, [0.4, 0.0, 0.25], size, tool, rng, max_tilt=np.radians(tilt))
    else:  # many poses: random joints (IK for 10,000 poses would dominate the benchmark)
        g = robot.geometry
        q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(n, g.n))
    truth = Truth(planted_table(model, rng), np.array([0.8, 0.3, -0.2, 0.02, -0.03, 1.2]),
                  tool + [0.001, -0.001, 0.002])
    return measure(model, truth, q, 5e-5, rng)


def _time(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def _cli_times(data, repeats):
    """{name: (median wall time, median CPU time)} [s] of `kincal --help` and of a 60-pose
    `kincal calibrate --method ls`, each a new process as from a shell. The CPU time (user +
    system of the child) is what the wall time would be on an idle machine; on a shared
    one the wall time also counts waiting for a core."""
    exe = shutil.which("kincal")
    kincal = [exe] if exe else [sys.executable, "-c",
                                "import sys; from kincal.cli import main; sys.exit(main())"]
    with tempfile.TemporaryDirectory(prefix="kincal-bench-") as tmp:
        csv = os.path.join(tmp, "poses.csv")
        with open(csv, "w") as fh:
            fh.write(data.to_csv_text())
        runs = {"help": kincal + ["--help"],
                "calibrate": kincal + ["calibrate", "ec66", csv, "--method", "ls", "--out",
                                       os.path.join(tmp, "out.urdf"), "--overwrite", "--quiet"]}
        out = {}
        for name, cmd in runs.items():
            subprocess.run(cmd, check=True, capture_output=True)  # warm the file cache
            wall, cpu = [], []
            for _ in range(repeats):
                before = os.times()
                t = time.perf_counter()
                subprocess.run(cmd, check=True, capture_output=True)
                wall.append(time.perf_counter() - t)
                after = os.times()
                cpu.append(after.children_user - before.children_user
                           + after.children_system - before.children_system)
            out[name] = (float(np.median(wall)), float(np.median(cpu)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-busy", action="store_true", help="skip the busy-machine figures")
    ap.add_argument("--cli-only", action="store_true", help="only the command-line wall times")
    ap.add_argument("--no-200k", action="store_true", help="skip the 200,000-pose figures")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(0)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    print("kincal identification benchmark: EC66, 2-core machine, times are medians of "
          f"{args.repeats} runs, whole calls from data to result")
    tracker = _data(robot, model, 60, 0.4, rng)
    rtest = _data(robot, model, 60, 0.02, rng, tilt=15)
    print(f"load average at the start: {os.getloadavg()[0]:.2f}")
    cli = _cli_times(tracker, args.repeats)
    for name, label, target in (("help", "kincal --help", 0.3),
                                ("calibrate", "kincal calibrate --method ls, 60 poses", 0.8)):
        wall, cpu = cli[name]
        print(f"{label + ',':<40} new process: {wall:6.3f} s wall, {cpu:6.3f} s CPU  "
              f"(target < {target} s)")
    if args.cli_only:
        return
    for name in MODELS:
        opts = CalibrationOptions(method="ls", model=name)
        t, res = _time(lambda: CalibrationProblem(robot, tracker, opts).solve(), args.repeats)
        print(f"LS fit, 60 poses (400 mm cube), model {name:<9}: {t * 1e3:8.1f} ms  "
              f"({res.solve.iterations} iterations, {len(res.identifiability.kept)} parameters"
              + (", target < 20 ms" if name == DEFAULT else "") + ")")
    for name, data in (("400 mm cube", tracker), ("20 mm cube", rtest)):
        t, res = _time(lambda: CalibrationProblem(robot, data, CalibrationOptions(method="l2", lam="cv")).solve(),
                       max(1, args.repeats // 2))
        print(f"Algorithm 1 (250 fold fits + final), 60 poses, {name}: {t:6.3f} s  "
              f"(lambda = {res.lam:.3g}, target < 1 s)")
    for n in (1000, 10000) + (() if args.no_200k else (200000,)):
        data = _data(robot, model, n, 0.4, rng)
        c = time.process_time()
        t, res = _time(lambda: CalibrationProblem(robot, data, CalibrationOptions(method="ls")).solve(),
                       max(1, args.repeats // 2) if n < 100000 else 1)
        cpu = (time.process_time() - c) / (max(1, args.repeats // 2) if n < 100000 else 1)
        tracemalloc.start()
        CalibrationProblem(robot, data, CalibrationOptions(method="ls")).solve()
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        print(f"LS fit, {n:>6} poses:                        {t:8.3f} s   peak memory "
              f"{peak / 2**20:7.1f} MiB ({peak / n / 1024:.1f} KiB per pose)"
              + ("  (target < 2 s)" if n == 10000 else "")
              + (f"  CPU {cpu:.2f} s, {res.solve.iterations} iterations, "
                 f"{'converged' if res.converged else 'NOT CONVERGED'}, load average "
                 f"{os.getloadavg()[0]:.1f}" if n >= 100000 else ""))
        if n >= 100000:
            c, w, load = time.process_time(), time.perf_counter(), os.getloadavg()[0]
            res = CalibrationProblem(robot, data, CalibrationOptions()).solve()
            print(f"L2 + CV, {n} poses (lambda by CV on {res.cv.subsample[0]} of them): "
                  f"{time.perf_counter() - w:6.2f} s  CPU {time.process_time() - c:.2f} s, "
                  f"lambda = {res.lam:.3g}, {'converged' if res.converged else 'NOT CONVERGED'}"
                  f", load average {load:.1f} at the start (target: well under a minute)")
    if args.no_busy:
        return
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                for _ in range(os.cpu_count() or 2)]
    try:
        time.sleep(1.0)
        for threads in (1, None):
            opts = CalibrationOptions(method="ls", blas_threads=threads)
            t, _ = _time(lambda: CalibrationProblem(robot, data, opts).solve(),
                         max(1, args.repeats // 2))
            print(f"LS fit, {n:>6} poses, {len(spinners)} cores busy, blas_threads={threads}: "
                  f"{t:6.3f} s")
    finally:
        for p in spinners:
            p.kill()
            p.wait()


if __name__ == "__main__":
    main()
