"""The plausibility gate on good and broken calibrations: prints what it measures.

Good: ``kincal simulate X --seed S`` (tracker and rtest designs) calibrated with l2 and ls,
for X in ec66, ur10, panda, ur3 and S in 0-2, plus the TIAGo motion-capture day when
../shared/data/tiago_mocap is present. Broken (UR10 and EC66 tracker data, seed 0):
positions in mm read as m, joint values in degrees read as radians, positions shuffled
against the joint rows, 100 mm noise, a tip frame one or three links short, and the UR5
URDF for UR10 data. Per run: the median error after calibration and the RMS movement of
the tool point by the corrections, both as % of the reach; the findings; the convergence.

Usage: python scripts/plausibility_cases.py [--quick] [--convergence]   (quick: seed 0 only)

Exit code 1 if a good run is refused or a broken one is not (the table's promise).

--convergence: instead, the simulated ls runs' convergence alone: how many of them stop at the
iteration limit, with the error models complete (the API's default) and mdh, each under the
relative stopping rule (the default) and the paper's absolute one (SolverOptions(rule="paper")),
and the largest single kinematic correction [mm, deg] against the RMS movement of the tool
point by the corrections [mm] over those runs.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from kincal import Measurements, Robot, calibrate
from kincal.cli.main import main as kincal
from kincal.identification.solver import SolverOptions

TIAGO = Path(__file__).resolve().parents[2] / "shared" / "data" / "tiago_mocap"


def _row(label, result):
    p = result.plausibility
    ev = p.evidence
    L = ev.reach_m * 1e3
    kinds = ", ".join(f.kind for f in p.findings) or "-"
    print(f"| {label} | {ev.residual_median_mm:.3g} ({ev.residual_median_mm / L:.2%}) | "
          f"{ev.change_rms_mm:.3g} ({ev.change_rms_mm / L:.2%}) | {kinds} | "
          f"{'plausible' if p.plausible else 'REFUSED'} |")
    return p.plausible


def _variant(src: Path, dst: Path, joints, how: str, rng) -> Path:
    lines = [r for r in src.read_text().splitlines() if not r.startswith("#")]  # no provenance
    header = lines[0].split(",")
    v = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    pos = [header.index(c) for c in "xyz"]
    if how == "mm read as m":
        v[:, pos] *= 1000.0
    elif how == "deg read as rad":
        v[:, [header.index(j) for j in joints]] *= 180.0 / np.pi
    elif how == "shuffled rows":
        v[:, pos] = v[rng.permutation(len(v))][:, pos]
    elif how == "100 mm noise":
        v[:, pos] += rng.normal(0.0, 0.1, (len(v), 3))
    dst.write_text(",".join(header) + "\n"
                   + "\n".join(",".join(repr(float(x)) for x in r) for r in v) + "\n")
    return dst


def _simulated(tmp: Path, X: str, design: str, s: int) -> Path:
    f = tmp / f"{X}_{design}_{s}.csv"
    with contextlib.redirect_stdout(io.StringIO()):
        kincal(["simulate", X, "--out", str(f), "--seed", str(s), "--design", design])
    return f


def convergence(seeds) -> None:
    """How many of the simulated ls runs stop at the iteration limit, per error model and
    stopping rule."""
    cases = [(model, rule) for model in ("complete", "mdh") for rule in ("relative", "paper")]
    stopped = dict.fromkeys(cases, 0)
    largest = {c: [0.0, 0.0, 0.0] for c in cases}  # [mm], [deg], tool moved RMS [mm]
    n = 0
    with tempfile.TemporaryDirectory() as tmp:
        for X in ("ec66", "ur10", "panda", "ur3"):
            robot = Robot.load(X)
            for design in ("tracker", "rtest"):
                for s in seeds:
                    data = Measurements.from_csv(_simulated(Path(tmp), X, design, s),
                                                 robot.joint_names)
                    n += 1
                    for model, rule in cases:
                        result = calibrate(robot, data, method="ls", model=model,
                                           solver=SolverOptions(rule=rule))
                        stopped[model, rule] += not result.converged
                        big = largest[model, rule]
                        for q in result.parameters[:result.layout.n_kinematic]:
                            if q.status == "identified":
                                i, f = (0, 1e3) if q.is_length else (1, 180.0 / np.pi)
                                big[i] = max(big[i], abs(q.deviation) * f)
                        big[2] = max(big[2], result.plausibility.evidence.change_rms_mm)
    for (model, rule), k in stopped.items():
        mm, deg, moved = largest[model, rule]
        print(f"ls, model {model}, {rule} stopping rule: {k} of {n} runs not converged; "
              f"largest correction {mm:.3g} mm, {deg:.3g} deg; tool moved at most {moved:.3g} "
              "mm RMS")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="seed 0 only")
    ap.add_argument("--convergence", action="store_true",
                    help="the ls runs' convergence per error model and stopping rule")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    seeds = (0,) if args.quick else (0, 1, 2)
    if args.convergence:
        convergence(seeds)
        return 0
    print("| run | median error after [mm] (% of reach) | tool moved by corrections, RMS [mm] "
          "| findings | gate |")
    print("|---|---|---|---|---|")
    good = bad = n_bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for X in ("ec66", "ur10", "panda", "ur3"):
            robot = Robot.load(X)
            for design in ("tracker", "rtest"):
                for s in seeds:
                    data = Measurements.from_csv(_simulated(tmp, X, design, s),
                                                 robot.joint_names)
                    for m in ("l2", "ls"):
                        good += _row(f"{X} {design} seed {s} {m}", calibrate(robot, data, method=m))
        if TIAGO.is_dir():
            robot = Robot.load(TIAGO / "tiago_48_schunk.urdf", tip="wrist_ft_tool_link")
            data = Measurements.from_csv(TIAGO / "qualisys_2021-11-30_static_postures.csv",
                                         robot.joint_names, position_columns=("x1", "y1", "z1"))
            for m in ("l2", "ls"):
                good += _row(f"TIAGo mocap {m}", calibrate(robot, data, method=m))
        n_good = 4 * 2 * len(seeds) * 2 + (2 if TIAGO.is_dir() else 0)
        rng = np.random.default_rng(0)
        for X in ("ur10", "ec66"):
            robot = Robot.load(X)
            src = tmp / f"{X}_tracker_0.csv"
            for how in ("mm read as m", "deg read as rad", "shuffled rows", "100 mm noise"):
                data = Measurements.from_csv(_variant(src, tmp / "bad.csv", robot.joint_names,
                                                      how, rng), robot.joint_names)
                bad += not _row(f"{X} {how} (l2)", calibrate(robot, data))
                n_bad += 1
        for tip in ("wrist_1_link", "forearm_link"):
            robot = Robot.load("ur10", tip=tip)
            data = Measurements.from_csv(tmp / "ur10_tracker_0.csv", robot.joint_names)
            bad += not _row(f"ur10 data, --tip {tip} (l2)", calibrate(robot, data))
            n_bad += 1
        robot = Robot.load("ur5")
        data = Measurements.from_csv(tmp / "ur10_tracker_0.csv", robot.joint_names)
        bad += not _row("ur10 data, ur5 URDF (l2)", calibrate(robot, data))
        n_bad += 1
    print(f"\ngood runs plausible: {good} of {n_good}; broken runs refused: {bad} of {n_bad}; "
          f"{time.perf_counter() - t0:.0f} s")
    return 0 if (good, bad) == (n_good, n_bad) else 1


if __name__ == "__main__":
    sys.exit(main())
