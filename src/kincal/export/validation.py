"""Held-out validation of a calibration, and the residual vectors per sample as CSV.

:class:`Validation` holds the errors of a held-out data set before calibration (nominal
kinematics, the frames fitted on the training data with them) and after (the calibrated
kinematics and frames), per sample and per axis. It is computed by the command line
(``kincal calibrate --validate``, through ``kincal evaluate``'s path) and written by the
one writer into the summary, REPORT.json and the HTML report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.identification.statistics import AngleStats, ErrorStats, angle_label
from kincal.measurements.csv_table import csv_line

AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Validation:
    """Errors of held-out data. source / kind: the file and its kind. rows: (N,) its line
    numbers. residuals_before / residuals_after: (N, dim) measured minus predicted [m];
    errors_before / errors_after: (N,) each sample's error [m]. Per-axis figures exist
    for point (one point per pose) and pose data, whose first three residual columns are
    x, y, z of the position in the measurement frame. angles: (before, after) statistics
    of the orientation errors [deg] (poses: the rotation angle; flush touches: the tilt
    against the plane, with its roll and pitch), None for kinds without one. chain: the
    chain it was judged on ("base -> tip") in a calibration of several, else "".
    angle_rows_before / angle_rows_after: (N, k) each sample's orientation error as angles
    [rad] (:meth:`kincal.measurements.kind.KindModel.angle_rows`), None without one."""

    source: str
    kind: str
    rows: np.ndarray
    residuals_before: np.ndarray
    residuals_after: np.ndarray
    errors_before: np.ndarray
    errors_after: np.ndarray
    per_axis: bool
    angles: tuple[AngleStats, AngleStats] | None = None
    chain: str = ""  # "base -> tip" when the calibration has several chains
    angle_rows_before: np.ndarray | None = None
    angle_rows_after: np.ndarray | None = None

    @property
    def before(self) -> ErrorStats:
        return ErrorStats.from_errors(self.errors_before)

    @property
    def after(self) -> ErrorStats:
        return ErrorStats.from_errors(self.errors_after)

    def axis_rms_mm(self, residuals: np.ndarray) -> np.ndarray:
        """(3,) root mean square of the x, y, z residual components [mm]."""
        return np.sqrt(np.mean(np.asarray(residuals)[:, :3] ** 2, axis=0)) * 1e3

    def table(self) -> list[tuple[str, float, float]]:
        """(name, before, after) rows [mm]: per axis rms, then the norm's mean, rms, max."""
        b, a = self.before, self.after
        out = []
        if self.per_axis:
            rb, ra = self.axis_rms_mm(self.residuals_before), self.axis_rms_mm(self.residuals_after)
            out += [(f"{axis} (rms)", float(rb[k]), float(ra[k])) for k, axis in enumerate(AXES)]
        out += [("norm: mean", b.mean, a.mean), ("norm: rms", b.rms, a.rms),
                ("norm: max", b.max, a.max)]
        if self.angles is not None:
            b0, a0 = self.angles
            label = angle_label(self.kind, short=True)
            out += [(f"{label}: mean [deg]", b0.mean, a0.mean),
                    (f"{label}: rms [deg]", b0.rms, a0.rms),
                    (f"{label}: max [deg]", b0.max, a0.max)]
            out += [(f"{k}: rms [deg]", vb, va) for (k, vb), (_, va) in zip(b0.axes, a0.axes)]
        return out

    def headline(self) -> str:
        what = "" if self.kind == "point" else f" ({self.kind} errors)"
        if self.chain:
            what += f" on {self.chain}"
        return (f"held-out {self.source}{what}, {len(self.rows)} samples: mean "
                f"{self.before.mean:.3f} -> {self.after.mean:.3f} mm, RMS "
                f"{self.before.rms:.3f} -> {self.after.rms:.3f} mm, max "
                f"{self.before.max:.3f} -> {self.after.max:.3f} mm")

    def lines(self) -> list[str]:
        """For the console summary."""
        out = [self.headline()]
        if self.per_axis:
            rb, ra = self.axis_rms_mm(self.residuals_before), self.axis_rms_mm(self.residuals_after)
            out.append("  rms per axis [mm]: " + ", ".join(
                f"{axis} {rb[k]:.3f} -> {ra[k]:.3f}" for k, axis in enumerate(AXES)))
        if self.angles is not None:
            b0, a0 = self.angles
            parts = "".join(f", {k} {vb:.4f} -> {va:.4f}"
                            for (k, vb), (_, va) in zip(b0.axes, a0.axes))
            out.append(f"  {angle_label(self.kind)} [deg]: mean {b0.mean:.4f} -> "
                       f"{a0.mean:.4f}, RMS {b0.rms:.4f} -> {a0.rms:.4f}, max {b0.max:.4f} -> "
                       f"{a0.max:.4f}"
                       + (f" ({parts[2:]})" if parts else ""))
        return out

    def as_dict(self) -> dict:
        """For REPORT.json (mm)."""
        from kincal.export.report import stats_dict

        out = {"source": self.source, "kind": self.kind, "samples": len(self.rows),
               **({"chain": self.chain} if self.chain else {}),
               "frames": "from the calibration (not refitted on the held-out data)",
               "errors": {"before": stats_dict(self.before), "after": stats_dict(self.after)}}
        if self.per_axis:
            out["rms_per_axis_mm"] = {
                "before": dict(zip(AXES, self.axis_rms_mm(self.residuals_before).tolist())),
                "after": dict(zip(AXES, self.axis_rms_mm(self.residuals_after).tolist()))}
        if self.angles is not None:
            from kincal.export.report import angle_dict

            out["orientation_errors"] = {"before": angle_dict(self.angles[0]),
                                         "after": angle_dict(self.angles[1])}
            if self.kind == "pose":  # the key REPORT.json had before orientation_errors
                out["orientation_mean_deg"] = {"before": self.angles[0].mean,
                                               "after": self.angles[1].mean}
        return out


def validation_dict(validations) -> dict | list | None:
    """REPORT.json's and the --json summary's ``validation``: None without held-out data,
    one file's dict, or a list of them (one held-out file per data file)."""
    dicts = [v.as_dict() for v in validations]
    return None if not dicts else dicts[0] if len(dicts) == 1 else dicts


def residuals_csv(result, validations=(), header: str = "", rows_per_piece: int = 4096):
    """Every sample's residual vector after calibration (training sets, then the held-out
    sets) as CSV: split, set, source, kind, row, error_m, orientation_error_rad, r1..rD (D
    the widest set's residual size), measured minus predicted: points dx dy dz [m] per
    measured point; distances, contacts [m]; poses dx dy dz [m] then the rotation vector
    [rad]; flush touches the height [m] then the roll and pitch against the plane [rad].
    orientation_error_rad: the norm of those angles (poses, flush), else empty. ``header``:
    ``#`` lines put first. Yields the text in pieces of ``rows_per_piece`` rows (the
    header lines first), made as the writer takes them: at many poses the file is never
    held whole, nor a Python string per row (0.4 KiB per pose at 300,000)."""
    from kincal.export.writer import printable  # a file name's undecoded bytes too

    parts = [("training", k + 1, s.source, s.kind, s.rows, s.residuals, s.errors_after,
              s.angle_rows_after) for k, s in enumerate(result.sets)]
    for validation in validations:
        parts.append(("held-out", len(parts) + 1, validation.source, validation.kind,
                      validation.rows, validation.residuals_after, validation.errors_after,
                      validation.angle_rows_after))
    width = max(np.asarray(p[5]).reshape(len(p[4]), -1).shape[1] for p in parts)
    lines = ["# residual vectors per sample after calibration, measured minus predicted: "
             "lengths [m], a pose's rotation vector and a flush touch's tilts [rad]"]
    lines += [line for line in header.splitlines() if line]
    lines.append(csv_line(["split", "set", "source", "kind", "row", "error_m",
                           "orientation_error_rad"] + [f"r{k + 1}" for k in range(width)]))
    yield "\n".join(lines) + "\n"
    for split, k, source, kind, rows, res, err, angles in parts:
        res = np.asarray(res).reshape(len(rows), -1)
        if angles is not None:  # the angle rows in radians, not through their sigma ratio
            a = np.asarray(angles).reshape(len(rows), -1)
            res = np.hstack([res[:, :res.shape[1] - a.shape[1]], a])
            norms = np.linalg.norm(a, axis=1)
        for s in range(0, len(rows), rows_per_piece):
            b = slice(s, s + rows_per_piece)
            o = ([""] * len(rows[b]) if angles is None else
                 [repr(float(v)) for v in norms[b]])
            lines = []
            for row, r, e, n in zip(rows[b], res[b], err[b], o):
                cells = [split, str(k), printable(str(source)), kind, str(int(row)), repr(float(e)), n]
                cells += [repr(float(v)) for v in r] + [""] * (width - len(r))
                lines.append(csv_line(cells))
            yield "\n".join(lines) + "\n"
