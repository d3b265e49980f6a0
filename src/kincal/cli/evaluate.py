"""``kincal evaluate``: the errors of a model on a data set (of any measurement kind)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from kincal.cli.checks import check_outputs
from kincal.cli.console import say, say_and_write, summary_lines
from kincal.cli.options import (Chain, Inputs, add_common, add_kinds, add_overwrite,
                                group, typed)
from kincal.cli.recorded_chain import chain_from_frames, load_recorded
from kincal.errors import DataError, OptionError


def register(subparsers) -> None:
    p = subparsers.add_parser("evaluate", help="errors of a model on a data set: positions, "
                              "orientations, distances, contacts")
    add_common(p)
    add_kinds(p, several=False)
    g = group(p, "frames")
    g.add_argument("--frames", help="FRAMES.json from 'kincal calibrate --frames-out'")
    g.add_argument("--fit-frames", nargs="?", const="all", choices=("all", "measurement"),
                   help="fit frames on these data first: all (the default: measurement frame "
                        "and tool, without --frames; another tool) or measurement (only the "
                        "measurement frame, the tool from --frames: the same tool on another "
                        "day)")
    group(p, "outputs").add_argument("--report", help="write the statistics as JSON")
    add_overwrite(p, help="replace an existing --report file")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Evaluate:
    """The options of ``kincal evaluate``."""

    chain: Chain
    inputs: Inputs
    frames: str | None  # FRAMES.json
    fit_frames: str | None  # "all", "measurement" or None
    report: str | None
    overwrite: bool
    json: bool = False
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def run(args) -> int:
    from kincal.export import report
    from kincal.frames_file import CellFrames
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.problem import CalibrationProblem
    from kincal.identification.statistics import ErrorStats, angle_label, angle_stats

    e = typed(Evaluate, args, chain=Chain.of(args), inputs=Inputs.of(args))
    if e.fit_frames == "measurement" and not e.frames:
        raise OptionError("--fit-frames measurement refits the measurement frame and keeps "
                          "the tool of --frames FRAMES.json: give it")
    if e.fit_frames != "measurement" and bool(e.frames) == bool(e.fit_frames):
        raise OptionError("give exactly one of --frames FRAMES.json or --fit-frames (with "
                          "--frames: --fit-frames measurement)")
    frames = None
    if e.frames:
        frames = CellFrames.read(e.frames)  # the one schema, any version; values checked
        frames = frames.for_chain(e.chain.base, e.chain.tip)  # a chain of several
        e = replace(e, chain=chain_from_frames(e.chain, frames))
    if e.inputs.order_column and not (frames is not None and frames.backlash):
        raise OptionError("--order-column gives the approach directions of backlash terms: "
                          + (f"{e.frames} has none" if frames is not None else
                             "--fit-frames fits none (the backlash values come from "
                             "--frames FRAMES.json)"))
    robot = load_recorded(e.chain, frames)
    protect = check_outputs(robot, [e.report], overwrite=e.overwrite,
                            inputs=(e.inputs.data, e.frames))
    held = None
    notes: tuple[str, ...] = ()
    if frames is not None:
        from kincal.measurements.fixed_joints import HeldJoints
        from kincal import urdf_origins
        from kincal.tilts_in_urdf import on_urdf

        frames.check_chain(robot)
        frames, notes = on_urdf(frames, robot)  # a contact face's tilt this URDF lacks
        other = urdf_origins.note(frames, robot)  # the nominal URDF with calibrated frames
        notes += (other,) if other else ()
        held = HeldJoints.of(frames, robot)  # a file without their columns gets them
    sets = e.inputs.read_sets(robot, held)
    backlash = tuple(frames.backlash) if frames is not None else ()
    if frames is None:
        problem = CalibrationProblem(robot, sets, CalibrationOptions(
            method="frames", tool_guess=e.inputs.tool_guess))
        x = problem.solve().x
        how = "measurement frame and tool point fitted on these data"
    else:
        problem, x, served = with_frames(robot, sets, frames, e.inputs.tool_guess)
        lay = problem.layout
        # a point file on a pose calibration: its frames serve the points (SetFrames.as_points)
        whose = "" if served[0] == problem.kinds[0].kind else f"the {served[0]} set's "
        how = f"frames from {e.frames}" + (f" ({whose}measurement frame and tool origin)"
                                           if whose else "")
        terms = ""
        if backlash:
            terms += (f" with backlash of {', '.join(lay.backlash)} (approach directions "
                      f"from {getattr(problem.kinds[0].data, 'order_source', 'the row order')})")
        if lay.compliance:
            terms += (f" with compliance of {', '.join(lay.compliance)} (gravity torques "
                      "from the URDF's inertials)")
        how += terms
        if e.fit_frames == "measurement":
            from kincal.identification.frame_refit import moved, refit_measurement_frame

            saved = x.copy()
            for i, km in enumerate(problem.kinds):
                x[lay.frame_slices[i]] = refit_measurement_frame(km, *lay.split(x, i))
            mm, deg = moved(lay.frames(saved, 0), lay.frames(x, 0), problem.kinds[0])
            how = (f"tool and kinematics from {e.frames}"
                   + (f" ({whose}tool origin)" if whose else "") + ", measurement frame "
                   f"refitted on these data (moved {mm:.2f} mm, {deg:.3f} deg)" + terms)
    _beyond_the_chain(problem, e.inputs.data)
    stats = [ErrorStats.from_errors(err) for _, err in problem.sample_errors(x)]
    km = problem.kinds[0]
    angle = angle_stats(km, problem.residuals(x, 0))
    what = "" if km.kind == "point" else f" ({km.kind} errors)"
    lines = [f"{robot.name} ({robot.base} -> {robot.tip}) on {e.inputs.data}, {how}{what}:",
             f"  {'position: ' if km.kind == 'pose' else ''}{stats[0].line()}"]
    if angle is not None:
        lines.append(f"  {angle_label(km.kind)}: {angle.line()}")
    fixed, source = _held(e, robot, km.data, held)
    if fixed:
        lines.append(f"  {fixed}")
    lines += [f"  note: {n}" for n in notes]
    content = {"format": "kincal-evaluation-1", "robot": str(robot.source),
               "data": str(e.inputs.data), "kind": km.kind, "frames": how,
               "errors": report.stats_dict(stats[0]),
               "orientation_errors": None if angle is None else report.angle_dict(angle),
               "fixed_joints": dict(getattr(km.data, "fixed_joints", ())),
               "fixed_joints_source": source, "notes": list(notes)}
    summary = {"command": "evaluate", **{k: v for k, v in content.items() if k != "format"}}
    if not e.report:
        say(summary_lines(e.json, lines, summary))
    else:
        from kincal.export.outputs import File

        say_and_write([File(e.report, "json", content)],
                      lambda written: summary_lines(e.json, lines, summary, written),
                      provenance=e.chain.provenance(robot, (e.inputs.data, e.frames),
                                                    e.command_line),
                      overwrite=e.overwrite, protect=protect)
    return 0


def _beyond_the_chain(problem, source) -> None:
    """Warn of the data's columns for URDF joints below the tip (or above the base), which
    the chain ignores though they may move the measured point: data of another chain (a
    FRAMES.json of several chains, --tip). calibrate's gate says the same (a note, or the
    likely cause of a refusal); evaluate judges nothing, so it warns."""
    import warnings

    from kincal.errors import KincalWarning
    from kincal.identification.gate_causes import names_text

    beyond = problem.chains.off_chain_columns([km.data for km in problem.kinds])[0]
    if beyond:
        warnings.warn(f"{source}: the columns of {names_text(beyond)}, URDF joints beyond the "
                      f"chain's ends ({problem.robots[0].base} -> {problem.robots[0].tip}), "
                      "are ignored: if they move the measured point, the chain does not match "
                      "the data (check --tip and --base)", KincalWarning)


def _held(e: Evaluate, robot, data, held) -> tuple[str, dict]:
    """(the line saying which joints the file had no column for and where their values came
    from, or "", {joint: "--joint-value" or the FRAMES.json}) of the set ``data``."""
    from kincal.measurements.fixed_joints import held_text

    given = e.inputs.held_joints([robot])
    fixed = tuple(getattr(data, "fixed_joints", ()))
    source = {j: "--joint-value" if j in given or held is None else held.source
              for j, _ in fixed}
    kinds = dict(zip(robot.joint_names, robot.geometry.kinds))
    parts = [held_text(j, v, kinds[j]) + ("" if source[j] == "--joint-value"
                                           else f" (as {source[j]} records)")
             for j, v in fixed]
    return ("joints held during the measurements (not in the file): " + ", ".join(parts)
            if parts else ""), source


def with_frames(robot, sets, frames, tool_guess=None):
    """(problem, x, served): ``sets`` on ``robot``'s kinematics as they are, with the frames
    (and backlash) of ``frames`` (a CellFrames); nothing is fitted, the problem only lays
    out the parameters. served: per set, the kind of the FRAMES.json set its frames came
    from (its own kind, or "pose" for points on a pose calibration). The one path of
    ``evaluate --frames`` and ``calibrate --validate``."""
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.problem import CalibrationProblem
    from kincal.measurements.checks import warn_units

    backlash, compliance = tuple(frames.backlash), tuple(frames.compliance)
    problem = CalibrationProblem(robot, sets, CalibrationOptions(
        method="ls", tool_guess=tool_guess, backlash=backlash, compliance=compliance))
    warn_units(problem.kinds, tool_guess)  # as a fit's start does (nothing is fitted here)
    lay = problem.layout
    x = problem.x_nominal
    used: set[int] = set()
    served = []
    for i, km in enumerate(problem.kinds):
        x[lay.frame_slices[i]], kind = saved_frames(frames, km, used)
        served.append(kind)
    if backlash or compliance:
        x[lay.backlash_slice] = ([frames.backlash[j] for j in lay.backlash]
                                 + [frames.compliance[j] for j in lay.compliance])
    return problem, x, tuple(served)


def saved_frames(frames, km, used: set) -> tuple[list[float], str]:
    """(values, kind): the frame values FRAMES.json holds for a set of ``km``'s kind and the
    kind of the set they come from. Of the sets not used yet, those of that kind, then, for
    points, the pose sets' measurement frame and tool origin (:meth:`SetFrames.as_points`):
    the one calibrated on this very file (its recorded source), else the first (another
    day's file); a point set may read fewer tool points than the file has."""
    names = tuple(km.frame_names)
    mine = [(j, s) for j, s in enumerate(frames.sets) if s.kind == km.kind]
    if km.kind == "point":
        mine += [(j, s.as_points()) for j, s in enumerate(frames.sets) if s.kind == "pose"]
    fits = [(j, s) for j, s in mine if j not in used and s is not None and s.has(*names)]
    same = [(j, s) for j, s in fits if _same_file(s.source, km.data.source)]
    for j, s in same[:1] or fits[:1]:
        used.add(j)
        return [s.value(n) for n in names], frames.sets[j].kind
    kinds = {s.kind for s in frames.sets}
    if km.kind == "point":
        K = km.data.n_points
        for s in frames.sets:
            if s.kind == "point" and s.has("tool.x") and len(s.tools) < K:
                raise DataError(f"{km.data.source} has {K} measured points per pose, "
                                f"{frames.source} has {len(s.tools)} tool point(s)")
        if "pose" in kinds and "point" not in kinds and K > 1:
            raise DataError(f"{km.data.source} has {K} measured points per pose, "
                            f"{frames.source} holds a pose calibration's frames: its tool "
                            "frame has one origin (tool.x .y .z), the tool point of one "
                            "measured point per pose; evaluate a file of one point per pose "
                            "(--position-columns of one point) or fit the frames on these "
                            "data (--fit-frames)")
    if km.kind == "pose" and "point" in kinds and "pose" not in kinds:
        raise DataError(f"{frames.source} holds a point calibration's frames: a point "
                        "calibration holds no tool orientation (tool.rx .ry .rz), which the "
                        f"orientations of {km.data.source} are compared with; evaluate its "
                        "positions with --positions-only (the point set's measurement frame "
                        "and tool point), or fit the frames on these data (--fit-frames)")
    have = "; ".join(f"{s.kind} ({', '.join(s.names[:9])})" for s in frames.sets)
    raise DataError(f"{frames.source} holds no {km.kind} set with frames {', '.join(names)} "
                    f"for {km.data.source} (it holds: {have})")


def _same_file(recorded: str, read: str) -> bool:
    """Whether FRAMES.json's recorded source of a set names the data file ``read`` (the same
    path, or, when that file is not where it was, the same name)."""
    import os

    if not recorded or not read:
        return False
    try:
        return os.path.samefile(recorded, read)
    except OSError:
        return os.path.basename(recorded) == os.path.basename(read)
