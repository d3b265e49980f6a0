"""TIAGo: the four hand markers turned into 6-DoF hand poses, calibrated with the pose kind,
beside the point kind on the same markers (docs/kinds.md).

    python scripts/tiago_poses.py

Reads ../shared/data/tiago_mocap/ at run time. Rigid-body fit per posture: the marker
body (the four markers in a body frame at their centroid) is found on the training day by
generalised Procrustes (Kabsch of each posture to the current body, body re-estimated as
the mean of the back-transformed markers, until it settles), then every posture of both
days gets (R, t) by Kabsch to that body. The four markers of these files are rigid to
1e-4 mm (the motion-capture system reports a rigid body), so the fit's residual cannot
state the noise: the poses take the file's ``marker_std_mm`` (per posture) as their
position sigma, and its median over the body's RMS radius as the orientation sigma
(first order for a rigid fit).

Training: 30 Nov (37 postures); held out: 26 Nov (62 postures); error model complete,
method l2, lambda by 5-fold CV. Score: held-out RMS [mm] of the four markers predicted
with the identified kinematics and frames (the pose kind predicts a marker as the
identified tool frame times the body's marker position).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from kincal import Measurements, Robot, calibrate
from kincal.measurements.csv_table import read_columns
from kincal.measurements.pose import PoseData
from kincal.models.chain import Chain
from kincal.rotations import base_rotation, kabsch

import os

# the project's shared data beside the repository (KINCAL_SHARED overrides, as for the tests)
DATA = Path(os.environ.get("KINCAL_SHARED", Path(__file__).resolve().parents[2] / "shared")) \
    / "data" / "tiago_mocap"
TRAIN = DATA / "qualisys_2021-11-30_static_postures.csv"
TEST = DATA / "qualisys_2021-11-26_static_postures.csv"
MARKERS = tuple(f"{c}{k}" for k in range(1, 5) for c in "xyz")


def markers(path) -> np.ndarray:
    """(N, 4, 3) marker positions [m]."""
    v = read_columns(path, MARKERS).values
    return np.stack([np.column_stack([v[f"{c}{k}"] for c in "xyz"]) for k in range(1, 5)], 1)


def fit_body(M: np.ndarray, rounds: int = 50) -> np.ndarray:
    """(4, 3) the marker body (centroid at 0) that best fits every posture M (N, 4, 3)."""
    body = M[0] - M[0].mean(axis=0)
    for _ in range(rounds):
        back = []
        for m in M:
            R, t = kabsch(body, m)
            back.append((m - t) @ R)  # R^T (m - t)
        new = np.mean(back, axis=0)
        new -= new.mean(axis=0)
        if np.abs(new - body).max() < 1e-12:
            break
        body = new
    return body


def poses(M, body):
    """(positions (N, 3), rotations (N, 3, 3), residuals (N, 4, 3)) of the rigid fits."""
    P, R, res = [], [], []
    for m in M:
        Rk, tk = kabsch(body, m)
        P.append(tk)
        R.append(Rk)
        res.append(m - (body @ Rk.T + tk))
    return np.array(P), np.array(R), np.array(res)


def main() -> int:
    warnings.simplefilter("ignore")
    if not TRAIN.exists():
        print(f"no data at {DATA}")
        return 1
    robot = Robot.load(DATA / "tiago_48_schunk.urdf", tip="wrist_ft_tool_link")
    names, prismatic = robot.joint_names, ["torso_lift_joint"]
    read = dict(prismatic=prismatic, position_columns=MARKERS, order_column="t_start_robot")
    train4 = Measurements.from_csv(TRAIN, names, **read)
    test4 = Measurements.from_csv(TEST, names, **read)
    Mtr, Mte = markers(TRAIN), markers(TEST)
    body = fit_body(Mtr)
    Ptr, Rtr, res_tr = poses(Mtr, body)
    Pte, Rte, res_te = poses(Mte, body)
    sigma = read_columns(TRAIN, ("marker_std_mm",)).values["marker_std_mm"] * 1e-3  # [m]
    radius = float(np.sqrt(np.mean(np.sum(body ** 2, axis=1))))
    sigma_deg = math.degrees(float(np.median(sigma)) / radius)
    print(f"marker body: RMS radius {radius * 1e3:.1f} mm; largest rigid-fit residual "
          f"{np.abs(res_tr).max() * 1e3:.1e} mm (training), {np.abs(res_te).max() * 1e3:.1e} mm "
          f"(held out); stated pose noise: marker_std_mm (median {np.median(sigma) * 1e3:.2f} "
          f"mm), {sigma_deg:.3f} deg")
    q_tr = train4.joint_values[::4]
    pose_set = PoseData(joint_names=names, joint_values=q_tr, positions=Ptr, rotations=Rtr,
                        sigma=sigma, orientation_sigma_deg=sigma_deg,
                        source=str(TRAIN))

    def score(kin, base, tools_of_marker):
        """Held-out RMS and mean [mm] of the four markers."""
        s = Chain(res_pose.error_model, test4.joint_values[::4]).state(kin, None, keep=False)
        Rb = base_rotation(*base[3:])
        e = []
        for k in range(4):
            pred = (s.p_tip + s.R_tip @ tools_of_marker[k]) @ Rb.T + base[:3]
            e.append(np.linalg.norm(pred - Mte[:, k], axis=1))
        e = np.concatenate(e) * 1e3
        return float(np.sqrt(np.mean(e ** 2))), float(np.mean(e))

    rows = []
    res_pose = calibrate(robot, [pose_set])
    f = res_pose.sets[0].frames
    tool_R = base_rotation(*f[9:12])
    rows.append(("pose kind (rigid-body fits)", res_pose,
                 score(res_pose.kinematic, f[:6], [f[6:9] + tool_R @ b for b in body])))
    res_pts = calibrate(robot, train4)
    rows.append(("point kind, 4 markers", res_pts,
                 score(res_pts.x[:res_pts.space.n_kinematic], res_pts.base, res_pts.tools)))
    print("error model complete, method l2 (lambda by 5-fold CV); training 30 Nov (37 "
          "postures), held out 26 Nov (62 postures), all four markers")
    print(f"{'':30s} {'identified':>10s} {'lambda':>9s}  held-out RMS / mean [mm]")
    for label, res, (rms, mean) in rows:
        n = sum(p.status == "identified" for p in res.parameters)
        print(f"{label:30s} {n:10d} {res.lam:9.3g}  {rms:6.3f} / {mean:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
