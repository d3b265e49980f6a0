"""TIAGo: write the hand's 6-DoF poses of both motion-capture days as FIGAROH-style pose
files (docs/kinds.md, "Poses as loggers write them").

    python scripts/tiago_pose_files.py ../shared/data/tiago_mocap OUTDIR

Reads the shared TIAGo files at run time (never copied into the repository) and writes OUTDIR/tiago_poses_2021-11-30.csv (training, 37 postures) and
OUTDIR/tiago_poses_2021-11-26.csv (held out, 62): the chain joints, ``x1 y1 z1`` (marker 1,
as measured) and ``phix1 phiy1 phiz1``, the orientation of the marker body in radians as
FIGAROH writes it (R = Rz(phiz) Ry(phiy) Rx(phix): kincal's ``--orientation-format
rpy-zyx``). The body is fitted once on the training day (generalised Procrustes, as in
scripts/tiago_poses.py) and each posture's rotation is the Kabsch fit of the four markers
to it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tiago_poses import fit_body, markers, poses  # noqa: E402

from kincal.measurements.csv_table import read_columns  # noqa: E402

JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))


def rpy_zyx(R: np.ndarray) -> np.ndarray:
    """(N, 3) angles (about x, y, z) with R = Rz Ry Rx [rad]."""
    return np.column_stack([np.arctan2(R[:, 2, 1], R[:, 2, 2]),
                            np.arctan2(-R[:, 2, 0], np.hypot(R[:, 2, 1], R[:, 2, 2])),
                            np.arctan2(R[:, 1, 0], R[:, 0, 0])])


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
