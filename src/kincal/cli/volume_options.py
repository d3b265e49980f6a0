"""The command-line options of a measurement volume (``kincal plan`` and ``kincal simulate``).

``--in-cube``/``--in-sphere``, ``--max-tilt``, ``--tilt-direction``, ``--floor``/``--no-floor``
and (plan) ``--home`` become a :class:`kincal.planning.volume_candidates.VolumeSpec`.
"""

from __future__ import annotations

import math

from kincal.errors import OptionError


def volume_spec(args, robot, unit: float, tool, default_tilt: float = 30.0):
    """A VolumeSpec from --in-cube/--in-sphere, --max-tilt, --tilt-direction, --home, --floor
    (lengths in ``unit`` [m per unit], --home in the plan's joint units), or None.
    default_tilt: [deg] when --max-tilt is not given."""
    from kincal.planning.volume_candidates import Volume, VolumeSpec

    if args.in_cube is not None and args.in_sphere is not None:
        raise OptionError("give at most one of --in-cube and --in-sphere")
    if args.in_cube is None and args.in_sphere is None:
        for flag in ("max_tilt", "tilt_direction", "home"):
            if getattr(args, flag, None) is not None:
                raise OptionError(f"--{flag.replace('_', '-')} needs a volume: --in-cube or --in-sphere")
        return None
    c = args.in_cube if args.in_cube is not None else args.in_sphere
    make = Volume.cube if args.in_cube is not None else Volume.sphere
    volume = make([v * unit for v in c[:3]], c[3] * unit)
    home = None
    if getattr(args, "home", None) is not None:
        angle = math.radians(1.0) if getattr(args, "angle_unit", "rad") == "deg" else 1.0
        if len(args.home) != len(robot.joint_names):
            raise OptionError(f"--home needs {len(robot.joint_names)} values "
                              f"({', '.join(robot.joint_names)}), got {len(args.home)}")
        home = [v * (unit if k == "prismatic" else angle)
                for v, k in zip(args.home, robot.geometry.kinds)]
    floor = None if args.no_floor else args.floor * unit
    return VolumeSpec(volume, tuple(tool), math.radians(default_tilt if args.max_tilt is None
                                                        else args.max_tilt),
                      tuple(args.tilt_direction or (0.0, 0.0, -1.0)), home, floor)


def add_volume_options(p, unit_help):
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
    p.add_argument("--floor", type=float, default=0.0, metavar="Z",
                   help=f"height of the floor in the base frame ({unit_help}; default 0): no "
                        "link may go below it")
    p.add_argument("--no-floor", action="store_true", help="no floor check")
