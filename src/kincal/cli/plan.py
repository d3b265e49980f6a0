"""``kincal plan``: choose which poses to measure (I- or D-optimal)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from kincal.cli.checks import check_outputs
from kincal.cli.console import say_and_write, summary_lines
from kincal.cli.options import (Chain, add_common, add_joint_columns, add_model, add_overwrite,
                                add_units, group, joint_map, length_scale, tool_guess, typed)
from kincal.cli.volume_options import VolumeRequest, add_volume_options, volume_spec
from kincal.errors import OptionError

_TARGETS = "target poses (--target-poses)"  # what the working volume's draws are, in errors


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "plan", help="choose which poses to measure (I- or D-optimal)",
        description="Choose N of the candidate poses that best predict the measured point "
        "where the robot works (I-optimal: smallest mean predicted position variance over "
        "target poses, the measurement frame and tool refitted there; default for --kind "
        "point) or that best determine the parameters (D-optimal: largest det of J^T J; "
        "--criterion d, default for the other kinds), at the nominal robot. The candidates "
        "must be safe, reachable and measurable: kincal does not check collisions or line "
        "of sight.")
    add_common(p, data=False)
    i = group(p, "inputs")
    i.add_argument("candidates", nargs="?", metavar="CANDIDATES.csv",
                   help="CSV with the chain joint columns (no positions needed); or use --random")
    i.add_argument("--random", type=int, metavar="M",
                   help="instead of a CSV: M random candidates uniform within the joint limits; "
                        "with --in-cube/--in-sphere: M candidates in the volume (default 2000)")
    i.add_argument("--seed", type=int, help="seed of --random or of the volume's candidates "
                   "(default 0)")
    c = group(p, "choice")
    c.add_argument("--poses", type=int, required=True, metavar="N", help="poses to choose")
    i.add_argument("--measured", metavar="DATA.csv",
                   help="poses already measured (joint columns; other columns ignored): the "
                        "N new poses are chosen to complement them")
    group(p, "outputs").add_argument(
        "--out", required=True,
        help="CSV of the chosen poses: chain joint columns in SI units (rad, m) whatever the "
             "input units, in the order chosen, and with a CSV of candidates their line "
             "numbers there (candidate_line)")
    add_units(p, length="prismatic joints in CANDIDATES and of --tool-offset",
              angle="revolute joints in CANDIDATES")
    add_model(p, allow_auto=True, auto="poses for the model calibrate's auto starts from and "
              "keeps unless the data tell otherwise, the chain's default (complete; placement "
              "on a tree path)")
    c.add_argument("--fix", nargs="+", default=[], metavar="NAME",
                   help="parameters held nominal (left out of the criterion)")
    c.add_argument("--noise-mm", type=float, default=0.05,
                   help="length noise [mm] per axis, distance or height for the predicted "
                        "standard errors (default 0.05; orientations and tilts weigh as in a "
                        "set stating no sigma: 0.01 and 0.05 deg per 0.05 mm)")
    add_joint_columns(p, "CANDIDATES and --measured")
    add_overwrite(p, help="replace an existing output file")
    add_volume_options(p, "in --length-unit")
    group(p, "measurement volume").add_argument(
        "--home", nargs="+", type=float, metavar="J",
        help="with a volume: a configuration on the arm branch to keep (in "
             "--angle-unit/--length-unit); default: found automatically")
    c.add_argument("--criterion", choices=("d", "i"),
                   help="i: I-optimal over the target poses (default for --kind point); d: "
                        "D-optimal (default for the other kinds)")
    c.add_argument("--target-cube", nargs=4, type=float, metavar=("CX", "CY", "CZ", "EDGE"),
                   help="with --criterion i: the working volume whose mean predicted position "
                        "variance is minimised (in --length-unit); default: the 400 mm cube "
                        "centred on --in-cube/--in-sphere, tilt up to 30 deg, or without a "
                        "volume the candidates themselves")
    c.add_argument("--target-poses", type=int, metavar="T",
                   help="poses drawn in the target cube (default 1000)")
    c.add_argument("--kind", choices=("point", "pose", "distance", "plane", "flush"),
                   default="point",
                   help="the measurement kind the poses are for (D-optimal over its Jacobian)")
    c.add_argument("--pivot", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="--kind distance: guess of the pivot in the base frame, length unit")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Plan:
    """The options of ``kincal plan`` (lengths in ``length_unit``)."""

    chain: Chain
    volume: VolumeRequest
    candidates: str | None
    random: int | None
    seed: int
    poses: int
    measured: str | None
    out: str
    length_unit: str
    angle_unit: str
    model: str  # an error model, or "auto": the chain's default (kincal.models.default_for)
    fix: tuple[str, ...]
    noise_mm: float
    joint_columns: tuple[tuple[str, str], ...]
    overwrite: bool
    criterion: str  # d | i
    target_cube: tuple[float, float, float, float] | None
    target_poses: int
    kind: str
    pivot: tuple[float, float, float] | None
    tool_offset: tuple[float, float, float] | None
    json: bool = False
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def run(args) -> int:
    p = typed(Plan, args, chain=Chain.of(args), volume=VolumeRequest.of(args))
    if p.volume.given and p.candidates is not None:
        raise OptionError("give either CANDIDATES.csv or a volume (--in-cube/--in-sphere)")
    if not p.volume.given and (p.candidates is None) == (p.random is None):
        raise OptionError("give exactly one of CANDIDATES.csv, --random M or --in-cube/--in-sphere")
    if p.target_cube is not None and p.criterion != "i":
        raise OptionError("--target-cube is the working volume of --criterion i; "
                          "--criterion d does not use it")
    robot = p.chain.load()  # drawn candidates on a chain with a mimic joint and its
    # master: refused where they are drawn (random_candidates, volume_candidates)
    protect = check_outputs(robot, [p.out], overwrite=p.overwrite,
                            inputs=[p.candidates, p.measured])
    return _plan(p, robot, protect)


def _plan(p: Plan, robot, protect: list) -> int:
    import numpy as np

    from kincal.planning.candidates import candidates_csv_text, random_candidates, read_candidates
    from kincal.planning.pose_selection import select_poses

    unit = length_scale(p.length_unit)
    tool = tool_guess(p.tool_offset, p.length_unit)
    tool = (0.0, 0.0, 0.0) if tool is None else tool
    columns = joint_map(p.joint_columns)
    spec = volume_spec(p.volume, robot, unit, tool)
    targets, collision = None, None  # collision: what the check of drawn poses covered
    if spec is not None:
        from kincal.planning.volume_candidates import volume_candidates

        m = 2000 if p.random is None else p.random
        if m < p.poses:
            raise OptionError(f"--random {m} candidates are fewer than the {p.poses} poses to "
                              "choose: ask for more candidates or fewer poses")
        vc = volume_candidates(robot, spec, m, seed=p.seed)
        q, lines = np.array(vc.joint_values), None
        source, collision = vc.summary(), vc.collision_note
    planes = None
    if p.kind in ("plane", "flush") and p.candidates is not None:  # contacts: a plane column
        from kincal.measurements.plane import PlaneData

        contacts = PlaneData.from_csv(p.candidates, robot.joint_names,
                                      [n for n, k in zip(robot.joint_names, robot.geometry.kinds)
                                       if k == "prismatic"], p.length_unit, p.angle_unit,
                                      joint_columns=columns)
        planes = contacts.planes if contacts.labels != ("",) else None
    if p.kind in ("plane", "flush") and (p.candidates is None or p.measured is not None):
        raise OptionError(f"--kind {p.kind} plans among contact poses: give CANDIDATES.csv "
                          "(joint columns of poses in contact; a 'plane' column where they touch "
                          "several planes), without --random or --measured")
    if p.candidates is not None:
        q, lines = read_candidates(p.candidates, robot, p.length_unit, p.angle_unit,
                                   joint_columns=columns)
        source = f"{len(q)} candidates from {p.candidates}"
    elif spec is None:
        assert p.random is not None  # one of CANDIDATES.csv, --random, a volume (run)
        q, lines = random_candidates(robot, p.random, p.seed), None
        source = f"{len(q)} random candidates within the joint limits (seed {p.seed})"
    measured = np.zeros((0, q.shape[1]))
    if p.measured is not None:  # poses already measured: kept, and only new ones written
        measured, _ = read_candidates(p.measured, robot, p.length_unit, p.angle_unit,
                                      kind="measured poses", joint_columns=columns)
        source += f", plus the {len(measured)} poses already measured in {p.measured}"
    k = len(measured)
    if p.target_cube is not None:
        from kincal.planning.volume_candidates import Volume, volume_candidates

        c = p.target_cube
        base_spec = spec if spec is not None else volume_spec(
            replace(p.volume, in_cube=c), robot, unit, tool)
        tspec = replace(base_spec, volume=Volume.cube([v * unit for v in c[:3]], c[3] * unit),
                        home=None if spec is None else tuple(vc.home))
        try:
            tv = volume_candidates(robot, tspec, p.target_poses, seed=p.seed + 1, what=_TARGETS)
        except OptionError as e:  # the volume named is the target cube, not --in-cube
            raise OptionError(f"--target-cube: {e}") from None
        targets = np.array(tv.joint_values)
        source += (f"\n  {len(targets)} target poses in the {tspec.volume.describe()} (same tilt "
                   "range and branch" + (f"; {tv.collision_note})" if spec is None else ")"))
        collision = tv.collision_note
    elif p.criterion == "i" and spec is not None:  # the default working volume
        from kincal.planning.volume_candidates import volume_candidates, working_volume

        tspec = working_volume(spec, vc.home)
        try:
            targets = np.array(volume_candidates(robot, tspec, p.target_poses,
                                                 seed=p.seed + 1, what=_TARGETS).joint_values)
        except OptionError as e:
            raise OptionError(f"the default working volume of --criterion i, {e}; give the "
                              "working volume (--target-cube) or --criterion d") from None
        source += (f"\n  {len(targets)} target poses in the {tspec.volume.describe()} around "
                   "the measurement volume (default working volume; tilt <= "
                   f"{math.degrees(tspec.max_tilt):g} deg, same branch)")
    elif p.criterion == "i":  # no volume: the candidates are where the robot can work
        targets = q
        source += "\n  target poses: the candidates themselves"
    from kincal.identification.blas_threads import limited

    with limited(1):  # small batched matrices: BLAS threads would only wait for each other
        selection = select_poses(robot, np.vstack([measured, q]), k + p.poses, tool=tool,
                                 fix=p.fix, keep=tuple(range(k)), method=p.criterion.upper(),
                                 model=None if p.model == "auto" else p.model,
                                 targets=targets, kind=p.kind,
                                 pivot=None if p.pivot is None else np.array(p.pivot) * unit,
                                 planes=planes)
    new = [i - k for i in selection.indices if i >= k]
    said = [f"{source}:", selection.summary(
        p.noise_mm, checked=None if spec is None else
        "candidates checked as above; line of sight is not checked")]
    if k:
        said.append(f"  (the selection includes the {k} poses already measured; {len(new)} new)")
    from kincal.export.outputs import File

    summary = {"command": "plan", "robot": str(robot.source), "candidates": int(len(q)),
               "measured": int(k), "criterion": p.criterion, "kind": p.kind,
               "model": selection.model, "collision": collision,
               "chosen": int(len(new)),
               "candidate_lines": None if lines is None else [int(v) for v in lines[new]],
               "joint_names": list(selection.joint_names),
               "joint_values_si": q[new].tolist(), "log_det": selection.log_det,
               "condition_number": selection.condition, "noise_mm": p.noise_mm,
               "noise": selection.noise_text(p.noise_mm),
               "std_errors": [{"name": n, "unit": u, "std_error": float(v)} for n, u, v in zip(
                   selection.parameters, selection.units, selection.std_errors(p.noise_mm))],
               "not_identifiable": list(selection.not_identifiable)}
    say_and_write([File(p.out, "csv", candidates_csv_text(
        selection.joint_names, q[new], None if lines is None else lines[new]))],
        lambda written: summary_lines(p.json, said, summary, written, wrote=lambda path: (
            f"  wrote {path} ({len(new)} new poses, joint values in rad and m)")),
        provenance=p.chain.provenance(robot, (p.candidates, p.measured), p.command_line),
        overwrite=p.overwrite, protect=protect)
    return 0
