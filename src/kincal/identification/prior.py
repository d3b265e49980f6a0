"""A fleet prior: what the units of one robot model share, as a Gaussian over the deviations
of their kinematic parameters from the nominal design (FLEET.json).

Learned from calibrated units (:func:`FleetPrior.estimate`, or the hierarchical fit of
:mod:`kincal.fleet.hierarchical`), it replaces the paper's pull toward nominal: the penalty
of a new unit's calibration is centred on the fleet's mean deviation and shaped by the
fleet's covariance, ``lam * (x_k - nominal - mean)^T Sigma^-1 (x_k - nominal - mean)``
over the kinematic parameters (in the solver's units, mm and deg), with its overall scale
``lam`` chosen as without a prior (evidence: the covariance times one scale; CV: one
lambda). Only kinematic parameters are covered: the measurement frame and tool point differ
from cell to cell and keep their flat prior, and backlash keeps its pull toward zero.

The prior is bound to the chain it was learned on (a hash of the robot description and
chain, :func:`kincal.frames_file.chain_hash`), to the error model, to its parameter names
and to their nominal values: another robot, model or parameter set is refused
(:class:`PriorError`), and so is a robot of another design with the same joints (a UR5e's
prior on a UR10e, a unit's corrected URDF): the mean is a deviation from the nominal it was
learned on, and the chain hash leaves the link lengths out (a calibration changes them).

Plain numpy: no pinocchio, no file writing (the fleet's writer writes ``dumps()``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kincal.errors import PriorError
from kincal.frames_file import chain_hash

FORMAT = "kincal-fleet-prior"
VERSION = 2  # 2: each parameter's nominal value (version 1 had none: not checkable)
# [mm or deg]^2: a parameter whose fleet variance is below this never moved in any unit
# (redundant in the error model, or fixed): it is held at the fleet mean, not penalised
COVERED_VARIANCE = 1e-18
# [m or rad]: a nominal value further than this from the prior's is another design (the
# same description gives the same values to rounding; a corrected URDF or another model's
# differs by micrometres and more)
NOMINAL_TOLERANCE = 1e-9


def _number(v) -> float:
    """A JSON number as a float (TypeError for a string, a boolean, null: not read as one)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"{v!r} is not a number")
    return float(v)


def shrink_to_diagonal(X: np.ndarray) -> tuple[np.ndarray, float]:
    """(Sigma (k, k), intensity in [0, 1]): the sample covariance of the rows of X (n, k),
    its correlations shrunk toward zero by the Schaefer-Strimmer intensity (the variance of
    the sample correlations over their square; 1 with fewer than 3 rows). The variances are
    kept: the target is the diagonal."""
    n, k = X.shape
    Xc = X - X.mean(axis=0)
    var = np.sum(Xc ** 2, axis=0) / max(n - 1, 1)
    if n < 3:
        return np.diag(var), 1.0
    sd = np.sqrt(var)
    W = np.divide(Xc, sd, out=np.zeros_like(Xc), where=sd > 0)
    prods = W[:, :, None] * W[:, None, :]  # (n, k, k)
    R = prods.sum(axis=0) / (n - 1)
    var_r = n / (n - 1) ** 3 * np.sum((prods - prods.mean(axis=0)) ** 2, axis=0)
    off = ~np.eye(k, dtype=bool)
    denom = float(np.sum(R[off] ** 2))
    lam = 1.0 if denom <= 0 else min(1.0, max(0.0, float(np.sum(var_r[off])) / denom))
    Rs = np.where(off, (1.0 - lam) * R, 1.0)
    return Rs * np.outer(sd, sd), lam


@dataclass(frozen=True)
class FleetPrior:
    """The fleet's Gaussian over the kinematic deviations from nominal.

    robot: the robot description's name; robot_hash: chain_hash of the chain (robot, base,
    tip, joints, axes). model: the error model. names: the kinematic parameter names, in the
    model's order; is_length: (k,) True for lengths [m], False for angles [rad].
    nominal: (k,) the nominal values the deviations are from [m or rad] (the robot's design).
    mean: (k,) mean deviation from nominal [m or rad]. covariance: (k, k) [SI], correlations
    shrunk toward diagonal by ``shrinkage`` (0: the sample covariance, 1: its diagonal).
    units: the units it was learned from (their names); n_units: how many.
    method: "per-unit" (each unit calibrated alone, the mean and covariance of their
    estimates) or "hierarchical" (empirical Bayes over the units' data jointly).
    """

    robot: str
    robot_hash: str
    model: str
    names: tuple[str, ...]
    is_length: tuple[bool, ...]
    nominal: np.ndarray
    mean: np.ndarray
    covariance: np.ndarray
    units: tuple[str, ...]
    shrinkage: float
    method: str = "per-unit"

    @property
    def n_units(self) -> int:
        return len(self.units)

    @property
    def std(self) -> np.ndarray:
        """(k,) the fleet scatter per parameter [m or rad]."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @classmethod
    def estimate(cls, robot, model: str, names, is_length, nominal, deviations: np.ndarray,
                 units, method: str = "per-unit",
                 extra_covariance: np.ndarray | None = None) -> "FleetPrior":
        """From (n, k) deviations of n units [SI] from ``nominal`` (k,) [SI];
        extra_covariance: (k, k) added to the shrunk scatter (the hierarchical fit's mean
        posterior covariance)."""
        X = np.asarray(deviations, float)
        cov, lam = shrink_to_diagonal(X)
        if extra_covariance is not None:
            cov = cov + extra_covariance
        return cls(robot.model_name, chain_hash(robot), model, tuple(names),
                   tuple(bool(v) for v in is_length), np.array(nominal, float),
                   X.mean(axis=0), cov, tuple(units), float(lam), method)

    # ---------------------------------------------------------------- the file
    def as_dict(self) -> dict:
        unit = ["m" if v else "rad" for v in self.is_length]
        return {"format": FORMAT, "version": VERSION, "robot": self.robot,
                "robot_hash": self.robot_hash, "model": self.model, "method": self.method,
                "n_units": self.n_units, "units": list(self.units),
                "shrinkage": self.shrinkage,
                "parameters": [{"name": n, "unit": u, "nominal": float(v), "mean": float(m),
                                "std": float(s)} for n, u, v, m, s in
                               zip(self.names, unit, self.nominal, self.mean, self.std)],
                "covariance": self.covariance.tolist()}

    @classmethod
    def read(cls, path) -> "FleetPrior":
        """Read and check a FLEET.json (PriorError naming what is wrong)."""
        from kincal.input_files import read_json

        path = Path(path)  # read as FRAMES.json is (no FIFO or device, nesting, encoding)
        d = read_json(path, "fleet prior", "a kincal fleet prior", PriorError,
                      expected="the FLEET.json that kincal fleet wrote")
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise PriorError(f"{path}: not a fleet prior (expected \"format\": \"{FORMAT}\", "
                             "as kincal fleet writes in DIR/FLEET.json)")
        if d.get("version") == 1:
            raise PriorError(f"{path}: fleet prior version 1, which does not record the "
                             "nominal values its deviations are from, so it cannot be checked "
                             f"against this robot's design; this kincal reads version {VERSION}"
                             ": learn the prior again (kincal fleet)")
        if d.get("version") != VERSION:
            raise PriorError(f"{path}: fleet prior version {d.get('version')!r}; this kincal "
                             f"reads version {VERSION}")
        try:
            params = d["parameters"]
            names = tuple(str(p["name"]) for p in params)
            is_length = tuple({"m": True, "rad": False}[p["unit"]] for p in params)
            nominal = np.array([_number(p["nominal"]) for p in params])
            mean = np.array([_number(p["mean"]) for p in params])
            cov = np.array(d["covariance"], dtype=float)
            units = d["units"]
            if not isinstance(units, list) or not all(isinstance(u, str) for u in units):
                raise TypeError(f"units must be a list of the units' names, got {units!r:.60}")
            units = tuple(units)
            if d.get("n_units", len(units)) != len(units):
                raise ValueError(f"n_units {d['n_units']!r} but {len(units)} units named")
            out = cls(str(d["robot"]), str(d["robot_hash"]), str(d["model"]), names, is_length,
                      nominal, mean, cov, units, float(d["shrinkage"]),
                      str(d.get("method", "per-unit")))
        except (KeyError, TypeError, ValueError) as e:
            raise PriorError(f"{path}: malformed fleet prior ({type(e).__name__}: {e}); "
                             "expected robot, robot_hash, model, units, shrinkage, parameters "
                             "(name, unit m or rad, nominal, mean) and a k x k covariance"
                             ) from None
        k = len(names)
        if cov.shape != (k, k) or not np.all(np.isfinite(cov)):
            raise PriorError(f"{path}: the covariance must be a finite {k} x {k} matrix (one "
                             f"row per parameter), got " + (f"shape {cov.shape}" if cov.shape
                                                            != (k, k) else "a NaN or infinity"))
        for what, v in (("mean deviation", mean), ("nominal value", nominal)):
            if not np.all(np.isfinite(v)):
                raise PriorError(f"{path}: the {what} of "
                                 f"{names[int(np.flatnonzero(~np.isfinite(v))[0])]} is not a "
                                 "finite number")
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=0) or np.linalg.eigvalsh(
                cov).min() < -1e-9 * max(float(np.abs(cov).max()), 1e-300):
            raise PriorError(f"{path}: the covariance is not symmetric positive semidefinite")
        if out.n_units < 2:
            raise PriorError(f"{path}: a fleet prior needs at least 2 units, got {out.n_units}")
        return out

    # ----------------------------------------------------------- binding
    def check(self, robot, model: str, names, nominal, source: str = "the fleet prior"
              ) -> None:
        """Refuse a prior of another robot or chain, error model or parameter set, or of a
        robot of another design (``nominal``: (k,) this calibration's nominal values [SI])."""
        h = chain_hash(robot)
        if h != self.robot_hash:
            raise PriorError(
                f"{source} was learned on another robot or chain (robot {self.robot!r}, "
                f"{self.robot_hash[:19]}...), not on this one (robot {robot.model_name!r}, "
                f"{robot.base} -> {robot.tip}, {h[:19]}...); use a prior of this robot's "
                "fleet with the same --base/--tip")
        if model != self.model:
            raise PriorError(f"{source} is of error model {self.model}, this calibration uses "
                             f"{model}: give --model {self.model}")
        if tuple(names) != self.names:
            extra = sorted(set(names) ^ set(self.names))
            raise PriorError(f"{source} covers another parameter set than this calibration's "
                             f"{len(names)} kinematic parameters (differing: "
                             f"{', '.join(extra[:6]) or 'the order'}); learn the prior with "
                             "the same model and options")
        nominal = np.asarray(nominal, float)
        differ = np.abs(nominal - self.nominal)
        off = np.flatnonzero(differ > NOMINAL_TOLERANCE)
        if off.size:
            i = int(off[np.argmax(differ[off])])
            k, unit = (1e3, "mm") if self.is_length[i] else (180.0 / math.pi, "deg")
            there, here = (f"{round(v * k, 4) + 0.0:.4f} {unit}"  # no "-0.0000"
                           for v in (self.nominal[i], nominal[i]))
            raise PriorError(
                f"{source} was learned on a robot of another design: {off.size} of its "
                f"{len(self.names)} nominal values differ from this robot's (the most "
                f"{self.names[i]}: {there} there, {here} here); its mean is a deviation "
                "from its own nominal: calibrate with the robot description the fleet was "
                "learned on (the design's URDF, not a unit's corrected one)")


@dataclass(frozen=True)
class BoundPrior:
    """A fleet prior on one calibration problem's parameter vector (p entries).

    covered: (p,) the kinematic parameters the prior shapes (fleet variance > 0, not fixed).
    held: (p,) kinematic parameters held at the fleet mean (no fleet variance).
    centre: (p,) nominal + mean deviation on the kinematic entries [SI], 0 elsewhere.
    precision: (p, p) the inverse fleet covariance over the covered block, in the solver's
    units (mm, deg), 0 elsewhere.
    """

    prior: FleetPrior
    covered: np.ndarray
    held: np.ndarray
    centre: np.ndarray
    precision: np.ndarray

    def penalty(self, lam):
        """The solver's penalty weights: ``lam`` (one weight, or (p,) weights with one value
        on every covered parameter, as the evidence's fleet class gives) becomes the (p, p)
        matrix lam * precision on the covered block, diagonal elsewhere; a matrix stays."""
        if np.ndim(lam) == 2:
            return lam
        p = self.covered.size
        w = np.broadcast_to(np.asarray(lam, float), (p,))
        M = np.diag(np.where(self.covered, 0.0, w))
        c = np.flatnonzero(self.covered)
        if c.size:
            M[np.ix_(c, c)] = float(w[c[0]]) * self.precision[np.ix_(c, c)]
        return M


def bind(prior: FleetPrior, problem) -> BoundPrior:
    """The prior on ``problem`` (a CalibrationProblem), checked against its chain, model and
    kinematic parameters (PriorError)."""
    lay = problem.layout
    p, k = lay.size, lay.n_kinematic
    prior.check(problem.robot, problem.model_name, lay.kinematic_names, problem.x_nominal[:k])
    centre = problem.x_nominal.copy()
    centre[lay.is_frame] = 0.0
    centre[:k] += prior.mean
    s = problem.scale[:k]
    cov_u = prior.covariance / np.outer(s, s)  # SI -> mm and deg
    unfixed = problem._unfixed()[:k]
    covered = np.zeros(p, bool)
    covered[:k] = (np.diag(cov_u) > COVERED_VARIANCE) & unfixed
    held = np.zeros(p, bool)
    held[:k] = ~covered[:k] & unfixed
    precision = np.zeros((p, p))
    c = np.flatnonzero(covered)
    if c.size:
        precision[np.ix_(c, c)] = np.linalg.pinv(cov_u[np.ix_(c, c)], hermitian=True)
    return BoundPrior(prior, covered, held, centre, precision)


def read_prior(path) -> FleetPrior:
    """FleetPrior.read, for the CLI and the API."""
    return FleetPrior.read(path)


def mahalanobis(prior: FleetPrior, deviation: np.ndarray) -> float:
    """sqrt((d - mean)^T Sigma^+ (d - mean)) of one unit's deviations [SI] (NaN if no
    parameter varies)."""
    v = np.diag(prior.covariance) > 0
    if not v.any():
        return math.nan
    r = (np.asarray(deviation) - prior.mean)[v]
    return float(math.sqrt(max(r @ np.linalg.pinv(prior.covariance[np.ix_(v, v)],
                                                  hermitian=True) @ r, 0.0)))
