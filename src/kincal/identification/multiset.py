"""Calibration from several measurement sets, each of its own kind (points, poses,
distances, plane contacts), sharing the robot's kinematic and backlash parameters.

``MultiSetProblem(robot, sets, options)`` builds; ``.analyze()``, ``.solve()`` as
:class:`kincal.identification.calibration.CalibrationProblem` (which stays the path of a
single point set). The parameter vector is

    [ kinematic (error model) | set 1 frames | set 2 frames | ... | backlash ]

Set 1's frame parameters keep the kind's names (``base.x``, ``tool.rz``, ``pivot.y``,
``plane2.d``); set k >= 2 prefixes them ``set<k>.``. Frames are not penalised.

Weights: each sample's residual rows are divided by its stated sigma (the set's
``sigma``, or :data:`kincal.measurements.kind.DEFAULT_SIGMA` when a set states none),
normalised to RMS 1 over all samples: sets without sigmas weigh alike. Cross-validation
splits each set's poses into the k folds on its own; its error is the mean weighted
sample error [mm].
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from kincal import models as error_models
from kincal.errors import DataError
from kincal.identification import blas_threads
from kincal.identification.cross_validation import (CrossValidation, cross_validate, fold_fitter,
                                                    lambda_grid)
from kincal.identification.options import CalibrationOptions
from kincal.identification.parameters import DEG, MM
from kincal.identification.selection import Identifiability, analyze
from kincal.identification.solver import SolveSummary, solve
from kincal.measurements.kind import DEFAULT_SIGMA
from kincal.measurements.sets import kind_model, kind_of
from kincal.robot import Robot


class MultiSetProblem:
    """The identification of one robot chain from a list of measurement sets."""

    def __init__(self, robot: Robot, sets, options: CalibrationOptions | None = None):
        if not isinstance(sets, (list, tuple)) or not sets:
            raise DataError("give the measurement sets as a non-empty list")
        self.robot = robot
        self.options = o = (options or CalibrationOptions()).validated()
        if o.robust is not None:
            raise DataError("a robust loss is not available with several measurement sets "
                            "or non-point kinds yet")
        self.error_model = em = error_models.build(o.model, robot.geometry)
        self.backlash = tuple(j for j in em.joint_names if j in set(o.backlash))
        unknown = [j for j in o.backlash if j not in em.joint_names]
        if unknown:
            raise DataError(f"no chain joint {unknown[0]!r} for a backlash term; chain joints: "
                            f"{', '.join(em.joint_names)}")
        bidx = tuple(em.joint_names.index(j) for j in self.backlash)
        self.kinds = [kind_model(em, d, bidx) for d in sets]
        for km in self.kinds:
            if km.N < 3:
                raise DataError(f"{km.data.source}: {km.N} samples; a set needs at least 3")
        names, is_len, self.frame_slices = list(em.names), list(em.is_length), []
        for i, km in enumerate(self.kinds):
            prefix = "" if i == 0 else f"set{i + 1}."
            self.frame_slices.append(slice(len(names), len(names) + km.n_frames))
            names += [prefix + n for n in km.frame_names]
            is_len += list(km.frame_is_length)
        self.n_kinematic = em.size
        self.n_frames_total = len(names) - em.size
        names += [f"{j}.backlash" for j in self.backlash]
        is_len += [em.kinds[i] == "prismatic" for i in bidx]
        self.names = tuple(names)
        self.is_length = np.array(is_len, dtype=bool)
        self.is_frame = np.zeros(len(names), dtype=bool)
        self.is_frame[em.size:em.size + self.n_frames_total] = True
        self.scale = np.where(self.is_length, o.length_scale, o.angle_scale)
        self.offsets = np.cumsum([0] + [km.N for km in self.kinds])
        sig = np.concatenate([np.full(km.N, DEFAULT_SIGMA) if km.data.sigma is None
                              else km.data.sigma for km in self.kinds])
        inv = 1.0 / sig
        self.weights = inv / np.sqrt(np.mean(inv ** 2))
        self._x_start = self._ident = None

    # ----------------------------------------------------------------- layout
    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def n_samples(self) -> int:
        return int(self.offsets[-1])

    def index(self, name: str) -> int:
        from kincal.errors import ParameterError, listing, suggest

        if name not in self.names:
            raise ParameterError(f"unknown parameter {name!r}." + suggest(name, self.names)
                                 + f" Valid names: {listing(self.names, 60)}", valid=self.names)
        return self.names.index(name)

    def indices(self, patterns) -> np.ndarray:
        import fnmatch

        out = set()
        for p in (patterns,) if isinstance(patterns, str) else patterns:
            if any(c in p for c in "*?["):
                hits = [k for k, n in enumerate(self.names) if fnmatch.fnmatchcase(n, p)]
                if not hits:
                    self.index(p)  # raises with the valid names
                out.update(hits)
            else:
                out.add(self.index(p))
        return np.array(sorted(out), dtype=int)

    def split(self, x: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kinematic, set i's frames, backlash) of a parameter vector."""
        return x[:self.n_kinematic], x[self.frame_slices[i]], \
            x[self.n_kinematic + self.n_frames_total:]

    def _parts(self, rows):
        """[(set index, kind model on those rows, global positions of the rows)]."""
        if rows is None:
            return [(i, km, np.arange(self.offsets[i], self.offsets[i + 1]))
                    for i, km in enumerate(self.kinds)]
        rows = np.asarray(rows)
        out = []
        for i, km in enumerate(self.kinds):
            mine = rows[(rows >= self.offsets[i]) & (rows < self.offsets[i + 1])]
            if mine.size:
                out.append((i, km.subset(mine - self.offsets[i]), mine))
        return out

    # -------------------------------------------------------------- residuals
    def residual_function(self, rows=None, kinematic: bool = True) -> Callable:
        """residual(u, with_jacobian) over the samples ``rows`` (global indices), in mm."""
        parts = self._parts(rows)
        s, k, nb = self.scale, self.n_kinematic, len(self.backlash)

        def residual(u, with_jacobian):
            x = u * s
            rs, Js = [], []
            for i, km, g in parts:
                w = self.weights[g][:, None]
                kin, fr, b = self.split(x, i)
                if not with_jacobian:
                    rs.append((km.residuals(kin, fr, b) * w).ravel())
                    continue
                r, Jk, Jf, Jb = km.residuals(kin, fr, b, jacobian=True, kinematic=kinematic)
                rs.append((r * w).ravel())
                J = np.zeros((km.N, km.dim, self.size))
                J[:, :, :k] = Jk
                J[:, :, self.frame_slices[i]] = Jf
                if nb:
                    J[:, :, -nb:] = Jb
                Js.append((J * w[:, :, None]).reshape(-1, self.size))
            r = np.concatenate(rs) / MM
            if not with_jacobian:
                return r, None
            return r, np.concatenate(Js) * (s / MM)

        return residual

    def sample_errors(self, x: np.ndarray, rows=None, weighted: bool = False) -> list:
        """Per set: (set index, (n,) sample errors [m]) at parameters x."""
        out = []
        for i, km, g in self._parts(rows):
            r = km.residuals(*self.split(x, i))
            e = km.sample_errors(r)
            out.append((i, e * self.weights[g] if weighted else e))
        return out

    # ------------------------------------------------------------------ start
    @property
    def x_nominal(self) -> np.ndarray:
        x = np.zeros(self.size)
        x[:self.n_kinematic] = self.error_model.nominal
        return x

    def start(self) -> np.ndarray:
        """Nominal kinematics with every set's frames fitted (closed form, then
        Gauss-Newton on the frames alone)."""
        if self._x_start is None:
            x = self.x_nominal
            guess = self.options.tool_guess
            for i, km in enumerate(self.kinds):
                x[self.frame_slices[i]] = km.start(self.error_model.nominal, guess)
            sol = solve(self.residual_function(kinematic=False), x / self.scale, self.is_frame,
                        options=self.options.solver)
            self._x_start = sol.u * self.scale
        return self._x_start

    # ---------------------------------------------------------------- analyse
    def _unfixed(self) -> np.ndarray:
        free = (np.ones(self.size, dtype=bool) if self.options.method != "frames"
                else self.is_frame.copy())
        if self.options.fix:
            free[self.indices(self.options.fix)] = False
        return free

    def analyze(self) -> Identifiability:
        """Which parameters these sets identify, at the start, with each kind's notes."""
        if self._ident is None:
            _, J = self.residual_function()(self.start() / self.scale, True)
            J = J * (np.where(self.is_length, MM, DEG) / self.scale)
            ident = analyze(J, self.names, self.n_kinematic, self._unfixed(),
                            self.options.rank_tol)
            notes = [n for km in self.kinds for n in km.notes()]
            lost = [n for n in ident.dropped if self.is_frame[self.names.index(n)]]
            if lost:
                notes.append("frame parameters these data cannot fix, held at their start: "
                             + ", ".join(lost))
            self._ident = replace(ident, notes=ident.notes + tuple(notes))
        return self._ident

    def free_mask(self) -> np.ndarray:
        mask = np.zeros(self.size, dtype=bool)
        kept = self.analyze().kept
        if kept:
            mask[self.indices(kept)] = True
        if self.options.free:
            mask[self.indices(self.options.free)] = True
        return mask

    # ------------------------------------------------------------------- fits
    def fit(self, lam: float, rows=None, start=None, free=None, residual=None,
            options=None) -> SolveSummary:
        x0 = self.start() if start is None else start
        free = self.free_mask() if free is None else free
        residual = self.residual_function(rows) if residual is None else residual
        return solve(residual, x0 / self.scale, free, lam=lam, penalised=~self.is_frame,
                     prior=self.start() / self.scale, options=options or self.options.solver)

    def cross_validate(self) -> CrossValidation:
        o = self.options
        grid = lambda_grid(o.lambda_min, o.lambda_max, o.n_lambdas)
        free = self.free_mask()
        fit = fold_fitter(self, free)

        def error(sol, val):
            e = np.concatenate([e for _, e in self.sample_errors(sol.u * self.scale, val,
                                                                  weighted=True)])
            return float(np.mean(e) / MM)

        groups = np.concatenate([km.data.poses + 10 ** 9 * i
                                 for i, km in enumerate(self.kinds)])
        strata = np.repeat(np.arange(len(self.kinds)), [km.N for km in self.kinds])
        return cross_validate(fit, error, self.n_samples, grid, o.folds, o.seed, o.warm_start,
                              o.progress, groups=groups, strata=strata)

    # ------------------------------------------------------------------ solve
    def solve(self):
        from kincal.identification.multiset_result import MultiSetResult

        with blas_threads.limited(self.options.blas_threads):
            o = self.options
            ident = self.analyze()
            cv = None
            sol = ev = None
            how, choice = o.lam, ""
            if o.method == "l2" and o.lam == "auto":
                from kincal.identification.penalty_choice import automatic_sets

                how, why = automatic_sets(self)
                choice = f"{how}, chosen automatically: {why}"
            if o.method == "l2":
                if how == "evidence":
                    sol, ev = self._fit_evidence()
                    lam = ev.weights(self._prior_classes())
                elif isinstance(how, str):  # "cv"
                    cv = self.cross_validate()
                    lam = cv.best_lambda
                else:
                    lam = float(o.lam)
            else:
                lam = 0.0
            if sol is None:
                sol = self.fit(lam)
            return MultiSetResult._build(self, sol, lam, cv, ident, ev, choice)

    def _prior_classes(self) -> tuple[str | None, ...]:
        """(p,) evidence prior class of every parameter (None: the sets' frames, flat)."""
        from kincal.identification import evidence

        return tuple(evidence.prior_class(n, not f) for n, f in zip(self.names, self.is_frame))

    def _fit_evidence(self):
        """Per-class priors and the noise by maximum evidence over every set's residuals
        (each set weighted by its stated noise), iterated with the fit."""
        from kincal.identification.penalty_choice import fit_evidence

        return fit_evidence(self, self._prior_classes())


def calibrate_sets(robot: Robot, sets, options: CalibrationOptions | None = None,
                   **overrides):
    """Build, analyse and solve a calibration from several sets (or one of any kind)."""
    if options is None:
        options = CalibrationOptions(**overrides)
    elif overrides:
        options = replace(options, **overrides)
    return MultiSetProblem(robot, list(sets), options).solve()


__all__ = ["MultiSetProblem", "calibrate_sets", "kind_of"]
