"""LS versus L2 + CV on R-test-like data, 10 seeded scenarios; prints a Markdown table.

Each scenario: an EC66 with planted errors (0.3 mm / 0.03 deg sd), tool point 120 mm
along the flange axis, 60 calibration poses keeping the tool point inside a 20 mm cube
with the tool tilted up to 15 deg from pointing down, 0.05 mm noise per axis; 150
validation poses in a 400 mm cube (10 um noise). Validation as in the paper: the
identified kinematics stay fixed and only the measurement frame and tool point are
fitted on the validation set. Errors are mean Euclidean position errors [mm].

Usage: python scripts/rtest_scenarios.py [--seeds 10]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from kincal import mdh
from kincal.calibration import CalibrationOptions, CalibrationProblem, calibrate
from kincal.robot import Robot
from kincal.simulation import Truth, cube_poses, measure, planted_table

BASE = np.array([0.9, -0.4, 0.2, 0.05, -0.1, 2.0])


def scenario(seed: int) -> dict:
    """The same scenario as tests/test_calibration.py::_rtest_scenario."""
    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    tool = np.array([0.0, 0.0, 0.12])
    q = cube_poses(robot, 60, [0.4, 0.0, 0.25], 0.02, tool, rng, max_tilt=np.radians(15))
    q_val = cube_poses(robot, 150, [0.4, 0.0, 0.25], 0.4, tool, rng, max_tilt=np.radians(30))
    truth = Truth(planted_table(model, rng), BASE, tool + rng.normal(size=3) * 1e-3)
    data = measure(model, truth, q, 5e-5, rng)
    val = measure(model, truth, q_val, 1e-5, rng)
    row = {"seed": seed}
    before = CalibrationProblem(robot, val, CalibrationOptions(method="frames")).solve()
    row["before"] = before.after.mean
    for method in ("ls", "l2"):
        res = calibrate(robot, data, method=method)
        v = CalibrationProblem(res.corrected, val, CalibrationOptions(method="frames")).solve()
        row[method] = v.after.mean
        row[f"{method}_cal"] = res.after.mean
        if method == "l2":
            row["lambda"] = res.lam
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")  # LS on 20 mm data may stop at the iteration limit
    t = time.perf_counter()
    rows = [scenario(s) for s in range(args.seeds)]
    print("| seed | before [mm] | LS + R-test [mm] | L2 + R-test [mm] | lambda (CV) | L2 better |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['before']:.3f} | {r['ls']:.3f} | {r['l2']:.3f} | "
              f"{r['lambda']:.3g} | {'yes' if r['l2'] < r['ls'] else 'no'} |")
    mean = {k: np.mean([r[k] for r in rows]) for k in ("before", "ls", "l2", "ls_cal", "l2_cal")}
    wins = sum(r["l2"] < r["ls"] for r in rows)
    print(f"| mean | {mean['before']:.3f} | {mean['ls']:.3f} | {mean['l2']:.3f} | | {wins} of {len(rows)} |")
    print(f"\ncalibration-set mean error: LS {mean['ls_cal']:.3f} mm, L2 {mean['l2_cal']:.3f} mm "
          f"(ratio {mean['l2_cal'] / mean['ls_cal']:.2f}); validation mean errors above, "
          f"400 mm cube; {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
