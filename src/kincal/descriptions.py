"""Where robot descriptions come from: a URDF path, a bundled robot, or example-robot-data.

The example-robot-data wheel (6.x) installs its URDFs under its cmeel prefix and has
no Python loader, so the files are located on disk here.
"""

from __future__ import annotations

import importlib.resources
from dataclasses import dataclass
from pathlib import Path

from kincal.errors import InputFileError, listing, suggest


@dataclass(frozen=True)
class Description:
    """A robot description on disk.

    name: short name (``"ur10"``) or the file name for a user's URDF.
    urdf: path of the URDF file.
    default_tip: the usual tip frame of the arm, if known.
    """

    name: str
    urdf: Path
    default_tip: str | None = None


# short name -> (path below the robots/ folder of example-robot-data, usual tip frame)
_ERD: dict[str, tuple[str, str | None]] = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", "tool0"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_link8"),
    "tiago": ("tiago_description/robots/tiago.urdf", "arm_tool_link"),
    "tiago_no_hand": ("tiago_description/robots/tiago_no_hand.urdf", "arm_tool_link"),
    "kinova": ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector"),
    "z1": ("z1_description/urdf/z1.urdf", None),
    "so100": ("so_arm_description/urdf/so100.urdf", None),
    "so101": ("so_arm_description/urdf/so101.urdf", None),
    "talos_left_arm": ("talos_data/robots/talos_left_arm.urdf", None),
    "talos": ("talos_data/robots/talos_full_v2.urdf", "gripper_left_base_link"),
}

_BUNDLED: dict[str, tuple[str, str | None]] = {"ec66": ("ec66.urdf", "flange")}

# centre [m] of a measurement cube in each arm's base frame that the arm reaches with
# the tool pointing down (used by 'kincal simulate' when no --center-m is given), and the
# largest tracker-like cube edge [m] where the usual 400 mm is too much for a small arm
# (each checked with seeds 0-9 of 'kincal simulate ROBOT')
_CENTERS = {"ec66": (0.4, 0.0, 0.25), "ur3": (0.25, 0.05, 0.2), "ur5": (0.4, 0.1, 0.3),
            "ur10": (0.6, 0.2, 0.4), "panda": (0.45, 0.0, 0.3)}
_MAX_CUBE = {"ur3": 0.2}


def erd_robots_dir() -> Path | None:
    """The robots/ folder of the installed example-robot-data, or None."""
    import importlib.metadata  # here: the bundled robots never need it (15 ms of start-up)

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    path = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    return path if path.is_dir() else None


def known_names() -> list[str]:
    return sorted(_BUNDLED) + sorted(_ERD)


def resolve(robot: str | Path) -> Description:
    """A Description for a URDF path, a bundled robot (``ec66``) or an example-robot-data name."""
    text = str(robot)
    if text in _BUNDLED:
        fname, tip = _BUNDLED[text]
        path = Path(str(importlib.resources.files("kincal.urdf").joinpath(fname)))
        return Description(text, path, tip)
    if text in _ERD:
        root = erd_robots_dir()
        if root is None:
            raise InputFileError(
                f"robot {text!r} comes from example-robot-data, which is not installed; "
                "install it with 'pip install example-robot-data' or give a URDF path"
            )
        rel, tip = _ERD[text]
        return Description(text, root / rel, tip)
    path = Path(text).expanduser()
    looks_like_path = path.suffix != "" or "/" in text or "\\" in text
    if path.exists() or looks_like_path:
        if not path.exists():
            raise InputFileError(f"URDF file not found: {text}")
        if path.is_dir():
            raise InputFileError(f"expected a URDF file, got a directory: {text}")
        return Description(path.name, path, None)
    raise InputFileError(
        f"unknown robot {text!r}: give a URDF path or one of {listing(known_names())}."
        + suggest(text, known_names())
    )


def portable(robot: str | Path) -> str:
    """``robot`` as a process with another working folder (a fleet's worker) resolves it
    to the same description: a bundled or example-robot-data name unchanged (names come
    first in :func:`resolve`, whatever files the folder holds), a user's path absolute."""
    text = str(robot)
    if text in _BUNDLED or text in _ERD:
        return text
    import os

    path = Path(text).expanduser()
    return os.path.abspath(path) if path.exists() else text


def default_center(name: str) -> tuple[float, float, float]:
    """A reachable measurement-cube centre [m] for a known robot name."""
    from kincal.errors import OptionError

    if name not in _CENTERS:
        raise OptionError(f"no default cube centre for robot {name!r}; give --center-m X Y Z "
                          f"(metres, base frame). Known: {listing(sorted(_CENTERS))}")
    return _CENTERS[name]


def max_cube(name: str, size: float) -> float:
    """``size`` [m], or less for a small arm that cannot reach a cube that large."""
    return min(size, _MAX_CUBE.get(name, size))
