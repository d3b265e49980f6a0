"""TIAGo: write the hand's 6-DoF poses of both motion-capture days as FIGAROH-style pose
files (docs/kinds.md, "Poses as loggers write them").

    python scripts/tiago_pose_files.py ../shared/data/tiago_mocap OUTDIR [--score]

Reads the shared TIAGo files at run time (never copied into the repository) and writes
OUTDIR/tiago_poses_2021-11-30.csv (training, 37 postures) and
OUTDIR/tiago_poses_2021-11-26.csv (held out, 62): the chain joints, ``x1 y1 z1`` (marker 1,
as measured) and ``phix1 phiy1 phiz1``, the orientation of the marker body in radians as
FIGAROH writes it (R = Rz(phiz) Ry(phiy) Rx(phix): kincal's ``--orientation-format
rpy-zyx``), rows in acquisition order (the approach directions of backlash terms). The
body is fitted once on the training day (generalised Procrustes, as in
scripts/tiago_poses.py) and each posture's rotation is the Kabsch fit of the four markers
to it.

``--score`` then runs kincal's default (``--model auto``, lambda chosen automatically) on
the training file, with the noise the data state (:data:`NOISE`), and scores it on the
held-out day twice with ``kincal evaluate``: frames from training, and only the measurement
frame refitted (the marker body kept). It prints held-out position and orientation beside
FIGAROH's published figures on the same split (position only; FIGAROH publishes no
orientation error): about 10 s.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tiago_poses import fit_body, markers, poses  # noqa: E402

from kincal.measurements.csv_table import read_columns  # noqa: E402

JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
# the noise the data state: marker_std_mm's median (0.2 mm) and, for the orientation, that
# over the marker body's RMS radius (84 mm: 0.14 deg), as scripts/tiago_poses.py prints
NOISE = ("--set-sigma-mm", "0.2", "--orientation-sigma-deg", "0.14")
READ = ("--position-columns", "x1", "y1", "z1", "--orientation-format", "rpy-zyx")
# FIGAROH 1.0.2, marker 1, full 6-D joint placement errors + frames: held-out RMS / mean /
# max [mm] (the data's README)
FIGAROH_MM = (3.22, 2.67, 12.23)


def rpy_zyx(R: np.ndarray) -> np.ndarray:
    """(N, 3) angles (about x, y, z) with R = Rz Ry Rx [rad]."""
    return np.column_stack([np.arctan2(R[:, 2, 1], R[:, 2, 2]),
                            np.arctan2(-R[:, 2, 0], np.hypot(R[:, 2, 1], R[:, 2, 2])),
                            np.arctan2(R[:, 1, 0], R[:, 0, 0])])


def score(data: Path, out: Path) -> int:
    """Calibrate on the training file, evaluate on the held-out one; print the table."""
    import json

    from kincal.cli.main import main as kincal
    from kincal.identification.model_choice import label

    train, test = out / "tiago_poses_2021-11-30.csv", out / "tiago_poses_2021-11-26.csv"
    urdf, frames = out / "tiago_pose.urdf", out / "tiago_pose.json"
    code = kincal(["calibrate", str(data / "tiago_48_schunk.urdf"), str(train), "--tip",
                   "wrist_ft_tool_link", *READ, *NOISE, "--out", str(urdf), "--frames-out",
                   str(frames), "--report", str(out / "calibration.json"), "--overwrite",
                   "-q"])
    if code:
        return code
    rows = []
    for how, extra in (("frames from training", ()),
                       ("measurement frame refitted", ("--fit-frames", "measurement"))):
        report = out / f"evaluation_{len(rows)}.json"
        code = kincal(["evaluate", str(urdf), str(test), *READ, *NOISE, "--frames",
                       str(frames), *extra, "--report", str(report), "--overwrite", "-q"])
        if code:
            return code
        r = json.loads(report.read_text())
        rows.append((how, r["errors"], r["orientation_errors"]))
    choice = json.loads((out / "calibration.json").read_text())["model_choice"]["chosen"]
    model = label(choice["model"], choice["backlash"], choice["compliance"])
    print(f"kincal default on the training day (model chosen: {model}), held out on "
          f"26 Nov (62 postures):")
    print(f"{'':36s} {'position RMS / mean / max [mm]':>31s}  orientation RMS / mean / max "
          "[deg]")
    for how, p, o in rows:
        print(f"{'kincal, ' + how:36s} {p['rms_mm']:9.3f} / {p['mean_mm']:6.3f} / "
              f"{p['max_mm']:6.3f}   {o['rms_deg']:8.3f} / {o['mean_deg']:6.3f} / "
              f"{o['max_deg']:6.3f}")
    r, m, x = FIGAROH_MM
    print(f"{'FIGAROH 1.0.2, frames from training':36s} {r:9.2f} / {m:6.2f} / {x:6.2f}"
          f"   {'not published':>24s}")
    # the weight of the orientation rows against the position rows: the stated noise
    # ratio, and the ratio the training residuals show after the fit
    after = json.loads((out / "calibration.json").read_text())["sets"][0]
    p, o = after["errors"]["after"]["rms_mm"], after["orientation_errors"]["after"]["rms_deg"]
    stated = float(NOISE[1]) / float(NOISE[3])
    print(f"orientation weight: stated {NOISE[1]} mm / {NOISE[3]} deg = {stated:.2f} mm per "
          f"deg; training residuals after the fit {p:.3f} mm / {o:.3f} deg RMS = "
          f"{p / o:.2f} mm per deg")
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    scoring = "--score" in argv
    argv = [a for a in argv if a != "--score"]
    if len(argv) != 2:
        print(__doc__)
        return 2
    data = Path(argv[0])
    train = data / "qualisys_2021-11-30_static_postures.csv"
    test = data / "qualisys_2021-11-26_static_postures.csv"
    if not train.exists():
        print(f"no data at {data}")
        return 1
    out = Path(argv[1])
    out.mkdir(parents=True, exist_ok=True)
    body = fit_body(markers(train))
    for path in (train, test):
        M = markers(path)
        _, R, _ = poses(M, body)
        v = read_columns(path, JOINTS).values
        table = np.hstack([np.column_stack([v[j] for j in JOINTS]), M[:, 0], rpy_zyx(R)])
        name = out / f"tiago_poses_{path.name.split('_')[1]}.csv"
        header = list(JOINTS) + ["x1", "y1", "z1", "phix1", "phiy1", "phiz1"]
        name.write_text(",".join(header) + "\n" + "".join(
            ",".join(repr(float(x)) for x in row) + "\n" for row in table))
        print(f"wrote {name} ({len(table)} poses)")
    return score(data, out) if scoring else 0


if __name__ == "__main__":
    raise SystemExit(main())
