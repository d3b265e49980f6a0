"""``kincal calibrate``: identify the kinematics and write a corrected URDF.

One point file goes through the point problem, several files or other kinds through the
several-sets problem (two branches until they become one problem); each calibration
itself is one small function (:func:`_solve_points`, :func:`_solve_sets`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from kincal.cli.checks import check_outputs, plot_paths
from kincal.cli.console import say_and_write
from kincal.cli.options import (AccuracyRequest, Chain, Inputs, add_accuracy_options,
                                add_common, add_kinds, add_model, add_overwrite, group, typed)
from kincal.errors import KincalError, KincalWarning, OptionError


def register(subparsers) -> None:
    p = subparsers.add_parser("calibrate", help="identify the kinematics and write a corrected URDF")
    add_common(p)
    add_kinds(p)
    add_model(p)
    g = group(p, "model and penalty")
    g.add_argument("--method", choices=("l2", "ls", "frames"), default="l2")
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
    g.add_argument("--robust", choices=("huber", "cauchy"),
                   help="robust loss on the per-pose error; down-weighted samples are listed")
    g.add_argument("--robust-scale-mm", type=float, help="scale of the robust loss [mm] "
                   "(default 2.5 x the median pose error)")
    g.add_argument("--cv-max-poses", type=int, default=2000, metavar="N",
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
                   help="corrected joint origins as YAML keyed by joint name (x y z roll pitch "
                        "yaw, ur_description's kinematics layout)")
    o.add_argument("--mdh-out", metavar="MDH.csv",
                   help="corrected modified-DH (Craig) table, convention in its header")
    o.add_argument("--plots", help="directory for PNG plots")
    o.add_argument("--html", metavar="REPORT.html",
                   help="one self-contained HTML report (plots embedded, opens offline)")
    add_accuracy_options(p)
    add_overwrite(p)
    r = group(p, "the plausibility gate and the console")
    r.add_argument("--accept-implausible", action="store_true",
                   help="write the outputs even if the plausibility gate finds the result "
                        "implausible (wrong units, rows, tip or data are the usual causes)")
    r.add_argument("--accept-unconverged", action="store_true",
                   help="write the outputs even if the solver did not converge (best iterate)")
    r.add_argument("--quiet", action="store_true")
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
    folds: int
    seed: int
    fix: tuple[str, ...]
    free: tuple[str, ...]
    backlash: tuple[str, ...]
    robust: str | None
    robust_scale_mm: float | None
    cv_max_poses: int
    out: str
    frames_out: str | None
    add_frames: bool
    report: str | None
    yaml_out: str | None
    mdh_out: str | None
    plots: str | None
    html: str | None
    overwrite: bool
    accept_implausible: bool
    accept_unconverged: bool
    quiet: bool

    def outputs(self) -> list:
        """Every file this run writes, for the check before the work."""
        return [self.out, self.frames_out, self.report, self.yaml_out, self.mdh_out,
                self.html] + plot_paths(self.plots)


def calibration_options(c: Calibrate):
    """The CalibrationOptions of the run."""
    from kincal.cli.progress import FitStatus, progress_bar
    from kincal.identification.calibration import CalibrationOptions
    from kincal.identification.solver import SolverOptions

    lam = c.lam
    if lam not in ("auto", "cv", "evidence"):
        try:
            lam = float(lam)
        except ValueError:
            raise OptionError(f"--lambda must be 'auto', 'cv', 'evidence' or a number, got "
                              f"{lam!r}") from None
    return CalibrationOptions(model=c.model, method=c.method, lam=lam, folds=c.folds,
                              seed=c.seed, prior_mm=c.prior_mm, prior_deg=c.prior_deg,
                              noise_mm=c.noise_mm, fix=c.fix, free=c.free, backlash=c.backlash,
                              tool_guess=c.inputs.tool_guess, robust=c.robust,
                              robust_scale_mm=c.robust_scale_mm, progress=progress_bar(),
                              cv_max_poses=c.cv_max_poses or None,
                              solver=SolverOptions(progress=FitStatus.on_terminal()))


def run(args) -> int:
    c = typed(Calibrate, args, chain=Chain.of(args), inputs=Inputs.of(args),
              accuracy=AccuracyRequest.of(args))
    if c.inputs.wants_sets():  # several files, or poses, distances, plane contacts
        return _calibrate_sets(c)
    return _calibrate_points(c)


def _gate(result, verdict, c: Calibrate) -> None:
    """The plausibility gate: nothing is written for an implausible or unconverged result."""
    try:
        accepted = verdict.check(c.accept_implausible, c.accept_unconverged,
                                 refused="nothing is written")
    except KincalError:
        if not c.quiet:
            print(result.summary())
        raise
    for message in accepted + list(verdict.notes):
        warnings.warn(message, KincalWarning)


def _solve_points(robot, data, options):
    """The calibration of one point file: the result, its plausibility verdict in it."""
    from kincal.identification.calibration import CalibrationProblem

    try:
        return CalibrationProblem(robot, data, options).solve()
    finally:
        if options.solver.progress is not None:
            options.solver.progress.close()


def _solve_sets(robot, sets, options):
    """The calibration of several sets or other kinds: (result, plausibility verdict)."""
    from kincal.identification.multiset import MultiSetProblem
    from kincal.identification.plausibility import gather_sets, judge

    problem = MultiSetProblem(robot, sets, options)
    result = problem.solve()
    return result, judge(gather_sets(problem, result))


def _cell_exports(c: Calibrate, robot, corrected) -> list:
    from kincal.export.cell_exports import kinematics_yaml, mdh_table_csv

    files = []
    if c.yaml_out:
        files.append((c.yaml_out, kinematics_yaml(robot, corrected)))
    if c.mdh_out:
        files.append((c.mdh_out, mdh_table_csv(corrected)))
    return files


def _calibrate_points(c: Calibrate) -> int:
    from kincal.export import report

    robot = c.chain.load()
    check_outputs(robot, c.outputs(), overwrite=c.overwrite, inputs=c.inputs.files,
                  dirs=[c.plots])
    data = c.inputs.read_points(robot)
    options = calibration_options(c)
    with warnings.catch_warnings(record=True) as caught:  # kept for the HTML report
        warnings.simplefilter("always", KincalWarning)
        targets = c.accuracy.targets(robot)  # bad values fail here, before solving
        result = _solve_points(robot, data, options)
    for w in caught:  # and passed on to be printed as usual
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    _gate(result, result.plausibility, c)
    amap = None
    if targets or c.html:
        from kincal.planning.accuracy_map import result_accuracy_map

        if result.covariance is not None or targets:
            amap = result_accuracy_map(result, **targets)
    edits, moved = result.export_edits()
    text = result.urdf_with_frames(edits.text) if c.add_frames else edits.text
    files = [(c.out, text)]
    if c.frames_out:
        files.append((c.frames_out, report.dumps(result.frames_dict())))
    if c.report:
        content = report.result_dict(result, str(c.inputs.data))
        if amap is not None:
            content["accuracy_map"] = amap.as_dict()
        files.append((c.report, report.dumps(content)))
    files += _cell_exports(c, robot, result.corrected)
    if c.plots:
        files += _render_plots(result, Path(c.plots))
        if amap is not None and len(amap.std):
            from kincal.export.diagnostic_plots import plot_accuracy_map

            files.append((Path(c.plots) / "accuracy_map.png", plot_accuracy_map(amap)))
    if c.html:
        from kincal.export.html_report import html_report

        files.append((c.html, html_report(
            result, accuracy=amap, data_source=str(c.inputs.data),
            warnings=[str(w.message) for w in caught if issubclass(w.category, KincalWarning)],
            notes=[f"export: {m.describe()}" for m in moved])))
    def lines(written):
        if c.quiet:
            return []
        out = [result.summary()]
        out += [f"  {line}" for line in result.identifiability.summary().splitlines()[1:]
                if line.startswith(("weak", "  the poses"))]
        out += [f"  export: {m.describe()}" for m in moved]
        if amap is not None:
            out.append("  " + amap.summary().replace("\n", "\n  "))
        return out + [f"  wrote {path}" for path in written]

    say_and_write(files, lines, overwrite=c.overwrite, protect=[robot.source, c.inputs.data],
                  dirs=[c.plots] if c.plots else [])
    return 0


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


def _refuse_with_sets(c: Calibrate) -> None:
    """OptionError for an option the several-sets path does not have yet."""
    for option, given in (("plots", c.plots), ("add_frames", c.add_frames),
                          ("report", c.report), ("robust", c.robust), ("html", c.html),
                          ("accuracy_map", c.accuracy.accuracy_map),
                          ("accuracy_poses", c.accuracy.accuracy_poses)):
        if given:
            raise OptionError(f"--{option.replace('_', '-')} is not available with several "
                              "data files or with pose, distance or plane files yet")


def _calibrate_sets(c: Calibrate) -> int:
    from kincal.export import report

    _refuse_with_sets(c)
    robot = c.chain.load()
    check_outputs(robot, c.outputs(), overwrite=c.overwrite, inputs=c.inputs.files)
    sets = c.inputs.read_sets(robot)
    result, verdict = _solve_sets(robot, sets, calibration_options(c))
    _gate(result, verdict, c)
    files = [(c.out, result.corrected_urdf_text())]
    files += _cell_exports(c, robot, result.corrected)  # whatever measured it
    if c.frames_out:
        files.append((c.frames_out, report.dumps({"format": "kincal-frames-sets-1",
                                                  "tip": robot.tip, "base": robot.base,
                                                  **result.frames_dict()})))
    say_and_write(files, lambda written: [] if c.quiet else
                  [result.summary()] + [f"  wrote {path}" for path in written],
                  overwrite=c.overwrite, protect=[robot.source, *c.inputs.files])
    return 0
