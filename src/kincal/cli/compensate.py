"""``kincal compensate``: joint values with which the calibrated robot reaches given targets."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from pathlib import Path

from kincal.cli.checks import check_outputs
from kincal.cli.console import say_and_write, summary_lines
from kincal.cli.options import (ORIENTATION_FORMATS, Chain, add_overwrite, add_units,
                                add_xacro_args, group, typed, xacro_args)
from kincal.cli.recorded_chain import chain_from_frames, load_recorded
from kincal.errors import DataError, OptionError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "compensate", help="joint values with which the calibrated robot reaches given targets "
        "(or a nominal program's poses)",
        description="Solve the calibrated model's inverse kinematics from seed joint values: "
        "TARGETS.csv has the chain joints (seeds) and x,y,z of the tool point in the "
        "measurement frame (optionally an orientation: qx,qy,qz,qw or --orientation-format); "
        "or --program PROGRAM.csv with --nominal NOMINAL.urdf corrects joint values planned "
        "on the nominal model.")
    i, c = group(p, "inputs"), group(p, "chain")
    i.add_argument("robot", help="the calibrated URDF (or any robot name, see calibrate)")
    i.add_argument("targets", nargs="?", metavar="TARGETS.csv",
                   help="seed joint columns and x,y,z [qx,qy,qz,qw] in the measurement frame")
    c.add_argument("--tip", help="tip frame (as in the calibration)")
    c.add_argument("--base", help="base frame (default: the URDF root link)")
    add_xacro_args(i)
    c.add_argument("--frames", help="FRAMES.json from 'kincal calibrate --frames-out'")
    i.add_argument("--program", metavar="PROGRAM.csv",
                   help="joint values planned on the nominal model (chain joint columns)")
    i.add_argument("--nominal", metavar="NOMINAL.urdf",
                   help="the model the program was planned on (URDF, xacro or a robot name)")
    add_xacro_args(i, "--nominal-xacro-arg", "a xacro --nominal description (ROBOT's are "
                   "--xacro-arg)")
    i.add_argument("--position-columns", nargs=3, metavar="COL",
                   help="names of the target position columns (default x y z)")
    i.add_argument("--orientation-format", choices=ORIENTATION_FORMATS, metavar="FORMAT",
                   help="how TARGETS.csv writes the wanted orientations, as a pose file "
                        "(quat-xyzw, the default when qx qy qz qw are there; quat-wxyz, "
                        "rpy-zyx, rpy-xyz, rotvec, matrix); angles in --angle-unit")
    i.add_argument("--orientation-columns", nargs="+", metavar="COL",
                   help="the targets' orientation columns, in the format's order (default: "
                        "the format's usual names, as for pose files)")
    c.add_argument("--point", type=int, default=1,
                   help="which measured point of FRAMES.json is targeted (default 1)")
    add_units(p, length="positions and prismatic joints, in and out",
              angle="revolute joints (in and out) and the targets' orientation angles")
    s = group(p, "inverse kinematics")
    s.add_argument("--tolerance-mm", type=float, default=0.001,
                   help="a target counts as reached within this distance (default 0.001 mm)")
    s.add_argument("--flag-unreachable", action="store_true",
                   help="write unreachable targets marked reached=0 instead of failing")
    group(p, "outputs").add_argument("--out", required=True, help="JOINTS.csv to write")
    add_overwrite(p, help="replace an existing output file")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Compensate:
    """The options of ``kincal compensate``."""

    chain: Chain
    targets: str | None
    frames: str | None
    program: str | None
    nominal: str | None
    nominal_xacro_arg: tuple[str, ...]  # NAME:=VALUE of a xacro --nominal
    position_columns: tuple[str, str, str]
    orientation_format: str | None
    orientation_columns: tuple[str, ...] | None
    point: int  # 1-based, as the user counts
    length_unit: str
    angle_unit: str
    tolerance_mm: float
    flag_unreachable: bool
    out: str
    overwrite: bool
    json: bool = False
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def run(args) -> int:
    c = typed(Compensate, args, chain=Chain.of(args))
    if (c.targets is None) == (c.program is None):
        raise OptionError("give exactly one of TARGETS.csv or --program PROGRAM.csv")
    if (c.program is None) != (c.nominal is None):
        raise OptionError("--program and --nominal go together: the program's joint values "
                          "were planned on the NOMINAL.urdf model")
    if c.targets is not None and c.frames is None:
        raise OptionError("targets in the measurement frame need --frames FRAMES.json "
                          "(from 'kincal calibrate --frames-out')")
    return _compensate(c)


def _compensate(c: Compensate) -> int:
    from kincal.compensation import (CellFrames, HeldJoints, IkOptions, compensate,
                                     filter_program, read_targets)
    from kincal.planning.candidates import read_candidates
    from kincal.urdf_origins import check_calibrated

    options = IkOptions(position_tolerance=c.tolerance_mm * 1e-3)
    # the one FRAMES.json reader, before the robot loads (a broken file is the likelier error)
    frames = None if c.frames is None else CellFrames.read(c.frames)
    if frames is not None:
        frames = frames.for_chain(c.chain.base, c.chain.tip)  # a chain of several
        c = replace(c, chain=chain_from_frames(c.chain, frames))
    robot = load_recorded(c.chain, frames)  # a chain with a mimic joint and its master:
    # refused by compensate / filter_program (the API's path too)
    inputs: list[str | Path | None] = [c.targets, c.program, c.nominal, c.frames]
    protect = check_outputs(robot, [c.out], overwrite=c.overwrite, inputs=inputs)
    held = HeldJoints()  # the joints the calibration held: their columns may be left out
    if frames is not None:
        frames.check_chain(robot)  # before reading targets: a wrong file is the likelier error
        check_calibrated(frames, robot)  # and a nominal URDF with the calibrated frames
        held = HeldJoints.of(frames, robot)
    if c.program is not None:
        from kincal.robot import Robot

        assert c.nominal is not None  # --program comes with --nominal (run)
        nominal = Robot.load(c.nominal, tip=c.chain.tip, base=c.chain.base,
                             xacro_args=xacro_args(c.nominal_xacro_arg, "--nominal-xacro-arg"))
        q, lines = read_candidates(c.program, nominal, c.length_unit, c.angle_unit,
                                   kind="program", held=held)
        result = filter_program(nominal, robot, q, frames, lines, c.point - 1, options,
                                source=str(c.program))
        inputs = [c.program, nominal.source]
    else:
        assert frames is not None  # targets come with --frames (run)
        targets = read_targets(c.targets, robot, c.length_unit, c.angle_unit,
                               c.position_columns, c.orientation_format, c.orientation_columns,
                               held)
        result = compensate(robot, frames, targets, c.point - 1, options, c.length_unit)
        inputs = [c.targets]
    failures = result.failures()
    if failures and not c.flag_unreachable:
        import numpy as np

        posed = bool(np.any(result.orientation_required & ~result.reached))
        free = len(robot.joint_names) - len(held.as_dict())
        few = (f"; a full pose needs six free joints, this chain has {free} "
               f"({len(robot.joint_names) - free} held where the calibration held them; "
               "leave the orientation columns out to reach the positions alone)"
               if posed and free < 6 else "")
        raise DataError(f"{len(failures)} of {len(result)} targets cannot be reached by the "
                        f"calibrated model within {c.tolerance_mm:g} mm"
                        + (f" and {np.degrees(options.orientation_tolerance):.3g} deg"
                           if posed else "") + f"{few}: "
                        + "; ".join(failures[:10]) + (" ..." if len(failures) > 10 else "")
                        + "; nothing written; pass --flag-unreachable to write them marked "
                          "reached=0")
    said = [result.summary()] + [f"  NOT reached, written with reached=0: {line}"
                                 for line in failures]
    r = result.reached
    # built only for --json: the joint values of 100,000 targets as Python floats weigh
    # tens of MB, which the blocked writing below is there to avoid
    summary = {} if not c.json else {"command": "compensate", "robot": str(robot.source), "source": result.source,
               "targets": len(result), "reached": int(r.sum()), "not_reached": failures,
               "max_position_error_m": float(result.position_error[r].max()) if r.any() else None,
               "max_orientation_error_rad": (float(result.orientation_error[r].max())
                                             if r.any() else None),
               "joint_names": list(result.joint_names),
               "joint_values_si": result.joint_values.tolist(),
               "notes": list(result.notes)}
    from kincal.export.outputs import File

    # the file's one exception to SI, said in the file (a # line, as its provenance is)
    units = (f"# joint values in {c.angle_unit} (revolute) and {c.length_unit} (prismatic), "
             "as the input (--angle-unit, --length-unit)\n")
    say_and_write([File(c.out, "csv", itertools.chain(
                      [units], result.csv_blocks(c.length_unit, c.angle_unit)))],
                  lambda written: summary_lines(c.json, said, summary, written, wrote=lambda path: (
                      f"  wrote {path} (joint values in {c.angle_unit} and {c.length_unit}, as "
                      "the input)")),
                  provenance=c.chain.provenance(robot, (*inputs, c.frames), c.command_line),
                  overwrite=c.overwrite,
                  protect=protect)
    return 0
