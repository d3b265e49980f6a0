"""The distance kind: the distance from the tool point to a fixed pivot whose position is
unknown (a ballbar with a fixed socket, a drawstring encoder anchored at one point).

Plain numpy. With the pivot ``c`` in the robot's base frame and the tool point ``t`` in
the tip frame, the predicted distance is ``|p_tip + R_tip t - c|`` [m]; the residual is
the measured minus the predicted distance, one row per sample.

There is no measurement frame: a distance has no direction, so the instrument's
orientation does not enter, and the pivot (3 parameters) replaces the 6 of the frame.
What moves the robot rigidly with respect to the pivot cannot be seen either: a turn of
the whole chain about the first joint's axis, or about any line through the pivot, is
taken up by the pivot's position; the selection reports those parameters as dropped.
The distance is absolute (a ballbar of known length; a drawstring read against a
reference length), not relative to an unknown zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError
from kincal.measurements.kind import KindModel, SampleSet, read_set, readonly

FRAMES = ("pivot.x", "pivot.y", "pivot.z", "tool.x", "tool.y", "tool.z")


@dataclass(frozen=True, kw_only=True)
class DistanceData(SampleSet):
    """Measured distances (N,) [m] from the tool point to the pivot, all >= 0."""

    distances: np.ndarray

    kind = "distance"

    def __post_init__(self):
        super().__post_init__()
        d = readonly(self.distances)
        if d.shape != (len(self.joint_values),):
            raise DataError(f"{self.source}: {len(self.joint_values)} distances expected, "
                            f"got shape {d.shape}")
        if np.any(d < 0):
            k = int(np.argmax(d < 0))
            raise DataError(f"{self.source}, line {self.rows[k]}: distance {d[k]:.6g} is "
                            "negative; a distance from the tool point to the pivot is >= 0 "
                            "(a drawstring read relative to a zero needs that zero added)")
        object.__setattr__(self, "distances", d)

    def per_sample_fields(self):
        return super().per_sample_fields() + ("distances",)

    @classmethod
    def from_csv(cls, path, joint_names, prismatic=(), length_unit="m", angle_unit="rad",
                 distance_column="distance", joint_columns=None) -> "DistanceData":
        """Joint columns and ``distance`` [length unit]; optional ``sigma``."""
        c = read_set(path, joint_names, (distance_column,), ("sigma",), prismatic,
                     angle_unit, length_unit, joint_columns,
                     expected="the chain joints and a distance column")
        L = 1e-3 if length_unit == "mm" else 1.0
        v = c.values
        if "sigma" in v and np.any(v["sigma"] <= 0):
            k = int(np.argmax(v["sigma"] <= 0))
            raise DataError(f"{c.source}, line {c.rows[k]}, column 'sigma': must be > 0")
        return cls(joint_names=tuple(joint_names), joint_values=c.joint_values,
                   angle_unit=angle_unit,
                   distances=v[distance_column] * L,
                   sigma=v["sigma"] * L if "sigma" in v else None, rows=c.rows,
                   source=c.source, approach=c.approach, ignored_columns=c.ignored)


def sphere_center(P: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(3,) the point c best giving |P_k - c| = d_k (linear in c and |c|^2)."""
    A = np.column_stack([2.0 * P, -np.ones(len(P))])
    b = np.sum(P * P, axis=1) - d ** 2
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    return sol[:3]


def pivot_and_tool(p: np.ndarray, R: np.ndarray, d: np.ndarray) -> list[np.ndarray]:
    """[(6,) pivot c and tool point t] best giving |p_k + R_k t - c| = d_k, or [] when the
    tip's turns cannot fix them (fewer than 16 samples, or rank < 16). Linear in
    (|t|^2 + |c|^2, t, c, c t^T): d^2 - |p|^2 = k + 2 (R^T p).t - 2 p.c - 2 R : (c t^T)
    (the bilinear term's 9 products as unknowns of their own); closed form, no start."""
    N = len(d)
    if N < 16:
        return []
    A = np.column_stack([np.ones(N), 2.0 * np.einsum("nkj,nk->nj", R, p), -2.0 * p,
                         -2.0 * R.reshape(N, 9)])
    sol, _, rank, _ = np.linalg.lstsq(A, d ** 2 - np.sum(p * p, axis=1), rcond=None)
    return [np.concatenate([sol[4:7], sol[1:4]])] if rank == A.shape[1] else []


class DistanceKind(KindModel):
    """Residuals and Jacobian of measured distances (see the module notes)."""

    kind = "distance"
    dim = 1
    frame_names = FRAMES
    frame_is_length = (True,) * 6

    def residuals(self, kin, frames, backlash, jacobian=False, kinematic=True):
        c, t = frames[:3], frames[3:6]
        s = self.chain.state(kin, backlash, keep=jacobian and kinematic)
        P = s.p_tip + s.R_tip @ t
        v = P - c
        dist = np.linalg.norm(v, axis=1)
        r = (self.data.distances - dist)[:, None]
        if not jacobian:
            return r
        u = v / np.maximum(dist, 1e-12)[:, None]                  # (N, 3)
        if kinematic:
            Kp, Bp = s.point_columns(P)
            Jk = -np.einsum("ni,nip->np", u, Kp)[:, None, :]
            Jb = -np.einsum("ni,nip->np", u, Bp)[:, None, :]
        else:
            Jk, Jb = self._zero_chain_columns(1)
        Jf = np.empty((self.N, 1, 6))
        Jf[:, 0, :3] = u
        Jf[:, 0, 3:] = -np.einsum("ni,nij->nj", u, s.R_tip)
        return r, Jk, Jf, Jb

    def start(self, kin, tool_guess=None):
        """The pivot and tool point: with ``tool_guess`` (``--tool-offset``), that tool and
        the pivot that fits it; without, the better (by the distances' RMS) of the tool at
        the tip origin with its pivot and :func:`pivot_and_tool` (the tool unknown: in a
        small volume the tip origin's sphere is far off, and the fit from it ended in a
        false minimum, 3.3 mm RMS against 0.05 mm noise on a 20 mm cube)."""
        s = self.chain.state(kin, None, keep=False)
        d = self.data.distances
        t = np.zeros(3) if tool_guess is None else np.asarray(tool_guess, float)
        starts = [np.concatenate([sphere_center(s.p_tip + s.R_tip @ t, d), t])]
        if tool_guess is None:
            starts += pivot_and_tool(s.p_tip, s.R_tip, d)
        return min(starts, key=lambda f: float(np.mean((d - np.linalg.norm(
            s.p_tip + s.R_tip @ f[3:] - f[:3], axis=1)) ** 2)))

    def sample_errors(self, r):
        return np.abs(r[:, 0])

    def notes(self):
        return (f"{self.data.source}: distances carry no direction: no measurement-frame "
                "orientation is identified (the pivot is in the base frame), and a turn of "
                "the whole chain about the first joint's axis is taken up by the pivot",)
