"""``kincal evaluate``: the position errors of a model on a data set."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

from kincal.cli.checks import check_outputs
from kincal.cli.console import say, say_and_write
from kincal.cli.options import (Chain, Inputs, add_common, add_kinds, add_overwrite,
                                frames_document, group, typed)
from kincal.errors import DataError, KincalError, OptionError


def register(subparsers) -> None:
    p = subparsers.add_parser("evaluate", help="position errors of a model on a data set")
    add_common(p)
    add_kinds(p, several=False)
    g = group(p, "frames")
    g.add_argument("--frames", help="FRAMES.json from 'kincal calibrate --frames-out'")
    g.add_argument("--fit-frames", action="store_true",
                   help="fit the measurement frame and tool point on these data first")
    group(p, "outputs").add_argument("--report", help="write the statistics as JSON")
    add_overwrite(p, help=None)
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Evaluate:
    """The options of ``kincal evaluate``."""

    chain: Chain
    inputs: Inputs
    frames: str | None  # FRAMES.json
    fit_frames: bool
    report: str | None
    overwrite: bool


def run(args) -> int:
    e = typed(Evaluate, args, chain=Chain.of(args), inputs=Inputs.of(args))
    if e.inputs.wants_sets():
        return _evaluate_sets(e)
    if bool(e.frames) == bool(e.fit_frames):
        raise OptionError("give exactly one of --frames FRAMES.json or --fit-frames")
    if e.frames:
        e = replace(e, chain=chain_from_frames(e.chain, e.frames))
    return _evaluate_points(e)


def chain_from_frames(chain: Chain, frames) -> Chain:
    """The chain with base and tip from FRAMES.json where not given; refuse a mismatch.

    Frames identified for one chain mean nothing for another: the tool point lives in
    the recorded tip frame, the measurement frame is placed against the recorded base."""
    path = Path(frames)
    data = frames_document(path)
    if data is None:
        return chain  # missing, a folder or a device: the frames reader says what is wrong
    for role in ("base", "tip"):
        recorded, given = data.get(f"{role}_frame"), getattr(chain, role)
        if not isinstance(recorded, str):
            continue  # an older frames file without the chain: nothing to check
        if given is None:
            chain = replace(chain, **{role: recorded})
        elif given != recorded:
            from kincal.errors import FrameError

            raise FrameError(f"--{role} {given!r} does not match the {role} frame {recorded!r} "
                             f"recorded in {path} (its measurement frame and tool point were "
                             f"identified for {data.get('base_frame')} -> "
                             f"{data.get('tip_frame')}); use --{role} {recorded} or frames "
                             "identified for this chain", valid=(recorded,))
    return chain


def _evaluate_points(e: Evaluate) -> int:
    from kincal.compensation.frames import CellFrames
    from kincal.export import report
    from kincal.identification.calibration import CalibrationOptions, CalibrationProblem
    from kincal.identification.statistics import ErrorStats
    from kincal.measurements.point import MeasurementModel

    robot = e.chain.load()
    check_outputs(robot, [e.report], overwrite=e.overwrite, inputs=(e.inputs.data, e.frames))
    data = e.inputs.read_points(robot)
    problem = CalibrationProblem(robot, data, CalibrationOptions(
        method="frames", tool_guess=e.inputs.tool_guess))
    if e.frames:
        frames = CellFrames.read(e.frames)
        base, tools, backlash = frames.base, frames.tools, frames.backlash
        data = data.for_chain(robot.joint_names)
        if data.n_points > len(tools):
            raise DataError(f"{e.inputs.data} has {data.n_points} measured points per pose, "
                            f"{e.frames} has {len(tools)} tool point(s)")
        try:
            model = MeasurementModel(problem.error_model, data.joint_values, data.approach,
                                     backlash, data.points, len(tools))
        except KincalError as exc:
            raise DataError(f"{e.frames}: {exc}") from None
        x = model.space.join(problem.error_model.nominal, base, tools,
                             [backlash[j] for j in model.space.backlash])
        stats = ErrorStats.from_errors(data.positions - model.predict(x))
        how = f"frames from {e.frames}"
        if backlash:
            how += (f" with backlash of {', '.join(model.space.backlash)} (approach directions "
                    f"from {data.order_source})")
    else:
        stats = problem.solve().after
        how = "measurement frame and tool point fitted on these data"
    lines = [f"{robot.name} ({robot.base} -> {robot.tip}) on {e.inputs.data}, {how}:",
             f"  {stats.line()}"]
    if not e.report:
        say(lines)
    else:
        say_and_write([(e.report, report.dumps({"format": "kincal-evaluation-1",
                                            "robot": str(robot.source),
                                            "data": str(e.inputs.data), "frames": how,
                                                "errors": report.stats_dict(stats)}))],
                      lambda written: lines, overwrite=e.overwrite,
                      protect=[robot.source, e.inputs.data])
    return 0


def _evaluate_sets(e: Evaluate) -> int:
    from kincal.identification.multiset import MultiSetProblem
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.statistics import ErrorStats

    if e.report:
        raise OptionError("--report is not available with several data files or with pose, "
                          "distance or plane files yet")
    if bool(e.frames) == bool(e.fit_frames):
        raise OptionError("give exactly one of --frames FRAMES.json or --fit-frames")
    robot = e.chain.load()
    sets = e.inputs.read_sets(robot)
    problem = MultiSetProblem(robot, sets, CalibrationOptions(method="frames",
                                                              tool_guess=e.inputs.tool_guess))
    if e.fit_frames:
        x = problem.solve().x
        how = "frames fitted on these data"
    else:
        x = problem.x_nominal
        try:
            saved = json.loads(open(e.frames, encoding="utf-8").read())["sets"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise DataError(f"{e.frames}: not a FRAMES.json of a calibration from several "
                            f"sets or of pose, distance or plane files ({exc})") from None
        for i, km in enumerate(problem.kinds):
            match = [s for s in saved if s.get("kind") == km.kind
                     and tuple(s.get("frames", {})) == tuple(km.frame_names)]
            if not match:
                raise DataError(f"{e.frames} has no {km.kind} set with frames "
                                f"{', '.join(km.frame_names)} for {km.data.source}")
            x[problem.frame_slices[i]] = [match[0]["frames"][n] for n in km.frame_names]
        how = f"frames from {e.frames}"
    print(f"{robot.name} ({robot.base} -> {robot.tip}), {how}:")
    for i, err in problem.sample_errors(x):
        km = problem.kinds[i]
        print(f"  {km.kind} {km.data.source}: {ErrorStats.from_errors(err).line()}")
    return 0
