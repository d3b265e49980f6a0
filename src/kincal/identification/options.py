"""Calibration options: every choice of a calibration, with the paper's defaults."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from kincal.errors import OptionError
from kincal.frames_file import MAX_LENGTH
from kincal.identification.cross_validation import check_grid
from kincal.measurements.point_space import DEG, MM
from kincal.identification.robust import LOSSES, SCALE_RANGE_M
from kincal.identification.selection import RANK_TOL
from kincal.identification.solver import SolverOptions

if TYPE_CHECKING:
    from kincal.identification.prior import FleetPrior

METHODS = ("l2", "ls", "frames")
# accepted given prior scales [mm or deg] and noise [mm] of the evidence estimator: beyond,
# 1 / value^2 under- or overflows; the estimator's own scales stay within a decade inside
EVIDENCE_RANGE = (1e-6, 1e4)
DEFAULT_FOLDS = 5  # k of the k-fold cross-validation when none is given
# the largest penalty weight given as a number: the penalty's rows carry sqrt(lambda) per
# parameter [per mm or deg], a pose's data rows about 30 (a 2 m arm, mm per deg), so
# J^T J reaches ~1e10 at the ~3 million poses a 256 MB data file can hold; beyond 1e12 the
# penalty outweighs any data set a hundredfold and the result is the nominal kinematics
# (what method "frames" fits), and 1e308 overflows the cost
MAX_LAMBDA = 1e12


@dataclass(frozen=True)
class CalibrationOptions:
    """Every choice of a calibration, with the paper's defaults.

    model: the error model (kincal.models: "complete", "mdh", "placement", "offsets"):
        which geometric errors the chain may have; None (default): the chain's default,
        "complete", or "placement" on a tree path (a base off the tip's branch); "auto":
        the candidate structures (error models, backlash and compliance terms) compared by K-fold CV and
        the best used (kincal.identification.model_choice; the problem's ``model_choice``).
    method: "l2" (penalty toward nominal), "ls" (plain least squares) or "frames" (fit
        only the measurement frame and tool point; kinematics stay nominal).
    lam: "auto" (default): "evidence" when the data cover a small measurement volume
        (their extent below SMALL_VOLUME of the arm's reach, where CV judges only
        interpolation), else "cv"; "evidence" for Gaussian priors toward nominal per
        parameter class (lengths, twists, joint offsets, backlash) whose scales and the
        noise maximise the marginal likelihood (kincal.identification.evidence); "cv" to
        choose one lambda by cross-validation (the paper's Algorithm 1); or a number from 0
        to MAX_LAMBDA (method "l2"). The rule was chosen from scripts/estimators.py
        (README, "Choosing the penalty"). Given prior_mm / prior_deg / noise_mm make "auto" use evidence.
    prior_mm, prior_deg: with lam "evidence", the prior standard deviation [mm] of the
        length class and [deg] of the twist and joint-offset classes (tolerances), kept
        instead of estimated; None: estimated. noise_mm: likewise the measurement noise,
        standard deviation per axis of a unit-weight sample [mm]. Each within
        EVIDENCE_RANGE (1e-6 to 1e4).
    folds, seed: k and the seed of the fold split. folds None: DEFAULT_FOLDS
        (:attr:`fold_count`), and lam "auto" takes the evidence where that many folds
        cannot split the poses two each; a k given is the user's: too few poses for it is
        an error, not a reason to choose otherwise.
    lambda_min, lambda_max, n_lambdas: the CV grid (log-spaced; paper: 1e-6, 1e3, 50).
    length_scale [m], angle_scale [rad]: the unit s of the penalty
        lambda * sum(((x - x0) / s)^2); 1 mm and 1 deg by default, the paper's units.
    fix: parameter names held at their nominal values; shell-style patterns select
        several (``"*.d"``, ``"joint_[456].*"``, ``"tool.*"``), see ParameterLayout.expand.
    free: parameter names (or patterns) kept in the fit even if the analysis finds them
        redundant (sensible only with method "l2", whose penalty keeps them bounded).
    backlash: chain joints given a backlash term ``<joint>.backlash`` (half the play,
        nominally 0; see kincal.backlash), identified from the approach directions of
        the samples. Methods "l2" and "ls".
    compliance: chain joints given a compliance term ``<joint>.compliance`` (the joint's
        deflection per N m of the gravity torque it carries, nominally 0; see
        kincal.models.compliance), the torques from the URDF's inertials. Methods "l2"
        and "ls".
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
    cv_max_poses: the CV runs on a seeded random subsample of at most this many poses
        (None: all). Its 250 fold fits would otherwise cost 250 fits of the whole data
        (minutes at 200,000 poses), while lambda, the ratio of the noise variance to the
        prior variance of the errors, does not depend on the number of poses; the final
        fit uses every pose, and the summary says when a subsample chose lambda.
    solver: stopping rules (paper: 1e-5 mm^2 over 5 iterations, 100 iterations).
    blas_threads: BLAS threads while solving (1: faster on a busy machine, see
        kincal.blas_threads); None leaves BLAS as it is.
    progress: callback(done, total) during the CV sweep, or None.
    prior: a fleet prior (kincal.identification.prior.FleetPrior, from FLEET.json) or None:
        the penalty on the kinematic parameters is centred on the fleet's mean deviation
        and shaped by its covariance instead of pulling toward nominal; lam chooses its
        overall scale as usual ("evidence": one scale on the covariance). Method l2 only.
    prior_scale: with a prior and lam "evidence", that scale kept instead of estimated (1:
        the fleet covariance as it is; the hierarchical fit's rounds, kincal.fleet.fleet).
    shared_planes: the plane and flush sets touch the same physical planes: each plane's
        parameters (``plane.*``, or ``plane<label>.*`` per label of a ``plane`` column) are
        one set, the first such set's, shared by every set with that plane name (the sets'
        chains must have one base frame, in which the planes are fitted). False: every
        set fits its own planes.
    """

    model: str | None = None
    method: str = "l2"
    lam: float | str = "auto"
    prior_mm: float | None = None
    prior_deg: float | None = None
    noise_mm: float | None = None
    folds: int | None = None
    seed: int = 0
    lambda_min: float = 1e-6
    lambda_max: float = 1e3
    n_lambdas: int = 50
    length_scale: float = MM
    angle_scale: float = DEG
    fix: tuple[str, ...] = ()
    free: tuple[str, ...] = ()
    backlash: tuple[str, ...] = ()
    compliance: tuple[str, ...] = ()
    tool_guess: tuple[float, float, float] | None = None
    base_guess: tuple[float, ...] | None = None
    rank_tol: float = RANK_TOL
    robust: str | None = None
    robust_scale_mm: float | None = None
    warm_start: bool = True
    cv_step_tol: float = 1e-6
    cv_max_poses: int | None = 2000
    solver: SolverOptions = SolverOptions()
    blas_threads: int | None = 1
    progress: Callable | None = field(default=None, compare=False, repr=False)
    shared_planes: bool = False
    prior: FleetPrior | None = None
    prior_scale: float | None = None

    @property
    def fold_count(self) -> int:
        """k of the k-fold cross-validation: ``folds``, or DEFAULT_FOLDS."""
        return DEFAULT_FOLDS if self.folds is None else self.folds

    def validated(self) -> "CalibrationOptions":
        """These options checked, with sequences made tuples (``fix=[...]`` works as well as
        ``fix=(...)``) and numbers made plain; raises :class:`OptionError` naming the field."""
        o = self._normalised()
        from kincal.models import MODELS, SUITS

        if o.model is not None and o.model not in MODELS + ("auto",):
            raise OptionError(f"unknown error model {o.model!r}; expected auto or one of "
                              f"{', '.join(MODELS)} (" + "; ".join(f"{k}: {v}" for k, v in
                                                                 SUITS.items()) + ")")
        if o.method not in METHODS:
            raise OptionError(f"unknown method {o.method!r}; expected one of {', '.join(METHODS)}")
        if isinstance(o.lam, str):
            if o.lam not in ("auto", "cv", "evidence"):
                raise OptionError(f"lambda must be 'auto', 'cv', 'evidence' or a number >= 0, got "
                                  f"{o.lam!r}")
        elif not (math.isfinite(float(o.lam)) and 0 <= float(o.lam) <= MAX_LAMBDA):
            raise OptionError(f"lambda must be 'auto', 'cv', 'evidence' or a number from 0 to "
                              f"{MAX_LAMBDA:g}, got {o.lam!r}")
        for key in ("prior_mm", "prior_deg", "noise_mm"):
            value = getattr(o, key)
            if value is None:
                continue
            if o.lam not in ("evidence", "auto") or o.method != "l2":
                flag = "--" + key.replace("_", "-")
                raise OptionError(f"{key} ({flag}) is a setting of the evidence estimator: use "
                                  f"it with method l2 and lambda 'evidence' (got method "
                                  f"{o.method}, lambda {o.lam!r})")
            lo, hi = EVIDENCE_RANGE
            if not (math.isfinite(float(value)) and lo <= float(value) <= hi):
                unit = "deg" if key == "prior_deg" else "mm"
                raise OptionError(f"{key} (--{key.replace('_', '-')}) must be between {lo:g} "
                                  f"and {hi:g} {unit}, got {value!r}")
        if o.free and o.method != "l2":  # unpenalised, a redundant parameter is arbitrary
            raise OptionError(f"free (--free) applies to method l2 (its penalty keeps redundant "
                              f"parameters bounded); method {o.method} cannot fit them")
        if o.prior_scale is not None and (o.prior is None or o.lam != "evidence" or not (
                math.isfinite(float(o.prior_scale)) and float(o.prior_scale) > 0)):
            raise OptionError(f"prior_scale (of a fleet prior, kept by the evidence) needs a "
                              f"prior, lambda 'evidence' and a value > 0; got "
                              f"{o.prior_scale!r}, lambda {o.lam!r}")
        if not (o.length_scale > 0 and o.angle_scale > 0):
            raise OptionError("length_scale and angle_scale must be > 0")
        if o.tool_guess is not None and np.shape(o.tool_guess) != (3,):
            raise OptionError("tool_guess needs 3 numbers (x, y, z in the tip frame) [m]")
        if o.base_guess is not None and np.shape(o.base_guess) != (6,):
            raise OptionError("base_guess needs 6 numbers (x, y, z [m], rx, ry, rz [rad])")
        check_grid(o.lambda_min, o.lambda_max, o.n_lambdas)
        if o.cv_max_poses is not None and not (
                isinstance(o.cv_max_poses, (int, np.integer)) and not isinstance(
                    o.cv_max_poses, bool) and o.cv_max_poses >= 2):
            raise OptionError(f"cv_max_poses (--cv-max-poses) must be an integer >= 2 or None "
                              f"(0 on the command line: every pose), got {o.cv_max_poses!r}")
        if o.cv_max_poses is not None and o.cv_max_poses < o.fold_count:
            raise OptionError(f"folds (--folds) {o.fold_count} is more than the "
                              f"{o.cv_max_poses} poses the cross-validation runs on "
                              f"(cv_max_poses, --cv-max-poses): each fold needs a pose; ask "
                              f"for at most {o.cv_max_poses} folds, or a larger --cv-max-poses "
                              f"(0: every pose)")
        if o.robust is not None and o.robust not in LOSSES:
            raise OptionError(f"unknown robust loss {o.robust!r}; expected one of "
                              f"{', '.join(LOSSES)} (or none)")
        lo, hi = SCALE_RANGE_M
        if o.robust_scale_mm is not None and not lo <= o.robust_scale_mm * 1e-3 <= hi:
            raise OptionError(f"robust_scale_mm (--robust-scale-mm) must be between "
                              f"{lo * 1e3:g} and {hi * 1e3:g} mm (a pose error's scale), got "
                              f"{o.robust_scale_mm:g}")
        if o.blas_threads is not None and not (isinstance(o.blas_threads, int)
                                               and o.blas_threads >= 1):
            raise OptionError(f"blas_threads must be an integer >= 1 or None, got "
                              f"{o.blas_threads!r}")
        if o.prior is not None:
            from kincal.identification.prior import FleetPrior

            if not isinstance(o.prior, FleetPrior):
                raise OptionError(f"prior must be a FleetPrior (read_prior('FLEET.json')), got "
                                  f"{type(o.prior).__name__}")
            if o.method != "l2":
                raise OptionError(f"a fleet prior (--prior) shapes the penalty of method l2; "
                                  f"got method {o.method}")
            if not isinstance(o.lam, str) and float(o.lam) == 0:  # the least-squares fit
                raise OptionError("a fleet prior (--prior) weighs through the penalty, which "
                                  "lambda 0 (--lambda 0) switches off: the prior would be "
                                  "ignored; give --lambda evidence (the default with a small "
                                  "volume), cv or a value > 0")
        for term in ("backlash", "compliance"):
            if getattr(o, term) and o.method == "frames":
                raise OptionError(f"{term} terms need method l2 or ls; method frames fits only "
                                  "the measurement frame and tool point")
        return o

    def _normalised(self) -> "CalibrationOptions":
        """A copy with names as tuples of str, guesses as tuples of finite floats, and the
        counts as ints; OptionError for what cannot be made so."""
        changes: dict[str, Any] = {}
        for name in ("fix", "free", "backlash", "compliance"):
            value = getattr(self, name)
            items = (value,) if isinstance(value, str) else value
            try:
                items = tuple(items)
            except TypeError:
                raise OptionError(f"{name} must be a sequence of names, got {value!r}") from None
            if not all(isinstance(v, str) for v in items):
                raise OptionError(f"{name} must hold names (str), got {value!r}")
            changes[name] = items
        for name, n in (("tool_guess", 3), ("base_guess", 6)):
            value = getattr(self, name)
            if value is None:
                continue
            try:
                v = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                v = np.zeros(0)
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise OptionError(f"{name} needs {n} finite numbers, got {value!r}")
            if np.abs(v[:3]).max() > MAX_LENGTH:  # a unit slip; sums would overflow
                raise OptionError(f"{name}: {value!r} is over {MAX_LENGTH:g} m from its frame; "
                                  "positions are in metres")
            changes[name] = tuple(float(x) for x in v)
        for name, low in (("folds", 2), ("seed", 0), ("n_lambdas", 2)):
            value = getattr(self, name)
            if name == "folds" and value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")
            changes[name] = int(value)
        if not isinstance(self.method, str):
            raise OptionError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        for name in ("lam", "lambda_min", "lambda_max", "length_scale", "angle_scale",
                     "robust_scale_mm", "cv_step_tol"):
            value = getattr(self, name)
            if value is None or (name == "lam" and isinstance(value, str)):
                continue
            try:
                changes[name] = float(value)
            except (TypeError, ValueError):
                raise OptionError(f"{name} must be a number, got {value!r}") from None
        if not isinstance(self.solver, SolverOptions):
            raise OptionError(f"solver must be a SolverOptions, got {self.solver!r}")
        return replace(self, **changes)
