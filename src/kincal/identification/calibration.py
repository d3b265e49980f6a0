"""Calibration: build the problem, analyse what the data identify, solve, report.

``CalibrationProblem(robot, data, options)`` builds; ``.analyze()`` returns the
identifiability of the parameters on these data; ``.solve()`` runs the identification
(plain least squares, or L2 toward nominal: per-class priors chosen by maximum evidence,
lambda chosen by k-fold CV, or lambda given) and
returns a :class:`CalibrationResult`. ``calibrate(...)`` does all three. Options: :mod:`.options`; results: :mod:`.result`.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import fields, replace
from typing import Callable

import numpy as np

from kincal import models as error_models
from kincal.errors import (
    DataError,
    IdentifiabilityError,
    KincalWarning,
    OptionError,
    ParameterError,
    listing,
    suggest,
)
from kincal.identification import blas_threads, penalty_choice
from kincal.identification.cross_validation import (
    CrossValidation,
    cross_validate,
    fold_fitter,
    lambda_grid,
)
from kincal.identification.frames_init import initial_frames, point_in_tip
from kincal.identification.options import CalibrationOptions
from kincal.identification.parameters import MM, ParameterSpace
from kincal.identification.plausibility import gather, judge
from kincal.identification.result import CalibrationResult
from kincal.identification.robust import ROBUST_SCALE, Downweighted
from kincal.identification.robust import weights as robust_weights
from kincal.identification.selection import Identifiability, analyze
from kincal.identification.solver import SolverOptions, SolveSummary, solve
from kincal.measurements.checks import (
    angle_unit_warnings,
    distinct_poses,
    length_unit_warnings,
    limit_warnings,
)
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.models.mdh import TOOL_AXIS_WARNING
from kincal.robot import Robot
from kincal.rotations import base_angles, base_rotation

# samples evaluated together in a residual with Jacobian: more are done block by block
BLOCK_SAMPLES = 2048


class CalibrationProblem:
    """The identification of one robot chain from one set of measurements."""

    def __init__(self, robot: Robot, data: Measurements, options: CalibrationOptions | None = None):
        for name, value, kind in (("robot", robot, Robot), ("data", data, Measurements),
                                  ("options", options or CalibrationOptions(), CalibrationOptions)):
            if not isinstance(value, kind):
                raise OptionError(f"{name} must be a {kind.__name__}, got {type(value).__name__}"
                                  + ("; for one field use calibrate(robot, data, method=...)"
                                     if name == "options" else ""))
        self.robot = robot
        self.options = (options or CalibrationOptions()).validated()
        self.data = data.for_chain(robot.joint_names)
        self.error_model = error_models.build(self.options.model, robot.geometry)
        self.space = ParameterSpace.of_model(self.error_model,
                                             self.options.backlash, self.data.n_points)
        self.model = MeasurementModel(self.error_model, self.data.joint_values, self.data.approach,
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
            if not any(c in name for c in "*?["):
                self._check_name(name)  # a name of another model says which model has it
        # unknown names, and patterns matching nothing, raise ParameterError with the list
        self.space.expand(o.fix), self.space.expand(o.free)
        if not self._unfixed().any():
            raise OptionError(f"nothing to fit: every parameter method {o.method} fits is fixed; "
                              "leave at least one free (fix fewer names)")
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

    def _check_name(self, name: str) -> None:
        """A --fix/--free name of this model; one of another model says which model has it,
        anything else lists the valid names (ParameterError)."""
        if name in self.space.names:
            return
        for other in error_models.MODELS:
            if other != self.options.model and \
                    name in error_models.build(other, self.robot.geometry).names:
                raise ParameterError(
                    f"{name!r} is a parameter of error model {other}, not of {self.options.model}"
                    f" (choose --model {other}, or a name of {self.options.model}: "
                    f"{', '.join(self.space.kinematic_names[:8])}, ...)", valid=self.space.names)
        self.space.index(name)  # raises, listing the valid names

    # --------------------------------------------------------------- residuals
    def residual_function(self, rows=None, kinematic: bool = True) -> Callable:
        """residual(u, with_jacobian) on the samples ``rows`` (default all), in mm.

        kinematic=False: MD-H columns of the Jacobian left at zero (frame-only fits).
        """
        model = self.model if rows is None else self.model.subset(rows)
        P = self.data.positions if rows is None else self.data.positions[rows]
        w = (self.weights if rows is None else self.weights[rows])[:, None]
        s = self.scale

        blocks = self._blocks(model, rows is None)

        def residual(u, with_jacobian):
            x = u * s
            if not with_jacobian:
                return ((P - model.predict(x)) * w).ravel() / MM, None
            if blocks is None:
                pred, J = model.jacobian(x, kinematic)
                r = ((P - pred) * w).ravel() / MM
                return r, -(J * w[:, :, None]).reshape(-1, s.size) * (s / MM)
            # many samples: block by block into one (3N, p) array (see _blocks)
            r, Jr = np.empty(3 * model.N), np.empty((3 * model.N, s.size))
            for sl, block in blocks:
                pred, J = block.jacobian(x, kinematic)
                span = slice(3 * sl.start, 3 * sl.stop)  # its rows of r and J
                r[span] = ((P[sl] - pred) * w[sl]).ravel() / MM
                np.multiply((J * w[sl, :, None]).reshape(-1, s.size), -s / MM, out=Jr[span])
            return r, Jr

        return residual

    def _blocks(self, model: MeasurementModel, cache: bool):
        """[(slice, model of those samples)] in blocks of BLOCK_SAMPLES, or None if fewer.

        Evaluating many samples block by block keeps every temporary of the Jacobian small
        (a few MB, in cache) instead of a dozen (N, 3, p) arrays: at 200,000 poses it is
        several times faster. The blocks of all samples are built once (cache=True).
        """
        if model.N <= BLOCK_SAMPLES:
            return None
        key = (BLOCK_SAMPLES, model.N)
        if cache and getattr(self, "_all_blocks", (None,))[0] == key:
            return self._all_blocks[1]
        blocks = [(sl, model.subset(sl)) for sl in
                  (slice(a, min(a + BLOCK_SAMPLES, model.N))
                   for a in range(0, model.N, BLOCK_SAMPLES))]
        if cache:
            self._all_blocks = (key, blocks)
        return blocks

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
        return self.space.join(self.error_model.nominal, np.zeros(6), np.zeros((self.space.n_points, 3)))

    def start(self) -> np.ndarray:
        """Nominal kinematics with the measurement frame and tool point(s) fitted to the data.

        tool_guess is for point 1; further points follow from a linear solve."""
        if self._x_start is not None:
            return self._x_start
        o = self.options
        R_tip, p_tip = self.model.tip_poses(self.error_model.nominal)
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
        x = self.space.join(self.error_model.nominal, base, np.array(tools))
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
        pred, J = MeasurementModel(self.error_model, q, approach, self.space.backlash, points,
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
        dists = [self.error_model.last_axis_distance(t) for t in self.space.tools(self.start())]
        if dists[0] is None or max(dists) >= TOOL_AXIS_WARNING:
            return ""
        dist = max(dists)
        last = self.error_model.joint_names[-1]
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

        # many poses: choose lambda on a seeded subsample of them (see cv_max_poses)
        samples, subsample = np.arange(len(self.data)), None
        if o.cv_max_poses is not None and self.n_poses > o.cv_max_poses:
            poses = np.unique(self.data.poses)
            keep = np.random.default_rng(o.seed).choice(poses, o.cv_max_poses, replace=False)
            samples = np.flatnonzero(np.isin(self.data.poses, keep))
            subsample = (int(o.cv_max_poses), self.n_poses)
        fit = fold_fitter(self, free, samples)
        val_models = {}

        def error(sol, val):
            val = samples[val]
            key = val.tobytes()
            if key not in val_models:
                val_models.clear()
                val_models[key] = (self.model.subset(val), self.data.positions[val])
            model, P = val_models[key]
            e = P - model.predict(sol.u * self.scale)
            return float(np.mean(np.linalg.norm(e, axis=1)) / MM)

        cv = cross_validate(fit, error, len(samples), grid, o.folds, o.seed,
                            o.warm_start, o.progress, groups=self.data.poses[samples])
        if subsample is None:
            return cv
        return replace(cv, folds=tuple(samples[f] for f in cv.folds), subsample=subsample)

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
        cv = evidence = sol = None
        how, why = o.lam, ""
        if o.method == "l2" and o.lam == "auto":
            how, why = penalty_choice.automatic(self)
        if o.method == "l2":
            if how == "cv":
                cv = self.cross_validate()
                lam = cv.best_lambda
            elif how == "evidence":
                sol, evidence = penalty_choice.fit_evidence(self)
                lam = evidence.weights(penalty_choice.prior_classes(self))
            else:
                lam = float(o.lam)
        else:
            lam = 0.0
        if sol is None:
            sol = self.fit(lam)
        if cv is not None:
            note = penalty_choice.cv_warning(self, cv, sol, lam)
            if note:
                warnings.warn(f"{self.data.source}: {note}", KincalWarning)
        downweighted = ()
        if o.robust is not None:
            sol, downweighted = self._irls(sol, lam)
        if not sol.converged:
            warnings.warn(f"the solver did not converge in {sol.iterations} iterations; the "
                          "result is the best iterate and is flagged not converged", KincalWarning)
        result = CalibrationResult._build(self, sol, lam, cv, ident, evidence)
        return replace(result, downweighted=downweighted,
                       penalty_choice=f"{how}, chosen automatically: {why}" if why else "",
                       plausibility=judge(gather(self, result)))  # the gate's verdict

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



def calibrate(robot: Robot, data: Measurements, options: CalibrationOptions | None = None,
              **overrides) -> CalibrationResult:
    """Build, analyse and solve in one call; keyword arguments override ``options`` fields.

    ``data`` may also be a list of measurement sets, or one set of another kind (poses,
    distances, plane contacts): those go to :mod:`kincal.identification.multiset`."""
    unknown = sorted(set(overrides) - {f.name for f in fields(CalibrationOptions)})
    if unknown:
        raise OptionError(f"unknown option(s) {', '.join(unknown)}." + suggest(unknown[0], [
            f.name for f in fields(CalibrationOptions)]) + " Options: "
            + listing([f.name for f in fields(CalibrationOptions)]))
    if not isinstance(data, Measurements):
        from kincal.identification.multiset import calibrate_sets

        return calibrate_sets(robot, data if isinstance(data, (list, tuple)) else [data],
                              options, **overrides)
    if options is None:
        options = CalibrationOptions(**overrides)
    elif overrides:
        options = replace(options, **overrides)
    return CalibrationProblem(robot, data, options).solve()
