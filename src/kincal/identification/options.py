"""Calibration options: every choice of a calibration, with the paper's defaults."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from kincal.errors import OptionError
from kincal.identification.cross_validation import lambda_grid
from kincal.identification.parameters import DEG, MM
from kincal.identification.robust import LOSSES
from kincal.identification.selection import RANK_TOL
from kincal.identification.solver import SolverOptions

METHODS = ("l2", "ls", "frames")


@dataclass(frozen=True)
class CalibrationOptions:
    """Every choice of a calibration, with the paper's defaults.

    model: the error model (kincal.models: "complete" (default), "mdh", "placement",
        "offsets"): which geometric errors the chain may have.
    method: "l2" (penalty toward nominal), "ls" (plain least squares) or "frames" (fit
        only the measurement frame and tool point; kinematics stay nominal).
    lam: "auto" (default): "evidence" when the data cover a small measurement volume
        (their extent below SMALL_VOLUME of the arm's reach, where CV judges only
        interpolation), else "cv"; "evidence" for Gaussian priors toward nominal per
        parameter class (lengths, twists, joint offsets, backlash) whose scales and the
        noise maximise the marginal likelihood (kincal.identification.evidence); "cv" to
        choose one lambda by cross-validation (the paper's Algorithm 1); or a number >= 0
        (method "l2"). The rule was chosen from scripts/estimators.py (README, "Choosing
        the penalty"). Given prior_mm / prior_deg / noise_mm make "auto" use evidence.
    prior_mm, prior_deg: with lam "evidence", the prior standard deviation [mm] of the
        length class and [deg] of the twist and joint-offset classes (tolerances), kept
        instead of estimated; None: estimated. noise_mm: likewise the measurement noise,
        standard deviation per axis of a unit-weight sample [mm].
    folds, seed: k and the seed of the fold split.
    lambda_min, lambda_max, n_lambdas: the CV grid (log-spaced; paper: 1e-6, 1e3, 50).
    length_scale [m], angle_scale [rad]: the unit s of the penalty
        lambda * sum(((x - x0) / s)^2); 1 mm and 1 deg by default, the paper's units.
    fix: parameter names held at their nominal values; shell-style patterns select
        several (``"*.d"``, ``"joint_[456].*"``, ``"tool.*"``), see ParameterSpace.expand.
    free: parameter names (or patterns) kept in the fit even if the analysis finds them
        redundant (sensible only with method "l2", whose penalty keeps them bounded).
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
    cv_max_poses: the CV runs on a seeded random subsample of at most this many poses
        (None: all). Its 250 fold fits would otherwise cost 250 fits of the whole data
        (minutes at 200,000 poses), while lambda, the ratio of the noise variance to the
        prior variance of the errors, does not depend on the number of poses; the final
        fit uses every pose, and the summary says when a subsample chose lambda.
    solver: stopping rules (paper: 1e-5 mm^2 over 5 iterations, 100 iterations).
    blas_threads: BLAS threads while solving (1: faster on a busy machine, see
        kincal.blas_threads); None leaves BLAS as it is.
    progress: callback(done, total) during the CV sweep, or None.
    """

    model: str = "complete"
    method: str = "l2"
    lam: float | str = "auto"
    prior_mm: float | None = None
    prior_deg: float | None = None
    noise_mm: float | None = None
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
    cv_max_poses: int | None = 2000
    solver: SolverOptions = SolverOptions()
    blas_threads: int | None = 1
    progress: Callable | None = field(default=None, compare=False, repr=False)

    def validated(self) -> "CalibrationOptions":
        from kincal.models import MODELS, SUITS

        if self.model not in MODELS:
            raise OptionError(f"unknown error model {self.model!r}; expected one of "
                              f"{', '.join(MODELS)} (" + "; ".join(f"{k}: {v}" for k, v in
                                                                 SUITS.items()) + ")")
        if self.method not in METHODS:
            raise OptionError(f"unknown method {self.method!r}; expected one of {', '.join(METHODS)}")
        if isinstance(self.lam, str):
            if self.lam not in ("auto", "cv", "evidence"):
                raise OptionError(f"lambda must be 'auto', 'cv', 'evidence' or a number >= 0, got "
                                  f"{self.lam!r}")
        elif not (math.isfinite(float(self.lam)) and float(self.lam) >= 0):
            raise OptionError(f"lambda must be 'auto', 'cv', 'evidence' or a finite number >= 0, got "
                              f"{self.lam!r}")
        for key in ("prior_mm", "prior_deg", "noise_mm"):
            value = getattr(self, key)
            if value is None:
                continue
            if self.lam not in ("evidence", "auto") or self.method != "l2":
                flag = "--" + key.replace("_", "-")
                raise OptionError(f"{key} ({flag}) is a setting of the evidence estimator: use "
                                  f"it with method l2 and lambda 'evidence' (got method "
                                  f"{self.method}, lambda {self.lam!r})")
            if not (math.isfinite(float(value)) and float(value) > 0):
                raise OptionError(f"{key} must be a finite number > 0, got {value!r}")
        if not (self.length_scale > 0 and self.angle_scale > 0):
            raise OptionError("length_scale and angle_scale must be > 0")
        if self.tool_guess is not None and np.shape(self.tool_guess) != (3,):
            raise OptionError("tool_guess needs 3 numbers (x, y, z in the tip frame) [m]")
        if self.base_guess is not None and np.shape(self.base_guess) != (6,):
            raise OptionError("base_guess needs 6 numbers (x, y, z [m], rx, ry, rz [rad])")
        lambda_grid(self.lambda_min, self.lambda_max, self.n_lambdas)
        if self.cv_max_poses is not None and not (
                isinstance(self.cv_max_poses, (int, np.integer)) and not isinstance(
                    self.cv_max_poses, bool) and self.cv_max_poses >= max(2, self.folds)):
            raise OptionError(f"cv_max_poses must be an integer >= the number of folds "
                              f"({self.folds}) or None, got {self.cv_max_poses!r}")
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
