"""Diagnostic figures of one calibration: residuals pose by pose and against each joint,
and the predicted accuracy map.

Same conventions as :mod:`kincal.export.plots` (one ``Figure`` each, Agg canvas, no
pyplot; mm and deg in every label): with ``path`` a PNG file is written through the one
writer and its path returned, with ``path=None`` the PNG bytes are returned (for the HTML
report). A written figure of a result carries, unless ``source`` gives a Provenance,
``Provenance.of_run`` of the result's robot and data files (verdict "no gate": no
plausibility gate stands in front of a plot function).
"""

from __future__ import annotations

import math

import numpy as np

# the figure and save helpers are shared with the other plots on purpose: one look
from kincal.export.plots import (_COLORS, PngText, _figure, _save, angle_axis_label,
                                 equal_axes_mm, error_label)


def plot_residuals_per_pose(result, path=None, *, overwrite: bool = False,
                            source: PngText = "kincal", set_index: int = 0):
    """Error [mm] of every sample of set ``set_index`` before (frames fitted) and after
    calibration, in file order, x = the sample's line in the data file; below it, a pose
    or flush set's orientation error [deg] alike."""
    s = result.sets[set_index]
    panels = [(s.errors_before * 1e3, s.errors_after * 1e3, error_label(s.kind), "mm", ".3f")]
    if s.angles_before is not None and s.angles_after is not None:
        panels.append((np.degrees(s.angles_before), np.degrees(s.angles_after),
                       angle_axis_label(s.kind), "deg", ".4g"))
    k = np.arange(len(s.errors_after))
    fig = _figure(8.4, 3.6 if len(panels) == 1 else 6.0)
    axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True))
    step = max(1, len(k) // 20)
    for ax, (before, after, label, unit, fmt) in zip(axes, panels):
        ax.vlines(k, after, before, color="0.8", lw=0.8)
        ax.plot(k, before, "o", ms=3.5, color=_COLORS[0],
                label=f"before (mean {before.mean():{fmt}} {unit})")
        ax.plot(k, after, "o", ms=3.5, color=_COLORS[2],
                label=f"after (mean {after.mean():{fmt}} {unit})")
        ax.set_xticks(k[::step], [str(int(r)) for r in np.asarray(s.rows)[::step]], fontsize=7)
        ax.set_ylabel(label)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("sample (line in the data file)")
    what = "" if len(result.sets) == 1 else f" of set {set_index + 1} ({s.kind}, {s.source})"
    axes[0].set_title(f"Residuals per sample{what}, before and after calibration", fontsize=10)
    return _save(fig, path, overwrite, source, _made_from(result))


def plot_residuals_by_joint(result, path=None, *, overwrite: bool = False,
                            source: PngText = "kincal"):
    """Position error after calibration [mm] against each chain joint's value (deg, or mm
    for prismatic joints). With backlash terms in the model, each sample is coloured by
    the direction the joint last moved in (its approach), which separates the two flanks
    of the play."""
    q = np.asarray(result.joint_values)
    err = result.sets[0].errors_after * 1e3
    names, kinds = result.robot.joint_names, result.robot.geometry.kinds
    by_approach = result.layout.n_backlash > 0 and result.approach is not None
    n = len(names)
    ncol = min(4, n)
    nrow = math.ceil(n / ncol)
    fig = _figure(2.6 * ncol + 0.6, 2.2 * nrow + 0.7)
    axes = np.atleast_1d(fig.subplots(nrow, ncol, sharey=True)).ravel()
    for i, ax in enumerate(axes):
        if i >= n:
            ax.set_visible(False)
            continue
        prismatic = kinds[i] == "prismatic"
        v = q[:, i] * (1e3 if prismatic else 180.0 / math.pi)
        if by_approach:
            g = np.asarray(result.approach)[:, i]
            for sign, color, label in ((1, _COLORS[1], "approached from below"),
                                       (-1, _COLORS[2], "approached from above"),
                                       (0, _COLORS[0], "direction unknown")):
                m = np.sign(g) == sign
                if m.any():
                    ax.plot(v[m], err[m], "o", ms=2.5, color=color, label=label)
        else:
            ax.plot(v, err, "o", ms=2.5, color=_COLORS[2])
        ax.set_xlabel(f"{names[i]} ({'mm' if prismatic else 'deg'})", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        if i % ncol == 0:
            ax.set_ylabel("error after (mm)", fontsize=8)
    title = "Residuals after calibration against each joint"
    if by_approach:
        title += " (colour: the joint's approach direction)"
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=8)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path, overwrite, source, _made_from(result))


def plot_accuracy_map(amap, path=None, *, overwrite: bool = False, source: PngText = "kincal"):
    """The target points in 3-D [mm, base frame], coloured by the predicted 3-D standard
    deviation of the tool point [mm]; skipped (unreachable) grid points as grey x."""
    P = np.asarray(amap.positions) * 1e3
    S = np.asarray(amap.std) * 1e3
    fig = _figure(6.8, 5.6)
    ax = fig.add_subplot(projection="3d")
    if len(P):
        sc = ax.scatter(*P.T, c=S, cmap="viridis", s=28, depthshade=False,
                        vmin=float(S.min()), vmax=float(S.max()))
        fig.colorbar(sc, ax=ax, shrink=0.6, pad=0.08,
                     label="predicted 3-D std of the tool point (mm)")
    if len(amap.skipped):
        ax.scatter(*(np.asarray(amap.skipped) * 1e3).T, marker="x", s=18, color="0.6",
                   label=f"not reachable ({len(amap.skipped)})")
        ax.legend(fontsize=8, loc="upper left")
    both = np.vstack([P, np.asarray(amap.skipped) * 1e3]) if len(amap.skipped) else P
    equal_axes_mm(ax, both, min_half=1.0)
    ax.set_title(f"Predicted accuracy, {len(P)} targets (base frame)", fontsize=10)
    return _save(fig, path, overwrite, source)


def _made_from(result):
    """The provenance of a written figure of ``result`` given none, made when needed: its
    robot and data files."""
    def made():
        from kincal.export.provenance import Provenance

        return Provenance.of_run(result.robot, [s.source for s in result.sets])
    return made
