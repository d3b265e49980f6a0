"""The command line's measurement files: the kinds' options, reading every data file of a
command as its kind (points, poses, distances, plane contacts), ``simulate --kind``."""

from __future__ import annotations

import math

import numpy as np

from kincal.errors import OptionError


def add_kind_options(p) -> None:
    """Options of the kinds, for commands that read data files."""
    p.add_argument("--orientation-columns", nargs=4, metavar=("QX", "QY", "QZ", "QW"),
                   help="quaternion columns of a pose file (default qx qy qz qw, scalar last)")
    p.add_argument("--orientation-sigma-deg", type=float,
                   help="orientation noise of pose files [deg] (default 0.01, against the "
                        "position sigma, 0.05 mm unless a sigma column says otherwise)")
    p.add_argument("--set-sigma-mm", nargs="+", type=float, metavar="S",
                   help="noise of each data file [mm] (position or distance), one per file in "
                        "order: weighs the files against each other (default: a 'sigma' "
                        "column, else 0.05 mm)")
    p.add_argument("--on-plane", action="store_true",
                   help="files with joint columns only are plane contacts (a 'plane' column "
                        "names each row's plane)")
    p.add_argument("--flush", action="store_true",
                   help="with --on-plane: each contact is a flat face pressed flush on the "
                        "plane (its height and two tilts; optional 'sigma' [length] and "
                        "'sigma_deg' columns, tilt noise --orientation-sigma-deg)")


def files_of(args) -> list:
    return [args.data] + list(getattr(args, "more_data", None) or [])


def read_sets(args, robot, joint_columns=None) -> list:
    """Every data file of the command, each read as its kind (joint_columns: the
    --joint-columns mapping)."""
    from kincal.measurements.sets import read_set_file

    prismatic = [n for n, k in zip(robot.joint_names, robot.geometry.kinds) if k == "prismatic"]
    pos = tuple(args.position_columns) if tuple(args.position_columns) != ("x", "y", "z") else None
    if args.flush and not args.on_plane:
        raise OptionError("--flush describes plane contacts: give it with --on-plane")
    sets = [read_set_file(path, robot.joint_names, prismatic, args.length_unit,
                          args.angle_unit, pos, args.orientation_columns, args.on_plane,
                          args.orientation_sigma_deg, joint_columns, args.order_column,
                          flush=args.flush)
            for path in files_of(args)]
    if args.set_sigma_mm:
        from dataclasses import replace

        if len(args.set_sigma_mm) != len(sets) or min(args.set_sigma_mm) <= 0:
            raise OptionError(f"--set-sigma-mm takes one positive value per data file: "
                              f"{len(sets)} files, got {args.set_sigma_mm}")
        from kincal.measurements.kind import SIGMA_RANGE_M

        lo, hi = SIGMA_RANGE_M
        for s in args.set_sigma_mm:
            if not (math.isfinite(s) and lo <= s * 1e-3 <= hi):
                raise OptionError(f"--set-sigma-mm {s:g} is outside the accepted range "
                                  f"{lo * 1e3:g} mm to {hi * 1e3:g} mm (a file's measurement "
                                  "noise)")
        sets = [replace(d, sigma=np.full(len(d), s * 1e-3))
                for d, s in zip(sets, args.set_sigma_mm)]
    return sets


def simulate(args, robot, model, q, table, tool, base, rng) -> list:
    """(path, text) of a simulated set of kind ``args.kind`` (not points) at poses q."""
    from kincal.measurements.sets import to_csv_text
    from kincal.planning import kind_simulation as ks

    noise = args.noise_mm * 1e-3
    if args.kind == "pose":
        data = ks.simulate_poses(model, table, base, np.r_[tool, 0.0, 0.0, 0.0], q, noise,
                                 args.orientation_noise_deg, rng, source="simulated")
    elif args.kind == "distance":
        pivot = np.mean(ks.tool_points(model, table, q, tool), axis=0) + [0.0, 0.0, -0.3]
        data = ks.simulate_distances(model, table, pivot, tool, q, noise, rng, source="simulated")
    else:  # three planes through the middle of the poses' tool points: a table, two walls
        c = np.mean(ks.tool_points(model, table, q, tool), axis=0)
        planes = np.array([[0.0, 0.0, c[2]], [0.0, math.pi / 2, c[0]],
                           [-math.pi / 2, 0.0, c[1]]])
        g = robot.geometry
        lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
        hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
        cand = np.vstack([q, rng.uniform(lo, hi, size=(40 * len(q), g.n))])
        per = max(3, len(q) // 3)
        data = ks.simulate_contacts(model, table, tool, planes, cand, per, noise, rng,
                                    source="simulated")
    return [(args.out, to_csv_text(data))]
