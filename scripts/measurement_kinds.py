"""Simulated accuracy of each measurement kind on the EC66, over 5 seeds.

    python scripts/measurement_kinds.py [--seeds 5] [--quick]

The EC66 of kincal (error model ``complete``) gets planted errors (0.3 mm / 0.03 deg per
parameter, a new robot per seed) and is calibrated with method l2, lambda by 5-fold CV,
from one of:

- pose:     12 wide poses (random joint values), 6-DoF tool poses, 0.05 mm / 0.01 deg;
- distance: 100 wide poses, drawstring distances to a fixed pivot, 0.05 mm;
- plane:    60 contacts, 20 on each of 3 planes (a table and two walls), 0.01 mm;
- rtest+tracker: 60 R-test points (20 mm cube, 0.002 mm) and 10 wide laser-tracker points
  (0.05 mm) in one calibration, two sets with their own frames.

Each is scored on 200 held-out samples of its own kind (for rtest+tracker: wide tracker
points), as the mean error [mm] (position, distance, or distance to the plane) with the
identified parameters and frames, and as the ratio to that of the true parameters (the
noise floor: 1.00 would be perfect).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from kincal import models
from kincal.identification.problem import calibrate as calibrate
from kincal.identification.options import CalibrationOptions
from kincal.measurements.sets import kind_model
from kincal.planning import kind_simulation as ks
from kincal.planning.simulation import cube_poses, planted_table
from kincal.robot import Robot

BASE = np.array([1.2, -0.3, 0.1, 0.02, -0.03, 1.5])
TOOL = np.array([0.03, 0.02, 0.12])
TOOL6 = np.r_[TOOL, 0.1, -0.2, 0.3]
PIVOT = np.array([0.5, 0.2, -0.1])
PLANES = np.array([[0.0, 0.0, 0.05], [np.pi / 2, 0.0, 0.25], [0.0, np.pi / 2, 0.35]])


def wide(robot, rng, n):
    g = robot.geometry
    return rng.uniform(*g.ranges(), size=(n, g.n))


def floor_and_score(result, em, truth, held, true_frames, set_index=0):
    """(held-out mean error [mm], ratio to the true parameters')."""
    e = result.errors(held, set_index)
    km = kind_model(em, held)
    e0 = km.sample_errors(km.residuals(truth, true_frames, np.zeros(0)))
    return float(np.mean(e) * 1e3), float(np.mean(e) / np.mean(e0))


def scenario(name, robot, em, seed, options):
    rng = np.random.default_rng(seed)
    truth = planted_table(em, np.random.default_rng(1000 + seed))
    if name == "pose":
        sets = [ks.simulate_poses(em, truth, BASE, TOOL6, wide(robot, rng, 12), 5e-5, 0.01, rng)]
        held = ks.simulate_poses(em, truth, BASE, TOOL6, wide(robot, rng, 200), 5e-5, 0.01, rng)
        frames = np.r_[BASE, TOOL6]
    elif name == "distance":
        sets = [ks.simulate_distances(em, truth, PIVOT, TOOL, wide(robot, rng, 100), 5e-5, rng)]
        held = ks.simulate_distances(em, truth, PIVOT, TOOL, wide(robot, rng, 200), 5e-5, rng)
        frames = np.r_[PIVOT, TOOL]
    elif name == "plane":
        cand = wide(robot, rng, 3000)
        sets = [ks.simulate_contacts(em, truth, TOOL, PLANES, cand[:1500], 20, 1e-5, rng)]
        held = ks.simulate_contacts(em, truth, TOOL, PLANES, cand[1500:], 67, 1e-5, rng)
        frames = np.r_[TOOL, PLANES.ravel()]
    else:
        from dataclasses import replace

        q_rt = cube_poses(robot, 60, [0.45, 0.0, 0.35], 0.02, TOOL, rng, max_tilt=np.radians(15))
        rt = ks.simulate_points(em, truth, BASE, TOOL, q_rt, 2e-6, rng, source="rtest")
        tr = ks.simulate_points(em, truth, BASE[::-1] * 0.5, TOOL, wide(robot, rng, 10), 5e-5,
                                rng, source="tracker")
        sets = [replace(rt, sigma=np.full(len(rt), 2e-6)), replace(tr, sigma=np.full(10, 5e-5))]
        held = ks.simulate_points(em, truth, BASE[::-1] * 0.5, TOOL, wide(robot, rng, 200), 5e-5,
                                  rng)
        frames = np.r_[BASE[::-1] * 0.5, TOOL]
        result = calibrate(robot, sets, options)
        return floor_and_score(result, em, truth, held, frames, set_index=1) + (result,)
    result = calibrate(robot, sets, options)
    # plane frames: the identified normal may be the opposite one; compare by the data
    if name == "plane":
        frames = _matched_planes(result.sets[0].frames, frames)
    return floor_and_score(result, em, truth, held, frames) + (result,)


def _matched_planes(identified, true_frames):
    """The true plane parameters written with the identified normals' signs."""
    from kincal.measurements.plane import normal

    out = np.array(true_frames, float)
    for j in range(len(PLANES)):
        a = identified[3 + 3 * j: 6 + 3 * j]
        t = out[3 + 3 * j: 6 + 3 * j]
        if normal(a[0], a[1]) @ normal(t[0], t[1]) < 0:
            out[3 + 3 * j: 6 + 3 * j] = [t[0] + np.pi, -t[1], -t[2]]  # n(rx + pi, -ry) = -n
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="a coarse lambda grid (tests)")
    args = ap.parse_args(argv)
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    options = CalibrationOptions(n_lambdas=8 if args.quick else 50)
    names = ("pose", "distance", "plane", "rtest+tracker")
    print(f"EC66, error model complete, method l2 (lambda by 5-fold CV), {args.seeds} seeds; "
          "held-out mean error [mm] (ratio to the true parameters')")
    print(f"{'seed':>4s}  " + "".join(f"{n:>22s}" for n in names))
    table = {n: [] for n in names}
    for seed in range(args.seeds):
        cells = []
        for n in names:
            t = time.perf_counter()
            mean, ratio, _ = scenario(n, robot, em, seed, options)
            table[n].append((mean, ratio, time.perf_counter() - t))
            cells.append(f"{mean:10.4f} ({ratio:5.2f})")
        print(f"{seed:4d}  " + "".join(f"{c:>22s}" for c in cells), flush=True)
    print(f"{'mean':>4s}  " + "".join(
        f"{np.mean([m for m, _, _ in table[n]]):10.4f} ({np.mean([r for _, r, _ in table[n]]):5.2f})"
        .rjust(22) for n in names))
    print("seconds per calibration: " + ", ".join(
        f"{n} {np.mean([t for _, _, t in table[n]]):.1f}" for n in names))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
