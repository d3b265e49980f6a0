#!/usr/bin/env python3
"""Does D-optimal pose selection help? Held-out error of LS fits on chosen vs random poses.

Simulated EC66 (planted MD-H errors 0.3 mm / 0.03 deg SD, 0.05 mm noise per axis, tool
point (30, 20, 120) mm), per seed: 500 candidate poses uniform within the joint limits,
30 of them chosen by kincal.select_poses, against 30 drawn at random from the same
candidates; plain LS on each; mean position error on 200 other random poses. Each figure
is the mean of 3 noise draws (and of 3 random subsets), because with 30 poses one noise
draw moves the held-out error as much as the choice of poses does. Also prints the time
of one selection of 30 of 2,000 candidates (median of 5).

Usage: python scripts/pose_selection_gain.py [--seeds 0 1 2 3 4 5]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from kincal import Robot, calibrate, random_candidates, select_poses
from kincal.models import mdh
from kincal.planning.simulation import Truth, measure, planted_table, true_positions

TOOL = (0.03, 0.02, 0.12)
BASE = np.array([0.8, 0.3, -0.2, 0.01, -0.03, 1.0])


def held_out_error(robot, model, truth, q_fit, q_test, P_test, rng) -> float:
    """Mean held-out position error [mm] of an LS fit on noisy measurements at q_fit."""
    data = measure(model, truth, q_fit, 0.05e-3, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate(robot, data, method="ls", tool_guess=TOOL)
    return float(np.mean(np.linalg.norm(result.predict(q_test) - P_test, axis=1)) * 1e3)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(6)))
    args = ap.parse_args(argv)
    robot = Robot.load("ec66", tip="flange")
    model = mdh.extract(robot.geometry)
    print("| seed | D-optimal 30 [mm] | random 30 [mm] |\n|---|---|---|")
    chosen_all, random_all = [], []
    for seed in args.seeds:
        rng = np.random.default_rng(seed)
        candidates = random_candidates(robot, 500, rng)
        truth = Truth(planted_table(model, rng), BASE, np.array(TOOL))
        q_test = random_candidates(robot, 200, rng)
        P_test = true_positions(model, truth, q_test)
        chosen = list(select_poses(robot, candidates, 30, tool=TOOL).indices)
        a = np.mean([held_out_error(robot, model, truth, candidates[chosen], q_test, P_test, rng)
                     for _ in range(3)])
        b = np.mean([held_out_error(robot, model, truth,
                                    candidates[rng.choice(500, 30, replace=False)], q_test,
                                    P_test, rng) for _ in range(3)])
        chosen_all.append(a)
        random_all.append(b)
        print(f"| {seed} | {a:.4f} | {b:.4f} |")
    better = sum(a < b for a, b in zip(chosen_all, random_all))
    print(f"\nD-optimal better in {better} of {len(chosen_all)} seeds; mean {np.mean(chosen_all):.4f} "
          f"vs {np.mean(random_all):.4f} mm ({1 - np.mean(chosen_all) / np.mean(random_all):.0%} "
          "lower)")
    candidates = random_candidates(robot, 2000, 1)
    times = []
    for _ in range(5):
        t = time.perf_counter()
        select_poses(robot, candidates, 30, tool=TOOL)
        times.append(time.perf_counter() - t)
    print(f"select_poses, 30 of 2,000 candidates: {np.median(times):.3f} s (median of 5)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
