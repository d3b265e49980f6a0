"""Does the predicted accuracy map match repeated calibrations? A Monte Carlo check.

Simulated EC66 (0.3 mm / 0.03 deg planted errors), 60 random calibration poses, 0.05 mm
noise per axis. The same poses are measured again with new noise draws (60 by default)
and calibrated each time; the scatter of the predicted tool point at 15 other poses is
compared with the map's predicted 3-D standard deviation:

- LS: the calibration's own sandwich covariance (mean over the first 5 draws);
- L2 with a fixed lambda: the design covariance at the true noise
  (``design_accuracy_map``), and the calibration's own (which also counts the pull
  toward nominal in its residuals, so it is conservative).

    python scripts/accuracy_map_monte_carlo.py [--draws 60] [--lam 3]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh
from kincal.planning.accuracy_map import design_accuracy_map, result_accuracy_map
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=60)
    ap.add_argument("--lam", type=float, default=3.0)
    args = ap.parse_args()
    rng = np.random.default_rng(3)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    lo, hi = np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi)
    q = rng.uniform(lo, hi, size=(60, g.n))
    q_targets = rng.uniform(lo, hi, size=(15, g.n))
    truth = Truth(planted_table(model, rng), np.array([1.0, 0.2, 0.1, 0.01, 0.02, 0.3]),
                  np.array([0.03, 0.0, 0.1]))
    noise = 5e-5
    for label, options in (("LS", CalibrationOptions(method="ls")),
                           (f"L2, lambda {args.lam:g}",
                            CalibrationOptions(method="l2", lam=args.lam))):
        t0 = time.perf_counter()
        preds, own = [], []
        problem = None
        for k in range(args.draws):
            data = measure(model, truth, q, noise, np.random.default_rng(100 + k))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem = CalibrationProblem(robot, data, options)
                res = problem.solve()
            preds.append(res.predict(q_targets))
            if k < 5:
                own.append(result_accuracy_map(res, joint_values=q_targets).std)
        P = np.array(preds)
        mc = np.sqrt(np.mean(np.sum((P - P.mean(axis=0)) ** 2, axis=2), axis=0))
        design = design_accuracy_map(problem, noise, joint_values=q_targets,
                                     lam=options.lam if options.method == "l2" else 0.0).std
        print(f"{label}: {args.draws} re-calibrations in {time.perf_counter() - t0:.1f} s; "
              f"Monte Carlo 3-D std at 15 poses {mc.min() * 1e3:.4f}-{mc.max() * 1e3:.4f} mm")
        for name, pred in (("calibration's own map", np.mean(own, axis=0)),
                           ("design map (true noise)", design)):
            r = pred / mc
            print(f"  {name:<24} predicted / Monte Carlo: {r.min():.2f}-{r.max():.2f} "
                  f"(mean {r.mean():.2f})")


if __name__ == "__main__":
    main()
