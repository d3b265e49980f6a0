"""Every kincal error model on the real TIAGo motion-capture data (docs/results.md table).

    python scripts/tiago_models.py

Training day only (37 postures), held-out day (62 postures) predicted with the kinematics
and frames identified on the training day, marker 1 as the measured point; method L2 with
lambda by 5-fold CV (and plain LS for the offsets model), with and without a backlash term
on arm_6. Reads ../shared/data/tiago_mocap/ at run time.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from kincal import Measurements, Robot, calibrate
from kincal.models import MODELS

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "tiago_mocap"


def _effective(res) -> float:
    """Trace of the hat matrix: the effective number of identified parameters."""
    free = np.array([p.status == "identified" for p in res.parameters])
    J = res.solve.jacobian[:, free]
    H = J.T @ J + res.lam * np.diag(res.space.is_penalised[free].astype(float))
    return float(np.trace(np.linalg.solve(H, J.T @ J)))


def main():
    warnings.simplefilter("ignore")
    robot = Robot.load(DATA / "tiago_48_schunk.urdf", tip="wrist_ft_tool_link")
    read = dict(prismatic=["torso_lift_joint"], position_columns=("x1", "y1", "z1"),
                order_column="t_start_robot")
    train = Measurements.from_csv(DATA / "qualisys_2021-11-30_static_postures.csv",
                                  robot.joint_names, **read)
    test = Measurements.from_csv(DATA / "qualisys_2021-11-26_static_postures.csv",
                                 robot.joint_names, **read)
    print("model      method  backlash  identified (effective)  train RMS  held-out RMS / "
          "mean / max [mm]   lambda   fit [s]")
    runs = [(m, "l2", bl) for m in MODELS for bl in ((), ("arm_6_joint",))]
    runs.insert(runs.index(("offsets", "l2", ())), ("offsets", "ls", ()))
    for model, method, backlash in runs:
        t0 = time.perf_counter()
        res = calibrate(robot, train, model=model, method=method, backlash=backlash)
        wall = time.perf_counter() - t0
        e = np.linalg.norm(res.predict_data(test) - test.positions, axis=1) * 1e3
        n = sum(p.status == "identified" for p in res.parameters)
        print(f"{model:<10} {method:<7} {'arm_6' if backlash else '-':<9} "
              f"{n:3d} ({_effective(res):5.1f})            {res.after.rms:6.2f}     "
              f"{np.sqrt(np.mean(e ** 2)):6.3f} / {e.mean():6.3f} / {e.max():6.3f}      "
              f"{res.lam:7.3g}  {wall:6.2f}")


if __name__ == "__main__":
    main()
