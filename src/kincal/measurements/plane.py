"""The plane kind: the tool point touches a plane of unknown pose at every sample (touch
probe on a surface plate, a stylus on a machined face). Joint columns only.

Plain numpy. Plane k has the unit normal ``n_k = Rx(rx) Ry(ry) e_z`` and offset ``d``
[m] in the robot's base frame (the plane is ``{P: n . P = d}``); the residual is minus
the signed distance of the tool point, ``d - n . (p_tip + R_tip t)`` [m], one row per
sample. The normal's two angles are singular only for a normal along +-x (ry = +-90 deg).

Names: ``plane.rx .ry .d`` with one plane; with a ``plane`` column, ``plane<label>.*``
for each label. A plane sees only motion along its normal: a shift within it or a turn
about its normal is invisible. With planes whose normals span fewer than three
directions, some of the chain's parameters cannot be identified; three planes at large
angles see everything a point measurement sees but the measurement frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError, IdentifiabilityError
from kincal.measurements.kind import KindModel, SampleSet, read_set, readonly
from kincal.rotations import cross_rows, rotx, roty, tilt_angles

MIN_SPREAD = 1e-3  # [m] RMS spread of a plane's contacts across their best line


def plane_indices(data) -> np.ndarray:
    """(N,) read-only plane index of each sample of ``data`` (a set with ``planes`` and
    ``labels``; default all 0), checked against its labels (the plane and flush kinds)."""
    n = len(data.joint_values)
    k = readonly(np.zeros(n, int) if data.planes is None else data.planes, int)
    if k.shape != (n,) or (n and (k.min() < 0 or k.max() >= len(data.labels))):
        raise DataError(f"{data.source}: plane indices must be {n} values in "
                        f"0..{len(data.labels) - 1}")
    return k


@dataclass(frozen=True, kw_only=True)
class PlaneData(SampleSet):
    """Contacts with planes: planes (N,) index of each sample's plane into labels."""

    planes: np.ndarray | None = None
    labels: tuple[str, ...] = ("",)

    kind = "plane"

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "planes", plane_indices(self))

    def per_sample_fields(self):
        return super().per_sample_fields() + ("planes",)

    @classmethod
    def from_csv(cls, path, joint_names, prismatic=(), length_unit="m", angle_unit="rad",
                 plane_column="plane", joint_columns=None) -> "PlaneData":
        """Joint columns; optional ``plane`` (a number naming each row's plane) and
        ``sigma`` [length unit]."""
        c = read_set(path, joint_names, (), (plane_column, "sigma"), prismatic, angle_unit,
                     length_unit, joint_columns, expected="the chain joints")
        v = c.values
        L = 1e-3 if length_unit == "mm" else 1.0
        planes, labels = (plane_labels(v[plane_column], c.source, c.rows, plane_column)
                          if plane_column in v else (None, ("",)))
        if "sigma" in v and np.any(v["sigma"] <= 0):
            k = int(np.argmax(v["sigma"] <= 0))
            raise DataError(f"{c.source}, line {c.rows[k]}, column 'sigma': must be > 0")
        return cls(joint_names=tuple(joint_names), joint_values=c.joint_values,
                   angle_unit=angle_unit, planes=planes,
                   labels=labels, sigma=v["sigma"] * L if "sigma" in v else None,
                   rows=c.rows, source=c.source, approach=c.approach, ignored_columns=c.ignored)


def plane_labels(raw: np.ndarray, source: str, rows, column: str = "plane"):
    """((N,) plane index of each row, labels) from a column of whole numbers naming planes."""
    if np.any(raw != np.round(raw)):
        k = int(np.argmax(raw != np.round(raw)))
        raise DataError(f"{source}, line {rows[k]}, column {column!r}: a plane is named by a "
                        f"whole number, got {raw[k]!r}")
    values, planes = np.unique(raw.astype(int), return_inverse=True)
    return planes, tuple(str(x) for x in values)


def normal(rx: float, ry: float) -> np.ndarray:
    """(3,) the unit normal Rx(rx) Ry(ry) e_z of a plane of tilts rx, ry [rad]: the inverse of
    :func:`kincal.rotations.tilt_angles`."""
    return rotx(rx) @ roty(ry) @ np.array([0.0, 0.0, 1.0])


def normal_by_ry(rx: float, ry: float) -> np.ndarray:
    """(3,) the derivative of :func:`normal` by ry: Rx(rx) (e_y x Ry(ry) e_z) (its derivative
    by rx is e_x x normal)."""
    ey, ez = np.eye(3)[1:]
    return rotx(rx) @ np.cross(ey, roty(ry) @ ez)


def fit_plane(P: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(unit normal, offset d [m], RMS spread across the best line [m]) of points P."""
    m = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - m, full_matrices=False)
    n = Vt[-1]
    spread = s[1] / np.sqrt(len(P)) if len(s) > 1 else 0.0
    return n, float(n @ m), float(spread)


class PlaneKind(KindModel):
    """Residuals and Jacobian of contacts with planes (see the module notes)."""

    kind = "plane"
    dim = 1
    data: PlaneData

    def __init__(self, error_model, data, backlash=(), compliance=(), torque=None):
        super().__init__(error_model, data, backlash, compliance, torque)
        labels = self.data.labels
        prefixes = ["plane"] if labels == ("",) else [f"plane{lab}" for lab in labels]
        self.frame_names = ("tool.x", "tool.y", "tool.z") + tuple(
            f"{p}.{c}" for p in prefixes for c in ("rx", "ry", "d"))
        self.frame_is_length = (True,) * 3 + (False, False, True) * len(labels)

    def residuals(self, kin, frames, backlash, jacobian=False, kinematic=True):
        t = frames[:3]
        pl = frames[3:].reshape(-1, 3)
        k = self.data.planes
        s = self.chain.state(kin, backlash, keep=jacobian and kinematic)
        P = s.p_tip + s.R_tip @ t
        normals = np.array([normal(a, b) for a, b, _ in pl])     # (planes, 3)
        n = normals[k]                                            # (N, 3)
        r = (pl[k, 2] - np.sum(n * P, axis=1))[:, None]
        if not jacobian:
            return r
        if kinematic:
            Kp, Bp = s.point_columns(P)
            Jk = -np.einsum("ni,nip->np", n, Kp)[:, None, :]
            Jb = -np.einsum("ni,nip->np", n, Bp)[:, None, :]
        else:
            Jk, Jb = self._zero_chain_columns(1)
        Jf = np.zeros((self.N, 1, self.n_frames))
        Jf[:, 0, :3] = -np.einsum("ni,nij->nj", n, s.R_tip)
        rows = np.arange(self.N)
        ex = np.eye(3)[0]
        dn_rx = cross_rows(ex, n)
        dn_ry = np.stack([normal_by_ry(a, b) for a, b, _ in pl])[k]
        Jf[rows, 0, 3 + 3 * k] = -np.sum(dn_rx * P, axis=1)
        Jf[rows, 0, 4 + 3 * k] = -np.sum(dn_ry * P, axis=1)
        Jf[rows, 0, 5 + 3 * k] = 1.0
        return r, Jk, Jf, Jb

    def check_fixable(self, kin, tool_guess=None) -> None:
        """Raise IdentifiabilityError for a plane its contacts cannot fix: fewer than three
        contacts, or contacts on (nearly) a line, at the nominal kinematics."""
        s = self.chain.state(kin, None, keep=False)
        t = np.zeros(3) if tool_guess is None else np.asarray(tool_guess, float)
        P = s.p_tip + s.R_tip @ t
        assert self.data.planes is not None  # filled in by PlaneData.__post_init__
        for j, label in enumerate(self.data.labels):
            on = self.data.planes == j
            name = "the plane" if label == "" else f"plane {label}"
            spread = fit_plane(P[on])[2] if on.sum() >= 3 else 0.0
            if on.sum() < 3 or spread < MIN_SPREAD:
                raise IdentifiabilityError(
                    f"{self.data.source}: the contacts cannot fix {name}: {int(on.sum())} "
                    f"contacts spread {spread * 1e3:.3f} mm across their best line (at least 3 "
                    f"contacts, spread >= {MIN_SPREAD * 1e3:g} mm, are needed to fix its tilt); "
                    "touch it at points not on one line")

    def start(self, kin, tool_guess=None):
        self.check_fixable(kin, tool_guess)
        s = self.chain.state(kin, None, keep=False)
        t = np.zeros(3) if tool_guess is None else np.asarray(tool_guess, float)
        P = s.p_tip + s.R_tip @ t
        out = [t]
        for j in range(len(self.data.labels)):
            n, d, _ = fit_plane(P[self.data.planes == j])
            out.append([*map(float, tilt_angles(n)), d])
        return np.concatenate([np.ravel(o) for o in out])

    def sample_errors(self, r):
        return np.abs(r[:, 0])

    def notes(self):
        return (f"{self.data.source}: a plane contact sees only motion along the plane's "
                "normal: a shift within a plane or a turn about its normal is invisible, and "
                "there is no measurement frame (the planes are in the base frame)",)
