"""The command line for measurement kinds other than points and for several data files:
``calibrate``, ``analyze`` and ``evaluate`` over a list of sets, ``simulate --kind``.

Thin shells over :mod:`kincal.identification.multiset`; :mod:`kincal.cli.main` hands a
command here when it is given several files, ``--on-plane``, or a file of another kind.
"""

from __future__ import annotations

import json
import math

import numpy as np

from kincal.errors import DataError, OptionError


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


def files_of(args) -> list:
    return [args.data] + list(getattr(args, "more_data", None) or [])


def read_sets(args, robot) -> list:
    """Every data file of the command, each read as its kind."""
    from kincal.cli.main import _joint_columns
    from kincal.measurements.sets import read_set_file

    prismatic = [n for n, k in zip(robot.joint_names, robot.geometry.kinds) if k == "prismatic"]
    pos = tuple(args.position_columns) if tuple(args.position_columns) != ("x", "y", "z") else None
    sets = [read_set_file(path, robot.joint_names, prismatic, args.length_unit,
                          args.angle_unit, pos, args.orientation_columns, args.on_plane,
                          args.orientation_sigma_deg, _joint_columns(args), args.order_column)
            for path in files_of(args)]
    if args.set_sigma_mm:
        from dataclasses import replace

        if len(args.set_sigma_mm) != len(sets) or min(args.set_sigma_mm) <= 0:
            raise OptionError(f"--set-sigma-mm takes one positive value per data file: "
                              f"{len(sets)} files, got {args.set_sigma_mm}")
        sets = [replace(d, sigma=np.full(len(d), s * 1e-3))
                for d, s in zip(sets, args.set_sigma_mm)]
    return sets


def wants_sets(args) -> bool:
    """True when the command must go through the several-sets path: more than one file,
    --on-plane, or a file that is not points."""
    from kincal.measurements.sets import header_of
    from kincal.measurements.pose import QUATERNION_COLUMNS

    if (getattr(args, "more_data", None) or args.on_plane or args.orientation_columns
            or args.set_sigma_mm):
        return True
    header = header_of(args.data)
    return "distance" in header or all(c in header for c in QUATERNION_COLUMNS)


def _refuse(args, options: tuple[str, ...]) -> None:
    for name in options:
        if getattr(args, name, None):
            raise OptionError(f"--{name.replace('_', '-')} is not available with several data "
                              "files or with pose, distance or plane files yet")


def calibrate(args) -> int:
    from kincal.cli.main import _options, _robot
    from kincal.export import report
    from kincal.export.safe_write import write_all
    from kincal.identification.multiset import MultiSetProblem

    _refuse(args, ("plots", "add_frames", "report", "robust", "html", "accuracy_map",
                   "accuracy_poses"))
    robot = _robot(args)
    sets = read_sets(args, robot)
    problem = MultiSetProblem(robot, sets, _options(args, args.method))
    result = problem.solve()
    from kincal.errors import KincalError, KincalWarning
    from kincal.identification.plausibility import gather_sets, judge

    verdict = judge(gather_sets(problem, result))  # the gate: nothing written if implausible
    try:
        accepted = verdict.check(args.accept_implausible, args.accept_unconverged,
                                 refused="nothing is written")
    except KincalError:
        if not args.quiet:
            print(result.summary())
        raise
    import warnings

    for message in accepted + list(verdict.notes):
        warnings.warn(message, KincalWarning)
    files = [(args.out, result.corrected_urdf_text())]
    if args.yaml_out or args.mdh_out:  # the corrected robot, whatever measured it
        from kincal.export.cell_exports import kinematics_yaml, mdh_table_csv

        if args.yaml_out:
            files.append((args.yaml_out, kinematics_yaml(robot, result.corrected)))
        if args.mdh_out:
            files.append((args.mdh_out, mdh_table_csv(result.corrected)))
    if args.frames_out:
        files.append((args.frames_out, report.dumps({"format": "kincal-frames-sets-1",
                                                     "tip": robot.tip, "base": robot.base,
                                                     **result.frames_dict()})))
    written = write_all(files, overwrite=args.overwrite, protect=[robot.source, *files_of(args)])
    if not args.quiet:
        print(result.summary())
        for path in written:
            print(f"  wrote {path}")
    return 0


def analyze(args) -> int:
    from kincal.cli.main import _robot, _tool_offset
    from kincal.identification.multiset import MultiSetProblem
    from kincal.identification.options import CalibrationOptions

    _refuse(args, ("report", "accuracy_map", "accuracy_poses", "accuracy_plot"))
    robot = _robot(args)
    models = [args.model] if args.model != "all" else None
    if models is None:
        raise OptionError("--model all is not available with pose, distance or plane files yet")
    problem = MultiSetProblem(robot, read_sets(args, robot), CalibrationOptions(
        model=args.model, fix=tuple(args.fix), backlash=tuple(args.backlash),
        tool_guess=_tool_offset(args)))
    kinds = ", ".join(f"{km.kind} ({km.data.source}, {km.N} samples)" for km in problem.kinds)
    print(f"kincal analysis of {robot.name} ({robot.base} -> {robot.tip}), error model "
          f"{args.model}: {kinds}")
    print("  " + problem.analyze().summary().replace("\n", "\n  "))
    return 0


def evaluate(args) -> int:
    from kincal.cli.main import _robot, _tool_offset
    from kincal.identification.multiset import MultiSetProblem
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.statistics import ErrorStats

    _refuse(args, ("report", "accuracy_map", "accuracy_poses", "accuracy_plot"))
    if bool(args.frames) == bool(args.fit_frames):
        raise OptionError("give exactly one of --frames FRAMES.json or --fit-frames")
    robot = _robot(args)
    sets = read_sets(args, robot)
    problem = MultiSetProblem(robot, sets, CalibrationOptions(method="frames",
                                                              tool_guess=_tool_offset(args)))
    if args.fit_frames:
        x = problem.solve().x
        how = "frames fitted on these data"
    else:
        x = problem.x_nominal
        try:
            saved = json.loads(open(args.frames, encoding="utf-8").read())["sets"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise DataError(f"{args.frames}: not a FRAMES.json of a calibration from several "
                            f"sets or of pose, distance or plane files ({exc})") from None
        for i, km in enumerate(problem.kinds):
            match = [s for s in saved if s.get("kind") == km.kind
                     and tuple(s.get("frames", {})) == tuple(km.frame_names)]
            if not match:
                raise DataError(f"{args.frames} has no {km.kind} set with frames "
                                f"{', '.join(km.frame_names)} for {km.data.source}")
            x[problem.frame_slices[i]] = [match[0]["frames"][n] for n in km.frame_names]
        how = f"frames from {args.frames}"
    print(f"{robot.name} ({robot.base} -> {robot.tip}), {how}:")
    for i, e in problem.sample_errors(x):
        km = problem.kinds[i]
        print(f"  {km.kind} {km.data.source}: {ErrorStats.from_errors(e).line()}")
    return 0


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
