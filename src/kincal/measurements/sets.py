"""Measurement sets of any kind: the model of each, and reading a file of the right kind.

:func:`kind_model` gives the :class:`kincal.measurements.kind.KindModel` of a set's
samples; :func:`read_set_file` reads a CSV file and tells its kind from its columns:

- ``qx qy qz qw`` (or ``orientation_columns``, or any ``orientation_format``) beside the
  positions: ``pose`` (other orientation columns unread are refused unless
  ``positions_only``);
- ``distance`` and no positions: ``distance`` (both: ambiguous, refused);
- joint columns only (no positions, no distance), with ``on_plane``: ``plane``;
- positions otherwise: ``point`` (:class:`kincal.measurements.data.Measurements`).
"""

from __future__ import annotations

from kincal.errors import DataError
from kincal.measurements.csv_table import csv_line
from kincal.measurements.data import Measurements, joint_column_names
from kincal.measurements.distance import DistanceData, DistanceKind
from kincal.measurements.flush import FlushData, FlushKind, planning_set
from kincal.measurements.kind import SampleSet
from kincal.measurements.plane import PlaneData, PlaneKind
from kincal.measurements.point import PointKind
from kincal.measurements.pose import QUATERNION_COLUMNS, PoseData, PoseKind

KINDS = ("point", "pose", "distance", "plane", "flush")


def kind_of(data) -> str:
    if isinstance(data, Measurements):
        return "point"
    if isinstance(data, SampleSet):
        return data.kind
    raise DataError(f"a measurement set must be Measurements, PoseData, DistanceData or "
                    f"PlaneData, got {type(data).__name__}")


# the kinds whose samples are joint values alone: the reading is the contact itself
CONTACT_KINDS = ("plane", "flush")


def check_contacts_read(sets, files, on_plane: bool, flush: bool) -> None:
    """With --on-plane: refuse data files of which none was read as contacts (every one had
    measurement columns and was read as its kind: the option would be used nowhere)."""
    if not on_plane or any(kind_of(d) in CONTACT_KINDS for d in sets):
        return
    what = "; ".join(f"{f}: {kind_of(d)}" for f, d in zip(files, sets))
    from kincal.errors import OptionError

    raise OptionError(
        f"--on-plane{' --flush' if flush else ''} reads files of joint columns alone as "
        f"contacts, but every data file has measurement columns and is read as its kind "
        f"({what}); if those columns are not measurements (a logged floating base's x y z "
        "qx qy qz qw, say), rename or remove them")


def as_sets(data) -> list:
    """A list of measurement sets from one set or a sequence of them (DataError if empty)."""
    sets = list(data) if isinstance(data, (list, tuple)) else [data]
    if not sets:
        raise DataError("no measurement set given: give one set or a non-empty list of sets")
    for d in sets:
        kind_of(d)  # raises for anything that is not a measurement set
    return sets


def kind_model(error_model, data, backlash=(), compliance=(), torque=None):
    """The kind model of one set (backlash, compliance: chain indices of the joints with
    such a term; torque: (N, n) the samples' gravity torques [N m], for compliance)."""
    kind = kind_of(data)
    cls = {"point": PointKind, "pose": PoseKind, "distance": DistanceKind,
           "plane": PlaneKind, "flush": FlushKind}[kind]
    return cls(error_model, data, backlash, compliance, torque)


def header_of(path, columns=()) -> list[str]:
    """The column names of a CSV file (the reader that follows gives the notes). columns:
    the names the file should hold (the chain joints' columns), for the shift that would
    fit a header that does not fit its first row."""
    import warnings

    from kincal.errors import KincalNote
    from kincal.measurements.csv_table import read_columns

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalNote)
        return list(read_columns(path, [], optional=columns, header_only=True).header)


def read_set_file(path, joint_names, prismatic=(), length_unit="m", angle_unit="rad",
                  position_columns=None, orientation_columns=None, on_plane=False,
                  orientation_sigma_deg=None, joint_columns=None, order_column=None,
                  flush=False, orientation_format=None, positions_only=False):
    """One measurement set from a CSV file, its kind told by its columns (module notes).

    orientation_format: how a pose file writes its orientations (see
    :mod:`kincal.measurements.orientation_columns`; None: quaternions qx qy qz qw if the
    file has them). A file with orientation columns beside its positions is read as poses;
    read as positions only when ``positions_only`` says so, else refused (angles never
    ignored silently)."""
    from kincal.measurements.orientation_columns import (DEFAULT_FORMAT, found_columns,
                                                         unread_message)

    header = header_of(path, joint_column_names(joint_names, joint_columns).values())
    pos = tuple(position_columns) if position_columns else ("x", "y", "z")
    has_pos = all(c in header for c in pos)
    quat = tuple(orientation_columns) if orientation_columns else QUATERNION_COLUMNS
    if positions_only and (orientation_format or orientation_columns):
        raise DataError("--positions-only reads the positions alone: it cannot go with "
                        "--orientation-format or --orientation-columns")
    if on_plane and flush and not has_pos and "distance" not in header:
        return FlushData.from_csv(path, joint_names, prismatic, length_unit, angle_unit,
                                  joint_columns=joint_columns,
                                  orientation_sigma_deg=orientation_sigma_deg)
    if on_plane and not has_pos and "distance" not in header:
        return PlaneData.from_csv(path, joint_names, prismatic, length_unit, angle_unit,
                                  joint_columns=joint_columns)
    if "distance" in header:
        if has_pos:
            raise DataError(f"{path}: the file has both a 'distance' column and position "
                            f"columns ({', '.join(pos)}): is it distances to a pivot or "
                            "measured points? Keep only the columns of one kind (or rename "
                            "'distance')")
        return DistanceData.from_csv(path, joint_names, prismatic, length_unit, angle_unit,
                                     joint_columns=joint_columns)
    if has_pos and not positions_only and (orientation_format or orientation_columns
                                           or all(c in header for c in quat)):
        from kincal.measurements.pose import DEFAULT_ORIENTATION_SIGMA_DEG

        return PoseData.from_csv(path, joint_names, prismatic, length_unit, angle_unit, pos,
                                 orientation_columns,
                                 orientation_sigma_deg or DEFAULT_ORIENTATION_SIGMA_DEG,
                                 joint_columns, orientation_format or DEFAULT_FORMAT)
    read_as = joint_column_names(joint_names, joint_columns).values()
    unused = (found_columns(header, pos, (*read_as, order_column or ""))
              if has_pos and not positions_only else [])
    if unused:
        raise DataError(unread_message(path, unused[0], pos))
    return Measurements.from_csv(path, joint_names, prismatic, length_unit, angle_unit,
                                 position_columns or ("x", "y", "z"),
                                 order_column=order_column, joint_columns=joint_columns)


def to_csv_text(data, orientation_format: str = "quat-xyzw") -> str:
    """A set in the CSV layout :func:`read_set_file` reads (SI units, full precision);
    a pose set's orientations in ``orientation_format``
    (:mod:`kincal.measurements.orientation_columns`, read back with the same
    ``--orientation-format``; angles in radians)."""
    import numpy as np

    from kincal.measurements.orientation_columns import orientation_values, written_columns

    kind = kind_of(data)
    if kind in ("point", "flush"):
        return data.to_csv_text()
    cols = list(data.joint_names)
    extra: np.ndarray = np.zeros((0, 0))
    if kind == "pose":
        cols += ["x", "y", "z", *written_columns(orientation_format)]
        extra = np.hstack([data.positions, orientation_values(data.rotations,
                                                              orientation_format)])
    elif kind == "distance":
        cols += ["distance"]
        extra = data.distances[:, None]
    elif data.labels != ("",):
        cols += ["plane"]
        extra = np.array([[float(data.labels[k])] for k in data.planes])
    table = data.joint_values if len(extra) == 0 else np.hstack([data.joint_values, extra])
    if data.sigma is not None:
        cols.append("sigma")
        table = np.hstack([table, data.sigma[:, None]])
    lines = [csv_line(cols)] + [csv_line(repr(float(v)) for v in row) for row in table]
    return "\n".join(lines) + "\n"


class KindSpace:
    """Names and units of a kind's parameters for planning (kinematic, then frames): the
    part of :class:`kincal.measurements.point_space.ParameterSpace` that
    :func:`kincal.planning.pose_selection.select_poses` uses."""

    def __init__(self, names, is_length, n_kinematic: int):
        import numpy as np

        self.names = tuple(names)
        self.is_length = np.asarray(is_length, dtype=bool)
        self.n_kinematic = int(n_kinematic)
        self.size = len(self.names)

    def reporting_scale(self):
        import numpy as np

        from kincal.measurements.point_space import DEG, MM

        return np.where(self.is_length, MM, DEG)

    def indices(self, patterns):
        import fnmatch

        import numpy as np

        from kincal.errors import ParameterError, listing

        out = set()
        for p in (patterns,) if isinstance(patterns, str) else patterns:
            hits = [k for k, n in enumerate(self.names) if fnmatch.fnmatchcase(n, p)]
            if not hits:
                raise ParameterError(f"unknown parameter or pattern {p!r}. Valid names: "
                                     f"{listing(self.names, 60)}", valid=self.names)
            out.update(hits)
        return np.array(sorted(out), dtype=int)


def planning_rows(error_model, kind, q, tool, pivot=None, planes=None):
    """(rows_jacobian, :class:`KindSpace`, rows per pose) of a kind at candidate poses q
    (M, n), nominal kinematics: what D-optimal planning maximises over. rows_jacobian(idx)
    gives the candidates ``idx``'s J (len(idx), rows, p) in mm per mm or deg; take a block
    at a time (the kind's intermediates take several times the Jacobian's memory).

    pose: measurement frame at the identity, tool frame ``tool`` with no turn; distance:
    ``pivot`` (3,) [m] in the base frame (required: where the distances point decides what
    they see); plane: ``planes`` (M,) plane index of each candidate (default one plane),
    each plane fitted through the candidates' nominal tool points (they touch it)."""
    import numpy as np

    from kincal.errors import OptionError
    from kincal.measurements.plane import fit_plane
    from kincal.models.chain import Chain
    from kincal.models.kinematics import BLOCK
    from kincal.rotations import tilt_angles

    q = np.asarray(q, float)
    t = np.asarray(tool, float)
    names = tuple(error_model.joint_names)
    P, R = np.empty((len(q), 3)), np.empty((len(q), 3, 3))
    for b in range(0, len(q), BLOCK):  # the nominal tool points, a block at a time
        s = Chain(error_model, q[b:b + BLOCK]).state(error_model.nominal, None, keep=False)
        P[b:b + BLOCK], R[b:b + BLOCK] = s.p_tip + s.R_tip @ t, s.R_tip
    if kind == "pose":
        data = PoseData(joint_names=names, joint_values=q, positions=P, rotations=R)
        frames = np.r_[np.zeros(6), t, np.zeros(3)]
    elif kind == "distance":
        if pivot is None:
            raise OptionError("planning distances needs a guess of the pivot (--pivot X Y Z, "
                              "base frame): where the distances point decides what they see")
        c = np.asarray(pivot, float)
        data = DistanceData(joint_names=names, joint_values=q,
                            distances=np.linalg.norm(P - c, axis=1))
        frames = np.r_[c, t]
    elif kind == "plane":
        k = np.zeros(len(q), int) if planes is None else np.asarray(planes, int)
        labels = tuple(str(j + 1) for j in range(int(k.max()) + 1)) if planes is not None \
            else ("",)
        data = PlaneData(joint_names=names, joint_values=q, planes=k, labels=labels)
        fitted = []
        for j in range(len(labels)):
            n, d, _ = fit_plane(P[k == j])
            fitted += [*map(float, tilt_angles(n)), d]
        frames = np.r_[t, fitted]
    elif kind == "flush":
        data, frames = planning_set(error_model, q, t, planes)
    else:
        raise OptionError(f"unknown measurement kind {kind!r}; expected one of {', '.join(KINDS)}")
    km = kind_model(error_model, data)
    km.check_fixable(error_model.nominal, t) if kind == "plane" else None
    space = KindSpace(error_model.names + tuple(km.frame_names),
                      tuple(error_model.is_length) + tuple(km.frame_is_length), error_model.size)
    factor = space.reporting_scale() / 1e-3

    def rows_jacobian(idx) -> np.ndarray:
        _, Jk, Jf, _ = km.subset(np.asarray(idx)).residuals(error_model.nominal, frames,
                                                            np.zeros(0), jacobian=True)
        return np.concatenate([Jk, Jf], axis=2) * factor

    return rows_jacobian, space, km.dim
