"""The paper's experiment, written down: Tables 2-4 as Markdown, the plots, the report
folder and ``kincal demo`` (the experiment itself is :mod:`.paper_experiment`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from kincal.errors import ExportError, OptionError
from kincal.experiments.paper_experiment import (_MARK, METHODS, PAPER, ExperimentConfig,
                                                 ExperimentResult, run)


# ------------------------------------------------------------------ tables
def _cell(values) -> str:
    v = np.asarray(values, float)
    if v.size == 1:
        return f"{v[0]:.3f}"
    return f"{v.mean():.3f} ± {v.std(ddof=1):.3f}"


def _stats_row(results, key, which, space_label) -> str:
    ms = [r.method(key) for r in results]
    stats = [getattr(m, which) for m in ms]
    label = ms[0].label
    cells = [_cell([getattr(s, f) for s in stats]) for f in ("mean", "max", "std")]
    paper = PAPER.get((key, "validation" if which == "validation" else "calibration"))
    if key == "before" and which == "calibration_before" and space_label.startswith("400"):
        paper = PAPER[("before", "validation")]
    ptxt = " / ".join(f"{p:.3f}" for p in paper) if paper else ""
    return f"| {label} | {space_label} | " + " | ".join(cells) + f" | {ptxt} |"


def tables(results: Sequence[ExperimentResult]) -> str:
    """Markdown analogues of the paper's Tables 2, 3 and 4 (means over seeds ± std)."""
    if not results:
        raise OptionError("tables() needs at least one ExperimentResult")
    results = list(results)
    n = len(results)
    cfg = results[0].config
    spread = f"mean ± standard deviation over {n} seeds" if n > 1 else "one seed"
    lams = np.array([r.lam for r in results])
    head = ("| Method | Space | Mean (mm) | Max (mm) | Std (mm) | Paper mean / max / std (mm) |\n"
            "|---|---|---|---|---|---|")
    rt = f"{cfg.rtest_cube_edge_m * 1e3:g} mm cube"
    lt = f"{cfg.tracker_cube_edge_m * 1e3:g} mm cube"
    seeds = ", ".join(str(r.config.seed) for r in results)
    lines = [f"Simulated EC66, seed{'s' if n > 1 else ''} {seeds}; {spread}. "
             f"L2 lambda chosen by {cfg.folds}-fold CV over {cfg.n_lambdas} candidates: "
             + (f"median {np.median(lams):.3g} (range {lams.min():.3g} to {lams.max():.3g})"
                if n > 1 else f"{lams[0]:.3g}") + " [penalty in mm and deg]. Frames are "
             "fitted by least squares for every row, \"before\" included (the paper's "
             "\"before\" kept hand-eye / CPA frames).",
             "", "**Table 2.** R-test calibration (60 poses, "
             f"{rt}), validation on {cfg.n_tracker_points} laser-tracker points ({lt}).", "",
             head, "| *Calibration set* | | | | | |"]
    lines += [_stats_row(results, "before", "calibration", rt),
              _stats_row(results, "ls_rtest", "calibration", rt),
              _stats_row(results, "l2_rtest", "calibration", rt),
              "| *Validation set* | | | | | |",
              _stats_row(results, "before", "validation", lt),
              _stats_row(results, "ls_rtest", "validation", lt),
              _stats_row(results, "l2_rtest", "validation", lt)]
    lines += ["", f"**Table 3.** Laser-tracker calibration ({cfg.n_tracker_calibration} of the "
              f"{cfg.n_tracker_points} points); validation on all {cfg.n_tracker_points}.", "",
              head, "| *Calibration set* | | | | | |"]
    before_lt = [r.method("ls_tracker").calibration_before for r in results]
    cells = [_cell([getattr(s, f) for s in before_lt]) for f in ("mean", "max", "std")]
    lines += [f"| Before calibration | {lt} | " + " | ".join(cells)
              + " | " + " / ".join(f"{p:.3f}" for p in PAPER[("before", "validation")]) + " |",
              _stats_row(results, "ls_tracker", "calibration", lt),
              "| *Validation set* | | | | | |",
              _stats_row(results, "before", "validation", lt),
              _stats_row(results, "ls_tracker", "validation", lt)]
    lines += ["", "**Table 4.** Identified minus nominal kinematic parameters (mm or deg); "
              "— : not identified on these data (redundant, held at nominal). Truth: the "
              "planted errors (Table 4's tracker column plus the seeded jitter). With the ball on "
              "the joint-6 axis, joint_5.d, joint_5.theta, joint_6.a and joint_6.alpha are "
              "nearly redundant with the tool point: large LS values there compensate each "
              "other.", "",
              "| Parameter | LS + R-test | LS + laser tracker | L2 + R-test | Truth |",
              "|---|---|---|---|---|"]
    order = ("ls_rtest", "ls_tracker", "l2_rtest")
    r0 = results[0]
    for i, name in enumerate(r0.parameter_names):
        unit = "mm" if r0.is_length[i] else "deg"
        cells = []
        for key in order:
            ms = [r.method(key) for r in results]
            if not any(m.identified[i] for m in ms):
                cells.append("—")
            else:
                cells.append(_cell([m.deviations[i] for m in ms]))
        if all(c == "—" for c in cells) and all(abs(r.true_deviations[i]) < 1e-12 for r in results):
            continue
        cells.append(_cell([r.true_deviations[i] for r in results]))
        lines.append(f"| {name} ({unit}) | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


# -------------------------------------------------------------------- plots
PLOT_FILES = ("cv_curve.png", "point_sets.png", "validation_errors.png",
              "parameter_deviations.png")


def figures(result: ExperimentResult, source: str | dict[str, str] = "kincal"
            ) -> list[tuple[str, bytes]]:
    """(file name, PNG bytes) of the paper's Figs. 3-5 and Table 4 (nothing is written).

    source: the PNGs' "Software" field, or a dict of text fields (the provenance).
    """
    from kincal.export import plots

    cv = result.cv
    pngs = [
        plots.plot_cv_curve(cv.lambdas, cv.mean_error, cv.best_lambda, None,
                            fold_errors_mm=cv.fold_errors, source=source,
                            title=f"Cross-validation of L2 + R-test (seed {result.config.seed})"),
        plots.plot_point_sets(result.rtest_points_mm, result.tracker_points_mm,
                              None, source=source,
                              highlight_index=result.tracker_calibration_index),
        plots.plot_error_distributions([(m.label, m.validation_errors_mm) for m in result.methods],
                                       None, source=source,
                                       title="Validation errors, 400 mm cube "
                                             f"({len(result.tracker_points_mm)} points)"),
        plots.plot_parameter_deviations(
            result.parameter_names, result.is_length,
            [(result.method(k).label, result.method(k).deviations, result.method(k).identified,
              result.method(k).weak)
             for k in ("ls_rtest", "ls_tracker", "l2_rtest")]
            + [("Truth (planted)", result.true_deviations, np.ones(len(result.is_length), bool))],
            None, source=source),
    ]
    return [(name, plots.png_bytes(png)) for name, png in zip(PLOT_FILES, pngs)]


# ------------------------------------------------------------------ outputs
REPORT_FILES = ("tables.md", "results.json") + PLOT_FILES


def _check_ours(path: Path) -> None:
    """Pass if ``path`` is free or holds an earlier output of this module; else raise."""
    if not path.exists() and not path.is_symlink():
        return
    if path.is_file() and not path.is_symlink() and _MARK.encode() in path.read_bytes()[:8192]:
        return
    raise ExportError(f"{path}: exists and was not written by {_MARK}; refusing to "
                      "overwrite it (choose another output folder)")


def write_report(results: Sequence[ExperimentResult], out_dir, summary: dict | None = None,
                 provenance=None) -> list[Path]:
    """tables.md (all seeds), results.json (all numbers) and the plots of the first seed.

    ``out_dir`` is created if missing (its parents too), with the files. Only the names in
    REPORT_FILES are written, and an existing file of that name is replaced only if this
    module wrote it (its marker is checked first, so nothing is written when one of them
    belongs to someone else).
    summary: key numbers stored under "summary" in results.json. provenance: the run's
    :class:`~kincal.export.provenance.Provenance` every file carries (default: the Python
    API's, no robot file, no command line).
    """
    results = list(results)
    out_dir = Path(out_dir).expanduser()
    for name in REPORT_FILES:
        _check_ours(out_dir / name)
    from kincal.export.outputs import File, write_files
    from kincal.export.provenance import Provenance

    prov = provenance if provenance is not None else Provenance.of_run()
    rendered: dict[str, bytes] = {}

    def png(name: str):  # the figures rendered once, with the provenance's text fields
        def render(fields: dict) -> bytes:
            if not rendered:  # the marker in "Title": _check_ours finds it
                rendered.update(figures(results[0], {**fields, "Title": _MARK}))
            return rendered[name]
        return render

    md = f"<!-- {_MARK}: simulated reproduction, see the module docstring -->\n" + tables(results)
    payload = {"generator": _MARK, "summary": summary or {},
               "results": [r.as_dict() for r in results]}
    files = [File(out_dir / name, "png", png(name)) for name in PLOT_FILES]
    files += [File(out_dir / "tables.md", "md", md), File(out_dir / "results.json", "json", payload)]
    from kincal.export.safe_write import missing_folders

    # all files in one transaction: an interrupted or failed run leaves the folder as it was,
    # and the folders it would have made (out_dir and its missing parents) not made
    return write_files(files, prov, overwrite=True, dirs=missing_folders(out_dir))


@dataclass(frozen=True)
class DemoSummary:
    """What :func:`demo` produced: the key numbers [mm] and the files written."""

    out_dir: Path
    files: tuple[Path, ...]
    seed: int
    lam: float
    before_validation_mean_mm: float
    ls_rtest_validation_mean_mm: float
    l2_rtest_validation_mean_mm: float
    ls_tracker_validation_mean_mm: float
    elapsed_s: float

    def numbers(self) -> dict:
        """The key numbers as stored under "summary" in results.json."""
        return {"seed": self.seed, "lambda": self.lam,
                "before_validation_mean_mm": self.before_validation_mean_mm,
                "ls_rtest_validation_mean_mm": self.ls_rtest_validation_mean_mm,
                "l2_rtest_validation_mean_mm": self.l2_rtest_validation_mean_mm,
                "ls_tracker_validation_mean_mm": self.ls_tracker_validation_mean_mm}


def demo(out_dir, config: ExperimentConfig | None = None,
         progress: Callable[[str], None] | None = None, provenance=None) -> DemoSummary:
    """Run one seed of :meth:`ExperimentConfig.small` and :func:`write_report` it (with
    ``provenance``, see there)."""
    t0 = time.perf_counter()
    config = config or ExperimentConfig.small()
    out_dir = Path(out_dir).expanduser()
    for name in REPORT_FILES:  # fail before the work, not after
        _check_ours(out_dir / name)
    result = run(config, progress)
    m = {k: result.method(k).validation.mean for k, _ in METHODS}
    summary = DemoSummary(out_dir, (), config.seed, result.lam, m["before"], m["ls_rtest"],
                          m["l2_rtest"], m["ls_tracker"], 0.0)
    if progress:
        progress("writing tables and plots")
    files = write_report([result], out_dir, summary.numbers(), provenance)
    return replace(summary, files=tuple(files), elapsed_s=time.perf_counter() - t0)


