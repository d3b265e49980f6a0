"""``kincal simulate``: a synthetic data set from a robot with planted errors."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from kincal.cli.checks import check_outputs
from kincal.cli.console import say_and_write, summary_lines
from kincal.cli.options import (ORIENTATION_FORMATS, Chain, add_common, add_model,
                                add_overwrite, group, typed)
from kincal.cli.volume_options import VolumeRequest, add_volume_options, volume_spec
from kincal.errors import OptionError

if TYPE_CHECKING:
    from kincal.measurements.kind import SampleSet


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate",
                              help="a synthetic data set from a robot with planted errors")
    add_common(p, data=False)
    add_model(p, default="placement",
              help="error model in which the errors are planted (default placement: every "
                   "component of every joint placement, as a real arm has)")
    group(p, "outputs").add_argument("--out", required=True, help="CSV to write (SI units)")
    m = group(p, "measurement")
    m.add_argument("--design", choices=("tracker", "rtest"),
                   help="tracker (default): 400 mm cube, tilt <= 30 deg; rtest: 20 mm cube, "
                        "tilt <= 15 deg (with a volume: its default tilt only)")
    m.add_argument("--kind", choices=("point", "pose", "distance", "plane", "flush"),
                   default="point",
                   help="what is measured: points (default), 6-DoF tool poses, distances to "
                        "a pivot 0.3 m below the poses, contacts with 3 planes through them "
                        "(a third of --poses on each, at least 3)")
    m.add_argument("--orientation-noise-deg", type=float,
                   help="sd of orientation noise per axis [deg] (--kind pose, default 0.01; "
                        "--kind flush: of the face's two tilts, default 0.05)")
    m.add_argument("--orientation-format", choices=ORIENTATION_FORMATS, metavar="FORMAT",
                   help="how --kind pose writes its orientations (default quat-xyzw: qx qy qz "
                        "qw; quat-wxyz, rpy-zyx: roll pitch yaw as R = Rz Ry Rx, rpy-xyz, "
                        "rotvec, matrix; angles in radians): read it back with the same "
                        "--orientation-format")
    m.add_argument("--poses", type=int, help="poses to simulate (default 60)")
    m.add_argument("--center-m", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="cube centre in the base frame [m]")
    m.add_argument("--size-mm", type=float, help="cube edge [mm] (default: 400 for tracker, "
                   "200 for the small UR3; 20 for rtest)")
    m.add_argument("--tilt-deg", type=float, help="largest tilt of the tool from pointing down")
    t = group(p, "the simulated robot and cell")
    t.add_argument("--tool-m", nargs=3, type=float, default=(0.0, 0.0, 0.12),
                   metavar=("X", "Y", "Z"), help="true tool point in the tip frame [m]")
    t.add_argument("--base-frame", nargs=6, type=float, default=(0.8, 0.3, -0.2, 1.0, -2.0, 60.0),
                   metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   help="true measurement frame: x y z [m], rx ry rz [deg]")
    t.add_argument("--length-error-mm", type=float, default=0.3,
                   help="sd of planted length errors")
    t.add_argument("--angle-error-deg", type=float, default=0.03,
                   help="sd of planted angle errors")
    m.add_argument("--noise-mm", type=float, default=0.05, help="sd of position noise per axis")
    m.add_argument("--seed", type=int, default=0, help="seed of the poses and the noise")
    t.add_argument("--truth-seed", type=int, default=0,
                   help="seed of the planted errors: equal seeds, equal robot")
    group(p, "outputs").add_argument("--truth-out", help="JSON with the planted parameters")
    add_volume_options(p, "metres")
    m.add_argument("--poses-file", metavar="CHOSEN.csv",
                   help="simulate at these poses (chain joint columns in rad and m, e.g. from "
                        "'kincal plan') instead of drawing them")
    add_overwrite(p, help="replace existing output files (--out, --truth-out)")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Simulate:
    """The options of ``kincal simulate`` (SI unless the name says otherwise)."""

    chain: Chain
    volume: VolumeRequest
    model: str
    out: str
    design: str  # tracker | rtest
    kind: str  # point | pose | distance | plane | flush
    orientation_noise_deg: float
    orientation_format: str | None  # of --kind pose; None: quat-xyzw
    poses: int
    center_m: tuple[float, float, float] | None
    size_mm: float | None
    tilt_deg: float | None
    tool_m: tuple[float, float, float]
    base_frame: tuple[float, ...]  # x y z [m], rx ry rz [deg]
    length_error_mm: float
    angle_error_deg: float
    noise_mm: float
    seed: int
    truth_seed: int
    truth_out: str | None
    poses_file: str | None
    overwrite: bool
    json: bool = False
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def run(args) -> int:
    s = typed(Simulate, args, chain=Chain.of(args), volume=VolumeRequest.of(args))
    import numpy as np

    from kincal import models
    from kincal.planning import simulation

    if s.orientation_format is not None and s.kind != "pose":
        raise OptionError(f"--orientation-format is how --kind pose writes its orientations; "
                          f"--kind {s.kind} writes none")
    if s.truth_out and s.kind != "point":  # before the poses are solved, not after
        raise OptionError("--truth-out is written for --kind point only")
    robot = s.chain.load()  # drawn poses on a chain with a mimic joint and its master:
    # refused where they are drawn (cube_poses, volume_candidates; a poses file's are its own)
    if s.kind in ("plane", "flush"):  # contacts move every chain joint, given poses too
        from kincal.measurements.fixed_joints import refuse_coupled

        refuse_coupled(robot, "simulating contacts (every chain joint moved onto the planes, "
                              "candidates drawn beside the given poses)")
    protect = check_outputs(robot, [s.out, s.truth_out], overwrite=s.overwrite,
                            inputs=[s.poses_file])
    model = models.build(s.model, robot.geometry)
    rng = np.random.default_rng(s.seed)
    design = {"tracker": (0.4, 30.0), "rtest": (0.02, 15.0)}[s.design]
    tilt = s.tilt_deg if s.tilt_deg is not None else design[1]
    tool = np.array(s.tool_m)
    if s.tilt_deg is not None and s.volume.max_tilt is not None:
        raise OptionError("give --max-tilt or --tilt-deg, not both (the same limit)")
    spec = volume_spec(s.volume, robot, 1.0, tool, default_tilt=tilt)
    collision = None  # what the check of poses drawn in a volume covered
    if s.poses_file is not None:
        from kincal.planning.candidates import read_candidates

        if spec is not None:
            raise OptionError("give either --poses-file or a volume (--in-cube/--in-sphere)")
        q, _ = read_candidates(s.poses_file, robot, kind="poses")
        where = f"at the {len(q)} poses of {s.poses_file}"
    elif spec is not None:
        from kincal.planning.volume_candidates import volume_candidates

        vc = volume_candidates(robot, spec, s.poses, seed=s.seed)
        q, collision = np.array(vc.joint_values), vc.collision_note
        where = (f"{s.design}: {spec.volume.describe()}, tilt <= "
                 f"{math.degrees(spec.max_tilt):g} deg, random poses on one branch")
    else:  # the default cube: its centre and size are needed only here
        from kincal.cli.progress import progress_bar
        from kincal.descriptions import default_center, max_cube

        center = default_center(robot.name) if s.center_m is None else s.center_m
        size = max_cube(robot.name, design[0]) if s.size_mm is None else s.size_mm * 1e-3
        q = simulation.cube_poses(robot, s.poses, center, size, tool, rng,
                                  max_tilt=math.radians(tilt),
                                  progress=progress_bar(label="inverse kinematics", unit="poses")
                                  if s.poses >= 1000 else None)
        where = f"{s.design}: {size * 1e3:g} mm cube at {np.round(center, 3).tolist()} m"
    # the robot's errors have their own seed, so data sets with different pose seeds
    # (calibration, validation) come from one and the same simulated robot
    table = simulation.planted_table(model, np.random.default_rng(s.truth_seed),
                                     s.length_error_mm * 1e-3, math.radians(s.angle_error_deg))
    base = np.array(s.base_frame)
    base[3:] = np.radians(base[3:])
    from kincal.export.outputs import File

    prov = s.chain.provenance(robot, (s.poses_file,), s.command_line)
    summary = {"command": "simulate", "robot": str(robot.source), "kind": s.kind,
               "poses": len(q), "design": s.design, "where": where, "collision": collision,
               "noise_m": s.noise_mm * 1e-3, "seed": s.seed, "truth_seed": s.truth_seed}
    noted = [] if collision is None else [f"  {collision}"]  # said under the line
    if s.kind != "point":
        csv, n = _other_kind_csv(s, robot, model, q, table, tool, base, rng)
        # plane contacts come as a whole number per plane (at least 3): say what was written
        summary["poses"] = n
        asked = "" if n == len(q) else f"; {n // 3} on each of 3 planes, {len(q)} asked"
        say_and_write([File(s.out, "csv", csv)],
                      lambda written: summary_lines(s.json, [
                          f"simulated {s.kind} measurements of {robot.name} at {n} poses "
                          f"({s.design} design{asked}), noise {s.noise_mm} mm: "
                          + ", ".join(map(str, written)), *noted], summary, written,
                          wrote=None),
                      provenance=prov, overwrite=s.overwrite, protect=protect)
        return 0
    truth = simulation.Truth(table, base, tool)
    data = simulation.measure(model, truth, q, s.noise_mm * 1e-3, rng, source="simulated")
    files = [File(s.out, "csv", data.to_csv_text())]
    if s.truth_out:
        files.append(File(s.truth_out, "json", _truth_json(s, robot, model, truth)))
    say_and_write(files, lambda written: summary_lines(s.json, [
        f"simulated {len(q)} poses of {robot.name} ({where}, noise {s.noise_mm} mm): "
        + ", ".join(map(str, written)), *noted], summary, written, wrote=None),
        provenance=prov, overwrite=s.overwrite, protect=protect)
    return 0



def _truth_json(s: Simulate, robot, model, truth) -> dict:
    import numpy as np

    from kincal.measurements.point_space import ParameterSpace

    sp = ParameterSpace.of_model(model)
    x, x0 = truth.x(sp), sp.join(model.nominal, np.zeros(6), np.zeros(3))
    return {
        "format": "kincal-truth-1", "robot": str(robot.source), "seed": s.seed,
        "truth_seed": s.truth_seed, "parameters_si": dict(zip(sp.names, x.tolist())),
        "deviations_si": dict(zip(sp.names[:sp.n_kinematic],
                                  (x - x0)[:sp.n_kinematic].tolist())),
        "noise_m": s.noise_mm * 1e-3}


def _other_kind_csv(s: Simulate, robot, model, q, table, tool, base, rng) -> tuple[str, int]:
    """CSV text of a simulated set of kind ``s.kind`` (not points) at poses q, and its
    number of samples."""
    import numpy as np

    from kincal.measurements.sets import to_csv_text
    from kincal.planning import kind_simulation as ks

    noise = s.noise_mm * 1e-3
    data: SampleSet
    if s.kind == "pose":
        data = ks.simulate_poses(model, table, base, np.r_[tool, 0.0, 0.0, 0.0], q, noise,
                                 s.orientation_noise_deg, rng, source="simulated")
    elif s.kind == "distance":
        pivot = np.mean(ks.tool_points(model, table, q, tool), axis=0) + [0.0, 0.0, -0.3]
        data = ks.simulate_distances(model, table, pivot, tool, q, noise, rng, source="simulated")
    elif s.kind == "flush":  # a table through the middle of the poses' tool points
        c = np.mean(ks.tool_points(model, table, q, tool), axis=0)
        g = robot.geometry
        lo, hi = g.ranges()
        cand = np.vstack([q, rng.uniform(lo, hi, size=(40 * len(q), g.n))])
        data = ks.simulate_flush(model, table, np.r_[tool, 0.0, 0.0], [[0.0, 0.0, c[2]]],
                                 cand, len(q), noise, s.orientation_noise_deg, rng,
                                 source="simulated", limits=(lo, hi))
    else:  # three planes through the middle of the poses' tool points: a table, two walls
        c = np.mean(ks.tool_points(model, table, q, tool), axis=0)
        planes = np.array([[0.0, 0.0, c[2]], [0.0, math.pi / 2, c[0]],
                           [-math.pi / 2, 0.0, c[1]]])
        g = robot.geometry
        lo, hi = g.ranges()
        cand = np.vstack([q, rng.uniform(lo, hi, size=(40 * len(q), g.n))])
        per = max(3, len(q) // 3)
        data = ks.simulate_contacts(model, table, tool, planes, cand, per, noise, rng,
                                    source="simulated")
    return to_csv_text(data, s.orientation_format or "quat-xyzw"), len(data)
