"""The pose kind: position and orientation of a tool frame (6-DoF tracker probe, optical
CMM, a rigid body fitted to several markers).

Plain numpy. With the measurement frame ``R_b = Rx(rx) Ry(ry) Rz(rz)``, ``t_b`` and the
tool frame in the tip frame (``t_tool``, ``R_tool = Rx(tool.rx) Ry(tool.ry) Rz(tool.rz)``)
the predicted tool pose in the measurement frame is

    p = R_b (p_tip + R_tip t_tool) + t_b,      R = R_b R_tip R_tool.

Residuals per sample (6 rows): the position error ``p_measured - p`` [m] and the
orientation error ``c log(R_measured R^T)`` (a rotation vector in the measurement frame,
[rad]) times ``c = sigma_position / sigma_orientation`` [m/rad], so that both weigh by
their stated noise. The orientation rows' Jacobian includes the inverse right Jacobian of
SO(3) (exact, not only at zero error).

Sigmas: per sample from the ``sigma`` [length unit] and ``sigma_deg`` columns, else the
set's ``orientation_sigma_deg`` (default :data:`DEFAULT_ORIENTATION_SIGMA_DEG`) against
the position sigma (default :data:`kincal.measurements.kind.DEFAULT_SIGMA`, 0.05 mm): one
degree of orientation error then weighs like 5 mm of position error.
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError, KincalNote
from kincal.measurements.kind import (
    DEFAULT_SIGMA,
    SIGMA_RANGE_DEG,
    KindModel,
    SampleSet,
    check_sigmas,
    read_set,
    readonly,
)
from kincal.rotations import (base_angles, base_rotation, base_turns, cross_rows,
                              kabsch_rotation, rotation_log, rotx, roty, rotz, skew)

DEFAULT_ORIENTATION_SIGMA_DEG = 0.01  # [deg], a 6-DoF laser-tracker probe's order
QUATERNION_COLUMNS = ("qx", "qy", "qz", "qw")
FRAMES = ("base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz",
          "tool.x", "tool.y", "tool.z", "tool.rx", "tool.ry", "tool.rz")


@dataclass(frozen=True, kw_only=True)
class PoseData(SampleSet):
    """Measured tool poses: positions (N, 3) [m] and rotations (N, 3, 3) in the measurement
    frame. sigma_deg: (N,) orientation standard deviation [deg] or None (then
    ``orientation_sigma_deg``). orientation_format: the convention the orientations were
    read in where the file's columns do not fix it (roll/pitch/yaw angles, quaternion
    columns the user named; ``OTHER_CONVENTION`` has its other reading), "" where they do
    (ROS's qx qy qz qw, matrices, rotations given as such). convention_doubt: None until
    :func:`kincal.identification.orientation_convention.checked` has held that reading
    against the nominal model (the plausibility gate does, for every calibration); then
    why the orientations look read in the wrong convention, a finding of the gate, or "".
    angles_read_max: the largest |angle| of the file's angle columns (rpy, rotvec) read as
    radians, 0 otherwise (quaternions, matrices, --angle-unit deg): beyond a turn and a half,
    degrees most likely, a clue of the plausibility gate."""

    positions: np.ndarray
    rotations: np.ndarray
    sigma_deg: np.ndarray | None = None
    orientation_sigma_deg: float = DEFAULT_ORIENTATION_SIGMA_DEG
    orientation_format: str = ""
    convention_doubt: str | None = None
    angles_read_max: float = 0.0  # [rad]

    kind = "pose"

    def __post_init__(self):
        super().__post_init__()
        n = len(self.joint_values)
        P, R = readonly(self.positions), readonly(self.rotations)
        if P.shape != (n, 3) or R.shape != (n, 3, 3):
            raise DataError(f"{self.source}: pose data need positions ({n}, 3) and rotations "
                            f"({n}, 3, 3), got {P.shape} and {R.shape}")
        err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2)) if n else []
        if n and (np.max(err) > 1e-6 or np.any(np.linalg.det(R) < 0)):
            k = int(np.argmax(err))
            raise DataError(f"{self.source}: rotation of sample {k + 1} is not orthonormal")
        object.__setattr__(self, "positions", P)
        object.__setattr__(self, "rotations", R)
        if self.sigma_deg is not None:
            object.__setattr__(self, "sigma_deg", check_sigmas(
                self.sigma_deg, n, self.source, "sigma_deg", "deg", self.rows))
        lo, hi = SIGMA_RANGE_DEG
        o = self.orientation_sigma_deg
        if not (isinstance(o, numbers.Real) and not isinstance(o, bool) and math.isfinite(o)
                and lo <= o <= hi):
            raise DataError(f"the orientation sigma must be between {lo:g} and {hi:g} deg, "
                            f"got {o!r}")

    def per_sample_fields(self):
        return super().per_sample_fields() + ("positions", "rotations", "sigma_deg")

    def ratio(self) -> np.ndarray:
        """(N,) c = sigma_position / sigma_orientation [m/rad]."""
        sp = np.full(len(self), DEFAULT_SIGMA) if self.sigma is None else self.sigma
        so = (np.full(len(self), self.orientation_sigma_deg) if self.sigma_deg is None
              else self.sigma_deg)
        return sp / (so * math.pi / 180.0)

    @classmethod
    def from_csv(cls, path, joint_names, prismatic=(), length_unit="m", angle_unit="rad",
                 position_columns=("x", "y", "z"), orientation_columns=None,
                 orientation_sigma_deg=DEFAULT_ORIENTATION_SIGMA_DEG,
                 joint_columns=None, orientation_format="quat-xyzw") -> "PoseData":
        """Joint columns, positions and an orientation per row; optional ``sigma`` [length
        unit] and ``sigma_deg`` columns. orientation_format: how the orientation is written
        (:mod:`kincal.measurements.orientation_columns`: quat-xyzw, the default, scalar
        last as in ROS; quat-wxyz, rpy-zyx, rpy-xyz, rotvec, matrix); orientation_columns:
        its columns in the format's order (default: the usual names, e.g. qx qy qz qw;
        roll pitch yaw or phix phiy phiz, suffixed like the position columns)."""
        from kincal.measurements.csv_table import read_columns
        from kincal.measurements.data import unit_factors
        from kincal.measurements.orientation_columns import OrientationFormat, rotations

        position_columns = tuple(position_columns)
        fmt = OrientationFormat(orientation_format, None if orientation_columns is None
                                else tuple(orientation_columns))
        if len(position_columns) != 3:
            raise DataError(f"a pose needs 3 position columns, got {position_columns}")
        L, A = unit_factors(length_unit, angle_unit)  # a bad unit before the header is read
        with warnings.catch_warnings():  # the reading below gives the notes
            warnings.simplefilter("ignore", KincalNote)
            header = read_columns(path, [], header_only=True).header
        orientation_columns = fmt.resolve(header, position_columns, str(path))
        c = read_set(path, joint_names, position_columns + orientation_columns,
                     ("sigma", "sigma_deg"), prismatic, angle_unit, length_unit, joint_columns,
                     expected=f"the chain joints, positions and orientations ({fmt.name})")
        v = c.values
        angles = np.column_stack([v[k] for k in orientation_columns])
        R = rotations(angles, fmt.name, A, c.source, c.rows, orientation_columns)
        read_max = (float(np.abs(angles).max()) if A == 1.0 and angles.size and fmt.name in
                    ("rpy-zyx", "rpy-xyz", "rotvec") else 0.0)
        P = np.column_stack([v[k] for k in position_columns]) * L
        for name in ("sigma", "sigma_deg"):
            if name in v and np.any(v[name] <= 0):
                k = int(np.argmax(v[name] <= 0))
                raise DataError(f"{c.source}, line {c.rows[k]}, column {name!r}: must be > 0")
        return cls(joint_names=tuple(joint_names), joint_values=c.joint_values,
                   angle_unit=angle_unit,
                   positions=P, rotations=R,
                   sigma=v["sigma"] * L if "sigma" in v else None,
                   sigma_deg=v.get("sigma_deg"), orientation_sigma_deg=orientation_sigma_deg,
                   rows=c.rows, source=c.source, approach=c.approach, ignored_columns=c.ignored,
                   orientation_format=fmt.name if fmt.unfixed else "",
                   angles_read_max=read_max)


def right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """(N, 3, 3) J_r^{-1}(phi): log(exp(phi) exp(e)) = phi + J_r^{-1}(phi) e + O(e^2)."""
    theta = np.linalg.norm(phi, axis=1)
    small = theta < 1e-6
    t = np.where(small, 1.0, theta)
    coef = np.where(small, 1.0 / 12.0,
                    1.0 / t ** 2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    K = skew(phi)
    return np.eye(3) + 0.5 * K + coef[:, None, None] * (K @ K)


def base_columns(P_base: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives w.r.t. the measurement frame (x, y, z, rx, ry, rz) of points P_base
    (N, 3) seen in it: (position (N, 3, 6), small rotation of the frame (3, 3): the turn
    each angle causes, columns rx, ry, rz, in the measurement frame)."""
    N = len(P_base)
    Rx, Ry, Rz = rotx(base[3]), roty(base[4]), rotz(base[5])
    ex, ey, ez = np.eye(3)
    J = np.zeros((N, 3, 6))
    J[:, :, :3] = np.eye(3)
    J[:, :, 3] = cross_rows(ex, P_base @ (Rx @ Ry @ Rz).T)
    J[:, :, 4] = cross_rows(ey, P_base @ (Ry @ Rz).T) @ Rx.T
    J[:, :, 5] = cross_rows(ez, P_base @ Rz.T) @ (Rx @ Ry).T
    return J, base_turns(base[3], base[4])


class PoseKind(KindModel):
    """Residuals and Jacobian of measured tool poses (see the module notes)."""

    kind = "pose"
    dim = 6
    data: PoseData
    frame_names = FRAMES
    frame_is_length = (True,) * 3 + (False,) * 3 + (True,) * 3 + (False,) * 3

    def residuals(self, kin, frames, backlash, jacobian=False, kinematic=True):
        d = self.data
        base, t, a = frames[:6], frames[6:9], frames[9:12]
        s = self.chain.state(kin, backlash, keep=jacobian and kinematic)
        Rb = base_rotation(*base[3:])
        Rt = base_rotation(*a)
        P_base = s.p_tip + s.R_tip @ t
        p = P_base @ Rb.T + base[:3]
        R = Rb @ s.R_tip @ Rt
        phi = rotation_log(d.rotations @ np.transpose(R, (0, 2, 1)))
        c = d.ratio()[:, None]
        r = np.concatenate([d.positions - p, c * phi], axis=1)
        if not jacobian:
            return r
        N = self.N
        Ji = right_jacobian_inverse(phi) * -c[:, :, None]  # d(orientation rows)/d(turn)
        Tk, Tf, Tb = self._turns(s, base, a, kinematic)
        if kinematic:
            Kp, Bp = s.point_columns(P_base)
            Jk = np.concatenate([-(Rb @ Kp), Ji @ Tk], axis=1)
            Jb = np.concatenate([-(Rb @ Bp), Ji @ Tb], axis=1)
        else:
            Jk, Jb = self._zero_chain_columns(6)
        Jf = np.zeros((N, 6, 12))
        Jf[:, :3, :6] = -base_columns(P_base, base)[0]
        Jf[:, :3, 6:9] = -(Rb @ s.R_tip)
        Jf[:, 3:] = Ji @ Tf
        return r, Jk, Jf, Jb

    def _turns(self, s, base, a, kinematic=True):
        """(kinematic (N, 3, p), frames (N, 3, 12), joint terms (N, 3, n_terms)): the small
        turn of the tool frame [rad], in the measurement frame, per unit of each parameter
        (chain state ``s``, measurement frame ``base``, tool angles ``a``)."""
        Rb = base_rotation(*base[3:])
        Tk, Tb = (Rb @ K for K in s.rotation_columns()) if kinematic else \
            self._zero_chain_columns(3)
        Tf = np.zeros((self.N, 3, 12))
        Tf[:, :, 3:6] = base_turns(base[3], base[4])
        Tf[:, :, 9:12] = Rb @ s.R_tip @ base_turns(a[0], a[1])  # tool turns, tip frame
        return Tk, Tf, Tb

    def tool_turns(self, kin, frames, backlash=None) -> np.ndarray:
        """(N, 3, p + 12 + n_terms) the small turn of the tool frame [rad], in the
        measurement frame, per unit of each parameter: kinematic, this set's frames, joint
        terms (their values ``backlash``), in that order. What a parameter covariance C
        makes of the tool's orientation: T C T^T (:mod:`kincal.planning.accuracy_map`)."""
        s = self.chain.state(kin, backlash, keep=True)
        return np.concatenate(self._turns(s, frames[:6], frames[9:12]), axis=2)

    def start(self, kin, tool_guess=None):
        from kincal.measurements.frames_init import initial_frames

        d = self.data
        s = self.chain.state(kin, None, keep=False)
        Rb, tb, t, _, _ = initial_frames(s.R_tip, s.p_tip, d.positions, tool_guess)
        # tool orientation: the rotation nearest the mean of (R_b R_tip)^T R_measured, the
        # Kabsch rotation of its transpose (the rotation R maximising trace(R^T M))
        M = np.einsum("nji,njk->ik", Rb @ s.R_tip, d.rotations)
        Rt = kabsch_rotation(M.T)
        return np.concatenate([tb, base_angles(Rb), t, base_angles(Rt)])

    def sample_errors(self, r):
        return np.linalg.norm(r[:, :3], axis=1)

    def angle_rows(self, r) -> np.ndarray:
        """(N, 3) the rotation vector log(R_measured R^T) [rad], in the measurement frame,
        from the residual rows (their orientation rows over the sigma ratio)."""
        return r[:, 3:] / self.data.ratio()[:, None]

    def orientation_errors(self, r) -> np.ndarray:
        """(N,) orientation error angles [rad] from the residual rows."""
        return np.linalg.norm(self.angle_rows(r), axis=1)

    def notes(self):
        return (f"{self.data.source}: poses see the tool frame's orientation too; what a "
                "rigid change of the measurement frame or of the tool frame (tool.rx .ry .rz) "
                "absorbs, such as the last joint's offset, is not identified",)

