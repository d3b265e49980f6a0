"""The TIAGo motion-capture files: where they are and what they hold (for the scripts).

They are read in place from ``../shared/data/tiago_mocap`` (or ``DIR/data/tiago_mocap``
for a shared folder DIR given on the command line), never copied into the repository;
see the README there.
"""

from __future__ import annotations

from pathlib import Path

DEFAULT_SHARED = Path(__file__).resolve().parents[2] / "shared"
SUBDIR = Path("data") / "tiago_mocap"
URDF = "tiago_48_schunk.urdf"
TRAIN = "qualisys_2021-11-30_static_postures.csv"  # the training (calibration) day
HELD_OUT = "qualisys_2021-11-26_static_postures.csv"  # another day, for reporting only
TIP = "wrist_ft_tool_link"
ORDER_COLUMN = "t_start_robot"  # acquisition order, for the approach directions (backlash)


def locate(shared: str | Path | None = None) -> tuple[Path, list[str]]:
    """(the data folder, the names of the files missing from it)."""
    d = (Path(shared) if shared else DEFAULT_SHARED) / SUBDIR
    return d, [f for f in (URDF, TRAIN, HELD_OUT) if not (d / f).is_file()]
