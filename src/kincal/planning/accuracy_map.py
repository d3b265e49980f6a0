"""Predicted accuracy map: how well a calibration locates the tool point, pose by pose.

The parameter covariance C of a calibration [SI] and the measurement model's Jacobian
J_k = dP_k/dx (3, p) at a target pose k give the covariance of the predicted tool point,
Sigma_k = J_k C J_k^T [m^2], in the measurement frame (it includes the uncertainty of
the measurement frame and tool point: it is what an instrument in that frame would see
scatter over repeated calibrations with the same poses). Two numbers per pose, in mm:

- ``std``: sqrt(trace Sigma_k), the RMS length of the 3-D position error;
- ``worst_axis``: sqrt of the largest eigenvalue, the standard deviation along the
  worst direction.

For a pose set the map also gives the tool frame's orientation: with T_k = d(turn)/dx
(3, p), the small turn of the tool frame in the measurement frame per unit of each
parameter (the pose kind's orientation rows, :meth:`PoseKind.tool_turns`), Sigma_k =
T_k C T_k^T [rad^2] and ``orientation_std`` = sqrt(trace), the RMS angle [rad; deg in
the summary and the files].

Targets are either joint configurations (the calibration poses, or a candidates file), or
a cube of grid points in the chain's base frame, each reached by inverse kinematics on
the (corrected) robot from the nearest calibration pose, so the map stays on the branch
the robot was measured on. Unreachable grid points are skipped and counted.

This is the variance part of the error only: a bias (the pull of the L2 penalty, or
errors no MD-H model has, such as compliance) is not in it. It lives in planning because
it answers the planning question "where will the calibrated robot be accurate, and would
more poses help", and it takes a calibration's output as its input.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.errors import OptionError
from kincal.frames_file import MAX_LENGTH
from kincal.measurements.point_space import BASE, MM, ParameterSpace
from kincal.measurements.point import MeasurementModel
from kincal.measurements.pose import FRAMES as POSE_FRAMES
from kincal.measurements.pose import PoseData, PoseKind
from kincal.robot import Robot


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class AccuracyMap:
    """Predicted standard deviations of the tool point at M target poses.

    positions: (M, 3) tool point in the chain's base frame [m]. joint_values: (M, n)
    [rad, m]. std: (M,) sqrt(trace of the 3x3 covariance) [m]; worst_axis: (M,) standard
    deviation along the worst direction [m]. skipped: (K, 3) cube grid points no
    configuration within the joint limits reached [m] (empty for pose sets).
    targets: what the poses are, for reports ("5x5x5 grid ...", "the 60 calibration poses").
    covariance_source: where C came from ("calibration (sandwich)", "design, noise ...").
    orientation_std: (M,) sqrt(trace of the 3x3 covariance of the tool frame's small turn)
    [rad], for a pose set; None for points (no tool orientation).
    """

    positions: np.ndarray
    joint_values: np.ndarray
    std: np.ndarray
    worst_axis: np.ndarray
    skipped: np.ndarray
    targets: str
    covariance_source: str
    orientation_std: np.ndarray | None = None

    def summary(self) -> str:
        """A few lines with the figures in mm."""
        lines = [f"predicted accuracy (1 sd of the tool point, {self.covariance_source}) at "
                 f"{self.targets}:"]
        if len(self.std):
            s = self.std / MM
            lines.append(f"  3-D std: median {np.median(s):.4f}  mean {np.mean(s):.4f}  "
                         f"min {np.min(s):.4f}  max {np.max(s):.4f} mm  (n = {len(s)}); "
                         f"worst axis up to {np.max(self.worst_axis) / MM:.4f} mm")
            if self.orientation_std is not None:
                a = np.degrees(self.orientation_std)
                lines.append(f"  orientation std (tool frame): median {np.median(a):.4f}  "
                             f"mean {np.mean(a):.4f}  min {np.min(a):.4f}  max "
                             f"{np.max(a):.4f} deg")
        else:
            lines.append("  no target reached")
        if len(self.skipped):
            lines.append(f"  {len(self.skipped)} of {len(self.skipped) + len(self.std)} grid "
                         "points skipped: not reachable within the joint limits from the "
                         "calibration poses' branch")
        return "\n".join(lines)

    def as_dict(self) -> dict:
        """JSON-ready content (SI positions, figures in mm)."""
        s = self.std / MM
        out = {"targets": self.targets, "covariance": self.covariance_source,
                "frame": "positions in the chain's base frame [m]; std of the predicted "
                         "point in the measurement frame [mm]",
                "reached": int(len(self.std)), "skipped": int(len(self.skipped)),
                "std_mm": {"median": float(np.median(s)) if len(s) else None,
                           "mean": float(np.mean(s)) if len(s) else None,
                           "max": float(np.max(s)) if len(s) else None},
                "positions_m": self.positions.tolist(),
                "joint_values": self.joint_values.tolist(),
                "std_3d_mm": s.tolist(), "worst_axis_mm": (self.worst_axis / MM).tolist(),
                "skipped_positions_m": self.skipped.tolist()}
        if self.orientation_std is not None:  # a pose set: the tool frame's orientation too
            a = np.degrees(self.orientation_std)
            out |= {"orientation_std_deg": {"median": float(np.median(a)) if len(a) else None,
                                            "mean": float(np.mean(a)) if len(a) else None,
                                            "max": float(np.max(a)) if len(a) else None},
                    "orientation_std_per_pose_deg": a.tolist()}
        return out


def _chain_model(owner):
    """The chain's error model of a CalibrationResult or CalibrationProblem (what
    MeasurementModel takes); the one place that names the attribute. A calibration of
    several chains has no one chain model: refused."""
    chains = getattr(owner, "chains", None)
    if chains is not None and chains.several:
        raise OptionError("the accuracy map describes one chain; this calibration holds "
                          "several (one --base/--tip per file): calibrate a chain alone for it")
    return owner.error_model


def _measurement_model(chain, space: ParameterSpace, q: np.ndarray) -> MeasurementModel:
    """Point 1 at the poses q, backlash terms (if any) in the middle of their play."""
    return MeasurementModel(chain, q, np.zeros(q.shape), space.backlash,
                            np.zeros(len(q), dtype=int), space.n_points)


def predicted_std(chain, space: ParameterSpace, x: np.ndarray, covariance: np.ndarray,
                  joint_values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((M,) sqrt(trace Sigma_k), (M,) sqrt(max eig Sigma_k)) [m] of point 1 at the poses.

    chain: the chain's error model (``result.error_model``). covariance: (p, p) over
    ``space.names`` [SI]. Backlash terms are taken in the middle of their play (no
    approach direction), so their columns do not contribute.
    """
    q = np.atleast_2d(np.asarray(joint_values, float))
    _, J = _measurement_model(chain, space, q).jacobian(x)       # (M, 3, p)
    S = np.einsum("mip,pq,mjq->mij", J, covariance, J)           # (M, 3, 3)
    eig = np.linalg.eigvalsh(S)
    return np.sqrt(np.maximum(eig.sum(axis=1), 0.0)), np.sqrt(np.maximum(eig[:, -1], 0.0))


def predicted_turn_std(chain, backlash: tuple[str, ...], x: np.ndarray,
                       covariance: np.ndarray, joint_values: np.ndarray) -> np.ndarray:
    """(M,) sqrt(trace T_k C T_k^T) [rad]: the RMS angle of the tool frame's predicted
    orientation error at the poses (the module notes).

    chain: the chain's error model. backlash: the joints of its backlash terms. x and
    covariance: over the pose kind's parameters (kinematic, the 12 frames of
    :data:`kincal.measurements.pose.FRAMES`, the backlash terms) [SI]; backlash terms in
    the middle of their play, as for positions."""
    q = np.atleast_2d(np.asarray(joint_values, float))
    M = len(q)
    data = PoseData(joint_names=tuple(chain.joint_names), joint_values=q,
                    positions=np.zeros((M, 3)), rotations=np.tile(np.eye(3), (M, 1, 1)),
                    approach=np.zeros(q.shape))
    km = PoseKind(chain, data, [list(chain.joint_names).index(j) for j in backlash])
    p, f = chain.size, len(POSE_FRAMES)
    T = km.tool_turns(x[:p], x[p:p + f], x[p + f:])                # (M, 3, p + 12 + nb)
    S = np.einsum("mip,pq,mjq->mij", T, covariance, T)
    return np.sqrt(np.maximum(np.trace(S, axis1=1, axis2=2), 0.0))


def tool_positions(chain, space: ParameterSpace, x: np.ndarray,
                   joint_values: np.ndarray) -> np.ndarray:
    """(M, 3) point 1 in the chain's base frame [m] at the poses, with parameters x."""
    q = np.atleast_2d(np.asarray(joint_values, float))
    x_base = np.array(x, dtype=float)
    x_base[space.indices(BASE)] = 0.0  # identity measurement frame: the base frame itself
    return _measurement_model(chain, space, q).predict(x_base)


MAX_GRID = 25  # grid points per edge of an accuracy cube: 25^3 inverse kinematics at most


def cube_grid(center, edge: float, n: int = 5) -> np.ndarray:
    """(n^3, 3) points of an n x n x n grid filling a cube [m] (n = 1: the centre)."""
    c = np.asarray(center, float)
    if c.shape != (3,) or not np.all(np.isfinite(c)) or np.abs(c).max() > MAX_LENGTH:
        raise OptionError(f"the cube centre must be 3 finite numbers within {MAX_LENGTH:g} m "
                          f"of the base frame, got {center!r}")
    if not (np.isfinite(edge) and 0 < edge <= MAX_LENGTH):
        raise OptionError(f"the cube edge must be a positive length up to {MAX_LENGTH:g} m, "
                          f"got {edge!r}")
    if isinstance(n, bool) or int(n) != n or not 1 <= n <= MAX_GRID:
        raise OptionError(f"the grid must have 1 to {MAX_GRID} points per edge, got {n!r}")
    t = np.linspace(-edge / 2, edge / 2, int(n)) if n > 1 else np.zeros(1)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    return c + g


def reach(robot: Robot, targets: np.ndarray, tool: np.ndarray, seeds: np.ndarray,
          seed_positions: np.ndarray, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """((M, n) joint values, (M,) reached) putting the tool point at each target [m].

    Inverse kinematics on ``robot`` from the seed whose tool point is nearest the target,
    then from the next two nearest if that fails; reached means within ``tol`` [m] and
    the joint limits.
    """
    q_out = np.zeros((len(targets), len(robot.joint_names)))
    ok = np.zeros(len(targets), dtype=bool)
    for k, target in enumerate(targets):
        order = np.argsort(np.linalg.norm(seed_positions - target, axis=1))[:3]
        for s in order:
            q, converged = robot.inverse_kinematics(target, tool=tool, start=seeds[s],
                                                    tolerance=tol)
            if converged:
                q_out[k], ok[k] = q, True
                break
    return q_out, ok


def accuracy_map(robot: Robot, chain, space: ParameterSpace, x: np.ndarray,
                 covariance: np.ndarray, seeds: np.ndarray, *, cube=None, grid: int = 5,
                 joint_values=None, targets: str = "", covariance_source: str = "",
                 orientation: tuple[np.ndarray, np.ndarray] | None = None) -> AccuracyMap:
    """The map over a cube (``cube=(center (3,) [m], edge [m])``, base frame) or at the
    poses ``joint_values`` (M, n); exactly one of them.

    robot: the robot to reach grid points with (the corrected one after a calibration),
    consistent with ``chain`` (the error model) and ``x``. seeds: (S, n) joint values to
    start inverse kinematics from (the calibration poses). orientation: (x, covariance)
    over a pose set's parameters (:func:`predicted_turn_std`), or None (points).
    """
    if (cube is None) == (joint_values is None):
        raise OptionError("give exactly one of a cube or a set of poses for the accuracy map")
    tool = space.tools(x)[0]
    skipped = np.zeros((0, 3))
    if cube is not None:
        center, edge = cube
        points = cube_grid(center, edge, grid)
        seeds = np.atleast_2d(np.asarray(seeds, float))
        q, ok = reach(robot, points, tool, seeds, tool_positions(chain, space, x, seeds))
        q, skipped = q[ok], points[~ok]
        targets = targets or (f"a {grid}x{grid}x{grid} grid in a {edge / MM:g} mm cube at "
                              f"{np.round(np.asarray(center) / MM, 1).tolist()} mm "
                              f"({robot.base} frame)")
    else:
        q = np.atleast_2d(np.asarray(joint_values, float))
        targets = targets or f"{len(q)} poses"
    if len(q):
        std, worst = predicted_std(chain, space, x, covariance, q)
        pos = tool_positions(chain, space, x, q)
    else:
        std = worst = np.zeros(0)
        pos = np.zeros((0, 3))
    turn = None
    if orientation is not None:
        x_pose, c_pose = orientation
        turn = _ro(predicted_turn_std(chain, space.backlash, x_pose, c_pose, q) if len(q)
                   else np.zeros(0))
    return AccuracyMap(_ro(pos), _ro(q), _ro(std), _ro(worst),
                       _ro(skipped), targets, covariance_source, turn)


def point_view(layout, error_model, i: int, n_points: int):
    """(ParameterSpace of one point set, (q,) indices into ``layout``) for set i, which has
    a measurement frame and tool point(s): the layout's kinematic parameters, that set's
    base.* and tool points, and the backlash terms, in the point engine's order (compliance
    terms are left out: the map is of the geometric model's uncertainty)."""
    names = list(layout.frame_names(i))
    sl = layout.frame_slices[i]
    local = [names.index(layout.set_prefix(i) + n) for n in BASE]
    for k in range(1, n_points + 1):
        local += [names.index(layout.set_prefix(i) + ("tool." if k == 1 else f"tool{k}.") + c)
                  for c in "xyz"]
    idx = np.r_[np.arange(layout.n_kinematic), sl.start + np.array(local, dtype=int),
                np.arange(layout.backlash_slice.start,
                          layout.backlash_slice.start + layout.n_backlash)].astype(int)
    return ParameterSpace.of_model(error_model, layout.backlash, n_points), idx


def pose_view(layout, i: int) -> np.ndarray | None:
    """(q,) indices into ``layout`` of set i's pose-kind parameters (kinematic, its 12
    frames, the backlash terms; what :func:`predicted_turn_std` takes), None unless set i
    holds a tool frame's orientation (a pose set)."""
    names = layout.frame_names(i)
    mine = [layout.set_prefix(i) + n for n in POSE_FRAMES]
    if not all(n in names for n in mine):
        return None
    start = layout.frame_slices[i].start
    return np.r_[np.arange(layout.n_kinematic), [start + names.index(n) for n in mine],
                 np.arange(layout.backlash_slice.start,
                           layout.backlash_slice.start + layout.n_backlash)].astype(int)


def _orientation(layout, i: int, x: np.ndarray, covariance: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """(x, covariance) of set i's pose-kind parameters, or None (not a pose set)."""
    idx = pose_view(layout, i)
    return None if idx is None else (x[idx], covariance[np.ix_(idx, idx)])


def _locates(s) -> bool:
    """Whether set ``s`` (a kind model or set result) has base.* and tool.*."""
    names = tuple(s.frame_names)
    return "base.x" in names and "tool.x" in names


def mappable(sets) -> bool:
    """Whether any set (kind models or set results) has base.* and tool.*: a measurement
    frame and tool point an accuracy map can predict positions of (point and pose sets)."""
    return any(_locates(s) for s in sets)


def require_mappable(sets) -> None:
    """Refuse an accuracy map of data without a point or pose set (see :func:`mappable`),
    naming the kinds they have: before any work (the command lines) or at the map."""
    if not mappable(sets):
        raise OptionError("an accuracy map (--accuracy-map, --accuracy-poses) predicts "
                          "positions of a point or pose set (its measurement frame and tool "
                          "point); these data have none (" + ", ".join(
                              dict.fromkeys(s.kind for s in sets)) + ")")


def _located(sets) -> int:
    """Index of the first set (kind models or set results) with base.* and tool.*."""
    require_mappable(sets)
    return next(i for i, s in enumerate(sets) if _locates(s))


def result_accuracy_map(result, *, cube=None, grid: int = 5, joint_values=None,
                        targets: str = "") -> AccuracyMap:
    """The map of a :class:`~kincal.identification.result.CalibrationResult`, from its
    sandwich covariance; default targets: the calibration poses."""
    if result.covariance is None:
        raise OptionError("this calibration has no parameter covariance (no degrees of "
                          "freedom left to estimate the noise): no accuracy map")
    i = _located(result.sets)
    s = result.sets[i]
    space, idx = point_view(result.layout, result.error_model, i,
                            getattr(s.data, "n_points", 1) if s.kind == "point" else 1)
    seeds = np.unique(np.asarray(s.data.joint_values), axis=0)
    if cube is None and joint_values is None:
        joint_values = seeds
        targets = targets or f"the {len(seeds)} calibration poses"
    return accuracy_map(result.corrected, _chain_model(result), space, result.x[idx],
                        result.covariance[np.ix_(idx, idx)], seeds, cube=cube, grid=grid,
                        joint_values=joint_values, targets=targets,
                        orientation=_orientation(result.layout, i, result.x, result.covariance),
                        covariance_source=f"from the calibration ({result.options.method}, "
                                          + (f"lambda {result.lam:.3g}" if np.isfinite(result.lam)
                                             else "priors per class")  # evidence: no one lambda
                                          + ", sandwich covariance)")


def design_covariance(problem, noise: float, lam: float = 0.0) -> np.ndarray:
    """(p, p) predicted covariance [SI] of a fit of ``problem``'s data before solving.

    At the starting point (nominal kinematics, fitted frames), for independent noise of
    sd ``noise`` [m] per axis: sigma^2 H^-1 J^T J H^-1 with H = J^T J + lam P (lam in the
    penalty's units, 0: least squares), over the parameters the data identify.
    """
    if not (np.isfinite(noise) and noise > 0):
        raise OptionError(f"the noise level must be a positive length, got {noise!r}")
    free = problem.free_mask()
    _, J = problem.residual_function()(problem.start() / problem.scale, True)
    J = J[:, free]
    JtJ = J.T @ J
    Hi = np.linalg.pinv(JtJ + lam * np.diag(problem.layout.is_penalised[free].astype(float)))
    cov = (noise / MM) ** 2 * Hi @ JtJ @ Hi  # residuals in mm
    s = problem.scale[free]
    full = np.zeros((free.size, free.size))
    full[np.ix_(free, free)] = cov * np.outer(s, s)
    return full


def design_accuracy_map(problem, noise: float, *, cube=None, grid: int = 5,
                        joint_values=None, lam: float = 0.0, targets: str = "") -> AccuracyMap:
    """The map a calibration from ``problem``'s poses is predicted to give, at noise
    ``noise`` [m] per axis (see :func:`design_covariance`); default targets: the poses."""
    i = _located(problem.kinds)
    km = problem.kinds[i]
    space, idx = point_view(problem.layout, problem.error_model, i,
                            getattr(km.data, "n_points", 1) if km.kind == "point" else 1)
    x = problem.start()[idx]
    seeds = np.unique(km.data.joint_values, axis=0)
    if cube is None and joint_values is None:
        joint_values, targets = seeds, f"the {len(seeds)} measured poses"
    how = "least squares" if lam == 0 else f"L2, lambda {lam:g}"
    cov = design_covariance(problem, noise, lam)
    return accuracy_map(problem.robot, _chain_model(problem), space, x, cov[np.ix_(idx, idx)],
                        seeds, cube=cube, grid=grid, joint_values=joint_values, targets=targets,
                        orientation=_orientation(problem.layout, i, problem.start(), cov),
                        covariance_source=f"predicted before solving: {how}, noise "
                                          f"{noise / MM:g} mm per axis")
