"""A fleet's summary: per parameter the mean deviation, the scatter and the units flagged as
outliers; the units that failed or were refused. As a table (stdout), a dict (JSON) and a
self-contained HTML page with one plot per parameter class.

Outliers: a unit's deviation is flagged on a parameter when it lies more than
OUTLIER_Z robust standard deviations (1.4826 x the median absolute deviation, floored at
a tenth of the plain standard deviation) from the fleet's median; a unit is an outlier
when any parameter is flagged. The prior (FLEET.json) is learned from every calibrated
unit, outliers included: they are reported for a person to judge, not dropped.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass

import numpy as np

from kincal.fleet.unit import UnitOutcome
from kincal.identification.evidence import prior_class
from kincal.identification.prior import FleetPrior

OUTLIER_Z = 5.0
CLASS_TITLES = {"length": "lengths [mm]", "twist": "twists [deg]", "offset": "joint offsets [deg]"}


@dataclass(frozen=True)
class FleetSummary:
    """units: every unit's outcome, in the order given. prior: the fleet prior learned from
    the calibrated units (None with fewer than 2). outliers: (unit, parameter names) of the
    units flagged. rounds: rounds of the hierarchical fit (0: each unit alone)."""

    units: tuple[UnitOutcome, ...]
    prior: FleetPrior | None
    outliers: tuple[tuple[str, tuple[str, ...]], ...]
    rounds: int = 0

    @property
    def calibrated(self) -> tuple[UnitOutcome, ...]:
        return tuple(u for u in self.units if u.status == "calibrated")

    @classmethod
    def of(cls, units, prior: FleetPrior | None, rounds: int = 0) -> "FleetSummary":
        units = tuple(units)
        ok = [u for u in units if u.status == "calibrated"]
        outliers: tuple[tuple[str, tuple[str, ...]], ...] = ()
        if len(ok) >= 3:
            X = np.array([u.deviation for u in ok])
            med = np.median(X, axis=0)
            mad = 1.4826 * np.median(np.abs(X - med), axis=0)
            sd = np.maximum(mad, 0.1 * X.std(axis=0))
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(sd > 0, np.abs(X - med) / sd, 0.0)
            outliers = tuple((u.name, tuple(n for n, f in zip(u.names, z[i] > OUTLIER_Z) if f))
                             for i, u in enumerate(ok) if np.any(z[i] > OUTLIER_Z))
        return cls(units, prior, outliers, rounds)

    # -------------------------------------------------------------- rows
    def rows(self) -> list[tuple[str, str, float, float, list[str]]]:
        """(name, unit, mean, scatter, outlier units) per parameter, in mm or deg."""
        if self.prior is None:
            return []
        p = self.prior
        out = []
        for i, n in enumerate(p.names):
            k, unit = (1e3, "mm") if p.is_length[i] else (180.0 / math.pi, "deg")
            flagged = [u for u, names in self.outliers if n in names]
            out.append((n, unit, p.mean[i] * k, p.std[i] * k, flagged))
        return out

    def _si(self) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Per parameter of :meth:`rows`: its SI unit (m or rad), mean and scatter in it (as
        REPORT.json gives both: the human unit beside the file's SI)."""
        if self.prior is None:
            return [], np.zeros(0), np.zeros(0)
        p = self.prior
        return ["m" if v else "rad" for v in p.is_length], p.mean, p.std

    def table(self) -> str:
        ok = self.calibrated
        lines = [f"fleet: {len(self.units)} units, {len(ok)} calibrated, "
                 f"{sum(u.status == 'refused' for u in self.units)} refused by the gate, "
                 f"{sum(u.status == 'failed' for u in self.units)} failed"
                 + (f"; prior by {self.rounds} rounds of the hierarchical fit"
                    if self.rounds else "")]
        for u in self.units:
            if u.status == "calibrated":
                lines.append(f"  {u.name}: mean error {u.before_mm:.3f} -> {u.after_mm:.3f} mm")
            else:
                lines.append(f"  {u.name}: {u.status.upper()}: {u.message}")
        rows = self.rows()
        if rows:
            lines.append(f"  {'parameter':<18}{'unit':>5}{'mean':>11}{'scatter':>11}  outliers")
            for n, unit, m, s, flagged in rows:
                if s == 0 and m == 0:
                    continue  # never moved in any unit (redundant in the model)
                lines.append(f"  {n:<18}{unit:>5}{m:>11.4f}{s:>11.4f}  {', '.join(flagged)}")
        else:
            lines.append("  no prior: fewer than 2 units calibrated")
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {"units": [{"name": u.name, "source": u.source, "status": u.status,
                           "message": u.message, "before_mm": _num(u.before_mm),
                           "after_mm": _num(u.after_mm), "written": list(u.written),
                           "warnings": list(u.warnings)} for u in self.units],
                "parameters": [{"name": n, "unit": unit, "mean": m, "scatter": s,
                                f"mean_{si}": float(p_mean), f"scatter_{si}": float(p_std),
                                "outliers": flagged}
                               for (n, unit, m, s, flagged), si, p_mean, p_std in zip(
                                   self.rows(), *self._si())],
                "outliers": {u: list(n) for u, n in self.outliers},
                "hierarchical_rounds": self.rounds}

    # -------------------------------------------------------------- HTML
    def html(self) -> str:
        parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>kincal fleet"
                 "</title><style>body{font-family:sans-serif;max-width:1100px;margin:1em auto}"
                 "td,th{border:1px solid #ddd;padding:2px 8px}table{border-collapse:collapse}"
                 "img{max-width:100%}</style></head><body><h1>Fleet summary</h1>",
                 f"<pre>{html.escape(self.table())}</pre>"]
        ok = self.calibrated
        if len(ok) >= 2:
            for cls, title in CLASS_TITLES.items():
                png = _class_plot(ok, cls, title)
                if png:
                    data = base64.b64encode(png).decode("ascii")
                    parts.append(f"<h2>{html.escape(title)}</h2><img alt='{cls}' "
                                 f"src='data:image/png;base64,{data}'>")
        parts.append("</body></html>\n")
        return "\n".join(parts)


def _num(v: float):
    return None if not math.isfinite(v) else float(v)


def _class_plot(units, cls: str, title: str) -> bytes | None:
    """Each unit's deviation per parameter of one class (a dot per unit), the fleet's mean
    and +- one scatter; None when no parameter of the class moved."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = units[0].names
    idx = [i for i, n in enumerate(names) if prior_class(n) == cls]
    X = np.array([u.deviation for u in units])[:, idx]
    k = 1e3 if cls == "length" else 180.0 / math.pi
    keep = [j for j in range(len(idx)) if np.any(X[:, j] != 0)]
    if not keep:
        return None
    X = X[:, keep] * k
    fig, ax = plt.subplots(figsize=(max(4.0, 0.5 * len(keep) + 2), 3.2))
    pos = np.arange(len(keep))
    for row in X:
        ax.plot(pos, row, ".", color="0.5", alpha=0.6)
    ax.errorbar(pos, X.mean(axis=0), yerr=X.std(axis=0, ddof=1), fmt="o", color="C3",
                capsize=3, label="mean +- scatter")
    ax.set_xticks(pos, [names[idx[j]] for j in keep], rotation=60, ha="right", fontsize=7)
    ax.set_ylabel(title)
    ax.axhline(0, color="k", lw=0.5)
    ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": "kincal fleet"})
    plt.close(fig)
    return buf.getvalue()
