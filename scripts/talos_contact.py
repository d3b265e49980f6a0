"""TALOS flush table contacts (real robot): kincal's held-out accuracy beside FIGAROH's.

Reads ``../shared/data/talos_contact/`` at run time (21 training touches of 2022-10-28, 9
validation touches of 2022-11-07; see its README), calibrates the chain from the left sole
to the left gripper with the command line a user would type::

    kincal calibrate talos_full_v2.urdf left_train.csv --base left_sole_link \\
        --tip gripper_left_base_link --on-plane --flush --tool-offset 0 0 -0.12 \\
        --out CAL.urdf --frames-out FRAMES.json

and judges the files it wrote on the other day's touches, as an independent check would:
the corrected URDF (through Pinocchio), the contact point and face tilt from FRAMES.json,
the table plane fitted (SVD) through the training touches' contact points. Held-out RMS of
the validation touches' height above that plane [mm] and of the face's two tilts against its
normal, roll about the contact frame's x axis and pitch about its y axis [deg].

The validation file's header lacks the 4 leading empty names of the training file's, so
kincal refuses it as it is ("the names look shifted"); the script reads its rows by position
into a file with the training header, as its README says to.

Usage: python scripts/talos_contact.py [--variants]   (about 3 s; --variants: +1 min)

--variants adds other penalty and model choices (among them compliance terms on the stance
leg, whose joints carry the robot's weight: FRAMES.json's compliance is applied to the
held-out touches, with the gravity torques of the chain at each touch, the joints off the
chain at zero), and a floor: the defaults fitted on both
days together and judged in sample on the second day's touches (with the plane through
every touch), which no out-of-sample prediction can be expected to beat.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
import tempfile
import warnings
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "talos_contact"
BASE, TIP = "left_sole_link", "gripper_left_base_link"
LEG = tuple(f"leg_left_{k}_joint" for k in range(1, 7))  # the stance leg: it carries the body
FIGAROH = (5.76, 0.42, 0.49)  # published held-out RMS: height [mm], roll, pitch [deg]


def talos_urdf() -> Path:
    """example-robot-data's talos_full_v2.urdf (a dependency of kincal)."""
    from kincal.descriptions import resolve

    return resolve("talos").urdf


def joint_rows(path: Path) -> tuple[list[str], np.ndarray]:
    """(joint names, (N, 32) values) of a TALOS log, rows read by position: 5 metadata
    fields, then the joints in the order of the training file's header."""
    names = [h for h in next(csv.reader(open(DATA / "left_train.csv")))[5:] if h.strip()]
    rows = [r for r in csv.reader(open(path)) if r and r[0] == "gripper"]
    return names, np.array([[float(v) for v in r[5:5 + len(names)]] for r in rows])


def write_joint_csv(path: Path, names, values) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(names)
        w.writerows([[repr(float(v)) for v in row] for row in values])


def held_out(urdf: Path, frames_path: Path, q_train: np.ndarray, q_valid: np.ndarray,
             names) -> tuple[float, float, float]:
    """(height [mm], roll [deg], pitch [deg]) RMS on the validation touches, from the files
    a calibration wrote (see the module notes)."""
    from kincal.frames_file import CellFrames
    from kincal.measurements.flush import tilt_angles
    from kincal.measurements.plane import fit_plane
    from kincal.robot import Robot
    from kincal.rotations import base_rotation

    robot = Robot.load(urdf, base=BASE, tip=TIP)
    idx = [list(names).index(j) for j in robot.joint_names]
    cell = CellFrames.read(frames_path)
    s = cell.sets[0]
    c = np.array([cell.compliance.get(j, 0.0) for j in robot.joint_names])
    t = np.array([s.value(f"tool.{c}") for c in "xyz"])
    tilt = [s.value(f"tool.{c}") if s.has(f"tool.{c}") else 0.0 for c in ("rx", "ry")]
    R_c = base_rotation(tilt[0], tilt[1], 0.0)

    def contact(q):
        q = q[:, idx]
        if c.any():  # FRAMES.json's compliance terms: the joints sit at q + c tau(q)
            q = q + c * robot.gravity_torques(q)
        T = robot.tip_poses(q)
        return T[:, :3, 3] + T[:, :3, :3] @ t, T[:, :3, :3] @ R_c

    P, A = contact(q_train)
    n, d, _ = fit_plane(P)
    if np.mean(A[:, :, 2] @ n) < 0:  # the normal on the face's side
        n, d = -n, -d
    P, A = contact(q_valid)
    roll, pitch = tilt_angles(np.einsum("nji,j->ni", A, n))

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x))))

    return rms(P @ n - d) * 1e3, float(np.degrees(rms(roll))), float(np.degrees(rms(pitch)))


def nominal_frames(folder: Path, urdf: Path) -> Path:
    """A FRAMES.json with the nominal contact point (0, 0, -0.12) m and no tilt."""
    from kincal.frames_file import CellFrames, SetFrames

    path = folder / "nominal_frames.json"
    frames = CellFrames("", "", BASE, TIP, (), (SetFrames(
        "flush", "nominal", ("tool.x", "tool.y", "tool.z"), (0.0, 0.0, -0.12)),))
    path.write_text(frames.dumps())
    return path


def calibrate(folder: Path, urdf: Path, train: Path, tag: str, *extra: str):
    from kincal.cli.main import main

    out, frames = folder / f"{tag}.urdf", folder / f"{tag}_frames.json"
    argv = ["calibrate", str(urdf), str(train), "--base", BASE, "--tip", TIP, "--on-plane",
            "--flush", "--tool-offset", "0", "0", "-0.12", "--out", str(out), "--frames-out",
            str(frames), "--quiet", *extra]
    with warnings.catch_warnings(), redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        code = main(argv)
    if code != 0:
        sys.exit(f"talos_contact: kincal {' '.join(argv)} failed ({code})")
    return out, frames


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", action="store_true",
                        help="also the other penalty and error model choices")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        sys.exit(f"talos_contact: {DATA} not found (the shared data sit beside the repository)")
    urdf = talos_urdf()
    names, q_train = joint_rows(DATA / "left_train.csv")
    _, q_valid = joint_rows(DATA / "left_validation.csv")
    rows = [("FIGAROH (published)", *FIGAROH)]
    with tempfile.TemporaryDirectory(prefix="kincal-talos-") as tmp:
        folder = Path(tmp)
        rows.append(("nominal model, plane fitted to the training touches",
                     *held_out(urdf, nominal_frames(folder, urdf), q_train, q_valid, names)))
        train = DATA / "left_train.csv"  # kincal reads the log as it is (metadata skipped)
        variants = [("kincal defaults (placement model, lambda auto: evidence)", ())]
        if args.variants:
            variants += [("kincal, --lambda cv", ("--lambda", "cv")),
                         ("kincal, --model offsets", ("--model", "offsets")),
                         ("kincal, tilt sigma 0.02 deg", ("--orientation-sigma-deg", "0.02")),
                         ("kincal, --lambda cv (model auto judged by CV)",
                          ("--lambda", "cv", "--model", "auto")),
                         ("kincal, --compliance on the stance leg's 6 joints",
                          ("--compliance", *LEG)),
                         ("kincal, --compliance on the stance leg's roll joints",
                          ("--compliance", "leg_left_2_joint", "leg_left_6_joint"))]
        for k, (label, extra) in enumerate(variants):
            cal, frames = calibrate(folder, urdf, train, f"v{k}", *extra)
            rows.append((label, *held_out(cal, frames, q_train, q_valid, names)))
        if args.variants:
            # the floor: both days fitted together, the plane through every touch, judged on
            # the second day's touches in sample: what the chain model can explain at best
            both = folder / "both_days.csv"
            write_joint_csv(both, names, np.vstack([q_train, q_valid]))
            q_both = np.vstack([q_train, q_valid])
            cal, frames = calibrate(folder, urdf, both, "both")
            rows.append(("kincal defaults fitted on both days (in sample: the floor)",
                         *held_out(cal, frames, q_both, q_valid, names)))
    print(f"TALOS left sole -> left gripper, flush table touches: {len(q_train)} training "
          f"(2022-10-28), {len(q_valid)} held-out (2022-11-07); held-out RMS")
    width = max(len(label) for label, *_ in rows)
    print(f"| {'model':<{width}} | height [mm] | roll [deg] | pitch [deg] |")
    print(f"|{'-' * (width + 2)}|-------------|------------|-------------|")
    for label, h, r, p in rows:
        print(f"| {label:<{width}} | {h:11.2f} | {r:10.2f} | {p:11.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
