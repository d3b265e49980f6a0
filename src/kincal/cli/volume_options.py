"""The command-line options of a measurement volume (``kincal plan`` and ``kincal simulate``).

``--in-cube``/``--in-sphere``, ``--max-tilt``, ``--tilt-direction``,
``--floor``/``--no-floor``, ``--no-collision`` and (plan) ``--home`` become a
:class:`kincal.planning.volume_candidates.VolumeSpec`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kincal.cli.options import angle_scale, group, typed
from kincal.errors import OptionError


@dataclass(frozen=True)
class VolumeRequest:
    """The volume options as given (lengths in the command's unit, angles in degrees)."""

    in_cube: tuple[float, float, float, float] | None = None  # CX CY CZ EDGE
    in_sphere: tuple[float, float, float, float] | None = None  # CX CY CZ R
    max_tilt: float | None = None  # [deg]
    tilt_direction: tuple[float, float, float] | None = None
    floor: float = 0.0  # height of the floor in the base frame
    no_floor: bool = False
    no_collision: bool = False  # no self-collision check (meshes not loaded)
    home: tuple[float, ...] | None = None  # plan only: joint values in the plan's units
    angle_unit: str = "rad"  # of --home

    @classmethod
    def of(cls, args) -> "VolumeRequest":
        return typed(cls, args)

    @property
    def given(self) -> bool:
        return self.in_cube is not None or self.in_sphere is not None


def volume_spec(request: VolumeRequest, robot, unit: float, tool, default_tilt: float = 30.0):
    """A VolumeSpec from --in-cube/--in-sphere, --max-tilt, --tilt-direction, --home, --floor,
    --no-collision (lengths in ``unit`` [m per unit], --home in the plan's joint units), or None.
    default_tilt: [deg] when --max-tilt is not given."""
    from kincal.planning.volume_candidates import Volume, VolumeSpec

    if request.in_cube is not None and request.in_sphere is not None:
        raise OptionError("give at most one of --in-cube and --in-sphere")
    if request.in_cube is None and request.in_sphere is None:
        for flag in ("max_tilt", "tilt_direction", "home"):
            if getattr(request, flag, None) is not None:
                raise OptionError(f"--{flag.replace('_', '-')} needs a volume: --in-cube or --in-sphere")
        return None
    c = request.in_cube if request.in_cube is not None else request.in_sphere
    assert c is not None  # one of them, checked above
    make = Volume.cube if request.in_cube is not None else Volume.sphere
    volume = make([v * unit for v in c[:3]], c[3] * unit)
    home = None
    if request.home is not None:
        angle = angle_scale(request.angle_unit)
        if len(request.home) != len(robot.joint_names):
            raise OptionError(f"--home needs {len(robot.joint_names)} values "
                              f"({', '.join(robot.joint_names)}), got {len(request.home)}")
        home = [v * (unit if k == "prismatic" else angle)
                for v, k in zip(request.home, robot.geometry.kinds)]
    floor = None if request.no_floor else request.floor * unit
    x, y, z = (float(v) for v in tool)
    return VolumeSpec(volume, (x, y, z), math.radians(default_tilt if request.max_tilt is None
                                                        else request.max_tilt),
                      request.tilt_direction or (0.0, 0.0, -1.0),
                      None if home is None else tuple(home), floor,
                      self_collision=not request.no_collision)


def add_volume_options(p, unit_help):
    p = group(p, "measurement volume")
    p.add_argument("--in-cube", nargs=4, type=float, metavar=("CX", "CY", "CZ", "EDGE"),
                   help=f"poses with the tool point inside this axis-aligned cube of the base "
                        f"frame ({unit_help})")
    p.add_argument("--in-sphere", nargs=4, type=float, metavar=("CX", "CY", "CZ", "R"),
                   help=f"or inside this sphere ({unit_help})")
    p.add_argument("--max-tilt", type=float, metavar="DEG",
                   help="largest angle of the tip z axis from --tilt-direction (default 30; "
                        "simulate: as --tilt-deg)")
    p.add_argument("--tilt-direction", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="mean direction of the tip z axis in the base frame (default 0 0 -1)")
    p.add_argument("--floor", type=float, metavar="Z",
                   help=f"height of the floor in the base frame ({unit_help}; default 0): no "
                        "link may go below it")
    p.add_argument("--no-floor", action="store_true", help="no floor check")
    p.add_argument("--no-collision", action="store_true",
                   help="no self-collision check: the URDF's collision meshes are not loaded "
                        "(for a URDF whose meshes cannot be found); the tool point and tip "
                        "are still kept above the floor, and the output says so")
