"""``kincal calibrate``: identify the kinematics and write a corrected URDF.

Every data file, whatever its kind, is a measurement set of one calibration problem
(:class:`kincal.identification.problem.CalibrationProblem`); every file the run writes goes
through the one writer and its gate (:func:`kincal.export.outputs.write_calibration`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from kincal.cli.checks import check_outputs, distinct_inputs, plot_paths
from kincal.cli.options import (AccuracyRequest, Chain, Inputs, add_accuracy_options,
                                add_common, add_gate_overrides, add_kinds, add_model,
                                add_overwrite, group, typed)
from kincal.errors import KincalError, KincalWarning, OptionError


def register(subparsers) -> None:
    p = subparsers.add_parser("calibrate", help="identify the kinematics and write a corrected URDF")
    add_common(p, chains=True)
    add_kinds(p)
    group(p, "inputs").add_argument(
        "--shared-plane", action="store_true", dest="shared_planes",
        help="with --on-plane: the files touch the same physical plane(s): one set of plane "
             "parameters (plane.rx .ry .d; with a 'plane' column, one per plane number, the "
             "same number meaning the same plane in every file) instead of one per file. The "
             "planes are fitted in the base frame: the files' chains must have one --base")
    add_model(p, allow_auto=True)
    g = group(p, "model and penalty")
    g.add_argument("--method", choices=("l2", "ls", "frames"), default="l2",
                   help="l2 (default): least squares with a penalty toward nominal (its "
                        "weight: --lambda); ls: plain least squares; frames: the "
                        "measurement frame and tool point alone, the kinematics kept "
                        "nominal (what the nominal model gives with fitted frames)")
    g.add_argument("--lambda", dest="lam",
                   help="'auto' (default: 'evidence' on data from a small measurement volume, "
                        "'cv' otherwise), 'evidence' (priors toward nominal per parameter "
                        "class, scales and noise by maximum evidence), 'cv' (the paper's "
                        "k-fold CV) or a value >= 0")
    g.add_argument("--prior-mm", type=float, metavar="MM",
                   help="with --lambda evidence: tolerance (prior std) of the lengths [mm], "
                        "given instead of estimated")
    g.add_argument("--prior-deg", type=float, metavar="DEG",
                   help="with --lambda evidence: tolerance of the twists and joint offsets "
                        "[deg], given instead of estimated")
    g.add_argument("--noise-mm", type=float, metavar="MM",
                   help="with --lambda evidence: measurement noise, std per axis [mm], given "
                        "instead of estimated")
    g.add_argument("--prior", metavar="FLEET.json",
                   help="a fleet prior (kincal fleet's DIR/FLEET.json): the penalty is centred "
                        "on the fleet's mean deviation and shaped by its covariance instead of "
                        "pulling toward nominal (its scale by --lambda as usual)")
    g.add_argument("--folds", type=int, help="k of the k-fold cross-validation (default 5)")
    g.add_argument("--seed", type=int, help="seed of the CV fold split (default 0)")
    g.add_argument("--fix", nargs="+", default=[], metavar="NAME",
                   help="parameters held nominal: names (joint_3.a, tool.z) or quoted shell "
                        "patterns ('*.d', 'joint_[456].*')")
    g.add_argument("--free", nargs="+", default=[], metavar="NAME",
                   help="parameters kept even if found redundant (method l2); names or patterns")
    g.add_argument("--backlash", nargs="+", default=[], metavar="JOINT",
                   help="give these joints a backlash term (needs the acquisition order: "
                        "rows in order, or --order-column)")
    g.add_argument("--compliance", nargs="+", default=[], metavar="JOINT",
                   help="give these joints a compliance term: each turns by its compliance "
                        "times the gravity torque it carries (from the URDF's inertials)")
    g.add_argument("--robust", choices=("huber", "cauchy"),
                   help="robust loss on the per-pose error; down-weighted samples are listed")
    g.add_argument("--robust-scale-mm", type=float, help="scale of the robust loss [mm] "
                   "(default 2.5 x the median pose error)")
    group(p, "inputs").add_argument(
        "--validate", metavar="HELD.csv", nargs="+", default=[],
        help="held-out data (read as DATA is, same kind as a training file, or points on a "
             "pose calibration: its measurement frame and tool origin): its errors "
             "before and after, per axis, with the frames from the calibration (as kincal "
             "evaluate --frames), in the summary, --report and --html. One file, or one per "
             "data file, each judged on that file's chain with its set's frames (several "
             "chains: one per data file)")
    g.add_argument("--cv-max-poses", type=int, metavar="N",
                   help="choose lambda by CV on a random N of the poses when there are more "
                        "(default 2000; 0: all poses); the final fit uses every pose")
    o = group(p, "outputs")
    o.add_argument("--out", required=True, help="corrected URDF to write")
    o.add_argument("--frames-out", help="FRAMES.json: measurement frame and tool point (SI)")
    o.add_argument("--add-frames", action="store_true",
                   help="also add the measurement frame and tool point to the URDF as fixed "
                        "frames (kincal_measurement_frame, kincal_tool_point)")
    o.add_argument("--report", help="REPORT.json: the whole result")
    o.add_argument("--yaml-out", metavar="KINEMATICS.yaml",
                   help="corrected joint origins as YAML (x y z roll pitch yaw per joint; "
                        "--yaml-format says how it is keyed)")
    o.add_argument("--yaml-format", choices=("kincal", "ur"), default=None,
                   help="--yaml-out's layout: kincal (joint-name keys, the default) or ur "
                        "(ur_description's kinematics file: segment keys and hash)")
    o.add_argument("--ur-hash", metavar="HASH",
                   help="the hash for --yaml-format ur (default: copied from the "
                        "kinematics_params file the xacro was expanded with)")
    o.add_argument("--mdh-out", metavar="MDH.csv",
                   help="corrected modified-DH (Craig) table, convention in its header")
    o.add_argument("--residuals-out", metavar="RESIDUALS.csv",
                   help="every sample's residual vector after calibration as CSV (training "
                        "sets and the --validate set) [m]")
    o.add_argument("--plots", help="directory for PNG plots")
    o.add_argument("--html", metavar="REPORT.html",
                   help="one self-contained HTML report (plots embedded, opens offline)")
    add_accuracy_options(p)
    add_overwrite(p)
    add_gate_overrides(p)
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Calibrate:
    """The options of ``kincal calibrate``, typed (lengths as the user gave them)."""

    chain: Chain
    inputs: Inputs
    accuracy: AccuracyRequest
    model: str
    method: str  # l2 | ls | frames
    lam: str  # 'auto', 'cv', 'evidence' or a number as text (checked by cli.checks)
    prior_mm: float | None
    prior_deg: float | None
    noise_mm: float | None
    prior: str | None
    folds: int | None  # None: the default, DEFAULT_FOLDS
    seed: int
    fix: tuple[str, ...]
    free: tuple[str, ...]
    backlash: tuple[str, ...]
    compliance: tuple[str, ...]
    robust: str | None
    robust_scale_mm: float | None
    cv_max_poses: int
    shared_planes: bool
    out: str
    frames_out: str | None
    add_frames: bool
    report: str | None
    yaml_out: str | None
    yaml_format: str | None
    ur_hash: str | None
    mdh_out: str | None
    plots: str | None
    html: str | None
    validate: tuple[str, ...]  # held-out files: none, one, or one per data file
    residuals_out: str | None
    overwrite: bool
    accept_implausible: bool
    accept_unconverged: bool
    quiet: bool
    verbose: bool
    json: bool
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance

    def outputs(self) -> list:
        """Every file this run writes, for the check before the work."""
        return [self.out, self.frames_out, self.report, self.yaml_out, self.mdh_out,
                self.html, self.residuals_out] + plot_paths(
                    self.plots, len(self.inputs.files),
                    accuracy=self.accuracy.asked or self.html is not None)  # a map may go there


def calibration_options(c: Calibrate):
    """The CalibrationOptions of the run."""
    from kincal.cli.progress import FitStatus, progress_bar
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.prior import read_prior
    from kincal.identification.solver import SolverOptions

    from kincal.cli.checks import lambda_value

    return CalibrationOptions(model=c.model, method=c.method, lam=lambda_value(c.lam),
                              folds=c.folds,
                              seed=c.seed, prior_mm=c.prior_mm, prior_deg=c.prior_deg,
                              noise_mm=c.noise_mm, fix=c.fix, free=c.free, backlash=c.backlash,
                              compliance=c.compliance,
                              tool_guess=c.inputs.tool_guess, robust=c.robust,
                              robust_scale_mm=c.robust_scale_mm,
                              progress=None if c.quiet or c.json else progress_bar(),
                              cv_max_poses=c.cv_max_poses or None,
                              shared_planes=c.shared_planes,
                              prior=None if c.prior is None else read_prior(c.prior),
                              solver=SolverOptions(progress=None if c.quiet or c.json
                                                   else FitStatus.on_terminal()))


def _ur_hash(c: Calibrate, robot) -> str:
    """The hash of --yaml-format ur: --ur-hash, else the xacro's kinematics_params file's."""
    from kincal.cli.options import xacro_args
    from kincal.export.cell_exports import (UR_SEGMENTS, ur_hash_of, ur_hash_problem,
                                            ur_joints, ur_layout_problem)

    if ur_joints(robot.joint_names) is None:
        raise OptionError("--yaml-format ur needs a chain of the six UR joints ("
                          + ", ".join(j for _, j in UR_SEGMENTS) + "); this chain has "
                          + (", ".join(robot.joint_names) or "none"))
    problem = ur_layout_problem(robot)  # before the work, as the writer would refuse it
    if problem is not None:
        raise OptionError(problem)
    given = None if c.ur_hash is None else ur_hash_problem(c.ur_hash, "--ur-hash")
    if given is not None:
        raise OptionError(f"{given}, or leave the option out to copy it from that file")
    found = c.ur_hash or ur_hash_of(robot.source, xacro_args(c.chain.xacro_arg))
    if not found:
        raise OptionError("--yaml-format ur: no hash found (no kinematics_params file with a "
                          "hash: line for this robot); pass --ur-hash HASH")
    return found


def json_summary(result, validations, refused: bool, notes=()) -> dict:
    """The summary of ``--json``: the run's figures (REPORT.json's keys, without the
    per-sample residuals), given out by :func:`kincal.cli.console.summary_lines`; notes:
    the export's (``export_notes``, as in REPORT.json)."""
    from kincal.export import report
    from kincal.export.validation import validation_dict

    full = report.result_dict(result)
    keep = ("robot", "data", "lambda", "penalty_choice", "evidence", "errors", "parameters",
            "frames", "convergence", "plausibility", "model_choice", "diagnosis",
            "term_evidence")
    return {"command": "calibrate", "verdict": "REFUSED" if refused else "written",
            **{k: full[k] for k in keep},
            "sets": [{k: v for k, v in s.items() if k != "residuals"} for s in full["sets"]],
            "identifiability": {k: full["identifiability"][k] for k in
                                ("rank", "condition_number", "kept", "fixed")},
            "validation": validation_dict(validations), "export_notes": list(notes)}


def run(args) -> int:
    from kincal.cli.console import say, summary_lines
    from kincal.cli.options import xacro_args
    from kincal.export.outputs import Outputs, gate, write_calibration
    from kincal.identification.problem import CalibrationProblem

    c = typed(Calibrate, args, chain=Chain.of(args), inputs=Inputs.of(args),
              accuracy=AccuracyRequest.of(args))
    if c.shared_planes and not c.inputs.on_plane:
        raise OptionError("--shared-plane shares the planes of plane contacts: give it with "
                          "--on-plane (the files of joint columns are then plane contacts)")
    if (c.yaml_format is not None or c.ur_hash is not None) and c.yaml_out is None:
        raise OptionError("--yaml-format and --ur-hash describe --yaml-out's file: give "
                          "--yaml-out KINEMATICS.yaml")
    if c.ur_hash is not None and c.yaml_format != "ur":
        raise OptionError("--ur-hash is the hash of ur_description's kinematics file: give it "
                          "with --yaml-format ur (the kincal YAML has no hash)")
    from kincal.export.provenance import utc_now

    utc_now()  # a bad SOURCE_DATE_EPOCH fails here, before the work
    robots = Chain.load_all(c.chain.per_file(len(c.inputs.files)))  # each file's chain
    robot = robots[0]
    several = len({(r.base, r.tip) for r in robots}) > 1
    if several and (c.mdh_out is not None or c.yaml_format == "ur"):
        raise OptionError("--mdh-out and --yaml-format ur describe one chain; this calibration "
                          "has several (one --base/--tip per file): write --out or --yaml-out "
                          "(kincal format, every chain's joints)")
    if c.mdh_out is not None:  # before the fit, as the writer would refuse it
        from kincal.export.cell_exports import mdh_table_problem

        why = mdh_table_problem(robot)
        if why is not None:
            raise OptionError(f"--mdh-out: {why} (--out, --yaml-out)")
    ur_hash = _ur_hash(c, robot) if c.yaml_format == "ur" else None
    if c.accuracy.asked and several:
        raise OptionError("--accuracy-map and --accuracy-poses describe one chain; this "
                          "calibration has several (one --base/--tip per file)")
    distinct_inputs(c.inputs.files, c.validate)
    inputs = c.inputs.files + c.validate + tuple(
        p for p in (c.prior, c.accuracy.accuracy_poses) if p)
    check_outputs(robot, c.outputs(), overwrite=c.overwrite, inputs=inputs, dirs=[c.plots],
                  urdf_out=c.out)
    if c.validate:
        from kincal.cli.validate import check_count

        check_count(len(c.validate), len(c.inputs.files), several)
    sets = c.inputs.read_sets(robots)  # every file, each read as its kind on its chain
    options = calibration_options(c)
    with warnings.catch_warnings(record=True) as caught:  # kept for the HTML report
        warnings.simplefilter("always", KincalWarning)
        targets = c.accuracy.targets(robot)  # bad values fail here, before solving
        problem = CalibrationProblem(robots, sets, options)
        if c.accuracy.asked:  # before the fit
            from kincal.planning.accuracy_map import require_mappable

            require_mappable(problem.kinds)
        try:
            result = problem.solve()
        finally:
            if options.solver.progress is not None:
                options.solver.progress.close()
    for w in caught:  # and passed on to be printed as usual
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    validations: tuple = ()
    if c.validate:
        from kincal.cli.validate import held_out

        validations = tuple(held_out(result, c.inputs, path, k if len(c.validate) > 1 else None)
                            for k, path in enumerate(c.validate))
    refused = False
    try:  # the gate before any further work (write_calibration checks it again, quietly)
        accepted = gate(result, c.accept_implausible, c.accept_unconverged)
    except KincalError:
        if not (c.report or c.html or c.plots or c.residuals_out):  # no diagnosis asked
            if not c.quiet:
                print("\n".join(summary_lines(c.json, [result.summary()],
                                               json_summary(result, validations, True))))
            raise
        refused, accepted = True, []  # the writer writes the diagnosis, then raises
    for message in accepted:
        warnings.warn(message, KincalWarning)
    amap = None
    if (targets or c.html) and not refused:
        from kincal.planning.accuracy_map import mappable, result_accuracy_map

        # --html alone: the map where the data allow one (a point or pose set, one chain)
        if ((result.covariance is not None or targets) and not result.chains.several
                and mappable(result.sets)):
            amap = result_accuracy_map(result, **targets)

    def lines(written, notes):
        if c.quiet:
            return []
        if c.json:  # stdout holds the JSON alone; what was written goes to stderr
            return summary_lines(True, (), json_summary(result, validations, refused, notes),
                                 written)
        out = [result.summary()]
        said = set(out[0].splitlines())  # -v: the notes under its identifiable line once
        out += [f"  {line}" for line in result.identifiability.summary().splitlines()[1:]
                if (c.verbose and f"  {line}" not in said)
                or line.startswith(("weak", "  the poses"))]
        for validation in validations:
            out += [f"  {line}" for line in validation.lines()]
        out += [f"  export: {n}" for n in notes]
        if amap is not None:
            out.append("  " + amap.summary().replace("\n", "\n  "))
        if refused:
            return out + [f"  wrote the diagnosis of the REFUSED calibration: {path}"
                          for path in written]
        return out + [f"  wrote {path}" for path in written]

    outputs = Outputs(urdf=c.out, frames=c.frames_out, report=c.report, html=c.html,
                      yaml=c.yaml_out, yaml_format=c.yaml_format or "kincal",
                      ur_hash=ur_hash, mdh=c.mdh_out, plots=c.plots, add_frames=c.add_frames,
                      residuals=c.residuals_out, overwrite=c.overwrite, protect=inputs)
    with warnings.catch_warnings():  # the gate's warnings were given above, by gate()
        warnings.simplefilter("ignore", KincalWarning)
        write_calibration(
            result, outputs, accept_implausible=c.accept_implausible,
            accept_unconverged=c.accept_unconverged, accuracy=amap,
            warnings_seen=[str(w.message) for w in caught
                           if issubclass(w.category, KincalWarning)] + accepted,
            data_source=", ".join(c.inputs.files), command=c.command_line or None,
            validations=validations,
            xacro_args=xacro_args(c.chain.xacro_arg),
            before_commit=lambda written, notes: say(lines(written, notes)))
    return 0
