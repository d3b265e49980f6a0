"""The ``kincal`` command line: a thin shell over the Python API.

``main(argv=None) -> int``. Every subcommand computes everything first and writes its
outputs last, all or none; a KincalError becomes one line on stderr and exit code 1
(usage errors: 2), with no traceback and no file written.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np

from kincal import __version__
from kincal.cli.checks import check_args, check_outputs
from kincal.errors import (DataError, KincalError, KincalNote, KincalWarning,
                           OptionError)

DEMO_DIR = "kincal-demo"


# ----------------------------------------------------------------- helpers
def _progress_bar(stream=sys.stderr, label="cross-validation", unit="fits"):
    """A progress callback drawing a bar on a terminal, and None elsewhere."""
    if not getattr(stream, "isatty", lambda: False)():
        return None

    def progress(done, total):
        width = 30
        filled = int(width * done / total)
        stream.write(f"\r  {label} [{'#' * filled}{'.' * (width - filled)}] "
                     f"{done}/{total} {unit}")
        if done == total:
            stream.write("\n")
        stream.flush()

    return progress


class _FitStatus:
    """A solver callback showing the iterations of a long fit on a terminal.

    Quiet for fits that end within ``after`` seconds (most do); a fit of many poses takes
    seconds per iteration, and then says where it is. ``close()`` ends the status line.
    """

    def __init__(self, stream=sys.stderr, after: float = 2.0):
        import time

        self.stream, self.after, self.clock = stream, after, time.perf_counter
        self.t0, self.drawn = self.clock(), False

    @classmethod
    def on_terminal(cls, stream=sys.stderr) -> "_FitStatus | None":
        return cls(stream) if getattr(stream, "isatty", lambda: False)() else None

    def __call__(self, iteration, max_iterations):
        elapsed = self.clock() - self.t0
        if elapsed >= self.after:
            self.stream.write(f"\r  solving: iteration {iteration} (at most {max_iterations}), "
                              f"{elapsed:.1f} s\033[K")
            self.stream.flush()
            self.drawn = True

    def close(self):
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()
            self.drawn = False


def _robot(args):
    from kincal.robot import Robot

    return Robot.load(args.robot, tip=args.tip, base=args.base)


def _joint_column_pair(text: str) -> tuple[str, str]:
    """argparse type of --joint-columns: URDF_NAME=CSV_NAME."""
    urdf, eq, column = text.partition("=")
    if not eq or not urdf.strip() or not column.strip():
        raise argparse.ArgumentTypeError(f"expected URDF_NAME=CSV_NAME, got {text!r}")
    return urdf.strip(), column.strip()


def _joint_columns(args) -> dict[str, str] | None:
    pairs = getattr(args, "joint_columns", None)
    if not pairs:
        return None
    mapping: dict[str, str] = {}
    for urdf, column in pairs:
        if urdf in mapping:
            raise OptionError(f"--joint-columns names joint {urdf} twice")
        mapping[urdf] = column
    return mapping


def _add_joint_columns(p, files="DATA"):
    # "extend": --joint-columns given twice adds to the mapping instead of replacing it
    p.add_argument("--joint-columns", nargs="+", action="extend", type=_joint_column_pair,
                   default=[], metavar="URDF_NAME=CSV_NAME",
                   help=f"read a chain joint from a column of another name in {files} "
                        "(default: the column named as the URDF joint)")


def _tool_offset(args):
    if args.tool_offset is None:
        return None
    return tuple(v * (1e-3 if args.length_unit == "mm" else 1.0) for v in args.tool_offset)


def _chain_from_frames(args, frames) -> None:
    """Take base and tip from FRAMES.json when not given; refuse a mismatch.

    Frames identified for one chain mean nothing for another: the tool point lives in
    the recorded tip frame, the measurement frame is placed against the recorded base."""
    for role in ("base", "tip"):
        recorded, given = getattr(frames, f"{role}_frame"), getattr(args, role)
        if not recorded:
            continue  # an older frames file without the chain: nothing to check
        if given is None:
            setattr(args, role, recorded)
        elif given != recorded:
            from kincal.errors import FrameError

            raise FrameError(f"--{role} {given!r} does not match the {role} frame {recorded!r} "
                             f"recorded in {args.frames} (its frames were identified for "
                             f"{frames.base_frame} -> {frames.tip_frame}); use --{role} "
                             f"{recorded} or frames identified for this chain",
                             valid=(recorded,))


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
        _add_joint_columns(p)
    p.add_argument("--tool-offset", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="initial guess of the tool point in the tip frame, in the length unit")


def _add_kinds(p, several: bool = True):
    """Measurement kinds (poses, distances, plane contacts) and further data files."""
    from kincal.cli.kinds import add_kind_options

    if several:
        p.add_argument("more_data", nargs="*", metavar="MORE.csv",
                       help="further data files, each of its own kind, sharing the robot's "
                            "parameters (set 2, 3, ...: frame parameters set2.base.x, ...)")
    add_kind_options(p)


def _add_model(p, allow_all: bool = False, default: str | None = None, help: str | None = None):
    from kincal.models import DEFAULT, MODELS, SUITS

    choices = MODELS + (("all",) if allow_all else ())
    p.add_argument("--model", choices=choices, default=default or DEFAULT, metavar="NAME",
                   help=help or ("error model: " + "; ".join(f"{k}: {v}" for k, v in SUITS.items())
                                 + ("; all: compare every model" if allow_all else "")))


def _options(args, method):
    from kincal.identification.problem import CalibrationOptions

    lam = args.lam
    if lam not in ("auto", "cv", "evidence"):
        try:
            lam = float(lam)
        except ValueError:
            raise OptionError(f"--lambda must be 'auto', 'cv', 'evidence' or a number, got "
                              f"{lam!r}") from None
    from kincal.identification.solver import SolverOptions

    return CalibrationOptions(model=args.model, method=method, lam=lam, folds=args.folds, seed=args.seed,
                              prior_mm=args.prior_mm, prior_deg=args.prior_deg,
                              noise_mm=args.noise_mm,
                              fix=tuple(args.fix), free=tuple(args.free),
                              backlash=tuple(args.backlash),
                              tool_guess=_tool_offset(args), robust=args.robust,
                              robust_scale_mm=args.robust_scale_mm, progress=_progress_bar(),
                              cv_max_poses=args.cv_max_poses or None,
                              solver=SolverOptions(progress=_FitStatus.on_terminal()))


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
    return pngs  # the folder itself is made by write_all, in the same transaction


def _add_accuracy_options(p):
    p.add_argument("--accuracy-map", nargs=4, type=float, metavar=("CX", "CY", "CZ", "EDGE"),
                   help="predicted accuracy over a cube: centre and edge in the chain's base "
                        "frame, in the length unit; grid points reached by inverse kinematics")
    p.add_argument("--grid", type=int, default=5,
                   help="grid points per edge of the --accuracy-map cube (default 5)")
    p.add_argument("--accuracy-poses", metavar="POSES.csv",
                   help="predicted accuracy at these poses instead (chain joint columns)")


def _accuracy_targets(args, robot) -> dict:
    """Keyword arguments of the accuracy-map functions from --accuracy-map/--accuracy-poses."""
    if args.accuracy_map is not None and args.accuracy_poses is not None:
        raise OptionError("give at most one of --accuracy-map and --accuracy-poses")
    k = 1e-3 if args.length_unit == "mm" else 1.0
    if args.accuracy_map is not None:
        from kincal.planning.accuracy_map import cube_grid

        c = args.accuracy_map
        cube_grid(np.array(c[:3]) * k, c[3] * k, args.grid)  # raises on bad values
        return {"cube": (np.array(c[:3]) * k, c[3] * k), "grid": args.grid}
    if args.accuracy_poses is not None:
        from kincal.planning.candidates import read_candidates

        q, _ = read_candidates(args.accuracy_poses, robot, args.length_unit, args.angle_unit,
                               kind="accuracy poses")
        return {"joint_values": q, "targets": f"the {len(q)} poses of {args.accuracy_poses}"}
    return {}


def _design_accuracy(args, robot, problem):
    """The accuracy map ``kincal analyze`` predicts before solving, or None if not asked."""
    if args.accuracy_map is None and args.accuracy_poses is None:
        if args.accuracy_plot:
            raise OptionError("--accuracy-plot needs --accuracy-map or --accuracy-poses")
        return None
    from kincal.planning.accuracy_map import design_accuracy_map

    if not (math.isfinite(args.noise_mm) and args.noise_mm > 0):
        raise OptionError(f"--noise-mm must be a positive number, got {args.noise_mm}")
    return design_accuracy_map(problem, args.noise_mm * 1e-3, **_accuracy_targets(args, robot))


# -------------------------------------------------------------- subcommands
def cmd_calibrate(args) -> int:
    from kincal.export.outputs import Outputs, gate, write_calibration
    from kincal.identification.problem import CalibrationProblem

    from kincal.cli import kinds

    robot = _robot(args)
    check_outputs(args, robot)
    options = _options(args, args.method)
    sets = kinds.read_sets(args, robot, _joint_columns(args))  # every file, each read as its kind (points too)
    with warnings.catch_warnings(record=True) as caught:  # kept for the HTML report
        warnings.simplefilter("always", KincalWarning)
        targets = _accuracy_targets(args, robot)  # bad values fail here, before solving
        try:
            result = CalibrationProblem(robot, sets, options).solve()
        finally:
            if options.solver.progress is not None:
                options.solver.progress.close()
    for w in caught:  # and passed on to be printed as usual
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    try:  # the plausibility gate, before any further work (write_calibration checks it too)
        gate(result, args.accept_implausible, args.accept_unconverged)
    except KincalError:
        if not args.quiet:
            print(result.summary())
        raise
    amap = None
    if targets or args.html:
        from kincal.planning.accuracy_map import result_accuracy_map

        if result.covariance is not None or targets:
            amap = result_accuracy_map(result, **targets)
    outputs = Outputs(urdf=args.out, frames=args.frames_out, report=args.report, html=args.html,
                      yaml=args.yaml_out, mdh=args.mdh_out, plots=args.plots,
                      add_frames=args.add_frames, overwrite=args.overwrite,
                      protect=tuple(kinds.files_of(args)))
    written = write_calibration(
        result, outputs, accept_implausible=args.accept_implausible,
        accept_unconverged=args.accept_unconverged, accuracy=amap,
        warnings_seen=[str(w.message) for w in caught if issubclass(w.category, KincalWarning)],
        data_source=", ".join(str(f) for f in kinds.files_of(args)))
    if not args.quiet:
        print(result.summary())
        for line in result.identifiability.summary().splitlines()[1:]:
            if line.startswith(("weak", "  the poses")):
                print(f"  {line}")
        for note in written.notes:
            print(f"  export: {note}")
        if amap is not None:
            print("  " + amap.summary().replace("\n", "\n  "))
        for path in written.paths:
            print(f"  wrote {path}")
    return 0


def cmd_evaluate(args) -> int:
    from kincal.export import report
    from kincal.frames_file import CellFrames
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.identification.statistics import ErrorStats

    from kincal.cli import kinds

    if bool(args.frames) == bool(args.fit_frames):
        raise OptionError("give exactly one of --frames FRAMES.json or --fit-frames")
    frames = None
    if args.frames:
        frames = CellFrames.read(args.frames)
        _chain_from_frames(args, frames)
    robot = _robot(args)
    check_outputs(args, robot)
    if frames is not None:
        frames.check_chain(robot)
    sets = kinds.read_sets(args, robot, _joint_columns(args))
    backlash = tuple(frames.backlash) if frames is not None else ()
    # with frames given nothing is fitted: the problem only lays out the parameters
    problem = CalibrationProblem(robot, sets, CalibrationOptions(
        method="frames" if frames is None else "ls", tool_guess=_tool_offset(args),
        backlash=backlash))
    lay = problem.layout
    if frames is None:
        x = problem.solve().x
        how = "measurement frame and tool point fitted on these data"
    else:
        x = problem.x_nominal
        used: set[int] = set()
        for i, km in enumerate(problem.kinds):
            x[lay.frame_slices[i]] = _saved_frames(frames, km, used, args)
        if backlash:
            x[lay.backlash_slice] = [frames.backlash[j] for j in lay.backlash]
        how = f"frames from {args.frames}"
        if backlash:
            how += (f" with backlash of {', '.join(lay.backlash)} (approach directions from "
                    f"{getattr(problem.kinds[0].data, 'order_source', 'the row order')})")
    errors = problem.sample_errors(x)
    stats = [ErrorStats.from_errors(e) for _, e in errors]
    if len(stats) == 1:
        print(f"{robot.name} ({robot.base} -> {robot.tip}) on {args.data}, {how}:")
        print(f"  {stats[0].line()}")
    else:
        print(f"{robot.name} ({robot.base} -> {robot.tip}), {how}:")
        for km, st in zip(problem.kinds, stats):
            print(f"  {km.kind} {km.data.source}: {st.line()}")
    if args.report:
        from kincal.export.safe_write import write_all

        content = {"format": "kincal-evaluation-1", "robot": str(robot.source),
                   "data": str(args.data), "frames": how,
                   "errors": report.stats_dict(stats[0]),
                   "sets": [{"kind": km.kind, "source": km.data.source,
                             "errors": report.stats_dict(st)}
                            for km, st in zip(problem.kinds, stats)]}
        write_all([(args.report, report.dumps(content))], overwrite=args.overwrite,
                  protect=[robot.source, *kinds.files_of(args)])
    return 0


def _saved_frames(frames, km, used: set, args) -> list[float]:
    """The frame values a FRAMES.json holds for a set of ``km``'s kind (the first of that
    kind not used yet); a point set may read fewer tool points than the file has."""
    names = tuple(km.frame_names)
    for j, s in enumerate(frames.sets):
        if j in used or s.kind != km.kind or not all(n in s.names for n in names):
            continue
        used.add(j)
        return [s.value(n) for n in names]
    if km.kind == "point":
        K = km.data.n_points
        for s in frames.sets:
            if s.kind == "point" and s.has("tool.x") and len(s.tools) < K:
                raise DataError(f"{km.data.source} has {K} measured points per pose, "
                                f"{args.frames} has {len(s.tools)} tool point(s)")
    have = "; ".join(f"{s.kind} ({', '.join(s.names[:9])})" for s in frames.sets)
    raise DataError(f"{args.frames} holds no {km.kind} set with frames {', '.join(names)} for "
                    f"{km.data.source} (it holds: {have})")


def cmd_analyze(args) -> int:
    from kincal.export import report
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.models import MODELS
    from kincal.cli import kinds

    robot = _robot(args)
    check_outputs(args, robot)
    sets = kinds.read_sets(args, robot, _joint_columns(args))
    names = MODELS if args.model == "all" else (args.model,)
    if args.model == "all" and args.fix:
        raise OptionError("--model all compares the models as they are: give --fix with one "
                          "model (the parameter names differ between models)")
    problems = {m: CalibrationProblem(robot, sets, CalibrationOptions(
        model=m, fix=tuple(args.fix), backlash=tuple(args.backlash),
        tool_guess=_tool_offset(args))) for m in names}
    if len(sets) == 1 and problems[names[0]].kinds[0].kind == "point":
        print(f"{robot.name} ({robot.base} -> {robot.tip}), {len(sets[0])} poses from {args.data}")
    else:
        print(f"{robot.name} ({robot.base} -> {robot.tip}), error model {args.model}: "
              + ", ".join(f"{km.kind} ({km.data.source}, {km.N} samples)"
                          for km in problems[names[0]].kinds))
    idents = {}
    for m, problem in problems.items():
        ident = idents[m] = problem.analyze()
        if len(names) > 1:
            print(f"\n== model {m}: {problem.error_model.describe()}")
        print(ident.summary())
    problem = problems[names[0]]
    lay = problem.layout
    if problem.kinds[0].kind == "point":
        tools = lay.frames(problem.start(), 0)[6:].reshape(-1, 3)
        for k, tool in enumerate(tools, start=1):
            which = "tool point" if len(tools) == 1 else f"measured point {k}"
            print(f"  {which} (first estimate, tip frame): {np.round(tool * 1e3, 3).tolist()} mm")
    if len(names) > 1:
        print("\ncomparison (identified kinematic parameters; '+' what a model identifies that "
              "mdh cannot express):")
        mdh_kept = set(idents["mdh"].kept)
        for m in names:
            p = problems[m]
            kin = [n for n in idents[m].kept if n in set(p.layout.kinematic_names)]
            extra = [n for n in kin if n not in mdh_kept and m == "complete"]
            line = (f"  {m:<10} {len(kin):3d} of {p.layout.n_kinematic:3d} kinematic parameters "
                    "identified")
            if extra:
                line += f"  (+ {', '.join(extra)})"
            print(line)
    amap = _design_accuracy(args, robot, problem)
    if amap is not None:
        print(amap.summary())
    files = []
    if args.report:
        content = (report.identifiability_dict(idents[names[0]]) if len(names) == 1 else
                   {m: report.identifiability_dict(i) for m, i in idents.items()})
        if amap is not None:
            content["accuracy_map"] = amap.as_dict()
        files.append((args.report, report.dumps(content)))
    if args.accuracy_plot and amap is not None and len(amap.std):
        from kincal.export.diagnostic_plots import plot_accuracy_map

        files.append((args.accuracy_plot, plot_accuracy_map(amap)))
    if files:
        from kincal.export.safe_write import write_all

        write_all(files, overwrite=args.overwrite, protect=[robot.source, *kinds.files_of(args)])
    return 0


def cmd_simulate(args) -> int:
    from kincal.export.safe_write import write_all
    from kincal import models
    from kincal.planning import simulation

    robot = _robot(args)
    check_outputs(args, robot)
    model = models.build(args.model, robot.geometry)
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
    if args.tilt_deg is not None and args.max_tilt is not None:
        raise OptionError("give --max-tilt or --tilt-deg, not both (the same limit)")
    from kincal.cli.volume_options import volume_spec

    spec = volume_spec(args, robot, 1.0, tool, default_tilt=tilt)
    if args.poses_file is not None:
        from kincal.planning.candidates import read_candidates

        if spec is not None:
            raise OptionError("give either --poses-file or a volume (--in-cube/--in-sphere)")
        q, _ = read_candidates(args.poses_file, robot, kind="poses")
        where = f"at the {len(q)} poses of {args.poses_file}"
    elif spec is not None:
        from kincal.planning.volume_candidates import volume_candidates

        q = np.array(volume_candidates(robot, spec, args.poses, seed=args.seed).joint_values)
        where = (f"{args.design}: {spec.volume.describe()}, tilt <= "
                 f"{math.degrees(spec.max_tilt):g} deg, random poses on one branch")
    else:
        q = simulation.cube_poses(robot, args.poses, center, size, tool, rng,
                                  max_tilt=math.radians(tilt),
                                  progress=_progress_bar(label="inverse kinematics", unit="poses")
                                  if args.poses >= 1000 else None)
        where = f"{args.design}: {size * 1e3:g} mm cube at {np.round(center, 3).tolist()} m"
    # the robot's errors have their own seed, so data sets with different pose seeds
    # (calibration, validation) come from one and the same simulated robot
    table = simulation.planted_table(model, np.random.default_rng(args.truth_seed),
                                     args.length_error_mm * 1e-3,
                                     math.radians(args.angle_error_deg))
    base = np.array(args.base_frame)
    base[3:] = np.radians(base[3:])
    if args.kind != "point":
        from kincal.cli import kinds

        if args.truth_out:
            raise OptionError("--truth-out is written for --kind point only")
        written = write_all(kinds.simulate(args, robot, model, q, table, tool, base, rng),
                            overwrite=args.overwrite, protect=[robot.source])
        print(f"simulated {args.kind} measurements of {robot.name} at {len(q)} poses "
              f"({args.design} design), noise {args.noise_mm} mm: "
              + ", ".join(str(p) for p in written))
        return 0
    truth = simulation.Truth(table, base, tool)
    data = simulation.measure(model, truth, q, args.noise_mm * 1e-3, rng, source="simulated")
    files = [(args.out, data.to_csv_text())]
    if args.truth_out:
        from kincal.export import report
        from kincal.measurements.point_space import ParameterSpace

        sp = ParameterSpace.of_model(model)
        x, x0 = truth.x(sp), sp.join(model.nominal, np.zeros(6), np.zeros(3))
        files.append((args.truth_out, report.dumps({
            "format": "kincal-truth-1", "robot": str(robot.source), "seed": args.seed,
            "truth_seed": args.truth_seed,
            "parameters_si": dict(zip(sp.names, x.tolist())),
            "deviations_si": dict(zip(sp.names[:sp.n_kinematic], (x - x0)[:sp.n_kinematic].tolist())),
            "noise_m": args.noise_mm * 1e-3})))
    written = write_all(files, overwrite=args.overwrite, protect=[robot.source])
    print(f"simulated {len(q)} poses of {robot.name} ({where}, noise "
          f"{args.noise_mm} mm): " + ", ".join(str(p) for p in written))
    return 0


def cmd_plan(args) -> int:
    from kincal.export.safe_write import write_all
    from kincal.planning.candidates import candidates_csv_text, random_candidates, read_candidates
    from kincal.planning.pose_selection import select_poses

    volume = args.in_cube is not None or args.in_sphere is not None
    if volume and args.candidates is not None:
        raise OptionError("give either CANDIDATES.csv or a volume (--in-cube/--in-sphere)")
    if not volume and (args.candidates is None) == (args.random is None):
        raise OptionError("give exactly one of CANDIDATES.csv, --random M or --in-cube/--in-sphere")
    if not (math.isfinite(args.noise_mm) and args.noise_mm > 0):
        raise OptionError(f"--noise-mm must be a positive number, got {args.noise_mm}")
    criterion = args.criterion.upper()
    if (criterion == "I") != (args.target_cube is not None):
        raise OptionError("--criterion i needs --target-cube CX CY CZ EDGE, and --target-cube "
                          "is for --criterion i")
    robot = _robot(args)
    check_outputs(args, robot)
    unit = 1e-3 if args.length_unit == "mm" else 1.0
    tool = _tool_offset(args)
    from kincal.cli.volume_options import volume_spec

    spec = volume_spec(args, robot, unit, (0.0, 0.0, 0.0) if tool is None else tool)
    targets = None
    if spec is not None:
        from kincal.planning.volume_candidates import volume_candidates

        m = 2000 if args.random is None else args.random
        if m < args.poses:
            raise OptionError(f"--random {m} candidates are fewer than the {args.poses} poses to "
                              "choose: ask for more candidates or fewer poses")
        vc = volume_candidates(robot, spec, m, seed=args.seed)
        q, lines = np.array(vc.joint_values), None
        source = vc.summary()
    planes = None
    if args.kind == "plane" and args.candidates is not None:  # contacts: a plane column
        from kincal.measurements.plane import PlaneData

        contacts = PlaneData.from_csv(args.candidates, robot.joint_names,
                                      [n for n, k in zip(robot.joint_names, robot.geometry.kinds)
                                       if k == "prismatic"], args.length_unit, args.angle_unit,
                                      joint_columns=_joint_columns(args))
        planes = contacts.planes if contacts.labels != ("",) else None
    if args.kind == "plane" and (args.candidates is None or args.measured is not None):
        raise OptionError("--kind plane plans among contact poses: give CANDIDATES.csv (joint "
                          "columns and a 'plane' column), without --random or --measured")
    if args.candidates is not None:
        q, lines = read_candidates(args.candidates, robot, args.length_unit, args.angle_unit,
                                   joint_columns=_joint_columns(args))
        source = f"{len(q)} candidates from {args.candidates}"
    elif spec is None:
        q, lines = random_candidates(robot, args.random, args.seed), None
        source = f"{len(q)} random candidates within the joint limits (seed {args.seed})"
    measured = np.zeros((0, q.shape[1]))
    if args.measured is not None:  # poses already measured: kept, and only new ones written
        measured, _ = read_candidates(args.measured, robot, args.length_unit, args.angle_unit,
                                      kind="measured poses", joint_columns=_joint_columns(args))
        source += f", plus the {len(measured)} poses already measured in {args.measured}"
    k = len(measured)
    if args.target_cube is not None:
        import dataclasses

        from kincal.planning.volume_candidates import Volume, volume_candidates

        c = args.target_cube
        base_spec = spec if spec is not None else volume_spec(
            argparse.Namespace(**{**vars(args), "in_cube": c}), robot, unit,
            (0.0, 0.0, 0.0) if tool is None else tool)
        tspec = dataclasses.replace(base_spec, volume=Volume.cube([v * unit for v in c[:3]],
                                                                  c[3] * unit),
                                    home=None if spec is None else tuple(vc.home))
        targets = np.array(volume_candidates(robot, tspec, args.target_poses,
                                             seed=args.seed + 1).joint_values)
        source += (f"\n  {len(targets)} target poses in the {tspec.volume.describe()} (same tilt "
                   "range and branch)")
    from kincal.identification.blas_threads import limited

    with limited(1):  # small batched matrices: BLAS threads would only wait for each other
        selection = select_poses(robot, np.vstack([measured, q]), k + args.poses,
                                 tool=(0.0, 0.0, 0.0) if tool is None else tool,
                                 fix=tuple(args.fix), keep=tuple(range(k)), method=criterion,
                                 targets=targets, kind=args.kind,
                                 pivot=None if args.pivot is None else np.array(args.pivot) * (
                                     1e-3 if args.length_unit == "mm" else 1.0), planes=planes)
    new = [i - k for i in selection.indices if i >= k]
    protect = [robot.source] + [f for f in (args.candidates, args.measured) if f is not None]
    written = write_all([(args.out, candidates_csv_text(
        selection.joint_names, q[new], None if lines is None else lines[new]))],
        overwrite=args.overwrite, protect=protect)
    print(f"{source}:")
    print(selection.summary(args.noise_mm, checked=None if spec is None else
                            "candidates checked as above; line of sight is not checked"))
    if k:
        print(f"  (the selection includes the {k} poses already measured; {len(new)} new)")
    for path in written:
        print(f"  wrote {path} ({len(new)} new poses, joint values in rad and m)")
    return 0


def cmd_compensate(args) -> int:
    from kincal.compensation import CellFrames, IkOptions, compensate, filter_program, read_targets
    from kincal.export.safe_write import write_all
    from kincal.planning.candidates import read_candidates

    if (args.targets is None) == (args.program is None):
        raise OptionError("give exactly one of TARGETS.csv or --program PROGRAM.csv")
    if (args.program is None) != (args.nominal is None):
        raise OptionError("--program and --nominal go together: the program's joint values "
                          "were planned on the NOMINAL.urdf model")
    if args.targets is not None and args.frames is None:
        raise OptionError("targets in the measurement frame need --frames FRAMES.json "
                          "(from 'kincal calibrate --frames-out')")
    if not (math.isfinite(args.tolerance_mm) and args.tolerance_mm > 0):
        raise OptionError(f"--tolerance-mm must be a positive number, got {args.tolerance_mm}")
    options = IkOptions(position_tolerance=args.tolerance_mm * 1e-3)
    robot = _robot(args)
    frames = None if args.frames is None else CellFrames.read(args.frames)
    if frames is not None:
        frames.check_chain(robot)  # before reading targets: a wrong file is the likelier error
    if args.program is not None:
        from kincal.robot import Robot

        nominal = Robot.load(args.nominal, tip=args.tip, base=args.base)
        q, lines = read_candidates(args.program, nominal, args.length_unit, args.angle_unit,
                                   kind="program")
        result = filter_program(nominal, robot, q, frames, lines, args.point - 1, options,
                                source=str(args.program))
        inputs = [args.program, nominal.source]
    else:
        targets = read_targets(args.targets, robot, args.length_unit, args.angle_unit,
                               args.position_columns)
        result = compensate(robot, frames, targets, args.point - 1, options, args.length_unit)
        inputs = [args.targets]
    failures = result.failures()
    if failures and not args.flag_unreachable:
        raise DataError(f"{len(failures)} of {len(result)} targets cannot be reached by the "
                        f"calibrated model within {args.tolerance_mm:g} mm: "
                        + "; ".join(failures[:10]) + (" ..." if len(failures) > 10 else "")
                        + "; nothing written; pass --flag-unreachable to write them marked "
                          "reached=0")
    written = write_all([(args.out, result.to_csv_text(args.length_unit, args.angle_unit))],
                        overwrite=args.overwrite,
                        protect=[robot.source, *inputs] + ([args.frames] if args.frames else []))
    print(result.summary())
    for line in failures:
        print(f"  NOT reached, written with reached=0: {line}")
    for path in written:
        print(f"  wrote {path} (joint values in {args.angle_unit} and {args.length_unit}, "
              "as the input)")
    return 0


def cmd_demo(args) -> int:
    from kincal.experiments.paper_report import demo

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
                                 "robots from URDF (MD-H errors, L2 toward nominal, evidence "
                                 "or k-fold CV).")
    ap.add_argument("--version", action="version", version=f"kincal {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("calibrate", help="identify the kinematics and write a corrected URDF")
    _add_common(p)
    _add_kinds(p)
    _add_model(p)
    p.add_argument("--method", choices=("l2", "ls", "frames"), default="l2")
    p.add_argument("--lambda", dest="lam",
                   help="'auto' (default: 'evidence' on data from a small measurement volume, "
                        "'cv' otherwise), 'evidence' (priors toward nominal per parameter "
                        "class, scales and noise by maximum evidence), 'cv' (the paper's "
                        "k-fold CV) or a value >= 0")
    p.add_argument("--prior-mm", type=float, metavar="MM",
                   help="with --lambda evidence: tolerance (prior std) of the lengths [mm], "
                        "given instead of estimated")
    p.add_argument("--prior-deg", type=float, metavar="DEG",
                   help="with --lambda evidence: tolerance of the twists and joint offsets "
                        "[deg], given instead of estimated")
    p.add_argument("--noise-mm", type=float, metavar="MM",
                   help="with --lambda evidence: measurement noise, std per axis [mm], given "
                        "instead of estimated")
    p.add_argument("--folds", type=int, help="k of the k-fold cross-validation (default 5)")
    p.add_argument("--seed", type=int, help="seed of the CV fold split (default 0)")
    p.add_argument("--fix", nargs="+", default=[], metavar="NAME",
                   help="parameters held nominal: names (joint_3.a, tool.z) or quoted shell "
                        "patterns ('*.d', 'joint_[456].*')")
    p.add_argument("--free", nargs="+", default=[], metavar="NAME",
                   help="parameters kept even if found redundant (method l2); names or patterns")
    p.add_argument("--backlash", nargs="+", default=[], metavar="JOINT",
                   help="give these joints a backlash term (needs the acquisition order: "
                        "rows in order, or --order-column)")
    p.add_argument("--robust", choices=("huber", "cauchy"),
                   help="robust loss on the per-pose error; down-weighted samples are listed")
    p.add_argument("--robust-scale-mm", type=float, help="scale of the robust loss [mm] "
                   "(default 2.5 x the median pose error)")
    p.add_argument("--cv-max-poses", type=int, default=2000, metavar="N",
                   help="choose lambda by CV on a random N of the poses when there are more "
                        "(default 2000; 0: all poses); the final fit uses every pose")
    p.add_argument("--out", required=True, help="corrected URDF to write")
    p.add_argument("--frames-out", help="FRAMES.json: measurement frame and tool point (SI)")
    p.add_argument("--add-frames", action="store_true",
                   help="also add the measurement frame and tool point to the URDF as fixed "
                        "frames (kincal_measurement_frame, kincal_tool_point)")
    p.add_argument("--report", help="REPORT.json: the whole result")
    p.add_argument("--yaml-out", metavar="KINEMATICS.yaml",
                   help="corrected joint origins as YAML keyed by joint name (x y z roll pitch "
                        "yaw, ur_description's kinematics layout)")
    p.add_argument("--mdh-out", metavar="MDH.csv",
                   help="corrected modified-DH (Craig) table, convention in its header")
    p.add_argument("--plots", help="directory for PNG plots")
    p.add_argument("--html", metavar="REPORT.html",
                   help="one self-contained HTML report (plots embedded, opens offline)")
    _add_accuracy_options(p)
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
    _add_kinds(p, several=False)
    p.add_argument("--frames", help="FRAMES.json from 'kincal calibrate --frames-out'")
    p.add_argument("--fit-frames", action="store_true",
                   help="fit the measurement frame and tool point on these data first")
    p.add_argument("--report", help="write the statistics as JSON")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("analyze", help="what the data can identify, without solving")
    _add_common(p)
    _add_kinds(p)
    _add_model(p, allow_all=True)
    p.add_argument("--fix", nargs="+", default=[], metavar="NAME")
    p.add_argument("--backlash", nargs="+", default=[], metavar="JOINT",
                   help="also analyse backlash terms of these joints (see calibrate)")
    p.add_argument("--report", help="write the identifiability report as JSON")
    _add_accuracy_options(p)
    p.add_argument("--noise-mm", type=float, default=0.05,
                   help="noise per axis [mm] for the predicted accuracy (least squares on "
                        "these poses; default 0.05)")
    p.add_argument("--accuracy-plot", metavar="MAP.png", help="plot of the accuracy map")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser("simulate", help="a synthetic data set from a robot with planted errors")
    _add_common(p, data=False)
    _add_model(p, default="placement",
               help="error model in which the errors are planted (default placement: every "
                    "component of every joint placement, as a real arm has)")
    p.add_argument("--out", required=True, help="CSV to write (SI units)")
    p.add_argument("--design", choices=("tracker", "rtest"), default="tracker",
                   help="tracker: 400 mm cube; rtest: 20 mm cube, varied orientation")
    p.add_argument("--kind", choices=("point", "pose", "distance", "plane"), default="point",
                   help="what is measured: points (default), 6-DoF tool poses, distances to "
                        "a pivot 0.3 m below the poses, contacts with 3 planes through them")
    p.add_argument("--orientation-noise-deg", type=float, default=0.01,
                   help="sd of orientation noise per axis (--kind pose)")
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
    from kincal.cli.volume_options import add_volume_options

    add_volume_options(p, "metres")
    p.add_argument("--poses-file", metavar="CHOSEN.csv",
                   help="simulate at these poses (chain joint columns in rad and m, e.g. from "
                        "'kincal plan') instead of drawing them")
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
                   help="instead of a CSV: M random candidates uniform within the joint limits; "
                        "with --in-cube/--in-sphere: M candidates in the volume (default 2000)")
    p.add_argument("--seed", type=int, help="seed of --random or of the volume's candidates "
                   "(default 0)")
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
    _add_joint_columns(p, "CANDIDATES and --measured")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    add_volume_options(p, "in --length-unit")
    p.add_argument("--home", nargs="+", type=float, metavar="J",
                   help="with a volume: a configuration on the arm branch to keep (in "
                        "--angle-unit/--length-unit); default: found automatically")
    p.add_argument("--criterion", choices=("d", "i"), default="d",
                   help="d: D-optimal (default); i: I-optimal over --target-cube")
    p.add_argument("--target-cube", nargs=4, type=float, metavar=("CX", "CY", "CZ", "EDGE"),
                   help="with --criterion i: the working volume whose mean predicted position "
                        "variance is minimised (in --length-unit)")
    p.add_argument("--target-poses", type=int, default=200, metavar="T",
                   help="poses drawn in the target cube (default 200)")
    p.add_argument("--kind", choices=("point", "pose", "distance", "plane"), default="point",
                   help="the measurement kind the poses are for (D-optimal over its Jacobian)")
    p.add_argument("--pivot", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="--kind distance: guess of the pivot in the base frame, length unit")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("compensate", help="joint values with which the calibrated robot "
                       "reaches given targets (or a nominal program's poses)",
                       description="Solve the calibrated model's inverse kinematics from seed "
                       "joint values: TARGETS.csv has the chain joints (seeds) and x,y,z of the "
                       "tool point in the measurement frame (optionally qx,qy,qz,qw); or "
                       "--program PROGRAM.csv with --nominal NOMINAL.urdf corrects joint values "
                       "planned on the nominal model.")
    p.add_argument("robot", help="the calibrated URDF (or any robot name, see calibrate)")
    p.add_argument("targets", nargs="?", metavar="TARGETS.csv",
                   help="seed joint columns and x,y,z [qx,qy,qz,qw] in the measurement frame")
    p.add_argument("--tip", help="tip frame (as in the calibration)")
    p.add_argument("--base", help="base frame (default: the URDF root link)")
    p.add_argument("--frames", help="FRAMES.json from 'kincal calibrate --frames-out'")
    p.add_argument("--program", metavar="PROGRAM.csv",
                   help="joint values planned on the nominal model (chain joint columns)")
    p.add_argument("--nominal", metavar="NOMINAL.urdf", help="the model the program was planned on")
    p.add_argument("--position-columns", nargs=3, default=("x", "y", "z"), metavar="COL",
                   help="names of the target position columns (default x y z)")
    p.add_argument("--point", type=int, default=1,
                   help="which measured point of FRAMES.json is targeted (default 1)")
    p.add_argument("--length-unit", choices=("m", "mm"), default="m",
                   help="unit of positions and prismatic joints, in and out (default m)")
    p.add_argument("--angle-unit", choices=("rad", "deg"), default="rad",
                   help="unit of revolute joints, in and out (default rad)")
    p.add_argument("--tolerance-mm", type=float, default=0.001,
                   help="a target counts as reached within this distance (default 0.001 mm)")
    p.add_argument("--flag-unreachable", action="store_true",
                   help="write unreachable targets marked reached=0 instead of failing")
    p.add_argument("--out", required=True, help="JOINTS.csv to write")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p.set_defaults(func=cmd_compensate)

    p = sub.add_parser("demo", help="the paper's experiment, simulated at a small size")
    p.add_argument("--out", default=DEMO_DIR, help=f"output directory (default {DEMO_DIR})")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier demo in that directory")
    p.set_defaults(func=cmd_demo)
    return ap


TIMED = ("calibrate", "evaluate", "analyze", "plan", "simulate")


class _Terminated(BaseException):
    """SIGTERM, raised like KeyboardInterrupt so that writes roll back on the way out."""


def _on_sigterm(signum, frame):
    raise _Terminated


def main(argv=None) -> int:
    import signal
    import threading
    import time

    t0 = time.perf_counter()
    parser = build_parser()
    args = parser.parse_args(argv)
    # SIGTERM unwinds like Ctrl-C (only the main thread may set handlers: main() called
    # from a worker thread keeps the default)
    sigterm = None
    if threading.current_thread() is threading.main_thread():
        sigterm = signal.signal(signal.SIGTERM, _on_sigterm)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", KincalWarning)
        try:
            check_args(args)
            code = args.func(args)
        except (KeyboardInterrupt, _Terminated) as exc:
            name, code = (("SIGINT", 130) if isinstance(exc, KeyboardInterrupt)
                          else ("SIGTERM", 143))
            print(f"kincal: error: interrupted ({name}); no output was written or changed",
                  file=sys.stderr)
            caught.clear()  # a half-run's warnings would only confuse
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
                    kind = "note" if issubclass(w.category, KincalNote) else "warning"
                    print(f"kincal: {kind}: {w.message}", file=sys.stderr)
            if sigterm is not None:
                signal.signal(signal.SIGTERM, sigterm)
    if code == 0 and args.command in TIMED:  # an error stays the one line it is
        print(f"kincal: done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
