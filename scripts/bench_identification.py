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
  (targets 0.3 s and 0.8 s; --cli-only runs just these). Commands run as a user runs
  them, printing their summaries (no --quiet: the summary's diagnosis is part of the
  cost).

Usage: python scripts/bench_identification.py [--repeats 5] [--no-busy] [--cli-only] [--no-200k]
       python scripts/bench_identification.py --issue20 [--large | --fixed-cost | --algorithm1]
       (issue 20's table, or only its per-fit fixed cost, or only its two Algorithm 1 rows:
       CPU time, minimum of repeats, each row next to numpy's least-squares solve of its size)
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
    if n <= 240:
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
                                       os.path.join(tmp, "out.urdf"), "--overwrite"]}
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


# ---------------------------------------------------------------- issue 20's table
def _cpu_min(fn, repeats, settle=False):
    """Minimum CPU time [s] of fn() over repeats (a shared machine disturbs it least).

    settle: one untimed call first, then 0.3 s idle, for the timings of small fits. The
    first fit of a process starts a BLAS worker thread (scipy's OpenBLAS, loaded lazily
    on the fit's path) that busy-waits for work about 0.1 s before it sleeps, and the
    process's CPU time counts that spin: fits of ~12 ms timed within that 0.1 s were
    charged about twice their cost (24 ms; seen per thread in /proc/self/task). The
    fits themselves run with one BLAS thread (CalibrationOptions.blas_threads)."""
    if settle:
        fn()
        time.sleep(0.3)
    best = float("inf")
    for _ in range(repeats):
        c = time.process_time()
        fn()
        best = min(best, time.process_time() - c)
    return best


def _child(cmd, repeats=1, env=None):
    """(min CPU [s] of the child, its peak resident memory [MiB]) of a new process."""
    import resource

    best, peak = float("inf"), 0.0
    for _ in range(repeats):
        before = os.times()
        out = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], capture_output=True,
                             text=True, check=True, env=env) if shutil.which("time") else \
            subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
        after = os.times()
        best = min(best, after.children_user - before.children_user
                   + after.children_system - before.children_system)
        last = out.stderr.strip().splitlines()[-1] if out.stderr.strip() else ""
        peak = max(peak, float(last) / 1024 if last.isdigit() else
                   resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)
    return best, peak


def _floor(m, p, repeats):
    """CPU [s] of numpy's least-squares solve of an (m, p) system: the raw-numpy floor."""
    rng = np.random.default_rng(0)
    A, b = rng.normal(size=(m, p)), rng.normal(size=m)
    return _cpu_min(lambda: np.linalg.lstsq(A, b, rcond=None), repeats)


def _fit_cpu_and_peak(robot, data, repeats, settle=False):
    opts = CalibrationOptions(method="ls")
    cpu = _cpu_min(lambda: CalibrationProblem(robot, data, opts).solve(), repeats, settle)
    tracemalloc.start()
    res = CalibrationProblem(robot, data, opts).solve()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return cpu, peak, res


def _fixed_cost_rows(row, robot, model, rng, repeats, p):
    """The 60-pose LS fit and the time per fit that does not depend on the pose count
    (printed with its method); returns the 60 poses."""
    # the per-fit cost that does not depend on the pose count: LS fits of 60, 120 and 240
    # poses of one design (tracker-like poses in the 400 mm cube), the minimum CPU time of
    # each after a settled warm-up (_cpu_min), a straight line through the three by least
    # squares: its value at 0 poses is that cost, its slope the cost of one more pose
    d60, sizes, ts = None, (60, 120, 240), []
    for n in sizes:
        d = _data(robot, model, n, 0.4, rng)
        d60 = d if n == 60 else d60
        ts.append(_fit_cpu_and_peak(robot, d, repeats, settle=True)[0])
    t60 = ts[0]
    slope, fixed = np.polyfit(sizes, ts, 1)
    row("LS fit, 60 poses", f"{t60 * 1e3:.1f} ms", f"{_floor(180, p, repeats) * 1e3:.2f} ms", "")
    row("time per fit that does not depend on the pose count", f"{fixed * 1e3:.1f} ms",
        "", "<= 5 ms")
    print("  (line through the LS fits of " + ", ".join(
        f"{n} poses {t * 1e3:.1f} ms" for n, t in zip(sizes, ts))
        + f": {slope * 1e6:.1f} us per pose; the 60-pose fit less 60 x that: "
        f"{(t60 - 60 * slope) * 1e3:.1f} ms)")
    return d60


def issue20(robot, model, rng, repeats, large):
    """Issue 20's rows: kincal's figure, the raw-numpy floor of the same size, the target."""
    exe = shutil.which("kincal")
    kincal = [exe] if exe else [sys.executable, "-m", "kincal"]
    p = 45  # parameters of the default model with the frames (EC66), for the floors
    try:
        import figaroh  # noqa: F401
        print("FIGAROH is installed: its side-by-side runs are scripts/bench_peers.py")
    except ImportError:
        print("FIGAROH is not installed in this environment: its column is skipped")
    print(f"{'work':<58} {'kincal':>34} {'numpy floor':>22}  target")
    row = lambda w, k, f, t: print(f"{w:<58} {k:>34} {f:>22}  {t}")
    d60 = _fixed_cost_rows(row, robot, model, rng, repeats, p)
    cpu, peak, res = _fit_cpu_and_peak(robot, _data(robot, model, 100000, 0.4, rng), 1)
    row("LS fit, 100,000 poses", f"{cpu:.2f} s, {peak / 2**20:.0f} MiB "
        f"({peak / 1e5 / 1024:.2f} KiB/pose)", f"{_floor(300000, p, 1):.2f} s", "")
    if large:
        cpu, peak, res = _fit_cpu_and_peak(robot, _data(robot, model, 1000000, 0.4, rng), 1)
        row("LS fit, 1,000,000 poses", f"{cpu:.1f} s, {peak / 2**20:.0f} MiB",
            f"{_floor(3000000, p, 1):.1f} s", "<= 25 s, <= 600 MB")
    with tempfile.TemporaryDirectory(prefix="kincal-bench-") as tmp:
        csv = os.path.join(tmp, "p60.csv")
        with open(csv, "w") as fh:
            fh.write(d60.to_csv_text())
        out = os.path.join(tmp, "out.urdf")
        cal = lambda f: kincal + ["calibrate", "ec66", f, "--method", "ls", "--out", out,
                                  "--overwrite"]
        cpu, _ = _child(cal(csv), repeats)
        floor, _ = _child([sys.executable, "-c", "import numpy"], repeats)
        row("`kincal calibrate --method ls`, 60 poses, whole command", f"{cpu:.2f} s",
            f"{floor:.2f} s (import numpy)", "<= 0.5 s")
        # the same with Python's bytecode cache for every module (as pip leaves an installed
        # package: compiled once), in a folder of its own (PYTHONPYCACHEPREFIX), so the
        # source tree is left as it was; an editable install with PYTHONDONTWRITEBYTECODE
        # set compiles kincal's modules at every start instead (the row above then)
        env = {**os.environ, "PYTHONPYCACHEPREFIX": os.path.join(tmp, "pycache")}
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        _child(cal(csv), 1, env)  # compiles and caches
        cpu, _ = _child(cal(csv), repeats, env)
        floor, _ = _child([sys.executable, "-c", "import numpy"], repeats, env)
        row("  the same, bytecode cached (PYTHONPYCACHEPREFIX)", f"{cpu:.2f} s",
            f"{floor:.2f} s (import numpy)", "<= 0.5 s")
        print(f"  (PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r} "
              "in this environment)")
        cpu, _ = _child(kincal + ["--help"], repeats)
        floor, _ = _child([sys.executable, "-c", "pass"], repeats)
        row("`kincal --help`", f"{cpu:.3f} s", f"{floor:.3f} s (python)", "<= 0.12 s")
        if large:
            big = os.path.join(tmp, "p300k.csv")
            with open(big, "w") as fh:
                fh.write(_data(robot, model, 300000, 0.4, rng).to_csv_text())
            cpu, peak = _child(cal(big))
            row("`kincal calibrate` 300,000 poses, --method ls", f"{cpu:.1f} s, {peak:.0f} MiB "
                f"({peak * 1024 / 300000:.2f} KiB/pose)", f"{_floor(900000, p, 1):.1f} s",
                "<= 8 s, <= 1.0 KiB/pose")
    _algorithm1_rows(row, robot, model, d60, max(1, repeats // 2), p)
    _issue20_io_rows(row, kincal, robot, model, rng, repeats)


def _algorithm1_rows(row, robot, model, d60, repeats, p, settle=False):
    """The paper's Algorithm 1 (L2 + CV, the whole solve) on the 60 poses of the 400 mm cube
    and on R-test-like poses in a 20 mm cube (their own seeded draw). settle: one untimed
    solve first and 0.3 s idle (:func:`_cpu_min`)."""
    rtest = _data(robot, model, 60, 0.02, np.random.default_rng(1), tilt=15)
    for name, d in (("400 mm cube", d60), ("20 mm cube", rtest)):
        out = []
        t = _cpu_min(lambda: out.append(CalibrationProblem(
            robot, d, CalibrationOptions(method="l2", lam="cv")).solve()), repeats, settle)
        row(f"Algorithm 1 (50 lambdas x 5 folds), 60 poses, {name}",
            f"{t:.3f} s (lambda {out[-1].lam:.4g})",
            f"{251 * _floor(144, p, repeats):.3f} s (251 lstsq)", "<= 0.25 s")


def _issue20_io_rows(row, kincal, robot, model, rng, repeats):
    """Issue 20 item 5: `kincal simulate` of 20,000 poses and `kincal compensate` of 100,000
    targets (whole commands, CPU of the child and its peak resident memory), reading a
    200,000-row CSV; each next to numpy doing the same arithmetic or reading."""
    import json

    from kincal.export.outputs import corrected_urdf_text
    from kincal.measurements.csv_table import read_columns

    with tempfile.TemporaryDirectory(prefix="kincal-bench-") as tmp:
        path = lambda name: os.path.join(tmp, name)  # noqa: E731
        # simulate: the default tracker design, EC66, 20,000 poses (about 9 damped
        # least-squares steps per pose, each a 6x6 solve: numpy's floor for those solves)
        cpu, peak = _child(kincal + ["simulate", "ec66", "--poses", "20000", "--out",
                                     path("sim.csv"), "--overwrite"], repeats)
        A = np.eye(6) + 0.1 * np.random.default_rng(0).normal(size=(20000, 6, 6))
        b = np.ones((20000, 6, 1))
        floor = _cpu_min(lambda: [np.linalg.solve(A, b) for _ in range(9)], repeats)
        row("`kincal simulate`, 20,000 poses", f"{cpu:.2f} s, peak {peak:.0f} MiB",
            f"{floor:.2f} s (9 x 20,000 6x6 solves)", "<= 2 s")
        # compensate 100,000 targets with a calibration from 60 simulated poses
        # (`kincal calibrate --frames-out`), two target sets: (a) the points of a simulated
        # tracker design of the same robot (a realistic program: 100,000 poses of
        # `kincal simulate --seed 5`, their measured points as targets, their joint values
        # as seeds); (b) random joint values over the joints' whole ranges, seeds 0.5 deg
        # off the values that reach them exactly (some at singular wrists or limits: those
        # iterate to the IK's limit). The extra memory is the peak less that of the same
        # command on 300 targets.
        for args in (["simulate", "ec66", "--poses", "60", "--out", path("c60.csv")],
                     ["simulate", "ec66", "--poses", "100000", "--seed", "5", "--out",
                      path("design.csv")],
                     ["calibrate", "ec66", path("c60.csv"), "--method", "ls", "--out",
                      path("cal.urdf"), "--frames-out", path("frames.json")]):
            subprocess.run(kincal + args + ["--quiet"], check=True, capture_output=True)
        result = CalibrationProblem(robot, _data(robot, model, 60, 0.4, rng),
                                    CalibrationOptions(method="ls")).solve()
        with open(path("cal_random.urdf"), "w") as fh:
            fh.write(corrected_urdf_text(result))
        with open(path("frames_random.json"), "w") as fh:
            json.dump(result.frames_dict(), fh)
        g = robot.geometry
        q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), (100000, g.n))
        seeds = q + np.radians(0.5) * rng.normal(size=q.shape)
        header = ",".join(list(robot.joint_names) + ["x", "y", "z"])
        np.savetxt(path("random.csv"), np.column_stack([seeds, result.predict(q)]),
                   delimiter=",", header=header, comments="", fmt="%.17g")
        out = np.zeros((100000, 10))
        floor = _cpu_min(lambda: (np.loadtxt(path("random.csv"), delimiter=",", skiprows=1),
                                  np.savetxt(path("floor.csv"), out, delimiter=",",
                                             fmt="%.17g")), repeats)
        for label, targets, cal in (("design", "design.csv", ""), ("random", "random.csv",
                                                                     "_random")):
            with open(path(targets)) as fh:
                with open(path("t300.csv"), "w") as small:
                    small.writelines(fh.readline() for _ in range(301))
            comp = lambda t: kincal + ["compensate", path(f"cal{cal}.urdf"), path(t),  # noqa
                                       "--frames", path(f"frames{cal}.json"), "--out",
                                       path("joints.csv"), "--overwrite",
                                       "--flag-unreachable"]
            cpu, peak = _child(comp(targets), repeats)
            _, base = _child(comp("t300.csv"), repeats)
            row(f"`kincal compensate`, 100,000 targets ({label})",
                f"{cpu:.2f} s, +{peak - base:.0f} MiB", f"{floor:.2f} s (loadtxt + savetxt)",
                "<= 3 s, <= +50 MB")
        # reading a 200,000-row CSV: kincal's reader against np.loadtxt of the same file
        rows = path("r200k.csv")
        with open(rows, "w") as fh:
            fh.write(_data(robot, model, 200000, 0.4, rng).to_csv_text())
        names = list(robot.joint_names) + ["x", "y", "z"]
        cpu = _cpu_min(lambda: read_columns(rows, names), repeats)
        floor = _cpu_min(lambda: np.loadtxt(rows, delimiter=",", skiprows=1), repeats)
        row("reading a 200,000-row CSV", f"{cpu:.2f} s", f"{floor:.2f} s (loadtxt)", "<= 0.8 s")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-busy", action="store_true", help="skip the busy-machine figures")
    ap.add_argument("--cli-only", action="store_true", help="only the command-line wall times")
    ap.add_argument("--no-200k", action="store_true", help="skip the 200,000-pose figures")
    ap.add_argument("--issue20", action="store_true",
                    help="issue 20's table (CPU minimum of repeats, raw-numpy floors) only")
    ap.add_argument("--large", action="store_true",
                    help="with --issue20: the 1,000,000-pose fit and the 300,000-pose command "
                    "too (minutes)")
    ap.add_argument("--algorithm1", action="store_true",
                    help="with --issue20: only the two Algorithm 1 rows, each the CPU minimum "
                    "of --repeats solves after an untimed one")
    ap.add_argument("--fixed-cost", action="store_true",
                    help="with --issue20: only the 60-pose fit and the per-fit fixed cost")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(0)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    if args.issue20 and args.algorithm1:
        print(f"{'work':<58} {'kincal':>34} {'numpy floor':>22}  target")
        _algorithm1_rows(lambda w, k, f, t: print(f"{w:<58} {k:>34} {f:>22}  {t}"), robot,
                         model, _data(robot, model, 60, 0.4, rng), args.repeats, 45, settle=True)
        return
    if args.issue20 and args.fixed_cost:
        print(f"{'work':<58} {'kincal':>34} {'numpy floor':>22}  target")
        _fixed_cost_rows(lambda w, k, f, t: print(f"{w:<58} {k:>34} {f:>22}  {t}"), robot,
                         model, rng, args.repeats, 45)
        return
    if args.issue20:
        issue20(robot, model, rng, args.repeats, args.large)
        return
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
