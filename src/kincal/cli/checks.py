"""Checks of the command line's options and outputs, before any file is read or work done.

Every option is checked here: a value that is not finite or out of range, and a flag that
would be silently ignored, is an :class:`OptionError` (one line, exit code 1). Defaults of
options that only some settings use are None in the parser, so that "given but unused"
can be told apart. :func:`check_outputs` refuses, before the work, what the final write
would refuse (so a refused run creates no plots folder).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from kincal.errors import OptionError

# Every option is checked here, before a file is read: a value that is not finite or out
# of range, and a flag that would be silently ignored, is an error. Defaults of options
# that only some settings use are None, so that "given but unused" can be told apart.
# fleet --workers: processes of the local Dask cluster; beyond a few per CPU they only cost
# memory (100,000 asked for hung the machine at 6.7 GB, starting them)
MAX_WORKERS = 4 * (os.cpu_count() or 1)
MAX_POSES = 1_000_000  # simulate --poses, plan --random: beyond any real measurement campaign
DEFAULT_LAMBDA = "auto"  # --lambda when not given (None in the parser: "given" can be told)


LAMBDA_WORDS = ("auto", "cv", "evidence")


def lambda_value(text: str) -> str | float:
    """--lambda as the fit takes it: one of :data:`LAMBDA_WORDS`, or a finite number from 0
    to :data:`kincal.identification.options.MAX_LAMBDA` (calibrate and fleet); OptionError
    otherwise."""
    if text in LAMBDA_WORDS:
        return text
    try:
        value = float(text)
    except ValueError:
        raise OptionError(f"--lambda must be 'auto', 'cv', 'evidence' or a number, got "
                          f"{text!r}") from None
    from kincal.identification.options import MAX_LAMBDA

    _finite("--lambda", value, 0, MAX_LAMBDA, why="a penalty weight: beyond, the nominal "
            "kinematics outweigh any data set")
    return value


def _need(ok: bool, message: str) -> None:
    if not ok:
        raise OptionError(message)


def _finite(option: str, values, low=None, high=None, low_open=False, unit: str = "",
            why: str = "", scale: float = 1.0) -> None:
    """Each number of ``option`` times ``scale`` is finite and within [low, high] (low
    excluded if low_open: the bounds in the unit they are defined in, SI where ``scale``
    converts to it); else one line naming the option, the value and the range in the
    option's ``unit`` (the bounds divided by ``scale``), and ``why`` the range."""
    if values is None:
        return
    for v in (values if isinstance(values, (list, tuple)) else [values]):
        x = v * scale
        ok = math.isfinite(x) and (low is None or (x > low if low_open else x >= low)) \
            and (high is None or x <= high)
        if not ok:
            bound = ("" if low is None else f" {'>' if low_open else '>='} {low / scale:g}") + (
                "" if high is None else
                f"{' and' if low is not None else ''} <= {high / scale:g}")
            _need(False, f"{option} must be a finite number{bound}{' ' + unit if unit else ''}"
                  f", got {v:g}{f' ({why})' if why else ''}")


def _cell_lengths(option: str, values, args, size: bool = False,
                  what: str = "of the base frame") -> None:
    """Lengths of the robot cell, in the command's length unit (--length-unit; metres where
    it has none, simulate): each within :data:`kincal.frames_file.MAX_LENGTH` of the frame
    (``size``: a size > 0 and up to it)."""
    from kincal.cli.options import length_scale
    from kincal.frames_file import MAX_LENGTH

    unit = getattr(args, "length_unit", None) or "m"
    why = (f"a robot cell: up to {MAX_LENGTH:g} m" if size else
           f"a robot cell: within {MAX_LENGTH:g} m {what}") + (
        "; check --length-unit" if hasattr(args, "length_unit") else "")
    _finite(option, values, 0 if size else -MAX_LENGTH, MAX_LENGTH, low_open=size, unit=unit,
            why=why, scale=length_scale(unit))


def _count(option: str, value, low: int, high: int | None = None) -> None:
    if value is not None:
        _need(low <= value and (high is None or value <= high),
              f"{option} must be an integer >= {low}" + ("" if high is None else f" and <= {high:,}")
              + f", got {value}")


def _orientation_sigma(value) -> None:
    """--orientation-sigma-deg: within the range of every stated orientation sigma, the
    same for pose files and flush tilts (:data:`kincal.measurements.checks.SIGMA_RANGE_DEG`)."""
    if value is None:
        return
    from kincal.measurements.checks import SIGMA_RANGE_DEG

    lo, hi = SIGMA_RANGE_DEG
    _need(math.isfinite(value) and lo <= value <= hi,
          f"--orientation-sigma-deg {value:g}: the orientation sigma must be between {lo:g} and "
          f"{hi:g} deg (a standard deviation of the measurement)")


def _measurement_noise(value) -> None:
    """--noise-mm of analyze and plan (the noise of the predicted errors): the range of
    calibrate's --noise-mm, the same measurement noise per axis [mm]
    (:data:`kincal.identification.options.EVIDENCE_RANGE`)."""
    from kincal.identification.options import EVIDENCE_RANGE

    _finite("--noise-mm", value, *EVIDENCE_RANGE, unit="mm")


def _check_calibrate(args) -> None:
    m = args.method
    if args.lam is not None:
        _need(m == "l2", f"--lambda applies to method l2 only; method {m} has no penalty")
        lambda_value(args.lam)
    # a lambda given as a number, or no penalty at all: no cross-validation to fold or seed
    chosen = m == "l2" and (args.lam is None or args.lam in ("auto", "cv"))
    for option, value in (("--folds", args.folds), ("--seed", args.seed),
                          ("--cv-max-poses", args.cv_max_poses)):
        _need(value is None or chosen, f"{option} is used only when lambda may be chosen by "
              "cross-validation (method l2 with --lambda cv or auto)")
    _count("--folds", args.folds, 2)
    _count("--seed", args.seed, 0)
    _need(args.robust_scale_mm is None or args.robust is not None,
          "--robust-scale-mm needs --robust huber or --robust cauchy")
    from kincal.identification.robust import SCALE_RANGE_M

    _finite("--robust-scale-mm", args.robust_scale_mm, *SCALE_RANGE_M, unit="mm", scale=1e-3,
            why="a pose error's scale: beyond, no pose is down-weighted")
    args.lam = DEFAULT_LAMBDA if args.lam is None else args.lam
    args.seed = 0 if args.seed is None else args.seed
    if args.cv_max_poses is None:  # CalibrationOptions' default: 2000
        from kincal.identification.options import CalibrationOptions

        args.cv_max_poses = CalibrationOptions().cv_max_poses


def _check_floor(args, volume: bool, target_cube: bool = False) -> None:
    """--floor, --no-floor, --no-collision: checks of poses drawn in a volume (plan's
    --target-cube draws its target poses with the collision check too)."""
    _need(args.floor is None or not args.no_floor, "give --floor Z or --no-floor, not both")
    for option, given in (("--floor", args.floor is not None), ("--no-floor", args.no_floor)):
        _need(not given or volume, f"{option} is checked for poses drawn in a volume: it "
              "needs --in-cube or --in-sphere")
    _need(not args.no_collision or volume or target_cube, "--no-collision drops the "
          "self-collision check of poses drawn in a volume: it needs --in-cube or --in-sphere"
          + (" (or --target-cube)" if args.command == "plan" else ""))
    _cell_lengths("--floor", args.floor, args)
    args.floor = 0.0 if args.floor is None else args.floor


def _check_simulate(args) -> None:
    """Options that the chosen way of making poses would silently ignore."""
    volume = args.in_cube is not None or args.in_sphere is not None
    if args.poses_file is not None:
        for option, value in (("--poses", args.poses), ("--center-m", args.center_m),
                              ("--size-mm", args.size_mm), ("--tilt-deg", args.tilt_deg)):
            _need(value is None, f"{option} is not used with --poses-file (the poses are "
                  "the file's rows)")
        _need(args.design is None, "--design is not used with --poses-file (the poses are the "
              "file's rows)")
    elif volume:
        for option, value in (("--center-m", args.center_m), ("--size-mm", args.size_mm)):
            _need(value is None, f"{option} is not used with --in-cube/--in-sphere (the volume "
                  "gives the centre and the size)")
        _need(args.design is None or args.max_tilt is None, "--design is not used with "
              "--in-cube/--in-sphere and --max-tilt (the volume gives the centre and the size, "
              "--max-tilt the tilt; --design only sets the default tilt there)")
    _need(args.orientation_noise_deg is None or args.kind in ("pose", "flush"),
          "--orientation-noise-deg is the orientation noise of --kind pose (or the tilt "
          "noise of --kind flush)")
    _finite("--orientation-noise-deg", args.orientation_noise_deg, 0, 10, unit="deg")
    _volume_options(args)
    _check_floor(args, volume)
    args.poses = 60 if args.poses is None else args.poses
    args.design = "tracker" if args.design is None else args.design
    default = 0.05 if args.kind == "flush" else 0.01  # a face's tilt, a tracker's orientation
    args.orientation_noise_deg = (default if args.orientation_noise_deg is None
                                  else args.orientation_noise_deg + 0.0)


def _check_plan(args, volume: bool) -> None:
    """Options that this plan would silently ignore."""
    _check_floor(args, volume, target_cube=args.target_cube is not None)
    _need(args.pivot is None or args.kind == "distance",
          "--pivot is the guess of the pivot of --kind distance")
    _cell_lengths("--pivot", args.pivot, args)
    if args.criterion is None:  # I-optimal where it applies (the predicted point), else D
        args.criterion = "i" if args.kind == "point" else "d"
    _need(args.target_poses is None or args.criterion == "i",
          "--target-poses is the number of poses drawn in --target-cube: it needs --criterion i")
    _need(args.target_poses is None or args.target_cube is not None or volume,
          "--target-poses is the number of poses drawn in the target cube: give --target-cube, "
          "or a volume (--in-cube/--in-sphere) whose default working cube they are drawn in")
    _count("--target-poses", args.target_poses, 1, MAX_POSES)
    args.target_poses = 1000 if args.target_poses is None else args.target_poses
    if args.home is not None:  # within the joint limits: checked on the loaded robot
        _finite("--home", args.home)
    _volume_options(args)


def _volume_options(args) -> None:
    """The volumes (a cube's centre and edge, a sphere's centre and radius, plan's target
    cube) in the cell, said in the unit the user typed them in; a tilt direction (any
    finite length: only its direction counts) and the largest tilt."""
    from kincal.planning.volume_candidates import MAX_TILT_DEG

    for option, size in (("target_cube", "EDGE"), ("in_cube", "EDGE"), ("in_sphere", "R")):
        v = getattr(args, option, None)
        flag = "--" + option.replace("_", "-")
        _cell_lengths(f"{flag} CX CY CZ", None if v is None else v[:3], args)
        _cell_lengths(f"{flag} {size}", None if v is None else v[3], args, size=True)
    _finite("--tilt-direction", args.tilt_direction)
    _finite("--max-tilt", args.max_tilt, 0, MAX_TILT_DEG, unit="deg")


def check_args(args) -> None:
    """Raise OptionError for any option value or combination the command would not use."""
    _cell_lengths("--tool-offset", getattr(args, "tool_offset", None), args,
                  what="of the tip frame")
    c = args.command
    if hasattr(args, "backlash"):  # calibrate, analyze (evaluate reads backlash from FRAMES.json)
        # --model auto (the default) weighs backlash terms too: their directions need the order
        _need(getattr(args, "order_column", None) is None or bool(args.backlash)
              or getattr(args, "model", None) == "auto",
              "--order-column gives the approach directions of backlash terms: it needs "
              f"--backlash, or --model auto, which may add them (--model {args.model})")
    if hasattr(args, "grid"):
        _need(args.grid is None or args.accuracy_map is not None,
              "--grid is the number of grid points per edge of the --accuracy-map cube: it "
              "needs --accuracy-map")
        from kincal.planning.accuracy_map import MAX_GRID  # the cube's own checks, named

        cube = args.accuracy_map
        _cell_lengths("--accuracy-map CX CY CZ", None if cube is None else cube[:3], args)
        _cell_lengths("--accuracy-map EDGE", None if cube is None else cube[3], args, size=True)
        _count("--grid", args.grid, 1, MAX_GRID)
        args.grid = 5 if args.grid is None else args.grid
    _orientation_sigma(getattr(args, "orientation_sigma_deg", None))
    if c == "calibrate":
        _check_calibrate(args)
    elif c == "evaluate":
        _need(args.tool_offset is None or not args.frames, "--tool-offset is a starting guess "
              "for --fit-frames; with --frames the tool point comes from FRAMES.json")
    elif c == "analyze":
        _measurement_noise(args.noise_mm)
    elif c == "simulate":
        _need(args.tool_offset is None, "simulate does not use --tool-offset (a starting guess "
              "for calibration); the simulated tool point is --tool-m X Y Z [m]")
        _count("--poses", args.poses, 1, MAX_POSES)
        from kincal.planning.volume_candidates import MAX_TILT_DEG

        # upper bounds far above any real robot: beyond them the simulated robot is noise
        _finite("--size-mm", args.size_mm, 0, 10_000, low_open=True, unit="mm")
        _finite("--tilt-deg", args.tilt_deg, 0, MAX_TILT_DEG, unit="deg")
        _cell_lengths("--center-m", args.center_m, args)
        _cell_lengths("--tool-m", args.tool_m, args, what="of the tip frame")
        frame = args.base_frame
        _cell_lengths("--base-frame X Y Z", None if frame is None else frame[:3], args)
        _finite("--base-frame RX RY RZ", None if frame is None else frame[3:], -360, 360,
                unit="deg", why="one turn either way")
        for option, high in (("length_error_mm", 100), ("angle_error_deg", 10), ("noise_mm", 1000)):
            _finite("--" + option.replace("_", "-"), getattr(args, option), 0, high,
                    unit=option.rsplit("_", 1)[1])
        _count("--seed", args.seed, 0)
        _count("--truth-seed", args.truth_seed, 0)
        _check_simulate(args)
        for option in ("size_mm", "tilt_deg", "length_error_mm", "angle_error_deg", "noise_mm"):
            if getattr(args, option) is not None:  # -0.0 -> 0.0: numpy's checks test the sign bit
                setattr(args, option, getattr(args, option) + 0.0)
    elif c == "plan":
        _measurement_noise(args.noise_mm)
        _count("--poses", args.poses, 1)
        _count("--random", args.random, 1, MAX_POSES)
        volume = getattr(args, "in_cube", None) is not None or \
            getattr(args, "in_sphere", None) is not None
        _need(args.seed is None or args.random is not None or volume,
              "--seed is the seed of --random or of a volume's candidates; it is not used "
              "with a CSV of candidates")
        _count("--seed", args.seed, 0)
        args.seed = 0 if args.seed is None else args.seed
        _check_plan(args, volume)
    elif c == "compensate":
        from kincal.compensation.ik import POSITION_TOLERANCE_RANGE

        _finite("--tolerance-mm", args.tolerance_mm, *POSITION_TOLERANCE_RANGE, unit="mm",
                scale=1e-3, why="below, the inverse kinematics chase rounding; above, an "
                "uncorrected seed would count as reached")
        _count("--point", args.point, 1)
        _need(args.program is None or not (args.position_columns or args.orientation_format
                                           or args.orientation_columns),
              "--position-columns, --orientation-format and --orientation-columns describe "
              "TARGETS.csv; a --program has joint values only")
        args.position_columns = args.position_columns or ("x", "y", "z")
        _need(args.point == 1 or args.frames is not None,
              f"--point {args.point} picks a measured point of --frames FRAMES.json; without "
              "it the tip frame's origin is moved")
        _need(not args.nominal_xacro_arg or args.nominal is not None,
              "--nominal-xacro-arg is an argument of the --nominal description: it needs "
              "--nominal (ROBOT's xacro arguments are --xacro-arg)")
    elif c == "fleet":
        lambda_value(args.lam)
        _count("--workers", args.workers, 1, MAX_WORKERS)  # each a process: 100,000 hung
        from kincal.fleet.fleet import MAX_ROUNDS

        _count("--hierarchical", args.hierarchical, 0, MAX_ROUNDS)
    elif c == "demo":
        out = Path(args.out).expanduser()
        if out.exists() or out.is_symlink():
            _need(out.is_dir(), f"{args.out}: exists and is not a directory; choose another --out")
            _need(args.overwrite or not any(out.iterdir()), f"{args.out}: already exists (an "
                  "earlier demo?); choose another --out or pass --overwrite to replace its files")
        probe = out if out.exists() else out.parent
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if not os.access(probe, os.W_OK | os.X_OK):
            from kincal.errors import ExportError

            raise ExportError(f"{args.out}: cannot write in {probe.resolve()} (permission "
                              "denied or a read-only file system); choose another --out")


def check_outputs(robot, files, *, overwrite: bool, inputs=(), dirs=(), urdf_out=None) -> list:
    """Refuse now, before the work, what the final write would refuse; return the paths
    to protect, for that write (the one list of what the command read).

    files: the output paths the command will write (None entries are skipped); inputs:
    the files it reads (never overwritten, with or without --overwrite; None skipped), the
    robot's URDF added; dirs: folders it may create (a plots folder); urdf_out: the
    corrected URDF, which alone may replace the robot's URDF (with --overwrite)."""
    from kincal.export.safe_write import check_outputs as check_targets

    protect = [robot.source] + [p for p in inputs if p]
    check_targets([f for f in files if f], overwrite=overwrite, protect=protect,
                  dirs=[d for d in dirs if d is not None],  # "" refused, not skipped
                  in_place=[(urdf_out, robot.source)] if urdf_out else [])
    return protect


def distinct_inputs(files, held_out=()) -> None:
    """Refuse a data file given twice (the same file, or one of the same bytes: each sample
    would count twice, the noise look smaller, and a fold's validation samples sit in its
    training), and a held-out file (--validate) that is a data file, before any work."""
    from kincal.input_files import same_files

    same = same_files(files)
    if same is not None:
        raise OptionError(f"{same[1]} {same[2]}: a data file given twice counts each sample "
                          "twice (the noise looks smaller than it is, and cross-validation "
                          "sees its validation samples in training); give each file once")
    for held in held_out:
        same = same_files([*files, held])
        if same is not None:
            how = "is a data file" if same[2] == "is given twice" else same[2]
            raise OptionError(f"--validate {same[1]} {how}: held-out errors judge a "
                              "calibration on samples it did not see; give measurements kept "
                              "out of the training files")


def plot_paths(folder, n_sets: int = 1, accuracy: bool = False) -> list:
    """The files ``kincal calibrate --plots FOLDER`` may write, for the check before the
    work: a residual figure per data file, the accuracy map's with ``accuracy``
    (:func:`kincal.export.plots.calibration_figure_names`)."""
    if not folder:
        return []
    from kincal.export.plots import calibration_figure_names

    return [Path(folder) / n for n in calibration_figure_names(n_sets, accuracy)]
