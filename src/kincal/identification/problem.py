"""The calibration problem: one robot chain (or several sharing joints), one or many
measurement sets of any kind.

``CalibrationProblem(robot, sets, options)`` builds; ``.analyze()`` says what the data
identify; ``.solve()`` identifies (plain least squares, or L2 toward nominal with per-class
priors chosen by maximum evidence, lambda by k-fold CV, or lambda given) and returns a
:class:`~kincal.identification.result.CalibrationResult` carrying the plausibility gate's
verdict. ``calibrate(...)`` does all three. One data set is a list of one: no other path.

The sets share the kinematic and backlash parameters; each adds its kind's frames
(:mod:`kincal.identification.layout`). Weights: each sample's residual rows are divided by
its stated sigma (a set's ``sigma``, or :data:`kincal.measurements.kind.DEFAULT_SIGMA` where
a set states none), normalised to RMS 1 over all samples; sets without sigmas all weigh 1;
``row_scale`` (per set, one factor per row of a sample) holds the noise levels the evidence
estimates per kind of row. Residuals in mm; variables over their penalty scale (1 mm, 1 deg).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import fields, replace
from typing import Callable

import numpy as np

from kincal import models as error_models
from kincal.errors import (DataError, IdentifiabilityError, KincalWarning, OptionError,
                           ParameterError, listing, suggest)
from kincal.identification import blas_threads, model_choice, penalty_choice, term_evidence
from kincal.identification import prior as fleet_prior
from kincal.identification.chains import Chains
from kincal.identification.cross_validation import (CrossValidation, cross_validate,
                                                    fold_fitter, lambda_grid,
                                                    validation_error)
from kincal.identification.layout import MM, ParameterLayout
from kincal.identification.options import CalibrationOptions
from kincal.identification.plausibility import gather, judge
from kincal.identification.reduction import (analyze_rows, identifiable_rows, one_pass,
                                             residual_function)
from kincal.identification.result import CalibrationResult
from kincal.identification.robust import irls
from kincal.identification.selection import Identifiability, analyze, grouped, identifiable
from kincal.identification.solver import SolverOptions, SolveSummary, solve, steps
from kincal.measurements.checks import distinct_poses, input_warnings, warn_units
from kincal.measurements.fixed_joints import check_mimics
from kincal.measurements.kind import sample_weights
from kincal.measurements.sets import as_sets
from kincal.models.mdh import TOOL_AXIS_WARNING
from kincal.robot import Robot

# samples evaluated together in a residual with Jacobian: more are done block by block
BLOCK_SAMPLES = 2048
SUBSET_MEMO_SAMPLES = 20_000  # row selections up to this size keep their kind models


class CalibrationProblem:
    """The identification of robot chains from a list of measurement sets: ``robots`` is one
    Robot (every set on its chain) or one per set, several chains of one URDF sharing the
    joints they traverse (:mod:`kincal.identification.chains`)."""

    def __init__(self, robots: Robot | list, sets, options: CalibrationOptions | None = None):
        if not isinstance(options or CalibrationOptions(), CalibrationOptions):
            raise OptionError(f"options must be a CalibrationOptions, got {type(options).__name__}"
                              "; for one field use calibrate(robot, data, method=...)")
        self.options = o = (options or CalibrationOptions()).validated()
        sets = as_sets(sets)
        # model "auto": the candidate structures compared by CV, the best used (model_choice);
        # BLAS limited for its fits, as in solve (blas_threads), only then (nothing else to fit)
        with blas_threads.limited(o.blas_threads if o.model == "auto" else None):
            self._model_choice, o = model_choice.resolve(type(self), robots, sets, o)
        self.options = o
        self.chains = ch = Chains(robots, len(sets), o.model)
        self.robot, self.robots = ch.robot, ch.robots
        self.model_name, self.error_model = ch.model_name, ch.model
        backlash, soft = ch.backlash(o.backlash), ch.backlash(o.compliance, "compliance")
        self.kinds = [ch.kind(i, d, backlash, soft) for i, d in enumerate(sets)]
        self.layout = ParameterLayout.of(ch.model, self.kinds, o.backlash, ch.shared_planes(
            self.kinds) if o.shared_planes else (), soft, ch.torque_rms(self.kinds, soft))
        self.scale = self.layout.penalty_scale(o.length_scale, o.angle_scale)
        self.offsets = np.cumsum([0] + [km.N for km in self.kinds])
        self.weights = sample_weights([km.data.sigma for km in self.kinds],
                                      [km.N for km in self.kinds])
        self.row_scale = None
        for name in [n for n in o.fix + o.free if not any(c in n for c in "*?[")]:
            self._check_name(name)  # a name of another model says which model has it
        self.layout.expand(o.fix), self.layout.expand(o.free)  # unknown names raise, listed
        if not self._unfixed().any():
            raise OptionError(f"nothing to fit: every parameter method {o.method} fits is fixed; "
                              "leave at least one free (fix fewer names)")
        self.n_poses, self.prior = 0, None if o.prior is None else fleet_prior.bind(o.prior, self)
        for km in self.kinds:
            n = len(np.unique(km.data.poses))
            self.n_poses += n
            if n < 3:
                raise DataError(f"{km.data.source}: {n} poses; the frames of a measurement set "
                                "alone need at least 3 (a calibration needs many more)")
        self._warn_inputs()
        self._x_start: np.ndarray | None = None
        self._ident: Identifiability | None = None
        self._structural: Identifiability | None = None
        self._general_J: np.ndarray | None = None  # the structural analysis's Jacobian
        self._general_kept: tuple[str, ...] | None = None  # and its kept names
        self._all_blocks: dict = {}  # (set, block size): blocks of a whole set
        self._subsets: dict = {}  # the last row selections' parts (_parts)
        self._whole: dict = {}  # kinematic: (weights, scale, row_scale, residual_function())

    model_choice = property(lambda self: model_choice.counted(self._model_choice, self.free_mask),
                            doc="model auto: the structures compared and the chosen; else None")

    # ----------------------------------------------------------------- layout
    @property
    def space(self) -> ParameterLayout:
        """The parameter layout (also named ``layout``)."""
        return self.layout

    @property
    def n_samples(self) -> int:
        return int(self.offsets[-1])

    def _check_name(self, name: str) -> None:
        """A --fix/--free name of this model; one of another model says which model has it,
        anything else lists the valid names (ParameterError)."""
        if name in self.layout.names:
            return
        for other in error_models.MODELS:
            try:
                names = () if other == self.model_name else error_models.build(
                    other, self.robot.geometry).names
            except OptionError:  # a model that cannot describe this chain (a tree path)
                names = ()
            if name in names:
                raise ParameterError(
                    f"{name!r} is a parameter of error model {other}, not of {self.model_name}"
                    f" (choose --model {other}, or a name of {self.model_name}: "
                    f"{', '.join(self.layout.kinematic_names[:8])}, ...)",
                    valid=self.layout.names)
        self.layout.index(name)  # raises, listing the valid names

    def _warn_inputs(self) -> None:
        """The sets' warnings (:func:`kincal.measurements.checks.input_warnings`), then mimic
        columns off the URDF's rule (a reader of the URDF follows the rule), per set."""
        datas = [km.data for km in self.kinds]
        for message in input_warnings(datas, self.robots, self.layout.backlash):
            warnings.warn(message, KincalWarning)
        for data, r in zip(datas, self.robots):  # each set on its own chain
            check_mimics(data, r, data.source)

    # -------------------------------------------------------------- residuals
    def _parts(self, rows):
        """[(set index, kind model on those rows, global positions of the rows)]; the
        kind models of the last few small row selections are kept (CV asks for each
        fold's again at every lambda)."""
        if rows is None:
            return [(i, km, np.arange(self.offsets[i], self.offsets[i + 1]))
                    for i, km in enumerate(self.kinds)]
        rows = np.asarray(rows)
        key = (rows.dtype.str, rows.tobytes())
        if key in self._subsets:
            return self._subsets[key]
        out = []
        for i, km in enumerate(self.kinds):
            mine = rows[(rows >= self.offsets[i]) & (rows < self.offsets[i + 1])]
            if mine.size:
                out.append((i, km.subset(mine - self.offsets[i]), mine))
        if rows.size <= SUBSET_MEMO_SAMPLES:  # a large selection is not kept: its memory
            if len(self._subsets) >= 2 * self.options.fold_count + 2:
                self._subsets.pop(next(iter(self._subsets)))
            self._subsets[key] = out
        return out

    def _blocks(self, i: int, km, g: np.ndarray | None, cache: bool):
        """[(local slice, kind model of those samples)] in blocks of BLOCK_SAMPLES.

        Evaluating many samples block by block keeps every temporary of the Jacobian small
        (a few MB, in cache) instead of a dozen (N, dim, p) arrays: at 200,000 poses it is
        several times faster. The blocks of a whole set are built once (cache=True), on
        views of the set's arrays (slices: no copy of the data)."""
        if km.N <= BLOCK_SAMPLES:
            return [(slice(0, km.N), km)]
        if cache and (i, BLOCK_SAMPLES) in self._all_blocks:
            return self._all_blocks[i, BLOCK_SAMPLES]
        blocks = [(sl, km.subset(sl)) for sl in
                  (slice(a, min(a + BLOCK_SAMPLES, km.N)) for a in range(0, km.N, BLOCK_SAMPLES))]
        if cache:
            self._all_blocks[i, BLOCK_SAMPLES] = blocks
        return blocks

    def residual_function(self, rows=None, kinematic: bool = True) -> Callable:
        """residual(u, with_jacobian) -> (r [mm], J) over the samples ``rows`` (global
        indices over the sets in order; default all); u = x / scale. kinematic=False:
        kinematic and backlash columns left at zero (frame-only fits)."""
        w = self._whole.get(kinematic) if rows is None else None  # one for all samples:
        if w is not None and all(a is b for a, b in zip(w, (self.weights, self.scale,
                                                                self.row_scale))):
            return w[3]  # the pass it remembers (reduction.analyze_rows); irls and the
            #              evidence's noise groups change the weights
        parts = [(i, km, g, self._blocks(i, km, g, rows is None))
                 for i, km, g in self._parts(rows)]
        out = residual_function(parts, self.layout, self.weights, self.scale, kinematic,
                                self.row_scale)
        self._whole.update({kinematic: (self.weights, self.scale, self.row_scale, out)}
                           if rows is None else {})
        return out

    def sample_errors(self, x: np.ndarray, rows=None, weighted: bool = False) -> list:
        """Per set with samples in ``rows``: (set index, (n,) sample errors [m]) at x."""
        out = []
        for i, km, g in self._parts(rows):
            e = km.sample_errors(self.residuals(x, i) if rows is None else
                                 km.residuals(*self.layout.split(x, i)))
            out.append((i, e * self.weights[g] if weighted else e))
        return out

    def residuals(self, x: np.ndarray, i: int) -> np.ndarray:
        """(N_i, dim) set i's residuals, measured minus predicted [m] (orientation rows of
        poses scaled to metres by their sigma ratio); many poses in the blocks of the fit
        (:meth:`_blocks`), so no temporary grows with the whole set."""
        km, split = self.kinds[i], self.layout.split(x, i)
        blocks = self._blocks(i, km, None, True)
        if len(blocks) == 1:
            return km.residuals(*split)
        out = np.empty((km.N, km.dim))
        for sl, block in blocks:
            out[sl] = block.residuals(*split)
        return out

    # ------------------------------------------------------------------ start
    @property
    def x_nominal(self) -> np.ndarray:
        """Nominal kinematics, zero frames and joint terms."""
        x = np.zeros(self.layout.size)
        x[:self.layout.n_kinematic] = self.error_model.nominal
        return x

    def start(self) -> np.ndarray:
        """Nominal kinematics with every set's frames fitted to its data (closed form, then
        Gauss-Newton on the free frames). Fixed frame parameters stay at their start: the
        tool point at ``tool_guess`` (``--tool-offset``) when given."""
        if self._x_start is not None:
            return self._x_start
        o, lay = self.options, self.layout
        x = self.x_nominal if self.prior is None else self.prior.centre.copy()
        nominal = self.layout.kinematic(x)  # a fleet prior starts from the fleet mean
        warn_units(self.kinds, o.tool_guess)
        for i, km in enumerate(self.kinds):
            fs, own = lay.frame_slices[i], np.array(lay.own(i), dtype=bool)
            v = (km.start(nominal, o.tool_guess, o.base_guess if i == 0 else None)
                 if km.kind == "point" else km.start(nominal, o.tool_guess))
            if not own.all():  # a shared plane keeps the first set's start
                v = getattr(km, "adopt", lambda v, given, own: np.where(own, v, given))(
                    v, x[fs], own)
            x[fs] = v
        free = lay.is_frame & self._unfixed()
        if o.tool_guess is not None:  # a fixed tool point is held where the user put it
            for i in range(lay.n_sets):
                for c, v in zip("xyz", o.tool_guess):
                    name = lay.set_prefix(i) + "tool." + c
                    if name in lay.names and not free[lay.index(name)]:
                        x[lay.index(name)] = v
        if free.any():
            residual = self.residual_function(kinematic=False)
            one_pass(self.residual_function(), residual, x / self.scale, lay.is_frame)
            # only what the data can fix moves (an unseen flush contact point stays put)
            kept = set(identifiable_rows(residual, x / self.scale,
                                         lay.reporting_scale() / self.scale, lay.names,
                                         lay.n_kinematic, free, o.rank_tol,
                                         self.chains.preference))
            free = free & np.array([n in kept for n in lay.names])  # (np.isin sorts strings)
            sol = solve(residual, x / self.scale, free, options=o.solver)
            x = lay.wrap_frame_angles(sol.u * self.scale)
        self._x_start = x
        return x

    # ---------------------------------------------------------------- analyse
    def _unfixed(self) -> np.ndarray:
        """(p,) the parameters the method fits and the user did not fix."""
        lay = self.layout
        free = (np.ones(lay.size, dtype=bool) if self.options.method != "frames"
                else lay.is_frame.copy())
        if self.options.fix:
            free[lay.indices(self.options.fix)] = False
        return free

    def analyze(self) -> Identifiability:
        """Which parameters these data identify, at the start, with each kind's notes."""
        if self._ident is not None:
            return self._ident
        with blas_threads.limited(self.options.blas_threads):  # as solve's (blas_threads)
            lay, u = self.layout, self.start() / self.scale  # J in mm per mm or per deg
            ident = analyze_rows(self.residual_function(), u, lay.reporting_scale() / self.scale,
                                 lay.names, lay.n_kinematic, self._unfixed(),
                                 self.options.rank_tol, self.n_samples,
                                 self.chains.preference)
        notes = [n for km in self.kinds for n in km.notes()]
        lost = [n for n in ident.dropped if lay.is_frame[lay.index(n)]]
        for i, km in enumerate(self.kinds):
            mine = [n for n in lost if n in lay.frame_names(i)]
            if mine and km.kind == "point":  # a point set must locate its own frames
                why = "; ".join(d.describe() for d in ident.duplicates if d.name in mine)
                raise IdentifiabilityError(
                    f"{km.data.source}: the poses cannot even locate the measurement frame and "
                    f"tool point: {', '.join(mine)} cannot be identified ({why}). There are "
                    f"{distinct_poses(km.data.joint_values)} distinct poses of "
                    f"{len(np.unique(km.data.poses))}; add poses that differ in every "
                    "joint, or fix what the data cannot give (e.g. --fix tool.x tool.y tool.z "
                    "with --tool-offset). Identifiable now: " + ", ".join(ident.kept))
        if lost:
            notes.append("frame parameters these data cannot fix, held at their start: "
                         + grouped(lost))
        general = self._structural_kept()
        gone = [n for n in general if n not in ident.kept] if general is not None else []
        if gone and general is not None:
            d = self.kinds[0].data
            need = math.ceil(len(general) / (3 * d.n_points))
            notes.append(f"{len(gone)} parameters this chain can identify are not identifiable "
                         f"from these {self.n_poses} poses ({distinct_poses(d.joint_values)} "
                         f"distinct): {', '.join(gone)}; the {len(general)} identifiable "
                         f"parameters need at least {need} poses, and many more spread over the "
                         "workspace for a good result")
        note = self._tool_axis_note()
        if note:
            notes.append(note)
            warnings.warn(note, KincalWarning)
        self._ident = replace(ident, notes=ident.notes + tuple(notes), warned=(note,) if note
                              else ()).in_units(dict(zip(lay.names, lay.is_length.tolist())))
        return self._ident

    def structural(self) -> Identifiability | None:
        """What this chain can identify from generic poses (seeded random joint values), for
        one set of points (None otherwise). Compared with :meth:`analyze`, it tells which
        parameters are lost to the data (too few or too similar poses) rather than to the
        geometry of the chain."""
        J, lay = self._structural_jacobian(), self.layout
        if self._structural is None and J is not None:
            self._structural = analyze(J, lay.names, lay.n_kinematic, self._unfixed(),
                                       self.options.rank_tol)
        return self._structural

    def _structural_kept(self) -> tuple[str, ...] | None:
        """:meth:`structural`'s kept names without its report (the fit's two uses read only
        these; :func:`~kincal.identification.selection.identifiable`: the same partition)."""
        J, lay = self._structural_jacobian(), self.layout
        if self._general_kept is None and J is not None:
            self._general_kept = identifiable(J, lay.names, lay.n_kinematic, self._unfixed(),
                                              self.options.rank_tol)
        return self._general_kept

    def _structural_jacobian(self) -> np.ndarray | None:
        """:meth:`structural`'s Jacobian (reporting units) at the start, made once."""
        if self._general_J is None and len(self.kinds) == 1 and self.kinds[0].kind == "point":
            lay = self.layout
            _, J = self.chains.generic_poses(self.model_name, lay, self.kinds[0].data.n_points
                                             ).jacobian(self.start())
            self._general_J = J.reshape(-1, lay.size) * lay.reporting_scale() / MM
        return self._general_J

    def _tool_axis_note(self) -> str:
        """A warning when every tool point of a point set sits near the last (revolute) axis
        of its own chain (the first such set; a chain ending in a prismatic joint has none)."""
        lay, x = self.layout, self.start()
        for i, km in enumerate(self.kinds):
            dists = [km.error_model.last_axis_distance(t) for t in lay.frames(x, i)[6:]
                     .reshape(-1, 3)] if km.kind == "point" else []
            if not dists or dists[0] is None or max(dists) >= TOOL_AXIS_WARNING:
                continue
            dist, last = max(dists), km.error_model.joint_names[-1]
            which = "tool point is" if len(dists) == 1 else f"{len(dists)} measured points are all"
            return (f"the {which} {dist * 1e3:.2f} mm from the axis of {last}: turning about "
                    f"that axis barely moves it, so {km.error_model.last_axis_weak_text()}")
        return ""

    def free_mask(self) -> np.ndarray:
        """(p,) the parameters the fit moves: identifiable ones, and ``free`` names; with a
        fleet prior, of the kinematic ones exactly those it covers (the prior bounds what
        the data cannot see, and holds at its mean what never moved in the fleet)."""
        lay = self.layout
        mask = np.zeros(lay.size, dtype=bool)
        kept = self.analyze().kept  # names of this layout: no patterns to expand
        if kept:
            mask[[lay.index(n) for n in kept]] = True
        if self.options.free:
            mask[lay.indices(self.options.free)] = True
        return mask if self.prior is None else (mask & ~self.prior.held) | self.prior.covered

    # ------------------------------------------------------------------- fits
    def fit(self, lam, rows=None, start: np.ndarray | None = None,
            free: np.ndarray | None = None, residual: Callable | None = None,
            options: SolverOptions | None = None,
            start_u: np.ndarray | None = None, driven: bool = False) -> SolveSummary:
        """One solve with penalty weight ``lam`` (one, or per parameter) on the samples
        ``rows`` (default all); residual: a prebuilt :meth:`residual_function` for rows;
        start_u: the start in the solver's units u = x / scale, as is (instead of start,
        e.g. a previous solve's u: a warm start at exactly its end). driven: the solve as
        a generator whose caller evaluates its points (:func:`solver.steps`)."""
        u0 = (self.start() if start is None else start) / self.scale if start_u is None \
            else start_u
        free = self.free_mask() if free is None else free
        residual = self.residual_function(rows) if residual is None else residual
        return (steps if driven else solve)(
            residual, u0, free, lam=lam if self.prior is None else self.prior.penalty(lam),
            penalised=self.layout.is_penalised, prior=self.start() / self.scale,
            options=options or self.options.solver)

    def cross_validate(self) -> CrossValidation:
        """The CV curve over the lambda grid: folds of poses, each set split on its own;
        error: the mean sample error [mm] (weighted by the sets' sigmas with several)."""
        o = self.options
        grid = lambda_grid(o.lambda_min, o.lambda_max, o.n_lambdas)
        free = self.free_mask()
        groups = np.concatenate([km.data.poses + 10 ** 9 * i for i, km in enumerate(self.kinds)])
        strata = np.repeat(np.arange(len(self.kinds)), [km.N for km in self.kinds])
        samples, subsample = np.arange(self.n_samples), None
        if o.cv_max_poses is not None and self.n_poses > o.cv_max_poses:
            # many poses: choose lambda on a seeded subsample of them
            poses = np.unique(groups)
            keep = np.random.default_rng(o.seed).choice(poses, o.cv_max_poses, replace=False)
            samples = np.flatnonzero(np.isin(groups, keep))
            subsample = (int(o.cv_max_poses), self.n_poses)
        fit, error = fold_fitter(self, free, samples), validation_error(self, samples)
        cv = cross_validate(fit, error, len(samples), grid, o.fold_count, o.seed, o.warm_start,
                            o.progress, groups=groups[samples], strata=strata[samples])
        if subsample is None:
            return cv
        return replace(cv, folds=tuple(samples[f] for f in cv.folds), subsample=subsample)

    # ------------------------------------------------------------------ solve
    def solve(self):
        """Identify; the result carries the plausibility gate's verdict."""
        with blas_threads.limited(self.options.blas_threads):
            return self._solve()

    def _solve(self):
        o = self.options
        ident = self.analyze()
        lay = self.layout
        if o.method != "frames" and not any(lay.is_penalised[lay.index(n)] for n in ident.kept):
            free = (lay.is_penalised & self._unfixed()).any()  # --fix may hold them all
            raise IdentifiabilityError(
                ("these data identify none of the" if free else "--fix holds all")
                + f" {int(lay.is_penalised.sum())} kinematic parameters (identifiable: "
                f"{len(ident.kept)} of {int(self._unfixed().sum())}): nothing would be calibrated"
                + (". Check the sets' sigmas (a weight of 1e-300 silences a set), and measure "
                   "poses that move every joint" if free else "; fix fewer names"))
        general = self._structural_kept()
        if general is not None:
            m = 3 * self.n_samples
            per_pose = 3 * self.kinds[0].data.n_points
            if o.method != "l2" and m <= len(general) and len(ident.kept) < len(general):
                raise IdentifiabilityError(
                    f"{self.n_poses} poses give {m} equations for the {len(general)} "
                    f"parameters this chain can identify; method {o.method} needs at least "
                    f"{math.ceil((len(general) + 1) / per_pose)} poses (and many more "
                    "spread over the workspace); with these poses it would only interpolate. "
                    "Method l2 can work with fewer, pulling what the data cannot fix toward "
                    "nominal")
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
        if o.method == "l2":
            penalty_choice.warn_after_fit(self, ident, cv, sol, lam)
        downweighted = ()
        if o.robust is not None:
            sol, downweighted = irls(self, sol, lam)
        if not sol.converged:
            warnings.warn(f"the solver did not converge in {sol.iterations} iterations; the "
                          "result is the best iterate and is flagged not converged", KincalWarning)
        result = CalibrationResult.build(self, sol, lam, cv, ident, evidence,
                                         f"{how}, chosen automatically: {why}" if why else "",
                                         downweighted)
        if evidence is not None and not o.robust:  # a load-following error the fit misses
            result = replace(result, term_evidence=term_evidence.favoured(self, sol.u, evidence))
        return replace(result, plausibility=judge(gather(self, result)))  # the gate's verdict

def calibrate(robot: Robot, data, options: CalibrationOptions | None = None, **overrides):
    """Build, analyse and solve in one call: ``data`` is one measurement set (points,
    poses, distances, plane contacts) or a list of them; keyword arguments override
    ``options`` fields."""
    names = [f.name for f in fields(CalibrationOptions)]
    unknown = sorted(set(overrides) - set(names))
    if unknown:
        raise OptionError(f"unknown option(s) {', '.join(unknown)}." + suggest(unknown[0], names)
                          + " Options: " + listing(names))
    options = CalibrationOptions(**overrides) if options is None else replace(options, **overrides)
    return CalibrationProblem(robot, data, options).solve()
