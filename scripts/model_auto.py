"""``--model auto`` measured: does the choice find planted backlash or compliance, and only that?

Simulated EC66 and UR10 (60 tracker poses in a 0.4 m cube, planted MD-H errors of 0.3 mm
and 0.03 deg, tool 100 mm off the flange, noise 0.05 mm per axis, samples in acquisition
order): per seed, one half-play of 0.1 deg planted on one joint (the joint turns with the
seed, so not always the last) or none; ``calibrate(..., model="auto")`` must choose a
backlash term on exactly that joint, or none. Likewise a joint compliance (the joint
turns by c times the gravity torque it carries, from the URDF's inertials) sized to
deflect the joint by 0.2 deg at its RMS torque, on one of the joints that carry torque
(turning with the seed). Then the cost of auto against one default calibration on the
same 60 poses (CPU time: the machine may be shared), and the real TIAGo files with the
default command. Without a planted term, also how often the first forward step's score
test (the strongest joint term's Bonferroni p-value) falls below 0.05, 0.01 and the rule's
0.001: the test's false-positive rate, checked (``--null-seeds``: more seeds for that row).

    python scripts/model_auto.py [--seeds 20] [--null-seeds 50] [--no-tiago]
                                 [--terms backlash compliance] [--null-check FIRST LAST]

``--null-check 100 300``: only the first forward step's score test, on seeds FIRST to
LAST - 1 without a planted term (the default structure ``complete`` at its CV lambda):
how often the strongest term's Bonferroni p, and any single term's p, fall below 0.05,
0.01 and 0.001; calibrated, at most those fractions (Bonferroni: a little less).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from kincal.errors import KincalWarning
from kincal.identification.problem import calibrate
from kincal.models import mdh
from kincal.planning.simulation import Truth, cube_poses, measure, planted_table
from kincal.robot import Robot

REPO = Path(__file__).resolve().parents[1]
ROBOTS = {"EC66": (str(REPO / "urdf" / "ec66.urdf"), "flange", [0.4, 0.0, 0.25]),
          "UR10": ("ur10", "tool0", [0.6, 0.2, 0.4])}
BASE = np.array([0.9, -0.4, 0.2, 0.05, -0.1, 2.0])
TOOL = np.array([0.03, -0.02, 0.10])
HALF_PLAY = np.radians(0.1)  # [rad]
DEFLECTION = np.radians(0.2)  # [rad] a planted compliance's deflection at the RMS torque
NOISE = 0.05e-3  # [m] per axis


def case(name: str, seed: int, planted: bool, term: str = "backlash"):
    """(robot, data, planted joint or None) of one seed; term: what is planted."""
    path, tip, centre = ROBOTS[name]
    rng = np.random.default_rng(1000 + seed)
    robot = Robot.load(path, tip=tip)
    model = mdh.extract(robot.geometry)
    q = cube_poses(robot, 60, centre, 0.4, TOOL, rng)
    table = planted_table(model, rng, 0.3e-3, np.radians(0.03))
    if term == "compliance":
        rms = np.sqrt(np.mean(robot.gravity_torques(q) ** 2, axis=0))
        loaded = [j for j, t in zip(robot.joint_names, rms) if t > 0.1]  # [N m]
        joint = loaded[seed % len(loaded)] if planted else None
        c = DEFLECTION / rms[robot.joint_names.index(joint)] if joint else 0.0
        truth = Truth(table, BASE, TOOL, joint_compliance={joint: c} if joint else {},
                      robot=robot)
    else:
        joint = robot.joint_names[seed % robot.geometry.n] if planted else None
        truth = Truth(table, BASE, TOOL, backlash={joint: HALF_PLAY} if joint else {})
    return robot, measure(model, truth, q, NOISE, rng), joint


def study(seeds: int, terms=("backlash", "compliance"), null_seeds: int | None = None
          ) -> None:
    for name in ROBOTS:
        for term, planted in [(t, True) for t in terms] + [(terms[0], False)]:
            hits, chosen_any, costs, first_p = 0, 0, [], []
            n_seeds = seeds if planted or null_seeds is None else null_seeds
            for seed in range(n_seeds):
                robot, data, joint = case(name, seed, planted, term)
                t0 = time.process_time()
                calibrate(robot, data)
                t1 = time.process_time()
                res = calibrate(robot, data, model="auto")
                costs.append((time.process_time() - t1) / (t1 - t0))
                mc = res.model_choice
                got = mc.compliance if term == "compliance" else mc.backlash
                hits += got == ((joint,) if joint else ()) and not (
                    mc.backlash if term == "compliance" else mc.compliance)
                chosen_any += bool(mc.backlash or mc.compliance)
                first_p += mc.step_p[:1]
            what = (f"{term} planted, found on its joint (and nothing else)" if planted
                    else "none planted, a term chosen")
            n = hits if planted else chosen_any
            print(f"{name}: {what}: {n} of {n_seeds} seeds; auto / one default calibration: "
                  f"median {np.median(costs):.1f}x, max {np.max(costs):.1f}x")
            if not planted:
                p = np.array(first_p)
                print(f"{name}: none planted, first step's strongest term p < 0.05 / 0.01 / "
                      f"0.001 (Bonferroni): {np.sum(p < 0.05)} / {np.sum(p < 0.01)} / "
                      f"{np.sum(p < 0.001)} of {p.size} seeds")


def null_check(first: int, last: int) -> None:
    """The score test's false-positive rate on null seeds (model_choice's own test: the
    one place this script reaches into its private functions)."""
    from dataclasses import replace

    from kincal.identification import model_choice as mc
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.problem import CalibrationProblem

    for name in ROBOTS:
        strongest, single, terms = [], [], 0
        for seed in range(first, last):
            robot, data, _ = case(name, seed, planted=False)
            o = CalibrationOptions(model="complete", progress=None)
            p = CalibrationProblem(robot, data, o)
            pool = ([("b", j) for j in mc._backlash_joints(p, ())]
                    + [("c", j) for j in mc._compliance_joints(p)[0]])
            wide = CalibrationProblem(robot, data, replace(
                o, backlash=tuple(j for t, j in pool if t == "b"),
                compliance=tuple(j for t, j in pool if t == "c")))
            tests = mc._score_test(p, wide, pool, np.arange(len(data.joint_values)),
                                   p.cross_validate().best_lambda)
            strongest.append(tests[0][2])
            single += [pv / len(pool) for _, _, pv in tests]  # below 1/len(pool): exact
            terms += len(pool)
        b, r = np.array(strongest), np.array(single)
        print(f"{name}, none planted, seeds {first}-{last - 1}, first step's score test: "
              f"strongest term's Bonferroni p < 0.05 / 0.01 / 0.001 on "
              f"{np.sum(b < 0.05)} / {np.sum(b < 0.01)} / {np.sum(b < 0.001)} of {b.size} "
              f"seeds; a single term's p on {np.sum(r < 0.05)} / {np.sum(r < 0.01)} / "
              f"{np.sum(r < 0.001)} of {terms} terms")


def tiago() -> None:
    from kincal.cli.main import main

    data = REPO.parent / "shared" / "data" / "tiago_mocap"
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        common = ["--tip", "wrist_ft_tool_link", "--position-columns", "x1", "y1", "z1"]
        main(["calibrate", str(data / "tiago_48_schunk.urdf"),
              str(data / "qualisys_2021-11-30_static_postures.csv"), *common,
              "--out", f"{tmp}/t.urdf", "--frames-out", f"{tmp}/f.json", "--quiet"])
        main(["evaluate", f"{tmp}/t.urdf", str(data / "qualisys_2021-11-26_static_postures.csv"),
              *common, "--frames", f"{tmp}/f.json"])


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--null-seeds", type=int, default=None,
                    help="seeds without a planted term (default: --seeds)")
    ap.add_argument("--no-tiago", action="store_true")
    ap.add_argument("--null-check", type=int, nargs=2, metavar=("FIRST", "LAST"),
                    help="only the first step's score test on null seeds FIRST..LAST-1")
    ap.add_argument("--terms", nargs="+", default=["backlash", "compliance"],
                    choices=("backlash", "compliance"))
    a = ap.parse_args()
    warnings.simplefilter("ignore", KincalWarning)
    if a.null_check:
        null_check(*a.null_check)
        raise SystemExit(0)
    study(a.seeds, tuple(a.terms), a.null_seeds)
    if not a.no_tiago:
        tiago()
