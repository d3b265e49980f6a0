"""Position-error statistics, in millimetres."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of per-pose Euclidean position errors [mm] (std with ddof = 1)."""

    n: int
    mean: float
    max: float
    std: float
    rms: float
    median: float

    @classmethod
    def from_errors(cls, errors_m: np.ndarray) -> "ErrorStats":
        """From (N, 3) position differences or (N,) distances [m]."""
        e = np.asarray(errors_m, dtype=float)
        d = np.linalg.norm(e, axis=1) if e.ndim == 2 else np.abs(e)
        d = d * 1e3
        n = d.size
        return cls(n, float(d.mean()), float(d.max()), float(d.std(ddof=1)) if n > 1 else 0.0,
                   float(np.sqrt(np.mean(d ** 2))), float(np.median(d)))

    def as_dict(self) -> dict:
        return asdict(self)

    def line(self) -> str:
        return (f"mean {self.mean:.3f}  max {self.max:.3f}  std {self.std:.3f}  "
                f"RMS {self.rms:.3f} mm  (n = {self.n})")
