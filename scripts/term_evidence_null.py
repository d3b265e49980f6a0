"""How large the compliance diagnosis' evidence gain gets where there is no compliance.

kincal reports a compliance term the evidence favours (kincal.identification.term_evidence)
when its log evidence gain passes 7 + ln(candidates) nats. This script measures the gain's
null distribution, the largest gain over the joints tried per calibration, on data simulated
without any compliance:

- TALOS flush touches at the 21 real training postures (left sole -> left gripper), errors
  planted on every origin (1 mm, 0.3 deg), each touch moved until flush up to the noise
  kincal estimates on the real touches (0.9 mm, 0.45 deg), one seed per calibration;
- EC66 sets of 30 poses from ``kincal simulate ec66 --kind K --seed S`` (flush, plane,
  distance, pose), each calibrated with the evidence.

and prints, per case, the median, 90 % and largest gain, how many calibrations pass the
threshold, and beside them the real TALOS touches' gain (needs ../shared beside the
repository).

Usage: python scripts/term_evidence_null.py [--talos-seeds 70] [--ec66-seeds 40]
(about 3 min on the shared 2-core machine with the defaults).
"""

from __future__ import annotations

import argparse
import io
import math
import sys
import tempfile
import warnings
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import talos_contact as tc  # noqa: E402  (the TALOS study's data, URDF and simulation)


def top_gain(robot, data, tool) -> tuple[float, int]:
    """(largest gain [nats], joints tried) of one calibration by the evidence."""
    from kincal import CalibrationOptions, CalibrationProblem
    from kincal.identification import penalty_choice, term_evidence

    problem = CalibrationProblem(robot, data, CalibrationOptions(lam="evidence",
                                                                 tool_guess=tool))
    problem.analyze()
    sol, fit = penalty_choice.fit_evidence(problem)
    gains = term_evidence.gains(problem, sol.u, fit)
    return (max(gains)[0], len(gains)) if gains else (math.nan, 0)


def talos(seeds: int) -> tuple[np.ndarray, int]:
    from kincal.identification.chains import Chains
    from kincal.measurements.flush import FlushData, FlushKind
    from kincal.robot import Robot

    urdf = tc.talos_urdf()
    names, q_train = tc.joint_rows(tc.DATA / "left_train.csv")
    names = list(names)
    arm = Robot.load(urdf, base=tc.BASE, tip=tc.TIP)
    model = Chains([arm], 1, "placement").models[0]
    idx = [names.index(j) for j in arm.joint_names]
    nominal = FlushData(joint_names=arm.joint_names, joint_values=q_train[:, idx])
    plane = FlushKind(model, nominal).start(model.nominal, tc.CONTACT[:3])[:3]
    out, k = [], 0
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        truth = model.nominal + np.where(model.is_length, 1e-3, np.radians(0.3)) * rng.normal(
            size=model.size)
        rows = tc.simulated_touches(model, truth, q_train, names, arm, plane, (0.9, 0.45), rng,
                                    "simulated")
        data = FlushData(joint_names=arm.joint_names, joint_values=rows[:, idx],
                         source="simulated")
        g, k = top_gain(arm, data, (0.0, 0.0, -0.12))
        out.append(g)
    return np.array(out), k


def ec66(kind: str, seeds: int) -> tuple[np.ndarray, int]:
    from kincal import Robot
    from kincal.cli.main import main
    from kincal.measurements.sets import read_set_file

    robot = Robot.load("ec66")
    out, k = [], 0
    with tempfile.TemporaryDirectory(prefix="kincal-null-") as tmp:
        path = Path(tmp) / "sim.csv"
        for seed in range(seeds):
            with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
                code = main(["simulate", "ec66", "--kind", kind, "--poses", "30", "--seed",
                             str(seed), "--out", str(path), "--quiet", "--overwrite"])
            if code != 0:
                sys.exit(f"term_evidence_null: kincal simulate ec66 --kind {kind} failed")
            contact = kind in ("flush", "plane")
            data = read_set_file(path, robot.joint_names, on_plane=contact,
                                 flush=kind == "flush")
            g, k = top_gain(robot, data, (0.0, 0.0, 0.1) if contact else None)
            out.append(g)
    return np.array(out), k


def real_talos() -> float:
    from kincal.measurements.sets import read_set_file
    from kincal.robot import Robot

    arm = Robot.load(tc.talos_urdf(), base=tc.BASE, tip=tc.TIP)
    data = read_set_file(tc.DATA / "left_train.csv", arm.joint_names, on_plane=True,
                         flush=True)
    return top_gain(arm, data, (0.0, 0.0, -0.12))[0]


def line(label: str, gains: np.ndarray, k: int) -> str:
    threshold = 7.0 + math.log(k)
    return (f"| {label} | {len(gains)} | {k} | {threshold:.1f} | {np.median(gains):.2f} | "
            f"{np.quantile(gains, 0.9):.2f} | {gains.max():.2f} | "
            f"{int((gains > threshold).sum())} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--talos-seeds", type=int, default=70, metavar="N")
    parser.add_argument("--ec66-seeds", type=int, default=40, metavar="N")
    args = parser.parse_args(argv)
    if not tc.DATA.is_dir():
        sys.exit(f"term_evidence_null: {tc.DATA} not found (the shared data sit beside the "
                 "repository)")
    warnings.simplefilter("ignore")
    print("Largest compliance-term log evidence gain [nats] per calibration, data simulated "
          "without compliance")
    print("| case | calibrations | joints tried | threshold | median | 90 % | largest | "
          "passed |")
    print("|---|---|---|---|---|---|---|---|")
    print(line("TALOS flush touches (21, real postures)", *talos(args.talos_seeds)))
    for kind in ("flush", "plane", "distance", "pose"):
        print(line(f"EC66 {kind} (30 poses)", *ec66(kind, args.ec66_seeds)))
    print(f"Real TALOS training touches: {real_talos():.2f} nats")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
