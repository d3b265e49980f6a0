"""Calibration: build the problem, analyse what the data identify, solve, report.

``CalibrationProblem(robot, data, options)`` builds; ``.analyze()`` returns the
identifiability of the parameters on these data; ``.solve()`` runs the identification
(plain least squares, or L2 toward nominal with lambda given or chosen by k-fold CV) and
returns a :class:`CalibrationResult`. ``calibrate(...)`` does all three.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from . import blas_threads
from . import mdh as mdh_layer
from .mdh import TOOL_AXIS_WARNING
from .cross_validation import CrossValidation, cross_validate, lambda_grid
from .errors import DataError, IdentifiabilityError, KincalWarning, OptionError
from .data_checks import (angle_unit_warnings, distinct_poses, length_unit_warnings,
                          limit_warnings)
from .frames_init import initial_frames, point_in_tip
from .robust import LOSSES, ROBUST_SCALE, Downweighted, weights as robust_weights
from .measurement_model import MeasurementModel
from .measurements import Measurements
from .backlash import CONVENTION as BACKLASH_CONVENTION
from .parameters import BASE, DEG, MM, TOOL, ParameterSpace
from .robot import Robot
from .rotations import base_angles, base_rotation
from .selection import RANK_TOL, Identifiability, analyze
from .solver import SolverOptions, SolveSummary, solve
from .statistics import ErrorStats

METHODS = ("l2", "ls", "frames")


@dataclass(frozen=True)
class CalibrationOptions:
    """Every choice of a calibration, with the paper's defaults.

    method: "l2" (penalty toward nominal), "ls" (plain least squares) or "frames" (fit
        only the measurement frame and tool point; kinematics stay nominal).
    lam: "cv" to choose lambda by cross-validation, or a number >= 0 (method "l2").
    folds, seed: k and the seed of the fold split.
    lambda_min, lambda_max, n_lambdas: the CV grid (log-spaced; paper: 1e-6, 1e3, 50).
    length_scale [m], angle_scale [rad]: the unit s of the penalty
        lambda * sum(((x - x0) / s)^2); 1 mm and 1 deg by default, the paper's units.
    fix: parameter names held at their nominal values.
    free: parameter names kept in the fit even if the analysis finds them redundant
        (sensible only with method "l2", whose penalty keeps them bounded).
    backlash: chain joints given a backlash term ``<joint>.backlash`` (half the play,
        nominally 0; see kincal.backlash), identified from the approach directions of
        the samples. Methods "l2" and "ls".
    tool_guess: (3,) tool point in the tip frame [m], a starting guess; None: derived.
    base_guess: (6,) measurement frame (x, y, z [m], rx, ry, rz [rad]) start; None: derived.
    rank_tol: tolerance of the rank-revealing selection (see kincal.selection).
    robust: None (default: plain squares), "huber" or "cauchy": a robust loss on the
        per-pose error, by iteratively reweighted least squares after the chosen method
        (lambda stays as chosen); the down-weighted samples are reported.
    robust_scale_mm: the loss's scale c [mm]; None: 2.5 x the median pose error.
    warm_start: CV path solved from large to small lambda, each from the previous one.
    cv_step_tol: [mm or deg] step tolerance of the fold fits; a validation error needs
        far less precision than the final fit (which uses solver.step_tol).
    solver: stopping rules (paper: 1e-5 mm^2 over 5 iterations, 100 iterations).
    blas_threads: BLAS threads while solving (1: faster on a busy machine, see
        kincal.blas_threads); None leaves BLAS as it is.
    progress: callback(done, total) during the CV sweep, or None.
    """

    method: str = "l2"
    lam: float | str = "cv"
    folds: int = 5
    seed: int = 0
    lambda_min: float = 1e-6
    lambda_max: float = 1e3
    n_lambdas: int = 50
    length_scale: float = MM
    angle_scale: float = DEG
    fix: tuple[str, ...] = ()
    free: tuple[str, ...] = ()
    backlash: tuple[str, ...] = ()
    tool_guess: tuple[float, float, float] | None = None
    base_guess: tuple[float, ...] | None = None
    rank_tol: float = RANK_TOL
    robust: str | None = None
    robust_scale_mm: float | None = None
    warm_start: bool = True
    cv_step_tol: float = 1e-6
    solver: SolverOptions = SolverOptions()
    blas_threads: int | None = 1
    progress: Callable | None = field(default=None, compare=False, repr=False)

    def validated(self) -> "CalibrationOptions":
        if self.method not in METHODS:
            raise OptionError(f"unknown method {self.method!r}; expected one of {', '.join(METHODS)}")
        if isinstance(self.lam, str):
            if self.lam != "cv":
                raise OptionError(f"lambda must be 'cv' or a number >= 0, got {self.lam!r}")
        elif not (math.isfinite(float(self.lam)) and float(self.lam) >= 0):
            raise OptionError(f"lambda must be 'cv' or a finite number >= 0, got {self.lam!r}")
        if not (self.length_scale > 0 and self.angle_scale > 0):
            raise OptionError("length_scale and angle_scale must be > 0")
        if self.tool_guess is not None and np.shape(self.tool_guess) != (3,):
            raise OptionError("tool_guess needs 3 numbers (x, y, z in the tip frame) [m]")
        if self.base_guess is not None and np.shape(self.base_guess) != (6,):
            raise OptionError("base_guess needs 6 numbers (x, y, z [m], rx, ry, rz [rad])")
        lambda_grid(self.lambda_min, self.lambda_max, self.n_lambdas)
        if self.robust is not None and self.robust not in LOSSES:
            raise OptionError(f"unknown robust loss {self.robust!r}; expected one of "
                              f"{', '.join(LOSSES)} (or none)")
        if self.robust_scale_mm is not None and not self.robust_scale_mm > 0:
            raise OptionError(f"robust_scale_mm must be > 0, got {self.robust_scale_mm}")
        if self.blas_threads is not None and not (isinstance(self.blas_threads, int)
                                                  and self.blas_threads >= 1):
            raise OptionError(f"blas_threads must be an integer >= 1 or None, got "
                              f"{self.blas_threads!r}")
        if self.backlash and self.method == "frames":
            raise OptionError("backlash terms need method l2 or ls; method frames fits only "
                              "the measurement frame and tool point")
        return self


@dataclass(frozen=True)
class ParameterEstimate:
    """One row of the parameter table (SI units; ``deviation = estimate - nominal``).

    status: "identified", "dropped" (redundant on these data), "fixed" (by the user).
    is_length: True for lengths [m], False for angles [rad].
    std_error: NaN unless identified.
    """

    name: str
    is_length: bool
    nominal: float
    estimate: float
    std_error: float
    status: str

    @property
    def deviation(self) -> float:
        return self.estimate - self.nominal

    def reported(self) -> tuple[float, float, float, str]:
        """(nominal, deviation, std_error) in mm or deg, and the unit."""
        k, unit = (1e3, "mm") if self.is_length else (180.0 / math.pi, "deg")
        return self.nominal * k, self.deviation * k, self.std_error * k, unit


class CalibrationProblem:
    """The identification of one robot chain from one set of measurements."""

    def __init__(self, robot: Robot, data: Measurements, options: CalibrationOptions | None = None):
        self.robot = robot
        self.options = (options or CalibrationOptions()).validated()
        self.data = data.for_chain(robot.joint_names)
        self.mdh = mdh_layer.extract(robot.geometry)
        self.space = ParameterSpace.of_chain(self.mdh.joint_names, self.mdh.kinds,
                                             self.options.backlash, self.data.n_points)
        self.model = MeasurementModel(self.mdh, self.data.joint_values, self.data.approach,
                                      self.space.backlash, self.data.points,
                                      self.space.n_points)
        o = self.options
        self.scale = np.where(self.space.is_length, o.length_scale, o.angle_scale)
        if self.data.sigma is None:
            self.weights = np.ones(len(self.data))
        else:
            inv = 1.0 / self.data.sigma
            self.weights = inv / np.sqrt(np.mean(inv ** 2))
        for name in o.fix + o.free:
            self.space.index(name)  # unknown names raise ParameterError listing the valid ones
        pose = np.unique(self.data.poses, return_index=True)[1]  # one sample per pose
        self.n_poses = len(pose)
        if self.n_poses < 3:
            raise DataError(f"{self.data.source}: {self.n_poses} poses; the measurement frame "
                            "and tool point alone need at least 3 (a calibration needs many more)")
        g = robot.geometry
        q_poses = self.data.joint_values[pose]
        for message in (limit_warnings(g.joint_names, g.kinds, g.lower, g.upper, q_poses,
                                       self.data.rows[pose])
                        + angle_unit_warnings(g.joint_names, g.kinds, q_poses,
                                              self.data.angle_unit)
                        + self._approach_warnings()):
            warnings.warn(f"{self.data.source}: {message}", KincalWarning)
        self._x_start = None
        self._ident = None

    # --------------------------------------------------------------- residuals
    def residual_function(self, rows=None, kinematic: bool = True) -> Callable:
        """residual(u, with_jacobian) on the samples ``rows`` (default all), in mm.

        kinematic=False: MD-H columns of the Jacobian left at zero (frame-only fits).
        """
        model = self.model if rows is None else self.model.subset(rows)
        P = self.data.positions if rows is None else self.data.positions[rows]
        w = (self.weights if rows is None else self.weights[rows])[:, None]
        s = self.scale

        def residual(u, with_jacobian):
            x = u * s
            if not with_jacobian:
                return ((P - model.predict(x)) * w).ravel() / MM, None
            pred, J = model.jacobian(x, kinematic)
            r = ((P - pred) * w).ravel() / MM
            Jr = -(J * w[:, :, None]).reshape(-1, s.size) * (s / MM)
            return r, Jr

        return residual

    # ------------------------------------------------------------------ start
    def _approach_warnings(self) -> list[str]:
        """Backlash joints whose samples do not come from both directions, and a time-like
        column left unused while the directions come from the row order."""
        out = []
        timelike = [c for c in self.data.ignored_columns
                    if re.search(r"time|stamp|(^|_)t($|_)", c, re.IGNORECASE)]
        if self.space.n_backlash and not self.data.has_order_column and timelike:
            out.append(f"backlash: the approach directions come from {self.data.order_source}; "
                       f"the file has a column {timelike[0]!r} that looks like a time stamp: if "
                       f"the rows are not in acquisition order, give it as the order column "
                       f"(--order-column {timelike[0]})")
        for j, i in zip(self.space.backlash, self.space.backlash_joint_index):
            g = self.data.approach[:, i]
            up, down = int(np.sum(g > 0)), int(np.sum(g < 0))
            if min(up, down) < 3:
                out.append(f"{j}.backlash: {up} samples approached {j} from below and {down} "
                           f"from above (acquisition order: {self.data.order_source}); "
                           "backlash is identifiable only from both directions, a few of "
                           "each at least")
        return out

    @property
    def x_nominal(self) -> np.ndarray:
        return self.space.join(self.mdh.table, np.zeros(6), np.zeros((self.space.n_points, 3)))

    def start(self) -> np.ndarray:
        """Nominal kinematics with the measurement frame and tool point(s) fitted to the data.

        tool_guess is for point 1; further points follow from a linear solve."""
        if self._x_start is not None:
            return self._x_start
        o = self.options
        R_tip, p_tip = self.model.tip_poses(self.mdh.table)
        P, first = self.data.positions, self.data.points == 0
        guess = np.zeros(3) if o.tool_guess is None else np.asarray(o.tool_guess, float)
        for message in length_unit_warnings(P[first], p_tip[first] + R_tip[first] @ guess,
                                            self.data.length_unit):
            warnings.warn(f"{self.data.source}: {message}", KincalWarning)
        Rb, tb, tool, _, _ = initial_frames(R_tip[first], p_tip[first], P[first], o.tool_guess)
        base = np.concatenate([tb, base_angles(Rb)])
        if o.base_guess is not None:
            base = np.asarray(o.base_guess, dtype=float)
            Rb, tb = base_rotation(*base[3:]), base[:3]
            if o.tool_guess is not None:
                tool = np.asarray(o.tool_guess, dtype=float)
        tools = [tool] + [point_in_tip(R_tip[m], p_tip[m], P[m], Rb, tb)
                          for m in (self.data.points == k for k in range(1, self.space.n_points))]
        x = self.space.join(self.mdh.table, base, np.array(tools))
        free = self.space.is_frame
        sol = solve(self.residual_function(kinematic=False), x / self.scale, free,
                    options=o.solver)
        self._x_start = sol.u * self.scale
        return self._x_start

    # ---------------------------------------------------------------- analyse
    def analyze(self) -> Identifiability:
        """Which parameters these data identify, at the starting point."""
        if self._ident is not None:
            return self._ident
        o = self.options
        free = self._unfixed()
        _, J = self.residual_function()(self.start() / self.scale, True)
        # reporting units: mm per mm or per degree, whatever the penalty scale
        J = J * (self.space.reporting_scale() / self.scale)
        ident = analyze(J, self.space.names, self.space.n_kinematic, free, o.rank_tol)
        frame_names = set(np.array(self.space.names)[self.space.is_frame])
        frames_lost = [n for n in ident.dropped if n in frame_names]
        if frames_lost:
            why = "; ".join(d.describe() for d in ident.duplicates if d.name in frames_lost)
            distinct = distinct_poses(self.data.joint_values)
            raise IdentifiabilityError(
                f"{self.data.source}: the poses cannot even locate the measurement frame and "
                f"tool point: {', '.join(frames_lost)} cannot be identified ({why}). There are "
                f"{distinct} distinct poses of {self.n_poses}; add poses that differ in every "
                "joint, or fix what the data cannot give (e.g. --fix tool.x tool.y tool.z with "
                "--tool-offset). Identifiable now: " + ", ".join(ident.kept))
        general = self.structural()
        lost = [n for n in general.kept if n not in ident.kept]
        if lost:
            need = math.ceil(len(general.kept) / (3 * self.space.n_points))
            ident = replace(ident, notes=ident.notes + (
                f"{len(lost)} parameters this chain can identify are not identifiable from "
                f"these {self.n_poses} poses "
                f"({distinct_poses(self.data.joint_values)} "
                f"distinct): {', '.join(lost)}; the {len(general.kept)} identifiable "
                f"parameters need at least {need} poses, and many more spread over the "
                "workspace for a good result",))
        note = self._tool_axis_note()
        if note:
            ident = replace(ident, notes=ident.notes + (note,))
            warnings.warn(note, KincalWarning)
        self._ident = ident
        return ident

    def structural(self) -> Identifiability:
        """What this chain can identify from generic poses (seeded random joint values).

        Compared with :meth:`analyze`, it tells which parameters are lost to the data (too
        few or too similar poses) rather than to the geometry of the chain.
        """
        if getattr(self, "_structural", None) is not None:
            return self._structural
        g = self.robot.geometry
        lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
        hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
        rng = np.random.default_rng(0)
        K = self.space.n_points
        q = np.repeat(rng.uniform(lo, hi, size=(2 * self.space.size, g.n)), K, axis=0)
        approach = np.repeat(rng.choice([-1.0, 1.0], size=(2 * self.space.size, g.n)), K, axis=0)
        points = np.tile(np.arange(K), 2 * self.space.size)
        pred, J = MeasurementModel(self.mdh, q, approach, self.space.backlash, points,
                                   K).jacobian(self.start())
        J = J.reshape(-1, self.space.size) * self.space.reporting_scale() / MM
        free = self._unfixed()
        self._structural = analyze(J, self.space.names, self.space.n_kinematic, free,
                                   self.options.rank_tol)
        return self._structural

    def _unfixed(self) -> np.ndarray:
        """(p,) the parameters the method fits and the user did not fix."""
        free = (np.ones(self.space.size, dtype=bool) if self.options.method != "frames"
                else self.space.is_frame)
        free[self.space.indices(self.options.fix)] = False
        return free

    def _tool_axis_note(self) -> str:
        """A warning when every tool point sits near the axis of the last (revolute) joint."""
        dists = [self.mdh.last_axis_distance(t) for t in self.space.tools(self.start())]
        if dists[0] is None or max(dists) >= TOOL_AXIS_WARNING:
            return ""
        dist = max(dists)
        last = self.mdh.joint_names[-1]
        which = "tool point is" if len(dists) == 1 else f"{len(dists)} measured points are all"
        return (f"the {which} {dist * 1e3:.2f} mm from the axis of {last}: turning about "
                f"that axis barely moves it, so {last}.theta and the tilt of that axis "
                f"({last}.alpha) are weak or redundant; an offset tool point (>= 20 mm off the "
                "axis) makes them identifiable")

    def free_mask(self) -> np.ndarray:
        ident = self.analyze()
        mask = np.zeros(self.space.size, dtype=bool)
        mask[self.space.indices(ident.kept)] = True
        if self.options.free:
            mask[self.space.indices(self.options.free)] = True
        return mask

    # ------------------------------------------------------------------- fits
    def fit(self, lam: float, rows=None, start: np.ndarray | None = None,
            free: np.ndarray | None = None, residual: Callable | None = None,
            options: SolverOptions | None = None) -> SolveSummary:
        """One solve with penalty weight ``lam`` on the samples ``rows`` (default all).

        residual: a prebuilt :meth:`residual_function` for ``rows`` (saves rebuilding it).
        """
        x0 = self.start() if start is None else start
        free = self.free_mask() if free is None else free
        u_prior = self.start() / self.scale  # kinematics at nominal; frames not penalised
        residual = self.residual_function(rows) if residual is None else residual
        return solve(residual, x0 / self.scale, free, lam=lam,
                     penalised=self.space.is_penalised, prior=u_prior,
                     options=options or self.options.solver)

    def position_errors(self, x: np.ndarray, rows=None) -> np.ndarray:
        """(N, 3) measured minus predicted positions [m]."""
        model = self.model if rows is None else self.model.subset(rows)
        P = self.data.positions if rows is None else self.data.positions[rows]
        return P - model.predict(x)

    def cross_validate(self) -> CrossValidation:
        o = self.options
        grid = lambda_grid(o.lambda_min, o.lambda_max, o.n_lambdas)
        free = self.free_mask()

        fold_options = replace(o.solver, step_tol=max(o.solver.step_tol, o.cv_step_tol))
        cache = {}  # per fold: the training residual and the validation model

        def fit(train, lam, start):
            key = train.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = self.residual_function(train)
            return self.fit(lam, train, None if start is None else start.u * self.scale, free,
                            residual=cache[key], options=fold_options)

        val_models = {}

        def error(sol, val):
            key = val.tobytes()
            if key not in val_models:
                val_models.clear()
                val_models[key] = (self.model.subset(val), self.data.positions[val])
            model, P = val_models[key]
            e = P - model.predict(sol.u * self.scale)
            return float(np.mean(np.linalg.norm(e, axis=1)) / MM)

        return cross_validate(fit, error, len(self.data), grid, o.folds, o.seed,
                              o.warm_start, o.progress, groups=self.data.poses)

    # ------------------------------------------------------------------ solve
    def solve(self) -> "CalibrationResult":
        with blas_threads.limited(self.options.blas_threads):
            return self._solve()

    def _solve(self) -> "CalibrationResult":
        o = self.options
        ident = self.analyze()
        general = self.structural()
        m = 3 * len(self.data)
        per_pose = 3 * self.space.n_points
        if o.method != "l2" and m <= len(general.kept) and len(ident.kept) < len(general.kept):
            raise IdentifiabilityError(
                f"{self.n_poses} poses give {m} equations for the {len(general.kept)} "
                f"parameters this chain can identify; method {o.method} needs at least "
                f"{math.ceil((len(general.kept) + 1) / per_pose)} poses (and many more spread over the "
                "workspace); with these poses it would only interpolate. Method l2 can work "
                "with fewer, pulling what the data cannot fix toward nominal")
        cv = None
        if o.method == "l2":
            if o.lam == "cv":
                cv = self.cross_validate()
                lam = cv.best_lambda
            else:
                lam = float(o.lam)
        else:
            lam = 0.0
        sol = self.fit(lam)
        downweighted = ()
        if o.robust is not None:
            sol, downweighted = self._irls(sol, lam)
        if not sol.converged:
            warnings.warn(f"the solver did not converge in {sol.iterations} iterations; the "
                          "result is the best iterate and is flagged not converged", KincalWarning)
        result = CalibrationResult._build(self, sol, lam, cv, ident)
        return replace(result, downweighted=downweighted)

    def _irls(self, sol: SolveSummary, lam: float, rounds: int = 20):
        """Reweight poses by the robust loss until the weights settle (see kincal.robust)."""
        o = self.options
        base_weights = self.weights
        try:
            w = np.ones(len(self.data))
            for _ in range(rounds):
                e = np.linalg.norm(self.position_errors(sol.u * self.scale), axis=1) / MM
                c = o.robust_scale_mm or ROBUST_SCALE * float(np.median(e))
                w_new = robust_weights(e, o.robust, max(c, 1e-9))
                self.weights = base_weights * np.sqrt(w_new)  # residuals carry sqrt(weight)
                sol = self.fit(lam, start=sol.u * self.scale)
                done = np.max(np.abs(w_new - w)) < 1e-4
                w = w_new
                if done:
                    break
        finally:
            self.weights = base_weights
        e = np.linalg.norm(self.position_errors(sol.u * self.scale), axis=1) / MM
        low = np.flatnonzero(w < 0.5)
        out = tuple(Downweighted(int(self.data.rows[k]), float(e[k]), float(w[k]))
                    for k in low[np.argsort(w[low])])
        return sol, out


def _std_errors(sol: SolveSummary, free: np.ndarray, penalised: np.ndarray, lam: float,
                scale: np.ndarray) -> np.ndarray:
    """Sandwich standard errors [SI] of the free parameters (NaN for the others)."""
    J = sol.jacobian[:, free]
    H = J.T @ J + lam * np.diag(penalised[free].astype(float))
    out = np.full(scale.size, np.nan)
    try:
        Hi = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return out
    JtJ = J.T @ J
    dof = float(np.trace(Hi @ JtJ))  # effective number of parameters, trace of the hat matrix
    m = J.shape[0]
    if m - dof <= 0.5:
        return out
    s2 = float(sol.residual @ sol.residual) / (m - dof)
    cov = s2 * Hi @ JtJ @ Hi
    out[free] = np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale[free]
    return out


@dataclass(frozen=True)
class CalibrationResult:
    """Everything a calibration produced. Values in SI; reports in mm and degrees.

    robot: the nominal robot; corrected: the robot with identified joint placements.
    parameters: one ParameterEstimate per parameter (kinematic, base, tool).
    x_nominal / x_start / x: parameter vectors (nominal; nominal kinematics with fitted
    frames; identified). lam: the penalty weight used (0 for LS). cv: the CV curve or
    None. before / after: position errors on the calibration data [mm] with the start
    and the identified parameters. residuals: (N, 3) after calibration [m].
    solve: the final solve's summary (cost history, convergence).
    """

    robot: Robot
    corrected: Robot
    options: CalibrationOptions
    space: ParameterSpace
    parameters: tuple[ParameterEstimate, ...]
    x_nominal: np.ndarray
    x_start: np.ndarray
    x: np.ndarray
    lam: float
    cv: CrossValidation | None
    before: ErrorStats
    after: ErrorStats
    residuals: np.ndarray
    solve: SolveSummary
    identifiability: Identifiability
    mdh: mdh_layer.MdhModel
    rows: np.ndarray  # (N,) line numbers of the samples in their source file
    downweighted: tuple[Downweighted, ...] = ()  # samples a robust loss trusted less
    residuals_before: np.ndarray | None = None  # (N, 3) with the start parameters [m]
    order_source: str = ""  # how the samples' acquisition order was known (backlash terms)
    points: np.ndarray | None = None  # (N,) the measured point of each sample (0 = point 1)

    @classmethod
    def _build(cls, problem: CalibrationProblem, sol: SolveSummary, lam, cv, ident):
        sp = problem.space
        x = sol.u * problem.scale
        free = problem.free_mask()
        se = _std_errors(sol, free, sp.is_penalised, lam, problem.scale)
        fixed = set(ident.fixed)
        x_nom = problem.x_nominal.copy()
        x_start = problem.start()
        # base and tool have no nominal: their "nominal" is the fitted starting value
        x_nom[sp.is_frame] = x_start[sp.is_frame]
        rows = []
        for i, name in enumerate(sp.names):
            status = "identified" if free[i] else ("fixed" if name in fixed else "dropped")
            rows.append(ParameterEstimate(name, bool(sp.is_length[i]), float(x_nom[i]),
                                          float(x[i]), float(se[i]), status))
        table, _, _ = sp.split(x)
        corrected = problem.robot.with_joint_frames(problem.mdh.joint_frames(table))
        res_before = problem.position_errors(x_start)
        res = problem.position_errors(x)
        return cls(problem.robot, corrected, problem.options, sp, tuple(rows), x_nom, x_start,
                   x, float(lam), cv, ErrorStats.from_errors(res_before),
                   ErrorStats.from_errors(res), res, sol, ident, problem.mdh,
                   np.asarray(problem.data.rows), residuals_before=res_before,
                   order_source=problem.data.order_source, points=problem.data.points)

    # ------------------------------------------------------------ accessors
    @property
    def converged(self) -> bool:
        return self.solve.converged

    def parameter(self, name: str) -> ParameterEstimate:
        return self.parameters[self.space.index(name)]

    @property
    def base(self) -> np.ndarray:
        """(6,) measurement frame: x, y, z [m], rx, ry, rz [rad]."""
        return self.space.split(self.x)[1].copy()

    @property
    def tool(self) -> np.ndarray:
        """(3,) tool point (point 1) in the tip frame [m]."""
        return self.space.split(self.x)[2].copy()

    @property
    def tools(self) -> np.ndarray:
        """(K, 3) every measured point in the tip frame [m]."""
        return self.space.tools(self.x).copy()

    @property
    def backlash(self) -> dict[str, float]:
        """Half the play of each joint with a backlash term [rad, or m if prismatic]."""
        return dict(zip(self.space.backlash, map(float, self.space.backlash_values(self.x))))

    def frames_dict(self) -> dict:
        """The FRAMES.json content: measurement frame and tool point (and backlash) in SI.

        Backlash is not a property of a URDF, so it travels with the frames: ``kincal
        evaluate --frames`` applies it."""
        b, t = self.base, self.tool
        out = {"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), map(float, b))),
               "tool": dict(zip(("x", "y", "z"), map(float, t))),
               "convention": "P_measured = R_base (p_tip + R_tip t_tool) + t_base, "
                             "R_base = rotx(rx) roty(ry) rotz(rz); metres and radians",
               "base_frame": self.robot.base, "tip_frame": self.robot.tip}
        if self.space.n_points > 1:
            out["tool_points"] = [dict(zip(("x", "y", "z"), map(float, t))) for t in self.tools]
        if self.space.n_backlash:
            out["backlash"] = self.backlash
            out["backlash_convention"] = BACKLASH_CONVENTION
        return out

    def predict(self, joint_values: np.ndarray, approach: np.ndarray | None = None,
                points=0) -> np.ndarray:
        """(N, 3) predicted positions in the measurement frame [m] of measured points.

        approach: (N, n) approach directions for the backlash terms (e.g. the
        ``approach`` of a Measurements); None: every joint in the middle of its play.
        points: which measured point (0 = point 1), one for all or (N,) per row.
        """
        q = np.atleast_2d(joint_values)
        g = np.zeros(q.shape) if approach is None else np.atleast_2d(approach)
        idx = np.broadcast_to(np.asarray(points, dtype=int), (len(q),))
        return MeasurementModel(self.mdh, q, g, self.space.backlash, idx,
                                self.space.n_points).predict(self.x)

    def predict_data(self, data: Measurements) -> np.ndarray:
        """(N, 3) predictions for the samples of ``data``: its poses, approach directions
        and measured points [m]."""
        data = data.for_chain(self.robot.joint_names)
        return self.predict(data.joint_values, data.approach, data.points)

    def corrected_urdf_text(self, readable: bool = True) -> str:
        """The corrected URDF; see :mod:`kincal.readable_export` for ``readable``."""
        return self.export_edits(readable)[0].text

    def export_edits(self, readable: bool = True):
        """(EditResult, joint offsets moved to child origins) of the corrected URDF."""
        from .readable_export import corrected_text

        return corrected_text(self.robot, self.corrected, readable, source=str(self.robot.source))

    def urdf_with_frames(self, text: str) -> str:
        """``text`` plus fixed frames: ``kincal_measurement_frame`` (child of the base link,
        the pose of the measurement frame M in the base frame) and ``kincal_tool_point``
        (child of the tip link, at the tool point; ``kincal_tool_point_<k>`` for point k >= 2
        when several are measured)."""
        from .rotations import base_rotation, inverse, transform
        from .urdf_export import add_fixed_frame

        base_link, T_bl = self.robot.link_of(self.robot.base)
        tip_link, T_tl = self.robot.link_of(self.robot.tip)
        b = self.base
        T_MB = transform(base_rotation(*b[3:]), b[:3])  # base frame expressed in M
        text = add_fixed_frame(text, base_link, "kincal_measurement_frame",
                               "kincal_measurement_frame_joint", T_bl @ inverse(T_MB))
        for k, t in enumerate(self.tools, start=1):
            name = "kincal_tool_point" + ("" if k == 1 else f"_{k}")
            text = add_fixed_frame(text, tip_link, name, name + "_joint", T_tl @ transform(None, t))
        return text

    def export_urdf(self, path, overwrite: bool = False):
        """Write the corrected URDF (only chain joint origins differ from the input)."""
        from .safe_write import write_text_atomic

        protect = (self.robot.source,) if self.robot.source is not None else ()
        return write_text_atomic(path, self.corrected_urdf_text(), overwrite=overwrite,
                                 protect=protect)

    def summary(self) -> str:
        lines = [f"kincal calibration of {self.robot.name} ({self.robot.base} -> {self.robot.tip}), "
                 f"method {self.options.method}, lambda = {self.lam:.4g}"
                 + (" (chosen by cross-validation)" if self.cv is not None else ""),
                 f"  {self.identifiability.summary().splitlines()[0]}",
                 *([f"  {self.space.n_points} measured points per pose: statistics are over "
                    "every point"] if self.space.n_points > 1 else []),
                 f"  before: {self.before.line()}",
                 f"  after:  {self.after.line()}",
                 f"  solver: {self.solve.iterations} iterations, {self.solve.reason}"
                 + ("" if self.converged else "  [NOT CONVERGED]"),
                 *([f"  robust loss {self.options.robust}: {len(self.downweighted)} samples "
                    "down-weighted below 0.5: " + ", ".join(
                        f"line {d.row} ({d.error_mm:.3g} mm, weight {d.weight:.2f})"
                        for d in self.downweighted[:10])
                    + (" ..." if len(self.downweighted) > 10 else "")]
                   if self.options.robust else []),
                 *([f"  backlash terms ({', '.join(self.space.backlash)}): approach directions "
                    f"from {self.order_source}; the URDF models the middle of the play"]
                   if self.space.n_backlash else []),
                 "  parameter                 nominal      deviation    std.err  unit"]

        def z(v):  # no "-0.0000" for values that are zero to the digits shown
            return 0.0 if abs(v) < 5e-6 else v

        frames = []
        for p, is_frame in zip(self.parameters, self.space.is_frame):
            nom, dev, se, unit = p.reported()
            flag = "" if p.status == "identified" else f"  ({p.status})"
            if is_frame:
                frames.append(f"  {p.name:<24} {z(nom + dev):>14.4f} {z(se):>10.5f}  {unit}{flag}")
            elif p.status != "dropped":
                lines.append(f"  {p.name:<24} {z(nom):>10.4f} {z(dev):>+13.5f} {z(se):>10.5f}  "
                             f"{unit}{flag}")
        lines.append("  measurement frame and tool point   estimate    std.err  unit")
        return "\n".join(lines + frames)


def calibrate(robot: Robot, data: Measurements, options: CalibrationOptions | None = None,
              **overrides) -> CalibrationResult:
    """Build, analyse and solve in one call; keyword arguments override ``options`` fields."""
    if options is None:
        options = CalibrationOptions(**overrides)
    elif overrides:
        options = replace(options, **overrides)
    return CalibrationProblem(robot, data, options).solve()
