"""Refit only the measurement frame of a set, the rest held: another day's evaluation.

A motion-capture or tracker frame is set up again each day (it moves by millimetres and
tenths of a degree), while the tool on the robot (a marker body, a tracker nest) stays.
Evaluating a calibration on another day then fits the measurement frame ``base.*`` to that
day's data and keeps the kinematics, the tool and the backlash of the calibration: the
errors left are those of the model, not of a tool refitted to hide them. (When the tool
itself changed, the full refit of frame and tool is the fair one.)

Plain numpy/scipy: weighted least squares over the six ``base.*`` values, started from the
given frames, each sample weighed by its stated sigma as in the calibration.
"""

from __future__ import annotations

import numpy as np

from kincal.errors import DataError

BASE = ("base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz")


def refit_measurement_frame(km, kin: np.ndarray, frames: np.ndarray,
                            backlash: np.ndarray) -> np.ndarray:
    """The set's frame vector with ``base.*`` refitted to its data, every other value of
    ``frames`` (the tool, ...) and the kinematics ``kin`` held. km: the set's kind model."""
    from scipy.optimize import least_squares

    names = tuple(km.frame_names)
    if not all(n in names for n in BASE):
        raise DataError(f"{km.data.source}: a {km.kind} set has no measurement frame "
                        f"(base.*) to refit; --fit-frames measurement needs point or pose "
                        "data")
    idx = np.array([names.index(n) for n in BASE])
    sigma = getattr(km.data, "sigma", None)
    w = np.ones(len(km.data)) if sigma is None else 1.0 / np.asarray(sigma)
    f = np.array(frames, dtype=float)

    def fun(b):
        f[idx] = b
        return (km.residuals(kin, f, backlash) * w[:, None]).ravel()

    def jac(b):
        f[idx] = b
        _, _, Jf, _ = km.residuals(kin, f, backlash, jacobian=True, kinematic=False)
        return (Jf[:, :, idx] * w[:, None, None]).reshape(-1, len(idx))

    sol = least_squares(fun, f[idx], jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    f[idx] = sol.x
    return f


def moved(before: np.ndarray, after: np.ndarray, km) -> tuple[float, float]:
    """How far the measurement frame moved: (translation [mm], rotation angle [deg])."""
    from kincal.rotations import base_rotation, rotation_angle

    names = tuple(km.frame_names)
    i = [names.index(n) for n in BASE]
    a, b = np.asarray(before)[i], np.asarray(after)[i]
    angle = rotation_angle(base_rotation(*a[3:]).T @ base_rotation(*b[3:]))
    return float(np.linalg.norm(b[:3] - a[:3]) * 1e3), float(np.degrees(angle))
