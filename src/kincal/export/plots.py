"""Calibration figures as PNG files (matplotlib, Agg canvas, no display needed).

Each function takes plain arrays (or a :class:`~kincal.calibration.CalibrationResult`),
draws one figure on its own ``Figure`` (no pyplot, so no global state and no backend
switching) and, given a path, writes it through the one writer
(:func:`kincal.export.writer.write_files`) with its provenance in the PNG's text fields
(:meth:`kincal.export.provenance.Provenance.png_text`); it returns the path written
(with path None, the PNG bytes, e.g. to embed in HTML). Units are in every axis label:
positions and errors in mm, angles in deg.

``source``: what the PNG's text fields say. A written file carries a
:class:`~kincal.export.provenance.Provenance`: the one given as ``source``, else
``Provenance.of_run()`` (this kincal, its version and the time; the Python API, no input
file: plain arrays do not say where they came from); the figures of a result
(:mod:`kincal.export.diagnostic_plots`) name the result's robot and data files and their
SHA-256. PNG bytes (path None) may also be given a dict of text fields or a "Software"
string.

- :func:`plot_cv_curve`: mean CV error against lambda, chosen lambda marked (paper Fig. 3);
- :func:`plot_point_sets`: calibration and validation points in 3-D (Fig. 4);
- :func:`plot_error_distributions`: per-method error distributions (Fig. 5);
- :func:`plot_parameter_deviations`: identified minus nominal per method (Table 4);
- :func:`calibration_figures`: the figures of one calibration, for ``kincal calibrate --plots``.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Sequence, Union

import numpy as np

from kincal.errors import ExportError

if TYPE_CHECKING:
    from kincal.export.provenance import Provenance

# what a PNG's text fields say (see the module docstring)
PngText = Union[str, dict[str, str], "Provenance"]

_COLORS = ("#7f7f7f", "#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd")


def _figure(width: float, height: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def equal_axes_mm(ax, points: np.ndarray, min_half: float = 0.0) -> None:
    """A 3-D axis with equal scales around ``points`` (M, 3) [mm] (5 % margin, at least
    ``min_half`` either side), labelled in mm."""
    if len(points):
        mid = (points.max(0) + points.min(0)) / 2
        half = max((points.max(0) - points.min(0)).max() / 2 * 1.05, min_half)
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)
        ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))
    from matplotlib.ticker import MaxNLocator

    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):  # few, small ticks: no labels run together
        axis.set_major_locator(MaxNLocator(4))
    ax.tick_params(labelsize=7, pad=1)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")


def _save(fig, path, overwrite: bool, source: PngText, made_from=None) -> Path | bytes:
    """Write the PNG to ``path`` through the one writer with its provenance; with path
    None return its bytes (to embed, e.g. in HTML). source: see the module docstring.
    made_from: a function making the Provenance of a file written without one given
    (default ``Provenance.of_run()``). A refused run's figures say so on their face."""
    from kincal.export.provenance import Provenance

    if path is None:
        return _png(fig, source.png_text() if isinstance(source, Provenance) else source)
    if isinstance(source, Provenance):
        prov = source
    elif isinstance(source, str) and source == "kincal":  # the default: none given
        prov = made_from() if made_from is not None else Provenance.of_run()
    else:
        raise ExportError(f"a plot written to {path} carries a Provenance "
                          "(kincal.export.provenance) as its source, or none; got "
                          f"{type(source).__name__}: text fields are for PNG bytes (path None)")
    from kincal.export.writer import File, write_files

    return write_files([File(path, "png", lambda fields: _png(fig, fields))], prov,
                       overwrite=overwrite)[0]


def _png(fig, source) -> bytes:
    """The PNG bytes of ``fig`` with the text fields ``source`` (a dict, or the "Software"
    string)."""
    metadata = dict(source) if isinstance(source, dict) else {"Software": source}
    if "plausibility gate: REFUSED" in metadata.get("Comment", ""):
        mark = "REFUSED by the plausibility gate: diagnosis only"
        old = fig._suptitle.get_text() if fig._suptitle is not None else ""
        fig.suptitle(mark + (f"\n{old}" if old else ""), fontsize=10,
                     color="#b00020" if not old else None)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata=metadata)
    return buf.getvalue()


def plot_cv_curve(lambdas, mean_error_mm, best_lambda: float, path, *, fold_errors_mm=None,
                  title: str = "Cross-validation error against lambda",
                  overwrite: bool = False, source: PngText = "kincal") -> Path | bytes:
    """Mean validation error [mm] of each lambda candidate, log x, best lambda marked.

    lambdas: (M,); mean_error_mm: (M,); fold_errors_mm: optional (M, k), drawn faintly.
    """
    lam = np.asarray(lambdas, float)
    err = np.asarray(mean_error_mm, float)
    fig = _figure(6.4, 4.0)
    ax = fig.add_subplot()
    if fold_errors_mm is not None:
        folds = np.asarray(fold_errors_mm, float)
        for k in range(folds.shape[1]):
            ax.plot(lam, folds[:, k], color="0.75", lw=0.8,
                    label="single folds" if k == 0 else None)
    ax.plot(lam, err, "o-", color=_COLORS[2], ms=3.5, lw=1.5, label="mean over folds")
    best = int(np.argmin(np.abs(np.log(lam) - np.log(best_lambda))))
    ax.axvline(best_lambda, color=_COLORS[1], ls="--", lw=1)
    ax.plot([best_lambda], [err[best]], "o", color=_COLORS[1], ms=7,
            label=f"chosen: lambda = {best_lambda:.3g}, {err[best]:.3f} mm")
    ax.set_xscale("log")
    ax.set_xlabel("lambda (penalty weight, mm and deg units)")
    ax.set_ylabel("mean CV position error (mm)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path, overwrite, source)


def plot_point_sets(calibration_mm, validation_mm, path, *, highlight_index=None,
                    labels=("R-test calibration points", "laser-tracker validation points"),
                    overwrite: bool = False, source: PngText = "kincal") -> Path | bytes:
    """Two point sets [mm] in one 3-D view (paper Fig. 4), equal axis scales.

    calibration_mm: (N, 3); validation_mm: (M, 3), both in the same frame.
    highlight_index: validation points also used for a calibration (drawn filled).
    """
    C = np.asarray(calibration_mm, float)
    V = np.asarray(validation_mm, float)
    fig = _figure(6.4, 5.6)
    ax = fig.add_subplot(projection="3d")
    ax.scatter(*V.T, s=10, facecolors="none", edgecolors=_COLORS[2], lw=0.7,
               label=f"{labels[1]} ({len(V)})")
    if highlight_index is not None and len(highlight_index):
        H = V[np.asarray(highlight_index, int)]
        ax.scatter(*H.T, s=10, color=_COLORS[2], label=f"  of which used for LS ({len(H)})")
    ax.scatter(*C.T, s=14, color=_COLORS[1], depthshade=False, label=f"{labels[0]} ({len(C)})")
    equal_axes_mm(ax, np.vstack([C, V]))
    ax.set_title("Calibration and validation points (robot base frame)", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    return _save(fig, path, overwrite, source)


def error_label(kind: str) -> str:
    """The axis label of a set's per-sample errors [mm], by its measurement kind (a pose's
    is its position's: its orientation is drawn apart, :func:`angle_axis_label`)."""
    return {"point": "position", "pose": "position", "distance": "distance",
            "plane": "distance to the plane", "flush": "height"}.get(kind, "sample") + " error (mm)"


def angle_axis_label(kind: str) -> str:
    """The axis label of a set's per-sample orientation errors [deg] (poses, flush)."""
    from kincal.identification.statistics import angle_label

    return angle_label(kind) + (" (deg)" if kind == "flush" else " error (deg)")


def plot_error_distributions(series: Sequence[tuple[str, np.ndarray]], path, *,
                             title: str = "Position error distribution",
                             overwrite: bool = False, source: PngText = "kincal",
                             ylabel: str = "position error (mm)",
                             angles: Sequence[tuple[str, np.ndarray]] | None = None,
                             angle_ylabel: str = "orientation error (deg)") -> Path | bytes:
    """Box plots (with the points) of per-pose errors [mm], one per method.

    series: (label, (N,) errors [mm]) pairs, drawn left to right. A log axis is used
    when the largest median is over 20 times the smallest, so all boxes stay readable.
    ylabel: what the errors are (:func:`error_label` of a set's kind). angles: the same
    for each sample's orientation error [deg] (pose and flush sets), drawn beside them
    under ``angle_ylabel``.
    """
    fig = _figure(6.4 if angles is None else 9.6, 4.2)
    axes = [fig.add_subplot()] if angles is None else list(fig.subplots(1, 2))
    _boxes(axes[0], series, ylabel, ".3f")
    if angles is None:
        axes[0].set_title(title, fontsize=10)
    else:
        _boxes(axes[1], angles, angle_ylabel, ".4g")
        fig.suptitle(title, fontsize=10)
    return _save(fig, path, overwrite, source)


def _boxes(ax, series, ylabel: str, fmt: str) -> None:
    """One box (and its points, its mean written above in ``fmt``) per (label, values) of
    ``series``."""
    labels = [s[0] for s in series]
    data = [np.asarray(s[1], float) for s in series]
    pos = np.arange(1, len(data) + 1)
    ax.boxplot(data, positions=pos, widths=0.55, showfliers=False, medianprops={"color": "k"})
    ax.set_xticks(pos, labels)  # not boxplot(tick_labels=): that needs matplotlib 3.9
    rng = np.random.default_rng(0)  # fixed jitter: the same data give the same picture
    for i, d in enumerate(data):
        ax.scatter(pos[i] + rng.uniform(-0.18, 0.18, d.size), d, s=6, alpha=0.45,
                   color=_COLORS[i % len(_COLORS)])
        ax.annotate(f"mean {d.mean():{fmt}}", (pos[i], d.max()), textcoords="offset points",
                    xytext=(0, 4), ha="center", fontsize=8)
    meds = [np.median(d) for d in data if d.size]
    if meds and min(meds) > 0 and max(meds) / min(meds) > 20:
        ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.grid(True, axis="y", alpha=0.3)
    ax.tick_params(axis="x", labelsize=8)


def plot_parameter_deviations(names: Sequence[str], is_length, columns, path, *,
                              title: str = "Kinematic parameter deviations from nominal",
                              overwrite: bool = False, source: PngText = "kincal") -> Path | bytes:
    """Grouped bars of identified minus nominal parameters: lengths [mm] and angles [deg].

    names: (P,) parameter names; is_length: (P,) bool.
    columns: (label, (P,) deviations in mm or deg, (P,) bool shown) triples, or pairs
        (label, deviations) when every value is shown, or quadruples with a last (P,)
        bool or None: weak (identified, but barely told apart from the others). Parameters
        no column shows are left out. Values not shown (dropped as redundant) are marked
        with an x on the axis, weak ones drawn hatched and faint. Bars beyond 4x the
        largest deviation of the last column (the reference, e.g. the truth) are clipped
        and their value written at the edge.
    """
    names = list(names)
    is_length = np.asarray(is_length, bool)
    cols, weak = [], []
    for c in columns:
        vals = np.asarray(c[1], float)
        shown = np.asarray(c[2], bool) if len(c) > 2 else np.ones(len(names), bool)
        cols.append((c[0], np.where(shown, vals, np.nan)))
        weak.append(np.asarray(c[3], bool) if len(c) > 3 and c[3] is not None
                    else np.zeros(len(names), bool))
    keep = np.any([np.isfinite(v) & (np.abs(v) > 0) for _, v in cols], axis=0)
    fig = _figure(8.4, 6.0)
    axes = fig.subplots(2, 1)
    for ax, length, unit in ((axes[0], True, "mm"), (axes[1], False, "deg")):
        idx = np.flatnonzero(keep & (is_length == length))
        if idx.size == 0:
            ax.set_visible(False)
            continue
        ref = np.nanmax(np.abs(cols[-1][1][idx])) if np.any(np.isfinite(cols[-1][1][idx])) else 0
        limit = 4 * ref if ref > 0 else None
        w = 0.8 / len(cols)
        x = np.arange(idx.size)
        for j, (label, vals) in enumerate(cols):
            v = vals[idx]
            shown = np.where(np.isfinite(v), v, 0.0)
            if limit is not None:
                shown = np.clip(shown, -limit, limit)
            xs = x - 0.4 + w * (j + 0.5)
            color = _COLORS[(j + 1) % len(_COLORS)]
            faint = weak[j][idx]
            ax.bar(xs[~faint], shown[~faint], w, color=color)
            if faint.any():
                ax.bar(xs[faint], shown[faint], w, color=color, alpha=0.35, hatch="///",
                       edgecolor=color, lw=0)
            # a redundant parameter has no deviation of its own (it is held at nominal and
            # the others absorb its effect): a mark on the axis, never a bar
            gone = ~np.isfinite(v)
            if gone.any():
                ax.plot(xs[gone], np.zeros(gone.sum()), "x", ms=5, mew=1.2,
                        color=_COLORS[(j + 1) % len(_COLORS)])
            if limit is not None:
                for xi, vi in zip(xs, v):
                    if np.isfinite(vi) and abs(vi) > limit:
                        ax.annotate(f"{vi:.1f}", (xi, np.sign(vi) * limit), ha="center",
                                    va="bottom" if vi > 0 else "top", fontsize=7, rotation=90)
        if limit is not None:
            ax.set_ylim(-limit * 1.35, limit * 1.35)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x, [names[i] for i in idx], rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(f"deviation ({unit})")
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    from matplotlib.artist import Artist
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    # proxies: a column may have only weak (hatched) bars, or none on the first axes
    handles: list[Artist] = [Patch(facecolor=_COLORS[(j + 1) % len(_COLORS)])
                             for j in range(len(cols))]
    labels = [label for label, _ in cols]
    if any(np.any(~np.isfinite(v[keep])) for _, v in cols):

        handles.append(Line2D([], [], ls="", marker="x", color="k"))
        labels.append("x: dropped as redundant (held at nominal)")
    if any(np.any(wk[keep]) for wk in weak):
        handles.append(Patch(facecolor="0.7", hatch="///", edgecolor="0.4", lw=0))
        labels.append("hatched: weak (trades off against others)")
    fig.legend(handles, labels, loc="outside lower center", ncol=min(3, len(handles)),
               fontsize=8)
    return _save(fig, path, overwrite, source)


ACCURACY_MAP_PNG = "accuracy_map.png"  # a calibration's accuracy map, in its plots folder


def _residuals_png(i: int) -> str:
    """The residual figure of set ``i`` (0-based)."""
    return "residuals.png" if i == 0 else f"residuals_set{i + 1}.png"


def calibration_figure_names(n_sets: int, accuracy: bool = False) -> list[str]:
    """Every file name a calibration of ``n_sets`` sets may put in its plots folder
    (:func:`calibration_figures`, and the accuracy map with ``accuracy``): what the
    command line checks before the work."""
    return (["cv_curve.png"] + [_residuals_png(i) for i in range(n_sets)] + ["parameters.png"]
            + ([ACCURACY_MAP_PNG] if accuracy else []))


def calibration_figures(result, source: PngText = "kincal") -> list[tuple[str, bytes]]:
    """(file name, PNG bytes) of the figures of one calibration; nothing is written (the
    files go out through :func:`kincal.export.outputs.write_calibration`, behind the gate).

    cv_curve.png (if lambda was chosen by cross-validation), residuals.png (errors of the
    first set's samples before and after calibration; residuals_set<k>.png for set k >= 2)
    and parameters.png (identified kinematic deviations with one standard error).
    """
    out: list[tuple[str, bytes]] = []
    if result.cv is not None:
        cv = result.cv
        out.append(("cv_curve.png", png_bytes(plot_cv_curve(
            cv.lambdas, cv.mean_error, cv.best_lambda, None, fold_errors_mm=cv.fold_errors,
            source=source))))
    for i, s in enumerate(result.sets):  # one residual figure per measurement set
        after = s.errors_after * 1e3
        series = [("before (frames fitted)", s.errors_before * 1e3),
                  (f"after ({result.options.method})", after)]
        what = "" if len(result.sets) == 1 else f" of set {i + 1} ({s.kind}, {s.source})"
        title = (f"Calibration residuals{what}, {len(after)} samples; before: mean "
                 f"{s.before.mean:.3f}, max {s.before.max:.3f} mm")
        angles = None
        if s.angles_after is not None and s.angles_before is not None:
            from kincal.identification.statistics import angle_label

            title += (f"; {angle_label(s.kind)} mean {np.degrees(s.angles_before).mean():.4g} "
                      "deg")
            angles = [(series[0][0], np.degrees(s.angles_before)),
                      (series[1][0], np.degrees(s.angles_after))]
        out.append((_residuals_png(i), png_bytes(plot_error_distributions(
            series, None, title=title, source=source, ylabel=error_label(s.kind),
            angles=angles, angle_ylabel=angle_axis_label(s.kind)))))
    kin = list(result.parameters[:result.layout.n_kinematic])
    if any(p.status == "identified" for p in kin):
        how = result.options.method + (f", lambda = {result.lam:.3g}" if result.lam else "")
        if result.evidence is not None:  # one weight per class, no single lambda
            how = result.options.method + ", evidence priors"
        weak = {w.name for w in result.identifiability.weak}
        out.append(("parameters.png", png_bytes(_plot_estimates(
            kin, None, False, source, f"Identified deviations from nominal ({how})", weak))))
    return out


def png_bytes(made: Path | bytes) -> bytes:
    """The PNG bytes of a figure made with path None (:func:`_save`)."""
    assert isinstance(made, bytes), "made with path None: bytes, not a written file"
    return made


def _plot_estimates(params, path, overwrite, source, title, weak=frozenset()) -> Path | bytes:
    """Bars of deviations with +-1 standard error, lengths [mm] above angles [deg].

    Parameters not identified (dropped as redundant, or fixed) get a grey mark on the axis
    and their status beside their name, no bar: they have no deviation of their own.
    Weak ones (names in ``weak``) are hatched and faint; when they dwarf the others the
    axis is clipped to 4x the largest other bar and their values are written at the edge.
    """
    fig = _figure(8.0, 5.6)
    axes = fig.subplots(2, 1)
    legend: dict = {}  # one legend under the axes, never over the bars
    for ax, length, unit in ((axes[0], True, "mm"), (axes[1], False, "deg")):
        ps = [p for p in params if p.is_length == length]
        if not ps:
            ax.set_visible(False)
            continue
        rep = np.array([p.reported()[1:3] for p in ps], float)
        x = np.arange(len(ps))
        ident = np.array([p.status == "identified" for p in ps])
        err = np.where(np.isfinite(rep[:, 1]), rep[:, 1], 0.0)
        color = _COLORS[2 if length else 3]
        faint = np.array([p.name in weak for p in ps]) & ident
        strong = ident & ~faint
        ax.bar(x[strong], rep[strong, 0], 0.6, yerr=err[strong], capsize=3, color=color)
        if faint.any():
            ax.bar(x[faint], rep[faint, 0], 0.6, yerr=err[faint], capsize=3, color=color,
                   alpha=0.35, hatch="///", edgecolor=color, lw=0,
                   label="weak: barely told apart from others (trades off against them)")
            ref = np.max(np.abs(rep[strong, 0]) + err[strong]) if strong.any() else 0.0
            big = faint & (np.abs(rep[:, 0]) + err > 4 * ref)
            if ref > 0 and big.any():
                ax.set_ylim(-4.4 * ref, 4.4 * ref)
                for i in np.flatnonzero(big):
                    ax.annotate(f"{rep[i, 0]:.3g}", (x[i], np.clip(rep[i, 0], -4 * ref, 4 * ref)),
                                ha="center", va="bottom" if rep[i, 0] > 0 else "top",
                                fontsize=7, rotation=90)
        if (~ident).any():
            ax.plot(x[~ident], np.zeros((~ident).sum()), "x", color="0.5", ms=6, mew=1.2,
                    label="not identified: dropped as redundant, or fixed (held at nominal)")
        for h, label in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(label, h)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x, [p.name + (f" ({p.status})" if p.status != "identified" else
                                    " (weak)" if p.name in weak else "")
                          for p in ps], rotation=30, ha="right", fontsize=8)
        for tick, ok in zip(ax.get_xticklabels(), ident):
            if not ok:
                tick.set_color("0.5")
        ax.set_ylabel(f"deviation ({unit})")
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].set_title(title + "; error bars: one standard error", fontsize=10)
    if legend:
        fig.legend(list(legend.values()), list(legend), loc="outside lower center",
                   ncol=1, fontsize=7)
    return _save(fig, path, overwrite, source)
