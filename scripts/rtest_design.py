"""Pose design in a small measurement volume: the paper's setting versus planned tilted poses.

Each seed: an EC66 with planted errors (0.3 mm / 0.03 deg sd), tool point 120 mm along
the flange axis (plus 1 mm of unknown offset), 0.05 mm noise per axis; 60 calibration
poses with the tool point in a 20 mm cube at (0.4, 0, 0.25) m of the base, in one of
three designs:

- paper: random poses, tool tilted up to 30 deg from pointing down (``cube_poses``);
- random 60: random poses among kincal's volume candidates with tilt up to 60 deg;
- planned 60: the default of ``kincal plan --in-cube ... --max-tilt 60``: I-optimal choice
  (``select_poses``) among 2000 such candidates (``volume_candidates``) for 1000 target
  poses in the default working volume (``working_volume``: the 400 mm cube around the
  measurement cube, tilt up to 30 deg, same branch; the measurement frame and tool point
  refitted there);
- D-planned 60: D-optimal choice among the same candidates (``--criterion d``);
- I-planned 60: I-optimal choice among the same candidates, for 200 target poses in the
  400 mm validation cube with its tilt (up to 30 deg, same branch; other draws than the
  validation's).

Each design is calibrated with each estimator (LS; L2 with lambda by 5-fold CV, the
paper's method; others when kincal has them) and validated on 150 poses in a 400 mm cube,
tilt up to 30 deg, 0.05 mm noise, with the identified kinematics fixed and the
measurement frame and tool point refitted there (the paper's validation). "truth" is the
same validation with the true kinematics: the floor that the noise leaves. Every design
is measured with the same noise draws (paired comparisons). Figures:
mean position error [mm] over the validation poses, and the ratio to truth's.

Usage: python scripts/rtest_design.py [--seeds 10] [--candidates 2000]
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh as mdh_layer
from kincal.planning.pose_selection import select_poses
from kincal.planning.simulation import Truth, cube_poses, measure, planted_table
from kincal.planning.volume_candidates import (Volume, VolumeSpec, volume_candidates,
                                               working_volume)
from kincal.robot import Robot

CENTER = (0.4, 0.0, 0.25)
TOOL = np.array([0.0, 0.0, 0.12])
ESTIMATORS = (("LS", dict(method="ls")), ("L2 CV", dict(method="l2", lam="cv")),
              ("L2 evidence", dict(method="l2", lam="evidence")),
              ("L2 auto (default)", dict(method="l2")))


def _estimators():
    """The estimators compared (every one must be available: no silent omission)."""
    for name, kw in ESTIMATORS:
        CalibrationOptions(**kw).validated()
    return list(ESTIMATORS)


def scenario(seed: int, n_candidates: int, estimators) -> dict:
    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh_layer.extract(robot.geometry)
    truth = Truth(planted_table(model, rng), np.array([0.9, -0.4, 0.2, 0.05, -0.1, 2.0]),
                  TOOL + rng.normal(size=3) * 1e-3)
    true_robot = robot.with_joint_frames(model.joint_frames(truth.table))
    q_val = cube_poses(robot, 150, CENTER, 0.4, TOOL, rng, max_tilt=math.radians(30))
    val = measure(model, truth, q_val, 5e-5, rng)
    frames = CalibrationOptions(method="frames")
    row = {"truth": CalibrationProblem(true_robot, val, frames).solve().after.mean,
           "before": CalibrationProblem(robot, val, frames).solve().after.mean}

    spec = VolumeSpec(Volume.cube(CENTER, 0.02), tuple(TOOL), math.radians(60))
    vc = volume_candidates(robot, spec, n_candidates, seed=seed)
    cands = vc.joint_values
    tspec = VolumeSpec(Volume.cube(CENTER, 0.4), tuple(TOOL), math.radians(30), home=tuple(vc.home))
    targets = volume_candidates(robot, tspec, 200, seed=seed + 1000).joint_values
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tool point is on the last axis, as in the paper
        work = volume_candidates(robot, working_volume(spec, vc.home), 1000,
                                 seed=seed + 1).joint_values  # as kincal plan, seed + 1
        planned = select_poses(robot, cands, 60, tool=TOOL, method="I",
                               targets=work).joint_values
        d_planned = select_poses(robot, cands, 60, tool=TOOL).joint_values
        i_planned = select_poses(robot, cands, 60, tool=TOOL, method="I",
                                 targets=targets).joint_values
    designs = {"paper": cube_poses(robot, 60, CENTER, 0.02, TOOL, rng, max_tilt=math.radians(30)),
               "random 60": cands[:60], "planned 60": planned, "D-planned 60": d_planned,
               "I-planned 60": i_planned}
    state = rng.bit_generator.state
    for design, q in designs.items():
        rng.bit_generator.state = state  # the same noise draws for every design (paired)
        data = measure(model, truth, q, 5e-5, rng)
        for name, kw in estimators:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # LS on 20 mm data may hit the iteration limit
                res = CalibrationProblem(robot, data, CalibrationOptions(**kw)).solve()
            row[design, name] = CalibrationProblem(res.corrected, val, frames).solve().after.mean
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--candidates", type=int, default=2000)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")  # the paper's tool point is on the last axis: warned each fit
    estimators = _estimators()
    t = time.perf_counter()
    rows = [scenario(s, args.candidates, estimators) for s in range(args.seeds)]
    cols = [(d, e) for d in ("paper", "random 60", "planned 60", "D-planned 60", "I-planned 60")
            for e, _ in estimators]
    print("mean validation error [mm] (ratio to the true kinematics'), 400 mm cube:")
    print("| seed | truth | before | " + " | ".join(f"{d}, {e}" for d, e in cols) + " |")
    print("|---" * (3 + len(cols)) + "|")
    for s, r in enumerate(rows):
        cells = [f"{r[c]:.3f} ({r[c] / r['truth']:.2f})" for c in cols]
        print(f"| {s} | {r['truth']:.3f} | {r['before']:.3f} | " + " | ".join(cells) + " |")
    ratio = {c: np.mean([r[c] / r["truth"] for r in rows]) for c in cols}
    mean = {c: np.mean([r[c] for r in rows]) for c in cols + ["truth", "before"]}
    print(f"| mean | {mean['truth']:.3f} | {mean['before']:.3f} | "
          + " | ".join(f"{mean[c]:.3f} ({ratio[c]:.2f})" for c in cols) + " |")
    for design in ("planned 60", "D-planned 60", "I-planned 60"):
        for name, _ in estimators:
            worse = [s for s, r in enumerate(rows) if r[design, name] > r["paper", "L2 CV"]]
            print(f"{design} + {name} worse than the paper's method (paper + L2 CV) on seeds: "
                  f"{worse or 'none'}")
    print(f"({time.perf_counter() - t:.0f} s)")


if __name__ == "__main__":
    main()
