"""Reproduce the paper's Tables 2-4 and Figs. 3-5 on a simulated EC66; prints the tables.

Runs kincal.paper_experiment over several seeds (the full configuration: 60 R-test
poses, 150 tracker points, 50 lambda candidates, 5 folds), prints Markdown tables ready
for a README, and writes tables.md, results.json and the plots of the first seed into
--out. About 10-20 s per seed on one core; --jobs 2 runs two seeds at a time.

Usage: python scripts/reproduce_paper.py [--seeds 5] [--out paper_reproduction]
       [--jobs 2] [--tilt 8] [--lambdas 50]
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

from kincal.experiments.paper_experiment import ExperimentConfig, run  # noqa: E402
from kincal.experiments.paper_report import tables, write_report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="number of seeds, 0..N-1 (default 5)")
    ap.add_argument("--out", default="paper_reproduction",
                    help="folder for tables.md, results.json and the plots (default %(default)s)")
    ap.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    ap.add_argument("--tilt", type=float, default=None,
                    help="R-test orientation range [deg] (default: the config's, 8)")
    ap.add_argument("--lambdas", type=int, default=None, help="CV candidates (default 50)")
    args = ap.parse_args(argv)
    if args.seeds < 1 or args.jobs < 1:
        ap.error("--seeds and --jobs must be at least 1")
    config = ExperimentConfig()
    if args.tilt is not None:
        config = replace(config, rtest_max_tilt_deg=args.tilt)
    if args.lambdas is not None:
        config = replace(config, n_lambdas=args.lambdas)
    configs = [replace(config, seed=s).validated() for s in range(args.seeds)]
    t0 = time.perf_counter()
    if args.jobs == 1:
        results = [run(c) for c in configs]
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            results = list(pool.map(run, configs))
    elapsed = time.perf_counter() - t0
    lams = [r.lam for r in results]
    summary = {"seeds": args.seeds, "elapsed_s": elapsed, "median_lambda": float(np.median(lams))}
    files = write_report(results, args.out, summary)
    argv_text = " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    print(f"$ python scripts/reproduce_paper.py {argv_text}".rstrip())
    print()
    print(tables(results))
    print(f"{args.seeds} seeds in {elapsed:.0f} s ({args.jobs} processes); "
          f"plots of seed {configs[0].seed} and all numbers in {files[0].parent}:")
    for f in files:
        print(f"  {f.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
