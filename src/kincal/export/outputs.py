"""The one writer of every file kincal writes, with the plausibility gate in front of a
calibration's.

``write_calibration(result, Outputs(urdf=..., frames=..., report=..., html=..., yaml=...,
mdh=..., plots=...))`` is the only way the API and ``kincal calibrate`` write what a
calibration produced. It refuses an implausible or unconverged result (one KincalError line
naming the evidence) unless accepted, then composes every output, reads the corrected URDF
back strictly (:mod:`kincal.export.readback`), and writes them as one
transaction: all of them, or none (:func:`kincal.export.safe_write.write_all`).
``write_files(files, provenance, ...)`` (defined in :mod:`kincal.export.writer`, below
the figure modules, so that the plot functions write through it too) does the same for
every other file (simulate, plan, evaluate, ..., the public plot functions' PNGs): each
carries the run's provenance (:mod:`kincal.export.provenance`), the one way it gets there.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

from kincal.errors import (ExportError, ImplausibleResultError, KincalWarning,
                           NotConvergedError)
# re-exported: the one writer's general form (every file but a calibration's), whose face
# this module is
from kincal.export.writer import File, write_files


@dataclass(frozen=True)
class Outputs:
    """What to write (None: not written). urdf: the corrected URDF; frames: FRAMES.json
    (:mod:`kincal.frames_file`); report: REPORT.json; html: the self-contained report;
    yaml / mdh: the cell formats of :mod:`kincal.export.cell_exports`; plots: a folder of
    PNG plots; residuals: every sample's residual vector as CSV
    (:func:`kincal.export.validation.residuals_csv`, the held-out set's too). yaml_format: "kincal" (joint-name keys) or "ur" (ur_description's segment
    keys and ``ur_hash``, the robot's calibration hash, required then). add_frames: also put the measurement frame and tool point(s) into the URDF
    as fixed frames. overwrite: replace existing files. protect: input files that must
    never be replaced (the URDF and data are added from the result)."""

    urdf: Path | str | None = None
    frames: Path | str | None = None
    report: Path | str | None = None
    html: Path | str | None = None
    yaml: Path | str | None = None
    mdh: Path | str | None = None
    plots: Path | str | None = None
    residuals: Path | str | None = None
    yaml_format: str = "kincal"
    ur_hash: str | None = None
    add_frames: bool = False
    overwrite: bool = False
    protect: tuple = ()

    def paths(self) -> list[Path]:
        """The files and folders asked for, in writing order."""
        return [Path(p) for p in (self.urdf, self.frames, self.report, self.yaml, self.mdh,
                                  self.residuals, self.html, self.plots) if p is not None]


@dataclass(frozen=True)
class Written:
    """What :func:`write_calibration` wrote: the files, and the export's notes (joint
    offsets moved into child origins, rpy near gimbal lock), one line each."""

    paths: tuple[Path, ...]
    notes: tuple[str, ...]


def gate(result, accept_implausible: bool = False, accept_unconverged: bool = False) -> list[str]:
    """The gate's check: raises ImplausibleResultError / NotConvergedError (nothing is
    written) unless accepted; returns the warnings of what was accepted and the gate's
    notes."""
    if result.plausibility is None:
        raise ExportError("this result carries no plausibility verdict (it was not made by "
                          "CalibrationProblem.solve()); nothing is written")
    accepted = result.plausibility.check(accept_implausible, accept_unconverged,
                                         refused="nothing is written")
    return list(accepted) + list(result.plausibility.notes)


def corrected_urdf(result, readable: bool = True, add_frames: bool = False):
    """(text, export notes) of the corrected URDF: the original file with only the chains'
    joint origins changed (plus fixed frames for the measurement frame and tool points
    with ``add_frames``; a flush contact face's tilt in the fixed joint above the tip,
    :mod:`kincal.export.contact_fold`)."""
    text, notes, _ = _corrected(result, readable, add_frames)
    return text, notes


def _corrected(result, readable: bool = True, add_frames: bool = False,
               no_fold: str | None = None):
    """(text, export notes, the contact folds made). no_fold: why no contact face's tilt may
    go into the URDF (another file written beside cannot carry it), or None."""
    from kincal.export.contact_fold import folds
    from kincal.export.readable_export import corrected_text, regauged_joints
    from kincal.export.readback import chain_ends

    edits, moved = corrected_text(result.robot, result.corrected, readable,
                                  source=str(result.robot.source),
                                  joints=tuple(result.error_model.joint_names),
                                  ends=chain_ends(result))
    text = edits.text
    made: tuple = ()
    said: tuple[str, ...] = ()
    if add_frames or no_fold:
        if add_frames:
            from kincal.export.urdf_export import add_frames_of

            text = add_frames_of(result, text)
        why = no_fold or "--add-frames hangs the frames on the tip as identified"
        said = tuple(f"the contact face's tilt on {f.tip!r} stays in FRAMES.json only: {why}"
                     for f in folds(result)[0])
    else:  # the added frames hang tool points on the tip as identified: no fold under them
        from kincal.export.urdf_export import edit_joint_origins

        made, said = folds(result, exclude=regauged_joints(moved))
        if made:
            text = edit_joint_origins(text, {f.joint: f.origin for f in made},
                                      source=str(result.robot.source)).text
    from kincal.export import base_motion

    return (text, tuple(m.describe() for m in moved) + tuple(f.describe() for f in made) + said
            + base_motion.notes(result), made)


def corrected_urdf_text(result, readable: bool = True) -> str:
    """The corrected URDF text (no gate: for looking at; writing goes through
    :func:`write_calibration`)."""
    return corrected_urdf(result, readable)[0]


def write_calibration(result, outputs: Outputs, *, accept_implausible: bool = False,
                      accept_unconverged: bool = False, accuracy=None,
                      warnings_seen=(), data_source: str | None = None,
                      before_commit=None, command=None, xacro_args=None,
                      validations=(), dirs=(), shared_dirs=()) -> Written:
    """Check the gate, then write every output of ``outputs`` all-or-none.

    accuracy: a predicted accuracy map to add to the report, the HTML and the plots.
    warnings_seen: the run's warnings, for the HTML report. before_commit: called with
    (written paths, export notes) once every file is staged and before any takes its name
    (the command line prints there, so that a console that fails leaves nothing written).
    command / xacro_args: the command line and the xacro arguments, for the provenance
    every file carries (:mod:`kincal.export.provenance`). validations: the
    :class:`~kincal.export.validation.Validation` of each held-out file for the report and
    the HTML. dirs: folders the writing may make for the files, outermost first (one level
    each, removed again if it fails; :func:`kincal.export.safe_write.write_all`), e.g. a
    fleet unit's staging folder; shared_dirs: folders made if missing and never removed
    (other writers fill them at the same time: the fleet's folder). A result the gate
    refuses still gets the diagnosis asked for (report, HTML, plots, marked REFUSED; never
    the URDF, frames or cell files), then the refusal is raised naming where the diagnosis
    went.
    Returns :class:`Written`.
    """
    o = outputs
    if not isinstance(o, Outputs):
        raise ExportError(f"outputs must be an Outputs(urdf=..., frames=..., ...), got "
                          f"{type(o).__name__}")
    for name in ("urdf", "frames", "report", "html", "yaml", "mdh", "plots", "residuals"):
        value = getattr(o, name)
        if value is not None and (not isinstance(value, (str, Path)) or not str(value).strip()):
            raise ExportError(f"the {name} output path {value!r} is empty or not a path; "
                              "expected a file name (a folder for plots)")
    if o.yaml_format not in ("kincal", "ur"):
        raise ExportError(f"yaml_format must be 'kincal' or 'ur', got {o.yaml_format!r}")
    if o.ur_hash is not None and (o.yaml is None or o.yaml_format != "ur"):
        raise ExportError("ur_hash is the hash of ur_description's kinematics file: give it "
                          "with yaml=... and yaml_format='ur' (the kincal YAML has no hash)")
    several = result.chains is not None and result.chains.several
    if several and ((o.yaml is not None and o.yaml_format == "ur") or o.mdh is not None):
        raise ExportError("a UR kinematics file and an MD-H table describe one chain; this "
                          "calibration has several: write the URDF or the kincal YAML (every "
                          "chain's joints)")
    if o.yaml_format == "ur" and o.yaml is not None:
        from kincal.export.cell_exports import ur_hash_problem

        problem = ur_hash_problem(o.ur_hash, "yaml_format 'ur' needs ur_hash: it")
        if problem is not None:
            raise ExportError(problem)
    from kincal.export.provenance import Provenance, stamp_urdf

    sources = [s.source for s in result.sets]
    held = tuple(v.source for v in validations)
    try:
        accepted = gate(result, accept_implausible, accept_unconverged)
    except (ImplausibleResultError, NotConvergedError) as exc:
        if o.report is None and o.html is None and o.plots is None and o.residuals is None:
            raise
        diagnosis = Outputs(report=o.report, html=o.html, plots=o.plots, residuals=o.residuals,
                            overwrite=o.overwrite, protect=o.protect)
        why = _refusal(result, accept_implausible, accept_unconverged,
                       "no URDF, frames or cell file is written")
        prov = Provenance.of(result, command=command, xacro_args=xacro_args, refused=why,
                             more_data=held)
        staged = _diagnosis(result, diagnosis, prov, None, warnings_seen,
                            data_source or ", ".join(sources), (), validations, refused=why)
        written = _write(result, diagnosis, staged, sources, before_commit, (), dirs,
                         shared_dirs)
        result.plausibility.check(  # raises again, saying where the diagnosis went
            accept_implausible, accept_unconverged,
            refused="no URDF, frames or cell file is written; the diagnosis (marked REFUSED) "
                    "is in " + ", ".join(map(str, _shown(written.paths, o.plots))))
        raise  # not reached: check() raised
    for message in accepted:
        warnings.warn(message, KincalWarning)
    prov = Provenance.of(result, command=command, xacro_args=xacro_args, more_data=held)
    files: list = []
    notes: tuple[str, ...] = ()
    made: tuple = ()  # the contact folds of the URDF (FRAMES.json then holds zero tilts)
    if o.urdf is not None:
        from kincal.export.readback import check_readback

        text, notes, made = _corrected(result, add_frames=o.add_frames, no_fold=(
            "ur_description's kinematics file (--yaml-format ur) has no place for it, and the "
            "URDF written beside describes the same robot" if o.yaml is not None
            and o.yaml_format == "ur" else None))
        stamped = stamp_urdf(text, prov)  # the text as written, provenance comment and all:
        check_readback(result, stamped, o.add_frames, made)  # only the origins changed, and
        # to the calibrated model as a URDF reader reads them
        files.append((o.urdf, stamped))
    if o.frames is not None:  # made: a URDF text was written, whose folds are recorded
        from kincal.export.contact_fold import folded_frames

        frames = folded_frames(result.frames(), made, text if made else "")
        if o.urdf is not None:  # the origins written beside, for readers given a URDF
            from kincal.tilts_in_urdf import joint_origins

            frames = replace(frames, urdf_origins=joint_origins(
                text, result.error_model.joint_names))
        files.append((o.frames, frames.dumps(provenance=prov.as_dict())))
    if o.yaml is not None or o.mdh is not None:
        from kincal.export.cell_exports import (kinematics_yaml, mdh_table_csv,
                                                ur_kinematics_yaml)

        if o.yaml is not None and o.yaml_format == "ur":
            assert o.ur_hash is not None  # checked above
            files.append((o.yaml, prov.under_title(ur_kinematics_yaml(
                result.robot, result.corrected, o.ur_hash))))
        elif o.yaml is not None:
            files.append((o.yaml, prov.under_title(kinematics_yaml(
                result.robot, result.corrected, joints=result.error_model.joint_names,
                chains=result.chains_text(),
                fixed=[(f.joint, f.nominal, f.origin) for f in made]))))
        if o.mdh is not None:
            files.append((o.mdh, prov.under_title(mdh_table_csv(  # one chain: one fold
                result.corrected, made[0].change if made else None))))
    files += _diagnosis(result, o, prov, accuracy, warnings_seen,
                        data_source or ", ".join(sources), notes, validations)
    return _write(result, o, files, sources, before_commit, notes, dirs, shared_dirs)


def _refusal(result, accept_implausible, accept_unconverged, refused: str) -> str:
    """The gate's refusal message, ``refused`` saying what the refusal means."""
    try:
        result.plausibility.check(accept_implausible, accept_unconverged, refused=refused)
    except (ImplausibleResultError, NotConvergedError) as exc:
        return str(exc)
    raise ExportError("the gate refused this result once and accepted it the second time")


def _shown(written, plots) -> list:
    """The written paths with a plots folder named once."""
    out: list = []
    for p in written:
        p = Path(p)
        if plots is not None and p.parent.resolve() == Path(plots).resolve():
            p = Path(plots)
        if p not in out:
            out.append(p)
    return out


def _diagnosis(result, o: Outputs, prov, accuracy, warnings_seen, data_source, notes,
               validations, refused: str | None = None) -> list:
    """(path, content) of the report, the plots and the HTML: what a calibration's
    diagnosis is, written whether the gate accepted the result or refused it."""
    from kincal.export import report

    files: list = []
    if o.report is not None:
        content = report.result_tree(result, data_source)  # arrays made JSON as written
        if accuracy is not None:
            content["accuracy_map"] = accuracy.as_dict()
        if validations:
            from kincal.export.validation import validation_dict

            content["validation"] = validation_dict(validations)
        if refused is not None:
            content["refused"] = {"verdict": "REFUSED", "message": refused}
        content["export_notes"] = list(notes)  # what the summary says under "export:"
        content["provenance"] = prov.as_dict()
        files.append((o.report, report.dump_pieces(content)))
    if o.residuals is not None:
        from kincal.export.validation import residuals_csv

        files.append((o.residuals, residuals_csv(result, validations, prov.hash_comment())))
    if o.plots is not None:
        files += _plots(result, Path(o.plots), accuracy, prov)
    if o.html is not None:
        from kincal.export.html_report import html_report

        files.append((o.html, html_report(
            result, accuracy=accuracy, data_source=data_source,
            warnings=list(warnings_seen), notes=[f"export: {n}" for n in notes],
            provenance=prov, refused=refused, validations=validations)))
    return files


def _write(result, o: Outputs, files, sources, before_commit, notes, dirs=(),
           shared_dirs=()) -> Written:
    from kincal.export.safe_write import write_all

    if not files:
        if before_commit is not None:
            before_commit([], notes)
        return Written((), notes)
    protect = [p for p in (result.robot.source, *sources) if p and not str(p).startswith("<")]
    hook = None if before_commit is None else (lambda targets: before_commit(targets, notes))
    in_place = [(o.urdf, result.robot.source)] if o.urdf is not None and protect else []
    written = write_all(files, overwrite=o.overwrite, protect=[*protect, *o.protect],
                        in_place=in_place,
                        dirs=[*dirs, *([o.plots] if o.plots is not None else [])],
                        shared_dirs=shared_dirs, before_commit=hook)
    return Written(tuple(written), notes)


def _plots(result, out_dir: Path, accuracy=None, prov=None) -> list:
    """(path, png bytes) pairs of the calibration plots, so the PNGs go to ``out_dir`` in
    the same transaction as the other files; ``prov`` goes into each PNG's text fields."""
    from kincal.export.plots import ACCURACY_MAP_PNG, calibration_figures

    source = "kincal" if prov is None else prov.png_text()
    files = [(out_dir / name, png) for name, png in calibration_figures(result, source)]
    if accuracy is not None and len(accuracy.std):
        from kincal.export.diagnostic_plots import plot_accuracy_map

        files.append((out_dir / ACCURACY_MAP_PNG, plot_accuracy_map(accuracy, source=source)))
    return files
