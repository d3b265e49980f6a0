"""One unit of a fleet: calibrate one data file through the one calibration path and write
its outputs through the one writer, all or none, staged for DIR/<unit>/.

:func:`calibrate_unit` runs on a worker of the distributed engine (:mod:`kincal.fleet.engine`):
a :class:`UnitJob` and a :class:`UnitOutcome` are plain picklable values. A unit whose file is
bad, whose calibration fails or whose result the gate refuses comes back as an outcome with
that status and its one-line reason; it never raises (the fleet goes on).

All or none per unit: the writer writes into a hidden staging folder ``DIR/.partial-<unit>``,
and there it stays: the fleet's outcome decides. The command puts every staged unit in place
together once the fleet has succeeded, or discards them all (:mod:`kincal.fleet.folders`),
so a fleet that fails (fewer than two units calibrated) leaves no unit's files a pipeline
could take for its result, and replaces no earlier ones; an interrupted fleet keeps the
units finished by then, each complete, and no partial one.
"""

from __future__ import annotations

import shutil
import warnings
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from kincal.errors import ImplausibleResultError, KincalError, KincalWarning, NotConvergedError

if TYPE_CHECKING:
    from kincal.identification.options import CalibrationOptions

STAGING = ".partial-"
URDF, FRAMES, REPORT = "corrected.urdf", "FRAMES.json", "REPORT.json"


@dataclass(frozen=True)
class UnitJob:
    """One unit's calibration. name: the unit (its folder under out_dir). source: its data
    file. load: () -> Robot (the chain; cached per worker). read: (Robot) -> [measurement
    set] (the command's own reader, so a unit reads its file as ``kincal calibrate`` does).
    options: the CalibrationOptions (no callbacks: they do not travel to workers).
    out_dir: the fleet's folder (the unit's files are staged in it, put in place by
    :func:`kincal.fleet.folders.commit_units`), or None to write nothing (a round of the
    hierarchical fit).
    accept_implausible / accept_unconverged: the gate's overrides. overwrite: replace an
    existing DIR/<unit>. command / xacro_args: the command line and the xacro arguments,
    for the provenance of the unit's files."""

    name: str
    source: str
    load: Callable
    read: Callable
    options: CalibrationOptions
    out_dir: str | None
    accept_implausible: bool = False
    accept_unconverged: bool = False
    overwrite: bool = False
    command: tuple[str, ...] | None = None
    xacro_args: dict[str, str] | None = None


@dataclass(frozen=True)
class UnitOutcome:
    """What came back of one unit.

    status: "calibrated", "refused" (the gate refused the result: nothing written) or
    "failed" (a bad file or option, or a calibration that could not be made). message: the
    reason, one line ("" when calibrated). model / names / is_length: the error model and
    its kinematic parameters; nominal: (k,) their nominal values [SI]; deviation: (k,)
    estimate - nominal [SI]; covariance: (k, k)
    [SI] of the kinematic parameters: with a fleet prior under evidence the posterior
    covariance, else the result's sandwich covariance (None if not estimated); identified:
    (k,) which the unit's fit moved. before_mm / after_mm: mean error before and after [mm].
    written: the unit's files, as they are named once the fleet puts them in place (staged
    until then). warnings: its warnings, one line each.
    """

    name: str
    source: str
    status: str
    message: str = ""
    model: str = ""
    names: tuple[str, ...] = ()
    is_length: tuple[bool, ...] = ()
    nominal: np.ndarray | None = None
    deviation: np.ndarray | None = None
    covariance: np.ndarray | None = None
    identified: np.ndarray | None = None
    before_mm: float = float("nan")
    after_mm: float = float("nan")
    written: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()


@lru_cache(maxsize=4)
def _robot(load):
    return load()


def calibrate_unit(job: UnitJob) -> UnitOutcome:
    """Calibrate and write one unit; every KincalError becomes the outcome's status."""
    from kincal.export.outputs import gate
    from kincal.identification.problem import CalibrationProblem

    seen: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", KincalWarning)
            robot = _robot(job.load)
            problem = CalibrationProblem(robot, job.read(robot), job.options)
            result = problem.solve()
            gate(result, job.accept_implausible, job.accept_unconverged)  # refused: raises
        seen = [str(w.message) for w in caught if issubclass(w.category, KincalWarning)]
        k = result.layout.n_kinematic
        cov = _posterior_covariance(problem, result)
        if cov is None and result.covariance is not None:
            cov = np.array(result.covariance[:k, :k])
        out = UnitOutcome(job.name, job.source, "calibrated", "", result.chains.model_name, tuple(result.layout.kinematic_names),
                          tuple(bool(v) for v in result.layout.is_length[:k]),
                          np.array(result.x_nominal[:k]),
                          np.array(result.x[:k] - result.x_nominal[:k]), cov,
                          np.array([p.status == "identified" for p in result.parameters[:k]]),
                          float(result.before.mean), float(result.after.mean), (), tuple(seen))
        if job.out_dir is not None:
            out = replace(out, written=_write(job, result))
        return out
    except (ImplausibleResultError, NotConvergedError) as e:
        return UnitOutcome(job.name, job.source, "refused", _line(e), warnings=tuple(seen))
    except KincalError as e:
        return UnitOutcome(job.name, job.source, "failed", _line(e), warnings=tuple(seen))


def _posterior_covariance(problem, result) -> np.ndarray | None:
    """(k, k) [SI] the Bayesian posterior covariance of the kinematic parameters of a fit
    with a fleet prior under evidence, sigma^2 (J^T J + Lam)^-1 with Lam the fit's penalty
    (the frames' flat prior marginalised by taking the block of the inverse); None without
    a prior or evidence. Unlike the sandwich covariance (the estimator's scatter over
    repeated data, ~0 where the data are blind), it keeps the prior's width where the data
    see nothing: what the hierarchical fit's update needs."""
    from kincal.identification.penalty_choice import prior_classes

    ev = result.evidence
    if problem.prior is None or ev is None:
        return None
    free = problem.free_mask()
    lam = problem.prior.penalty(ev.weights(prior_classes(problem)))
    H = result.solve.normal_matrix(free) + lam[np.ix_(free, free)]
    try:
        Hi = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return None
    k, sc = result.layout.n_kinematic, problem.scale
    full = np.zeros((sc.size, sc.size))
    full[np.ix_(free, free)] = ev.noise_mm ** 2 * Hi * np.outer(sc[free], sc[free])
    return full[:k, :k]


def _line(e: BaseException) -> str:
    return " ".join(str(e).split())


def _write(job: UnitJob, result) -> tuple[str, ...]:
    """The unit's files through the one writer into its staging folder, where they wait for
    the fleet's outcome (:mod:`kincal.fleet.folders`); returns the names they will take.
    The writer makes the staging folder (removed again if the writing fails), and the
    fleet's folder if no unit made it yet, as a shared folder: never removed by a unit's
    failure, since other units may be about to write into it (the command removes it if
    the run leaves it empty)."""
    from kincal.export.outputs import Outputs, write_calibration

    assert job.out_dir is not None  # only a job with an out_dir writes
    final = Path(job.out_dir) / job.name
    stage = Path(job.out_dir) / f"{STAGING}{job.name}"
    if stage.exists():
        shutil.rmtree(stage)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", KincalWarning)  # collected in the outcome
            write_calibration(result, Outputs(urdf=stage / URDF, frames=stage / FRAMES,
                                              report=stage / REPORT, protect=(job.source,)),
                              accept_implausible=job.accept_implausible,
                              accept_unconverged=job.accept_unconverged,
                              data_source=job.source, command=job.command,
                              xacro_args=job.xacro_args, dirs=(stage,),
                              shared_dirs=(job.out_dir,))
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return tuple(str(final / n) for n in (URDF, FRAMES, REPORT))
