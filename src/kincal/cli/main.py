"""The ``kincal`` command line: a thin shell over the Python API.

``main(argv=None) -> int``. Every subcommand computes everything first and writes its
outputs last, all or none; a KincalError becomes one line on stderr and exit code 1
(usage errors: 2), with no traceback and no file written.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np

from kincal import __version__
from kincal.errors import DataError, InputFileError, KincalError, KincalWarning, OptionError

DEMO_DIR = "kincal-demo"


# ----------------------------------------------------------------- helpers
def _progress_bar(stream=sys.stderr):
    """A progress callback drawing a bar on a terminal, and None elsewhere."""
    if not getattr(stream, "isatty", lambda: False)():
        return None

    def progress(done, total):
        width = 30
        filled = int(width * done / total)
        stream.write(f"\r  cross-validation [{'#' * filled}{'.' * (width - filled)}] "
                     f"{done}/{total} fits")
        if done == total:
            stream.write("\n")
        stream.flush()

    return progress


def _robot(args):
    from kincal.robot import Robot

    return Robot.load(args.robot, tip=args.tip, base=args.base)


def _measurements(args, robot):
    from kincal.measurements.data import Measurements

    prismatic = [n for n, k in zip(robot.joint_names, robot.geometry.kinds) if k == "prismatic"]
    return Measurements.from_csv(args.data, robot.joint_names, prismatic=prismatic,
                                 length_unit=args.length_unit, angle_unit=args.angle_unit,
                                 position_columns=tuple(args.position_columns),
                                 order_column=args.order_column)


def _tool_offset(args):
    if args.tool_offset is None:
        return None
    return tuple(v * (1e-3 if args.length_unit == "mm" else 1.0) for v in args.tool_offset)


def _read_frames(path) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """(base (6,), tool points (K, 3), backlash {joint: value}) in SI from FRAMES.json."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"frames file not found: {path}")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        base = [float(data["base"][k]) for k in ("x", "y", "z", "rx", "ry", "rz")]
        tools = [[float(t[k]) for k in ("x", "y", "z")]
                 for t in data.get("tool_points", [data["tool"]])]
        backlash = {str(j): float(v) for j, v in data.get("backlash", {}).items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise DataError(f"{path}: not a kincal frames file ({exc.__class__.__name__}: {exc}); "
                        'expected {"base": {"x","y","z","rx","ry","rz"}, "tool": {"x","y","z"}} '
                        'and optionally "tool_points": [{"x","y","z"}, ...] and "backlash": '
                        "{joint: value}, in metres and radians") from None
    values = base + [v for t in tools for v in t] + list(backlash.values())
    if not tools or not all(math.isfinite(v) for v in values):
        raise DataError(f"{path}: frames contain a non-finite number or no tool point")
    return np.array(base), np.array(tools), backlash


def _chain_from_frames(args) -> None:
    """Take base and tip from FRAMES.json when not given; refuse a mismatch.

    Frames identified for one chain mean nothing for another: the tool point lives in
    the recorded tip frame, the measurement frame is placed against the recorded base."""
    import json

    path = Path(args.frames)
    if not path.is_file():
        return  # missing, a folder or a device: the frames reader says what is wrong
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return  # _read_frames reports an unreadable file with the expected layout
    if not isinstance(data, dict):
        return
    for role in ("base", "tip"):
        recorded, given = data.get(f"{role}_frame"), getattr(args, role)
        if not isinstance(recorded, str):
            continue  # an older frames file without the chain: nothing to check
        if given is None:
            setattr(args, role, recorded)
        elif given != recorded:
            from kincal.errors import FrameError

            raise FrameError(f"--{role} {given!r} does not match the {role} frame {recorded!r} "
                             f"recorded in {path} (its measurement frame and tool point were "
                             f"identified for {data.get('base_frame')} -> "
                             f"{data.get('tip_frame')}); use --{role} {recorded} or frames "
                             "identified for this chain", valid=(recorded,))


def _add_common(p, data=True):
    p.add_argument("robot", help="URDF path, 'ec66', or an example-robot-data name (ur10, panda, ...)")
    if data:
        p.add_argument("data", help="CSV with the chain joint names and x,y,z")
    p.add_argument("--tip", help="tip frame (link or joint name); default: the robot's usual tip")
    p.add_argument("--base", help="base frame (default: the URDF root link)")
    if data:
        p.add_argument("--length-unit", choices=("m", "mm"), default="m",
                       help="unit of positions and prismatic joints in DATA (default m)")
        p.add_argument("--angle-unit", choices=("rad", "deg"), default="rad",
                       help="unit of revolute joints in DATA (default rad)")
        p.add_argument("--position-columns", nargs="+", default=("x", "y", "z"),
                       metavar="COL", help="names of the position columns: X Y Z, or "
                       "X1 Y1 Z1 X2 Y2 Z2 ... for several points measured at each pose")
        p.add_argument("--order-column", metavar="COL",
                       help="column giving the acquisition order (e.g. a time stamp), for the "
                            "approach directions of backlash terms; default: the row order")
    p.add_argument("--tool-offset", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="initial guess of the tool point in the tip frame, in the length unit")


def _options(args, method):
    from kincal.identification.calibration import CalibrationOptions

    lam = args.lam
    if lam != "cv":
        try:
            lam = float(lam)
        except ValueError:
            raise OptionError(f"--lambda must be 'cv' or a number, got {lam!r}") from None
    return CalibrationOptions(method=method, lam=lam, folds=args.folds, seed=args.seed,
                              fix=tuple(args.fix), free=tuple(args.free),
                              backlash=tuple(args.backlash),
                              tool_guess=_tool_offset(args), robust=args.robust,
                              robust_scale_mm=args.robust_scale_mm, progress=_progress_bar())


def _render_plots(result, out_dir: Path):
    """(path, png bytes) pairs of the calibration plots, rendered away from ``out_dir``.

    Rendering first into a scratch folder keeps the outputs all-or-none: the PNGs go
    to ``out_dir`` in the same transaction as the URDF and the reports.
    """
    import tempfile

    from kincal.export.plots import plot_calibration

    with tempfile.TemporaryDirectory(prefix="kincal-plots-") as tmp:
        paths = plot_calibration(result, Path(tmp))
        pngs = [(out_dir / Path(p).name, Path(p).read_bytes()) for p in paths]
    if not out_dir.exists():
        out_dir.mkdir(parents=True)  # an output folder of its own; files inside are checked
    return pngs


# -------------------------------------------------------------- subcommands
def cmd_calibrate(args) -> int:
    from kincal.export import report
    from kincal.export.safe_write import write_all
    from kincal.identification.calibration import CalibrationProblem

    robot = _robot(args)
    data = _measurements(args, robot)
    result = CalibrationProblem(robot, data, _options(args, args.method)).solve()
    try:  # the plausibility gate: nothing is written for an implausible or unconverged result
        accepted = result.plausibility.check(args.accept_implausible, args.accept_unconverged,
                                             refused="nothing is written")
    except KincalError:
        if not args.quiet:
            print(result.summary())
        raise
    for message in accepted + list(result.plausibility.notes):
        warnings.warn(message, KincalWarning)
    edits, moved = result.export_edits()
    text = result.urdf_with_frames(edits.text) if args.add_frames else edits.text
    files = [(args.out, text)]
    if args.frames_out:
        files.append((args.frames_out, report.dumps(result.frames_dict())))
    if args.report:
        files.append((args.report, report.dumps(report.result_dict(result, str(args.data)))))
    if args.plots:
        files += _render_plots(result, Path(args.plots))
    protect = [robot.source, args.data]
    written = write_all(files, overwrite=args.overwrite, protect=protect)
    if not args.quiet:
        print(result.summary())
        for line in result.identifiability.summary().splitlines()[1:]:
            if line.startswith(("weak", "  the poses")):
                print(f"  {line}")
        for m in moved:
            print(f"  export: {m.describe()}")
        for path in written:
            print(f"  wrote {path}")
    return 0


def cmd_evaluate(args) -> int:
    from kincal.export import report
    from kincal.identification.calibration import CalibrationOptions, CalibrationProblem
    from kincal.identification.statistics import ErrorStats
    from kincal.measurements.point import MeasurementModel

    if bool(args.frames) == bool(args.fit_frames):
        raise OptionError("give exactly one of --frames FRAMES.json or --fit-frames")
    if args.frames:
        _chain_from_frames(args)
    robot = _robot(args)
    data = _measurements(args, robot)
    problem = CalibrationProblem(robot, data, CalibrationOptions(method="frames",
                                                                 tool_guess=_tool_offset(args)))
    if args.frames:
        base, tools, backlash = _read_frames(args.frames)
        data = data.for_chain(robot.joint_names)
        if data.n_points > len(tools):
            raise DataError(f"{args.data} has {data.n_points} measured points per pose, "
                            f"{args.frames} has {len(tools)} tool point(s)")
        try:
            model = MeasurementModel(problem.mdh, data.joint_values, data.approach, backlash,
                                     data.points, len(tools))
        except KincalError as exc:
            raise DataError(f"{args.frames}: {exc}") from None
        x = model.space.join(problem.mdh.table, base, tools,
                             [backlash[j] for j in model.space.backlash])
        stats = ErrorStats.from_errors(data.positions - model.predict(x))
        how = f"frames from {args.frames}"
        if backlash:
            how += (f" with backlash of {', '.join(model.space.backlash)} (approach directions "
                    f"from {data.order_source})")
    else:
        stats = problem.solve().after
        how = "measurement frame and tool point fitted on these data"
    print(f"{robot.name} ({robot.base} -> {robot.tip}) on {args.data}, {how}:")
    print(f"  {stats.line()}")
    if args.report:
        from kincal.export.safe_write import write_all

        write_all([(args.report, report.dumps({"format": "kincal-evaluation-1",
                                               "robot": str(robot.source), "data": str(args.data),
                                               "frames": how, "errors": report.stats_dict(stats)}))],
                  overwrite=args.overwrite, protect=[robot.source, args.data])
    return 0


def cmd_analyze(args) -> int:
    from kincal.export import report
    from kincal.identification.calibration import CalibrationOptions, CalibrationProblem

    robot = _robot(args)
    data = _measurements(args, robot)
    problem = CalibrationProblem(robot, data, CalibrationOptions(
        fix=tuple(args.fix), backlash=tuple(args.backlash), tool_guess=_tool_offset(args)))
    ident = problem.analyze()
    print(f"{robot.name} ({robot.base} -> {robot.tip}), {len(data)} poses from {args.data}")
    print(ident.summary())
    for k, tool in enumerate(problem.space.tools(problem.start()), start=1):
        which = "tool point" if problem.space.n_points == 1 else f"measured point {k}"
        print(f"  {which} (first estimate, tip frame): {np.round(tool * 1e3, 3).tolist()} mm")
    if args.report:
        from kincal.export.safe_write import write_all

        write_all([(args.report, report.dumps(report.identifiability_dict(ident)))],
                  overwrite=args.overwrite, protect=[robot.source, args.data])
    return 0


def cmd_simulate(args) -> int:
    from kincal.export.safe_write import write_all
    from kincal.models import mdh
    from kincal.planning import simulation

    robot = _robot(args)
    model = mdh.extract(robot.geometry)
    rng = np.random.default_rng(args.seed)
    design = {"tracker": (0.4, 30.0), "rtest": (0.02, 15.0)}[args.design]
    tilt = args.tilt_deg if args.tilt_deg is not None else design[1]
    tool = np.array(args.tool_m)
    center = args.center_m
    if center is None:
        from kincal.descriptions import default_center

        center = default_center(robot.name)
    if args.size_mm is not None:
        size = args.size_mm * 1e-3
    else:
        from kincal.descriptions import max_cube

        size = max_cube(robot.name, design[0])
    q = simulation.cube_poses(robot, args.poses, center, size, tool, rng,
                              max_tilt=math.radians(tilt))
    # the robot's errors have their own seed, so data sets with different pose seeds
    # (calibration, validation) come from one and the same simulated robot
    table = simulation.planted_table(model, np.random.default_rng(args.truth_seed),
                                     args.length_error_mm * 1e-3,
                                     math.radians(args.angle_error_deg))
    base = np.array(args.base_frame)
    base[3:] = np.radians(base[3:])
    truth = simulation.Truth(table, base, tool)
    data = simulation.measure(model, truth, q, args.noise_mm * 1e-3, rng, source="simulated")
    files = [(args.out, data.to_csv_text())]
    if args.truth_out:
        from kincal.export import report
        from kincal.identification.parameters import ParameterSpace

        sp = ParameterSpace(model.joint_names)
        x, x0 = truth.x(sp), sp.join(model.table, np.zeros(6), np.zeros(3))
        files.append((args.truth_out, report.dumps({
            "format": "kincal-truth-1", "robot": str(robot.source), "seed": args.seed,
            "truth_seed": args.truth_seed,
            "parameters_si": dict(zip(sp.names, x.tolist())),
            "deviations_si": dict(zip(sp.names[:sp.n_kinematic], (x - x0)[:sp.n_kinematic].tolist())),
            "noise_m": args.noise_mm * 1e-3})))
    written = write_all(files, overwrite=args.overwrite, protect=[robot.source])
    print(f"simulated {len(q)} poses of {robot.name} ({args.design}, {size * 1e3:g} mm cube "
          f"at {np.round(center, 3).tolist()} m, noise {args.noise_mm} mm): "
          + ", ".join(str(p) for p in written))
    return 0


def cmd_plan(args) -> int:
    from kincal.export.safe_write import write_all
    from kincal.planning.candidates import candidates_csv_text, random_candidates, read_candidates
    from kincal.planning.pose_selection import select_poses

    if (args.candidates is None) == (args.random is None):
        raise OptionError("give exactly one of CANDIDATES.csv or --random M")
    if not (math.isfinite(args.noise_mm) and args.noise_mm > 0):
        raise OptionError(f"--noise-mm must be a positive number, got {args.noise_mm}")
    robot = _robot(args)
    if args.candidates is not None:
        q, lines = read_candidates(args.candidates, robot, args.length_unit, args.angle_unit)
        source = f"{len(q)} candidates from {args.candidates}"
    else:
        q, lines = random_candidates(robot, args.random, args.seed), None
        source = f"{len(q)} random candidates within the joint limits (seed {args.seed})"
    measured = np.zeros((0, q.shape[1]))
    if args.measured is not None:  # poses already measured: kept, and only new ones written
        measured, _ = read_candidates(args.measured, robot, args.length_unit, args.angle_unit,
                                      kind="measured poses")
        source += f", plus the {len(measured)} poses already measured in {args.measured}"
    k = len(measured)
    tool = _tool_offset(args)
    selection = select_poses(robot, np.vstack([measured, q]), k + args.poses,
                             tool=(0.0, 0.0, 0.0) if tool is None else tool,
                             fix=tuple(args.fix), keep=tuple(range(k)))
    new = [i - k for i in selection.indices if i >= k]
    protect = [robot.source] + [f for f in (args.candidates, args.measured) if f is not None]
    written = write_all([(args.out, candidates_csv_text(
        selection.joint_names, q[new], None if lines is None else lines[new]))],
        overwrite=args.overwrite, protect=protect)
    print(f"{source}:")
    print(selection.summary(args.noise_mm))
    if k:
        print(f"  (the selection includes the {k} poses already measured; {len(new)} new)")
    for path in written:
        print(f"  wrote {path} ({len(new)} new poses, joint values in rad and m)")
    return 0


def cmd_demo(args) -> int:
    from kincal.experiments.paper_experiment import demo

    print("kincal demo: the paper's experiment on a simulated EC66 (one seed, small size)")
    s = demo(Path(args.out), progress=lambda message: print(f"  {message}", flush=True))
    print(f"validation in the 400 mm cube, mean position error [mm] (lambda = {s.lam:.3g}):")
    for label, value in (("before calibration", s.before_validation_mean_mm),
                         ("LS + R-test (20 mm cube)", s.ls_rtest_validation_mean_mm),
                         ("L2 + R-test (20 mm cube)", s.l2_rtest_validation_mean_mm),
                         ("LS + laser tracker", s.ls_tracker_validation_mean_mm)):
        print(f"  {label:<28} {value:8.3f}")
    print(f"wrote {len(s.files)} files to {s.out_dir}/ in {s.elapsed_s:.1f} s:")
    for f in s.files:
        print(f"  {f}")
    return 0


# ------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="kincal", description="Kinematic calibration of serial "
                                 "robots from URDF (MD-H errors, L2 toward nominal, k-fold CV).")
    ap.add_argument("--version", action="version", version=f"kincal {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("calibrate", help="identify the kinematics and write a corrected URDF")
    _add_common(p)
    p.add_argument("--method", choices=("l2", "ls", "frames"), default="l2")
    p.add_argument("--lambda", dest="lam", default="cv", help="'cv' (default) or a value >= 0")
    p.add_argument("--folds", type=int, default=5)
    p.add_argument("--seed", type=int, default=0, help="seed of the CV fold split")
    p.add_argument("--fix", nargs="+", default=[], metavar="NAME", help="parameters held nominal")
    p.add_argument("--free", nargs="+", default=[], metavar="NAME",
                   help="parameters kept even if found redundant (method l2)")
    p.add_argument("--backlash", nargs="+", default=[], metavar="JOINT",
                   help="give these joints a backlash term (needs the acquisition order: "
                        "rows in order, or --order-column)")
    p.add_argument("--robust", choices=("huber", "cauchy"),
                   help="robust loss on the per-pose error; down-weighted samples are listed")
    p.add_argument("--robust-scale-mm", type=float, help="scale of the robust loss [mm] "
                   "(default 2.5 x the median pose error)")
    p.add_argument("--out", required=True, help="corrected URDF to write")
    p.add_argument("--frames-out", help="FRAMES.json: measurement frame and tool point (SI)")
    p.add_argument("--add-frames", action="store_true",
                   help="also add the measurement frame and tool point to the URDF as fixed "
                        "frames (kincal_measurement_frame, kincal_tool_point)")
    p.add_argument("--report", help="REPORT.json: the whole result")
    p.add_argument("--plots", help="directory for PNG plots")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.add_argument("--accept-implausible", action="store_true",
                   help="write the outputs even if the plausibility gate finds the result "
                        "implausible (wrong units, rows, tip or data are the usual causes)")
    p.add_argument("--accept-unconverged", action="store_true",
                   help="write the outputs even if the solver did not converge (best iterate)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("evaluate", help="position errors of a model on a data set")
    _add_common(p)
    p.add_argument("--frames", help="FRAMES.json from 'kincal calibrate --frames-out'")
    p.add_argument("--fit-frames", action="store_true",
                   help="fit the measurement frame and tool point on these data first")
    p.add_argument("--report", help="write the statistics as JSON")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("analyze", help="what the data can identify, without solving")
    _add_common(p)
    p.add_argument("--fix", nargs="+", default=[], metavar="NAME")
    p.add_argument("--backlash", nargs="+", default=[], metavar="JOINT",
                   help="also analyse backlash terms of these joints (see calibrate)")
    p.add_argument("--report", help="write the identifiability report as JSON")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser("simulate", help="a synthetic data set from a robot with planted errors")
    _add_common(p, data=False)
    p.add_argument("--out", required=True, help="CSV to write (SI units)")
    p.add_argument("--design", choices=("tracker", "rtest"), default="tracker",
                   help="tracker: 400 mm cube; rtest: 20 mm cube, varied orientation")
    p.add_argument("--poses", type=int, default=60)
    p.add_argument("--center-m", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="cube centre in the base frame [m]")
    p.add_argument("--size-mm", type=float, help="cube edge [mm] (default: 400 for tracker, "
                   "200 for the small UR3; 20 for rtest)")
    p.add_argument("--tilt-deg", type=float, help="largest tilt of the tool from pointing down")
    p.add_argument("--tool-m", nargs=3, type=float, default=(0.0, 0.0, 0.12),
                   metavar=("X", "Y", "Z"), help="true tool point in the tip frame [m]")
    p.add_argument("--base-frame", nargs=6, type=float, default=(0.8, 0.3, -0.2, 1.0, -2.0, 60.0),
                   metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   help="true measurement frame: x y z [m], rx ry rz [deg]")
    p.add_argument("--length-error-mm", type=float, default=0.3, help="sd of planted length errors")
    p.add_argument("--angle-error-deg", type=float, default=0.03, help="sd of planted angle errors")
    p.add_argument("--noise-mm", type=float, default=0.05, help="sd of position noise per axis")
    p.add_argument("--seed", type=int, default=0, help="seed of the poses and the noise")
    p.add_argument("--truth-seed", type=int, default=0,
                   help="seed of the planted errors: equal seeds, equal robot")
    p.add_argument("--truth-out", help="JSON with the planted parameters")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("plan", help="choose which poses to measure (D-optimal)",
                       description="Choose N of the candidate poses that best determine the "
                       "parameters (D-optimal: largest det of J^T J at the nominal robot). The "
                       "candidates must be safe, reachable and measurable: kincal does not "
                       "check collisions or line of sight.")
    _add_common(p, data=False)
    p.add_argument("candidates", nargs="?", metavar="CANDIDATES.csv",
                   help="CSV with the chain joint columns (no positions needed); or use --random")
    p.add_argument("--random", type=int, metavar="M",
                   help="instead of a CSV: M random candidates uniform within the joint limits")
    p.add_argument("--seed", type=int, default=0, help="seed of --random")
    p.add_argument("--poses", type=int, required=True, metavar="N", help="poses to choose")
    p.add_argument("--measured", metavar="DATA.csv",
                   help="poses already measured (joint columns; other columns ignored): the "
                        "N new poses are chosen to complement them")
    p.add_argument("--out", required=True,
                   help="CSV of the chosen poses: chain joint columns in SI units (rad, m) "
                        "whatever the input units, in the order chosen, and with a CSV of "
                        "candidates their line numbers there (candidate_line)")
    p.add_argument("--length-unit", choices=("m", "mm"), default="m",
                   help="unit of prismatic joints in CANDIDATES and of --tool-offset (default m)")
    p.add_argument("--angle-unit", choices=("rad", "deg"), default="rad",
                   help="unit of revolute joints in CANDIDATES (default rad)")
    p.add_argument("--fix", nargs="+", default=[], metavar="NAME",
                   help="parameters held nominal (left out of the criterion)")
    p.add_argument("--noise-mm", type=float, default=0.05,
                   help="noise per axis [mm] for the predicted standard errors (default 0.05)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("demo", help="the paper's experiment, simulated at a small size")
    p.add_argument("--out", default=DEMO_DIR, help=f"output directory (default {DEMO_DIR})")
    p.set_defaults(func=cmd_demo)
    return ap


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", KincalWarning)
        try:
            code = args.func(args)
        except BrokenPipeError:  # output piped into head & co: stop quietly
            import os

            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            code = 0
        except KincalError as exc:
            message = " ".join(str(exc).split())  # one line
            print(f"kincal: error: {message}", file=sys.stderr)
            code = 1
        finally:
            for w in caught:
                if issubclass(w.category, KincalWarning):
                    print(f"kincal: warning: {w.message}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
