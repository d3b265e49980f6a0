"""Error statistics: positions in millimetres, orientations in degrees."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


def _summary(d: np.ndarray) -> tuple[int, float, float, float, float, float]:
    """(n, mean, max, std with ddof = 1, RMS, median) of (N,) non-negative values.

    numpy's mean, max, std, RMS and median to the bit, by their own arithmetic without
    their wrappers (which cost more than the sums of a set's few values, four sets of
    statistics a fit): the sums of the values, of the squared deviations from the mean and
    of the squares (np.add.reduce, the reduction np.mean and np.std call), divided by n (n
    - 1); max and median from the sorted values (a NaN sorts last: both NaN, as numpy's)."""
    n = d.size
    s = np.sort(d)
    top = float(s[-1])
    mid = float(s[n // 2]) if n % 2 else (float(s[n // 2 - 1]) + float(s[n // 2])) / 2.0
    mean = float(np.add.reduce(d)) / n
    dev = d - mean
    std = math.sqrt(float(np.add.reduce(dev * dev)) / (n - 1)) if n > 1 else 0.0
    return (n, mean, top, std, math.sqrt(float(np.add.reduce(d * d)) / n),
            math.nan if math.isnan(top) else mid)


@dataclass(frozen=True)
class _Stats:
    """n, mean, max, std (ddof = 1), RMS and median of per-sample errors, in the unit of
    the subclass."""

    n: int
    mean: float
    max: float
    std: float
    rms: float
    median: float

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class ErrorStats(_Stats):
    """Statistics of per-pose Euclidean position errors [mm] (std with ddof = 1)."""

    @classmethod
    def from_errors(cls, errors_m: np.ndarray) -> "ErrorStats":
        """From (N, 3) position differences or (N,) distances [m]."""
        e = np.asarray(errors_m, dtype=float)
        # np.linalg.norm(e, axis=1)'s own arithmetic, without its wrapper
        d = np.sqrt(np.add.reduce(e * e, axis=1)) if e.ndim == 2 else np.abs(e)
        return cls(*_summary(d * 1e3))

    def line(self) -> str:
        return (f"mean {self.mean:.3f}  max {self.max:.3f}  std {self.std:.3f}  "
                f"RMS {self.rms:.3f} mm  (n = {self.n})")


@dataclass(frozen=True)
class AngleStats(_Stats):
    """Statistics of per-sample orientation errors [deg]: each the angle of the rotation
    between the measured and the predicted orientation (std with ddof = 1). axes: the RMS
    [deg] of each signed component where a kind has named ones (flush touches: the roll
    about the contact frame's x axis and the pitch about its y axis), else empty."""

    axes: tuple[tuple[str, float], ...] = ()

    @classmethod
    def from_angles(cls, angles_rad: np.ndarray,
                    components_rad: dict[str, np.ndarray] | None = None) -> "AngleStats":
        """From (N,) angles [rad], each >= 0; components_rad: name -> (N,) signed
        components [rad] whose RMS the statistics also keep (``axes``)."""
        axes = tuple((k, float(np.degrees(np.sqrt(np.mean(np.square(v))))))
                     for k, v in (components_rad or {}).items())
        return cls(*_summary(np.degrees(np.abs(np.asarray(angles_rad, dtype=float)))), axes)

    def line(self) -> str:
        parts = ", ".join(f"{k} {v:.4f}" for k, v in self.axes)
        return (f"mean {self.mean:.4f}  max {self.max:.4f}  std {self.std:.4f}  "
                f"RMS {self.rms:.4f} deg  (n = {self.n})"
                + (f"; RMS {parts} deg" if parts else ""))

    def as_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "axes"}
        return {**d, **{f"{k}_rms": v for k, v in self.axes}}


def angle_label(kind: str, short: bool = False) -> str:
    """What a kind's orientation error is called in reports: a flush touch's "tilt against
    the plane" ("tilt" with ``short``), a pose's "orientation"."""
    if kind == "flush":
        return "tilt" if short else "tilt against the plane"
    return "orientation"


def error_label(kind: str) -> str:
    """What a kind's sample error is called in the gate's lines: a position (points, poses),
    a distance, a distance to the plane, a flush touch's height above it."""
    return {"distance": "distance", "plane": "distance to the plane",
            "flush": "height above the plane"}.get(kind, "position")


def angle_stats(kind_model, residuals: np.ndarray) -> AngleStats | None:
    """The statistics of :func:`angle_errors` (flush touches: also the RMS of the roll and
    of the pitch, about the contact frame's x and y axes), None for kinds without an
    orientation."""
    angles = angle_errors(kind_model, residuals)
    if angles is None:
        return None
    parts = None
    if kind_model.kind == "flush":
        tilts = kind_model.tilt_errors(residuals)
        parts = {"roll": tilts[:, 0], "pitch": tilts[:, 1]}
    return AngleStats.from_angles(angles, parts)


def angle_errors(kind_model, residuals: np.ndarray) -> np.ndarray | None:
    """(N,) orientation error of each sample [rad] from a set's residual rows: poses, the
    angle of the rotation between measured and predicted; flush contacts, the tilt against
    the plane (roll and pitch together); None for kinds without an orientation."""
    rows = kind_model.angle_rows(residuals)
    return None if rows is None else np.linalg.norm(rows, axis=1)
