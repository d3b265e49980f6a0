"""The point measurement kind: predicted positions of points on the tool and their
analytic identification Jacobian, vectorised over poses.

Plain numpy. For N samples with chain joint values q (N, n), and the parameter vector x of
:mod:`kincal.measurements.point_space`, the predicted tool point in the measurement frame is

    P_k = R_base (p_tip(q_k; x) + R_tip(q_k; x) t_tool) + t_base       [m]

computed with the chain of any error model (:mod:`kincal.models`; the same numbers
Pinocchio gives for the corrected URDF). The kinematic and backlash columns come from
:mod:`kincal.models.chain` (closed form, no finite differences); the frame columns are
those of the measurement frame (rotation Rx(rx) Ry(ry) Rz(rz)) and of the tool points.

With several measured points per pose (K tool points), each sample names its point; the
sample sees its own t_tool, and only that point's tool columns are non-zero.
"""

from __future__ import annotations

import numpy as np

from kincal.errors import DataError
from kincal.measurements.point_space import BASE, TOOL, ParameterSpace
from kincal.models.base import ErrorModel
from kincal.models.chain import Chain, axis_cross, equal_runs
from kincal.rotations import base_rotation, rotations_about, rotx, roty, rotz


_EYE3 = np.eye(3)  # the base translation's columns (read only)
_EYE3.flags.writeable = False


class MeasurementModel:
    """Forward model and Jacobian of point measurements over a fixed set of poses.

    model: the chain's error model (:mod:`kincal.models`). joint_values: (N, n) [rad or m],
    one row per sample. backlash: chain joints with a backlash term; approach: (N, n)
    approach directions of the samples (needed with backlash terms). points: (N,) index of
    the measured point of each sample (default all 0) among n_points (default: as many as
    the indices name). compliance: chain joints with a compliance term; torque: (N, n)
    gravity torques of the samples [N m] (needed with compliance terms). The joint motions
    are computed once here, so evaluating many parameter vectors on the same poses is cheap.
    """

    def __init__(self, model: ErrorModel, joint_values: np.ndarray,
                 approach: np.ndarray | None = None, backlash=(),
                 points: np.ndarray | None = None, n_points: int | None = None,
                 torque: np.ndarray | None = None, compliance=()):
        self.error_model = model
        try:
            q = np.asarray(joint_values, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"joint_values must be an (N, {model.n}) array of numbers "
                            f"({exc})") from None
        if q.ndim != 2 or q.shape[1] != model.n:
            raise DataError(f"joint_values must be (N, {model.n}), got {q.shape}")
        self.points = (np.zeros(len(q), dtype=int) if points is None
                       else np.asarray(points, dtype=int))
        if self.points.shape != (len(q),) or (len(q) and self.points.min() < 0):
            raise DataError(f"points must be ({len(q)},) indices >= 0")
        if n_points is None:
            n_points = int(self.points.max()) + 1 if len(q) else 1
        self.space = ParameterSpace.of_model(model, backlash, n_points, compliance)
        if len(q) and self.points.max() >= n_points:
            raise DataError(f"a point index is >= n_points = {n_points}")
        self.chain = Chain(model, q, approach, self.space.backlash_joint_index, torque,
                           self.space.compliance_joint_index)
        self.q, self.approach, self.N = q, self.chain.approach, len(q)
        self.torque = self.chain.torque

    def subset(self, rows) -> "MeasurementModel":
        return MeasurementModel(self.error_model, self.q[rows],
                                None if self.approach is None else self.approach[rows],
                                self.space.backlash, self.points[rows], self.space.n_points,
                                None if self.torque is None else self.torque[rows],
                                self.space.compliance)

    def _measured_points(self, x: np.ndarray, R_tip: np.ndarray, p_tip: np.ndarray) -> np.ndarray:
        """(N, 3) each sample's measured point in the base frame."""
        tools = self.space.tools(x)
        if tools.ndim == 3:  # one vector per sample (the products of R_tip @ tools[0])
            t = tools[np.arange(self.N), self.points]
            if tools.shape[1] == 1:
                return p_tip + np.matmul(R_tip, t[:, :, None])[:, :, 0]
            return p_tip + np.einsum("nij,nj->ni", R_tip, t)
        if len(tools) == 1:
            return p_tip + R_tip @ tools[0]
        return p_tip + np.einsum("nij,nj->ni", R_tip, tools[self.points])

    def tip_poses(self, kinematic: np.ndarray, backlash: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """(R (N, 3, 3), p (N, 3)) of the tip frame in the base frame."""
        return self.chain.tip(np.asarray(kinematic, float).ravel(), backlash)

    def predict(self, x: np.ndarray) -> np.ndarray:
        """(N, 3) predicted tool-point positions in the measurement frame [m]."""
        kin, base, _ = self.space.split(x)
        s = self.chain.state(kin, self.space.backlash_values(x), keep=False)
        P = self._measured_points(x, s.R_tip, s.p_tip)
        if x.ndim == 2:  # one vector per sample
            return _rotate(_base_rotations(base), P) + base[:, :3]
        return P @ base_rotation(*base[3:]).T + base[:3]

    def jacobian(self, x: np.ndarray, kinematic: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(prediction (N, 3), Jacobian (N, 3, p)) of the predicted positions w.r.t. x.

        kinematic=False leaves the kinematic and backlash columns at zero (cheaper, for
        frame-only fits).
        """
        kin, base, _ = self.space.split(x)
        s = self.chain.state(kin, self.space.backlash_values(x), keep=kinematic)
        P = self._measured_points(x, s.R_tip, s.p_tip)
        k, f = self.space.n_kinematic, self.space.n_frames
        J = np.empty((self.N, 3, self.space.size))
        if not kinematic:
            J[:, :, :k] = 0.0
            J[:, :, k + f:] = 0.0
            return self._frame_columns(J, P, s.R_tip, base)
        J[:, :, :k], J[:, :, k + f:] = s.point_columns(P)
        return self._frame_columns(J, P, s.R_tip, base, rotate_kinematic=True)

    def _frame_columns(self, J, P, R_tip, base, rotate_kinematic=False):
        """Fill the base and tool columns (and turn the kinematic ones into the measurement frame)."""
        N, k, f = self.N, self.space.n_kinematic, self.space.n_frames
        if base.ndim == 2:  # one vector per sample: one rotation per sample
            Rx, Rz, RxRy, Rb, RyRz = _sample_rotations(base)
        else:
            Rx, Ry, Rz = rotx(base[3]), roty(base[4]), rotz(base[5])
            RxRy, RyRz = Rx @ Ry, Ry @ Rz
            Rb = RxRy @ Rz
        if rotate_kinematic:
            J[:, :, :k] = np.matmul(Rb, J[:, :, :k])
            if k + f < J.shape[2]:  # joint terms (backlash, compliance)
                J[:, :, k + f:] = np.matmul(Rb, J[:, :, k + f:])
        Pm = _rotate(Rb, P) + base[..., :3]
        J[:, :, k:k + 3] = _EYE3
        axis_cross(0, Pm - base[..., :3], out=J[:, :, k + 3])
        J[:, :, k + 4] = _rotate(Rx, axis_cross(1, _rotate(RyRz, P)))
        J[:, :, k + 5] = _rotate(RxRy, axis_cross(2, _rotate(Rz, P)))
        # a sample moves with its own point only: its block gets R_b R_tip, the others 0
        if self.space.n_points == 1:  # one point: its columns are whole slices
            for c in range(3):
                J[:, :, k + 6 + c] = np.matmul(Rb, R_tip[:, :, c, None])[:, :, 0]
            return Pm, J
        J[:, :, k + 6:k + 6 + 3 * self.space.n_points] = 0.0
        rows, first = np.arange(N), k + 6 + 3 * self.points
        for c in range(3):
            J[rows, :, first + c] = np.matmul(Rb, R_tip[:, :, c, None])[:, :, 0]
        return Pm, J


def _rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N, 3) rows v (N, 3) turned by R: one (3, 3) rotation, or (N, 3, 3) one per row. The
    latter as (1, 3) x (3, 3) products of R's contiguous transposes, which give the bits of
    v @ R.T for equal R (checked for 2 to 300 rows; an einsum or a product with the
    transposed view rounds otherwise), so the folds of Algorithm 1 evaluated together
    follow the path of each fold on its own."""
    if R.ndim == 2:
        return v @ R.T
    return np.matmul(v[:, None, :], np.ascontiguousarray(R.transpose(0, 2, 1)))[:, 0, :]


def _sample_rotations(base: np.ndarray) -> tuple[np.ndarray, ...]:
    """(Rx, Rz, Rx Ry, Rx Ry Rz, Ry Rz), each (N, 3, 3), of (N, 6) frame vectors, one
    per sample: made once per run of equal rows and repeated (the folds of Algorithm 1
    evaluated together: a few frames over many samples), each matrix the product the rows
    would give one by one, so the same numbers."""
    runs = equal_runs(base)
    rep = None
    if len(runs) < len(base):
        base, rep = base[[a for a, _ in runs]], [b - a for a, b in runs]
    Rx, Ry, Rz = (rotations_about(c, base[:, 3 + c]) for c in range(3))
    RxRy = Rx @ Ry
    out = (Rx, Rz, RxRy, RxRy @ Rz, Ry @ Rz)
    return out if rep is None else tuple(np.repeat(R, rep, axis=0) for R in out)


def _base_rotations(base: np.ndarray) -> np.ndarray:
    """(N, 3, 3) the measurement frames' rotations Rx Ry Rz of (N, 6) frame vectors."""
    return _sample_rotations(base)[3]


# samples from which the closed-form first guess of the frames is made, at most: it is
# refined by Gauss-Newton on every sample, and its (N, 3, 6) systems would otherwise be the
# largest temporaries of a fit of many poses
START_SAMPLES = 20_000


class PointKind:
    """The point kind (the :class:`kincal.measurements.kind.KindModel` interface):
    residuals P_measured - P_predicted [m], through the one point engine
    :class:`MeasurementModel`.

    Frames: ``base.x .y .z .rx .ry .rz`` (measurement frame) and ``tool.*`` (``tool<k>.*``
    for further points). data: :class:`kincal.measurements.data.Measurements`.
    """

    kind = "point"
    dim = 3

    def __init__(self, error_model: ErrorModel, data, backlash=(), compliance=(), torque=None):
        self.error_model = error_model
        self.data = data.for_chain(error_model.joint_names)
        names = tuple(error_model.joint_names[i] for i in backlash)
        self.model = MeasurementModel(error_model, self.data.joint_values, self.data.approach,
                                      names, self.data.points, self.data.n_points, torque,
                                      tuple(error_model.joint_names[i] for i in compliance))
        K = self.data.n_points
        self.frame_names = BASE + TOOL + tuple(f"tool{k}.{c}" for k in range(2, K + 1)
                                               for c in "xyz")
        self.frame_is_length = (True,) * 3 + (False,) * 3 + (True,) * 3 * K
        self.N = len(self.data)
        self.chain = self.model.chain

    @property
    def n_frames(self) -> int:
        return len(self.frame_names)

    def subset(self, rows) -> "PointKind":
        other = object.__new__(PointKind)
        other.__dict__.update(self.__dict__)
        other.data = self.data.subset(rows)
        other.model = self.model.subset(rows)
        other.chain = other.model.chain
        other.N = len(other.data)
        return other

    def residuals(self, kin, frames, backlash, jacobian=False, kinematic=True):
        x = np.concatenate([kin, frames, backlash], axis=-1)
        P = self.data.positions
        if not jacobian:
            return P - self.model.predict(x)
        pred, J = self.model.jacobian(x, kinematic)
        k, f = kin.shape[-1], frames.shape[-1]
        return P - pred, -J[:, :, :k], -J[:, :, k:k + f], -J[:, :, k + f:]

    def start(self, kin, tool_guess=None, base_guess=None) -> np.ndarray:
        """Closed-form first guess of the measurement frame and tool points; base_guess
        (6,) replaces the measurement frame (the tool point then is tool_guess if given),
        and further points follow from that frame."""
        from kincal.measurements.frames_init import initial_frames, point_in_tip
        from kincal.rotations import base_angles, base_rotation

        model, P, pts = self.model, self.data.positions, self.data.points
        if self.N > START_SAMPLES:  # a first guess: from samples spread through the set
            K = self.data.n_points
            rows = np.concatenate([m[np.linspace(0, len(m) - 1, min(len(m), START_SAMPLES // K))
                                     .astype(int)] for m in (np.flatnonzero(pts == k)
                                                             for k in range(K)) if len(m)])
            rows.sort()
            model, P, pts = self.model.subset(rows), P[rows], pts[rows]
        R_tip, p_tip = model.tip_poses(kin)
        first = pts == 0
        Rb, tb, tool, _, _ = initial_frames(R_tip[first], p_tip[first], P[first], tool_guess)
        base = np.concatenate([tb, base_angles(Rb)])
        if base_guess is not None:
            base = np.asarray(base_guess, dtype=float)
            Rb, tb = base_rotation(*base[3:]), base[:3]
            if tool_guess is not None:
                tool = np.asarray(tool_guess, dtype=float)
        tools = [tool] + [point_in_tip(R_tip[m], p_tip[m], P[m], Rb, tb)
                          for m in (pts == k for k in range(1, self.data.n_points))]
        return np.concatenate([base, np.ravel(tools)])

    def sample_errors(self, r):
        return np.linalg.norm(r, axis=1)

    def angle_rows(self, r) -> None:
        """Points have no orientation (:meth:`KindModel.angle_rows`)."""
        return None

    def noise_rows(self) -> tuple[tuple[str, str, np.ndarray], ...]:
        """x, y, z: one kind of row, in mm (:meth:`KindModel.noise_rows`)."""
        return tuple(("", "mm", np.full(self.N, 1e-3)) for _ in range(self.dim))

    def noise_stated(self) -> bool:
        """Whether the set states its noise (a ``sigma`` column or ``--set-sigma-mm``)."""
        return self.data.sigma is not None

    def notes(self) -> tuple[str, ...]:
        return ()
