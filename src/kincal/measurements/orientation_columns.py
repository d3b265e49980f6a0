"""Orientation columns as loggers write them, read into rotation matrices.

Formats (the name says what the columns hold, in the order the columns are given):

- ``quat-xyzw``: a unit quaternion, scalar last (ROS, scipy): columns qx qy qz qw.
- ``quat-wxyz``: a unit quaternion, scalar first (Eigen's constructor, MuJoCo, many mocap
  exports): columns qw qx qy qz.
- ``rpy-zyx``: three angles (a, b, c) about the x, y and z axes, the rotation
  ``R = Rz(c) Ry(b) Rx(a)``: roll about the fixed x axis first, then pitch about the fixed
  y, then yaw about the fixed z (equivalently yaw, then pitch, then roll about the moving
  axes). URDF's ``rpy``, ROS's ``tf`` Euler angles and FIGAROH's ``phix phiy phiz`` read
  this way (scipy: ``Rotation.from_euler("xyz", [a, b, c])``, lower case).
- ``rpy-xyz``: the same three columns (about x, y, z) read as ``R = Rx(a) Ry(b) Rz(c)``
  (kincal's own measurement frame ``base.rx .ry .rz``; scipy:
  ``Rotation.from_euler("XYZ", [a, b, c])``, upper case).
- ``rotvec``: a rotation vector (axis times angle), as UR controllers log ``rx ry rz``.
- ``matrix``: the nine entries of the rotation matrix, row by row (r11 r12 r13 r21 ...).

Angles (rpy, rotvec) are in the file's angle unit (``--angle-unit``, as its revolute joints).
Quaternions and matrices must be unit and orthonormal to :data:`UNIT_TOL` (rounding in the
file); beyond it the row is refused with its line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError
from kincal.rotations import base_angles, rotation_exp, rotation_log, rotations_about

FORMATS = ("quat-xyzw", "quat-wxyz", "rpy-zyx", "rpy-xyz", "rotvec", "matrix")
DEFAULT_FORMAT = "quat-xyzw"
UNIT_TOL = 1e-3
MATRIX_COLUMNS = tuple(f"r{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3))
# column names tried when --orientation-columns is not given, each also with the suffix of
# the position columns (x1 y1 z1 -> phix1 phiy1 phiz1)
CANDIDATES = {
    "quat-xyzw": (("qx", "qy", "qz", "qw"),),
    "quat-wxyz": (("qw", "qx", "qy", "qz"),),
    "rpy-zyx": (("roll", "pitch", "yaw"), ("phix", "phiy", "phiz")),
    "rpy-xyz": (("roll", "pitch", "yaw"), ("phix", "phiy", "phiz")),
    "rotvec": (("rx", "ry", "rz"),),
    "matrix": (MATRIX_COLUMNS,),
}
SIZES = {"quat-xyzw": 4, "quat-wxyz": 4, "rpy-zyx": 3, "rpy-xyz": 3, "rotvec": 3, "matrix": 9}
OTHER_CONVENTION = {"rpy-zyx": "rpy-xyz", "rpy-xyz": "rpy-zyx",
                    "quat-xyzw": "quat-wxyz", "quat-wxyz": "quat-xyzw"}


def suffix_of(position_columns) -> str:
    """The common suffix of position columns x<s> y<s> z<s> ('' for x y z or other names)."""
    p = tuple(position_columns or ("x", "y", "z"))
    s = p[0][1:] if p[0][:1] == "x" else None
    return s if s is not None and p[:3] == ("x" + s, "y" + s, "z" + s) else ""


def candidate_columns(fmt: str, position_columns=None) -> list[tuple[str, ...]]:
    """The column groups a format is looked for under, suffixed ones first."""
    s = suffix_of(position_columns)
    out = [tuple(c + s for c in g) for g in CANDIDATES[fmt]] if s else []
    return out + list(CANDIDATES[fmt])


def found_columns(header, position_columns=None, exclude=()) -> list[tuple[str, ...]]:
    """Every group of orientation columns in ``header``, for the refusal of a pose file
    read as positions: each complete group of the usual names (any format), then the
    columns named as loggers name orientation components otherwise (:func:`looks_like`:
    ``Roll``, ``quat_x``, ``pose.orientation.w``, three of a quaternion's four), as one
    group in the header's order. exclude: columns read as something else (joints)."""
    seen: list[tuple[str, ...]] = []
    for fmt in FORMATS:
        for g in candidate_columns(fmt, position_columns):
            if all(c in header for c in g) and set(g) not in [set(x) for x in seen]:
                seen.append(g)
    known = {c for g in seen for c in g} | set(exclude) | set(position_columns or "xyz")
    suffix = suffix_of(position_columns)
    other = tuple(c for c in header if c not in known and looks_like(c, suffix))
    return seen + ([other] if other else [])


# the names of orientation components loggers write beyond the usual ones (CANDIDATES),
# matched without case, after a unit and the position columns' suffix are taken off: a
# quaternion's or rotation's x y z w ("quat_x", "pose.orientation.w", "Rotation X", "qw"),
# Euler angles ("Roll", "yaw"), rotation vectors and matrices ("Rx", "R11")
_COMPONENT = re.compile(r"^(?:.*[._\s-])?(?:q|quat|quaternion|orient|orientation|rot|rotation)"
                        r"[._\s-]?[xyzw]$|^(?:roll|pitch|yaw|phi[xyz]|r[xyz]|r[1-3][1-3])$")
_UNIT_TAIL = re.compile(r"[\s._-]*[\[(]?(?:deg|degrees|rad|radians)[\])]?$")


def looks_like(name: str, suffix: str = "") -> bool:
    """Whether a column ``name`` looks like an orientation component (see _COMPONENT);
    suffix: that of the position columns (x1 y1 z1: "1"), taken off first."""
    n = _UNIT_TAIL.sub("", str(name).strip().lower())
    if suffix and n.endswith(suffix.lower()) and len(n) > len(suffix):
        n = n[: len(n) - len(suffix)]
    return bool(_COMPONENT.match(n))


def is_usual(columns, position_columns=None) -> bool:
    """Whether ``columns`` are a complete group of the usual names of some format (which
    ``--orientation-format`` alone reads), not look-alikes needing --orientation-columns."""
    return any(set(columns) == set(g) for fmt in FORMATS
               for g in candidate_columns(fmt, position_columns))


def unread_message(path, columns, position_columns, purpose: str = "to calibrate poses",
                   alone: str = "--positions-only to use the positions alone") -> str:
    """The refusal of orientation columns that a reading as positions would drop; purpose:
    what reading them gives, alone: how to read the positions without them."""
    pos = " ".join(position_columns or ("x", "y", "z"))
    formats = "--orientation-format quat-xyzw, quat-wxyz, rpy-zyx, rpy-xyz, rotvec or matrix"
    how = (f"give their format ({formats}) {purpose}" if is_usual(columns, position_columns)
           else f"name them in their format's order ({formats}, with --orientation-columns) "
           f"{purpose}")
    return (f"{path}: orientation columns {', '.join(columns)} beside the position columns "
            f"{pos} would not be read: {how}, or {alone}")


@dataclass(frozen=True)
class OrientationFormat:
    """How a pose file writes its orientations: ``name`` one of :data:`FORMATS`; columns:
    the file's columns in the order the format lists them (None: looked for under the
    usual names, :data:`CANDIDATES`)."""

    name: str = DEFAULT_FORMAT
    columns: tuple[str, ...] | None = None

    def __post_init__(self):
        if self.name not in FORMATS:
            raise DataError(f"unknown orientation format {self.name!r}; expected one of "
                            f"{', '.join(FORMATS)}")
        if self.columns is not None and len(self.columns) != SIZES[self.name]:
            raise DataError(f"orientation format {self.name} takes {SIZES[self.name]} columns, "
                            f"got {len(self.columns)}: {' '.join(self.columns)}")

    @property
    def unfixed(self) -> bool:
        """Whether the file's columns leave the convention open (another one,
        :data:`OTHER_CONVENTION`, reads the same columns): angles, or quaternion columns
        the user named; the usual quaternion names fix theirs."""
        return self.name in OTHER_CONVENTION and (self.columns is not None
                                                  or not self.name.startswith("quat"))

    def resolve(self, header, position_columns=None, source="") -> tuple[str, ...]:
        """The columns to read in ``header`` (DataError naming what is missing)."""
        if self.columns is not None:
            return tuple(self.columns)  # the reader says which are missing
        groups = candidate_columns(self.name, position_columns)
        for g in groups:
            if all(c in header for c in g):
                return g
        raise DataError(f"{source}: no orientation columns for format {self.name}: looked for "
                        + " or ".join(" ".join(g) for g in groups)
                        + "; name them with --orientation-columns")


def rotations(values: np.ndarray, fmt: str, angle_scale: float = 1.0, source: str = "",
              rows=None, columns=()) -> np.ndarray:
    """(N, 3, 3) rotations from (N, k) column values in format ``fmt``; angle_scale:
    radians per unit of the angle columns (rpy, rotvec)."""
    v = np.asarray(values, dtype=float)
    rows = np.arange(2, len(v) + 2) if rows is None else np.asarray(rows)
    if fmt in ("quat-xyzw", "quat-wxyz"):
        q = v if fmt == "quat-xyzw" else v[:, [1, 2, 3, 0]]
        norm = np.linalg.norm(q, axis=1)
        _refuse(np.abs(norm - 1.0), source, rows, columns, "the quaternion", "has norm",
                norm, "not 1: give unit quaternions")
        from kincal.rotations import quaternion_to_matrix

        return quaternion_to_matrix(q / norm[:, None])  # renormalise the rounding only
    if fmt == "matrix":
        M = v.reshape(-1, 3, 3)
        off = np.abs(np.einsum("nji,njk->nik", M, M) - np.eye(3)).max(axis=(1, 2))
        off = np.where(np.linalg.det(M) > 0, off, np.inf)
        _refuse(off, source, rows, columns, "the matrix", "is off orthonormal by", off,
                "(rows r11 r12 r13, r21 ..., a proper rotation)")
        U, _, Vt = np.linalg.svd(M)  # the nearest rotation: the rounding only
        return U @ Vt
    a = v * angle_scale
    _unit_warning(v, angle_scale, source, columns)
    if fmt == "rotvec":
        return rotation_exp(a)
    Rx, Ry, Rz = (rotations_about(k, a[:, k]) for k in range(3))
    return Rz @ Ry @ Rx if fmt == "rpy-zyx" else Rx @ Ry @ Rz


def _unit_warning(v: np.ndarray, angle_scale: float, source, columns) -> None:
    """Warn angles read as radians beyond a turn (and a half): degrees, most likely. They
    are read in the revolute joints' unit, so a file of joints in radians and angles in
    degrees has no reading: the warning says so (the gate then refuses the calibration)."""
    import warnings

    from kincal.errors import KincalWarning
    from kincal.measurements.checks import DEGREES_AS_RADIANS

    biggest = float(np.abs(v).max()) if v.size else 0.0
    if angle_scale == 1.0 and biggest > DEGREES_AS_RADIANS:
        warnings.warn(f"{source}: orientation angles ({', '.join(columns)}) reach "
                      f"{biggest:.4g} rad: were they degrees? They are read in the revolute "
                      "joints' unit (--angle-unit deg reads both in degrees; joints in radians "
                      "and angles in degrees must be converted to one unit)", KincalWarning)


def _refuse(bad_amount, source, rows, columns, what, verb, shown, expected) -> None:
    bad = np.flatnonzero(bad_amount > UNIT_TOL)
    if bad.size:
        k = bad[np.argmax(bad_amount[bad])]
        raise DataError(f"{source}, line {rows[bad[0]]}: {what} ({', '.join(columns)}) {verb} "
                        f"{shown[bad[0]]:.6g}, {expected} ({bad.size} of {len(rows)} rows are "
                        f"off by more than {UNIT_TOL:g}; worst line {rows[k]}); or is the "
                        "orientation format another? (--orientation-format, --orientation-columns)")


def written_columns(fmt: str, position_columns=None) -> tuple[str, ...]:
    """The columns a pose file written in format ``fmt`` gets: the format's first usual
    names (roll pitch yaw for rpy), suffixed like the position columns."""
    return candidate_columns(fmt, position_columns)[0]


def orientation_values(R: np.ndarray, fmt: str, angle_scale: float = 1.0) -> np.ndarray:
    """(N, k) the columns of format ``fmt`` for rotations R (N, 3, 3): the inverse of
    :func:`rotations` (angles divided by ``angle_scale``, radians per unit). Quaternions with
    w >= 0; roll/pitch/yaw with the pitch in [-90, 90] deg; rotation vectors of angle <= pi."""
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    if fmt not in FORMATS:
        raise DataError(f"unknown orientation format {fmt!r}; expected one of "
                        f"{', '.join(FORMATS)}")
    if fmt == "matrix":
        return R.reshape(-1, 9)
    if fmt in ("quat-xyzw", "quat-wxyz"):
        from kincal.rotations import matrix_to_quaternion

        q = np.array([matrix_to_quaternion(r) for r in R]).reshape(-1, 4)  # qw >= 0
        return q if fmt == "quat-xyzw" else q[:, [3, 0, 1, 2]]
    if fmt == "rotvec":
        a = rotation_log(R)
    elif fmt == "rpy-zyx":  # R = Rz(c) Ry(b) Rx(a): a, then b and c from R Rx(a)^T
        x = np.arctan2(R[:, 2, 1], R[:, 2, 2])  # so that the angles give R back to
        M = R @ np.transpose(rotations_about(0, x), (0, 2, 1))  # rounding even at gimbal lock
        a = np.column_stack([x, np.arctan2(-M[:, 2, 0], M[:, 2, 2]),
                             np.arctan2(-M[:, 0, 1], M[:, 1, 1])])
    else:  # rpy-xyz: R = Rx(a) Ry(b) Rz(c), the measurement frame's angles
        a = base_angles(R)
    return a / angle_scale


# a reading of orientations looks wrong when it is this many times further from what the
# model says than the other reading, and at least this far [deg] (mean)
FAR_WORSE = 5.0
AT_LEAST_DEG = 5.0


def other_reading(R: np.ndarray, fmt: str) -> np.ndarray:
    """(N, 3, 3) the rotations the same columns give read in ``fmt``'s other convention
    (:data:`OTHER_CONVENTION`). From the rotations themselves: a quaternion's components,
    or angles with the middle one within +-90 deg (as loggers write them), come back
    exactly."""
    return rotations(orientation_values(R, fmt), OTHER_CONVENTION[fmt])


def reading_doubt(R_model: np.ndarray, R_read: np.ndarray, fmt: str, what: str,
                  model: str = "the model's") -> str:
    """"" or why orientations ``R_read`` (N, 3, 3), read in ``fmt`` (a convention the
    columns do not fix, :data:`OTHER_CONVENTION`), look read in the wrong one: their mean
    angle from ``R_model`` (what a model says they should be near) is at least
    :data:`AT_LEAST_DEG` and :data:`FAR_WORSE` times that of the other reading. what: the
    orientations, model: ``R_model``, for the message."""
    if fmt not in OTHER_CONVENTION or not len(R_read):
        return ""
    other = OTHER_CONVENTION[fmt]

    def mean_deg(R):
        turn = rotation_log(np.swapaxes(R_model, 1, 2) @ R)
        return float(np.degrees(np.mean(np.linalg.norm(turn, axis=1))))

    given, alt = mean_deg(R_read), mean_deg(other_reading(R_read, fmt))
    if given < AT_LEAST_DEG or given < FAR_WORSE * alt:
        return ""
    return (f"{what} read as {fmt} lie a mean {given:.1f} deg from {model}, read as "
            f"{other} {alt:.2f} deg: is the file's convention {other}? "
            "(--orientation-format)")
