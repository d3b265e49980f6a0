"""A fleet's calibration: every unit through the one calibration path on the distributed
engine, the fleet prior learned from them, optionally by a hierarchical fit.

Per unit (rounds=0): each unit is calibrated alone (its own data, the usual pull toward
nominal); the prior is the mean and the covariance (shrunk toward diagonal) of their
estimated deviations. Right when every unit is measured widely (a tracker): each estimate
is then close to the unit's truth.

Hierarchical (rounds=N > 0), for fleets measured only in small volumes, where each unit
alone identifies only part of its parameters and the per-unit estimates are pulled toward
nominal where its data are blind: an empirical-Bayes (EM-like) iteration over the units'
data jointly. Round 0 calibrates each unit alone and learns a first prior; each further
round (the E-step) calibrates every unit with the current prior as it is (the penalty
centred on the fleet mean, shaped by the fleet covariance, its scale held at 1; only the
noise by evidence) and re-estimates the prior from the units' posteriors (the M-step):
mean = the mean of the posterior means, covariance = the shrunk scatter of the posterior
means + the mean posterior covariance sigma^2 (J^T J + Lam)^-1 (the EM update of a
Gaussian hierarchical model, which credits the uncertainty each unit leaves: where a
unit's data are blind its posterior keeps the prior's width). What it assumes: the units
are independent draws from one Gaussian over the kinematic deviations (no unit-specific
structure, no outlier mixture); each unit's posterior is Gaussian at its linearisation;
the units' measurement frames and tool points are nuisance parameters of each unit (flat
prior); the fleet's blind directions (a parameter no unit's data see) keep what round 0
gave them, and the prior carries no information there beyond it.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from kincal.errors import OptionError
from kincal.fleet import engine
from kincal.fleet.summary import FleetSummary
from kincal.fleet.unit import UnitJob, UnitOutcome, calibrate_unit
from kincal.identification.prior import FleetPrior


# rounds of the hierarchical fit at most: each is a pass over every unit, and the EM's gains
# fall below 1 % a round after a few (docs/fleet.md: 8 rounds measured); more is a typo
MAX_ROUNDS = 100


def learn_prior(robot, outcomes, method: str = "per-unit", with_covariances: bool = False
                ) -> FleetPrior | None:
    """The prior of the calibrated outcomes (None with fewer than 2). with_covariances:
    add the units' mean posterior covariance to the scatter (the hierarchical update)."""
    ok = [u for u in outcomes if u.status == "calibrated"]
    if len(ok) < 2:
        return None
    extra = None
    if with_covariances:
        covs = [u.covariance for u in ok if u.covariance is not None]
        extra = np.mean(covs, axis=0) if covs else None
    return FleetPrior.estimate(robot, ok[0].model, ok[0].names, ok[0].is_length,
                               ok[0].nominal, np.array([u.deviation for u in ok]), [u.name for u in ok],
                               method, extra)


def _e_step(options, prior):
    """A unit's options in a round: the first (no prior yet) as given; the next ones the
    posterior under the current prior as it is (its scale fixed at 1, the noise by
    evidence), as the EM update assumes."""
    if prior is None:
        return options
    return replace(options, prior=prior, lam="evidence", prior_scale=1.0)


def calibrate_fleet(robot, jobs: list[UnitJob], workers: int = 1, scheduler: str | None = None,
                    rounds: int = 0, progress: Callable | None = None,
                    batch: int | None = None, on_round: Callable | None = None
                    ) -> FleetSummary:
    """Every job on the engine; the summary with the prior. The outputs are staged by the
    last round only (its jobs' out_dir), for the caller to put in place or discard
    (:mod:`kincal.fleet.folders`); earlier rounds of the hierarchical fit write nothing. progress(done, total, outcome) after each unit (total counts every round).
    batch: units per task (None: engine.batch_size). on_round(r, prior): the prior learned
    after round r (0: each unit alone), e.g. to compare the rounds. rounds: 0 to
    :data:`MAX_ROUNDS`."""
    if isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) \
            or not 0 <= rounds <= MAX_ROUNDS:
        raise OptionError(f"rounds (--hierarchical) must be an integer from 0 to {MAX_ROUNDS}, "
                          f"got {rounds!r}")
    total, done = len(jobs) * (rounds + 1), [0]
    prior, outcomes = None, []
    with engine.Engine(workers, scheduler) as eng:  # started once for every round
        for r in range(rounds + 1):
            last = r == rounds
            round_jobs = [replace(j, options=_e_step(j.options, prior),
                                  out_dir=j.out_dir if last else None) for j in jobs]
            got: dict[str, UnitOutcome] = {}

            def finished(outcome, got=got):
                got[outcome.name] = outcome
                done[0] += 1
                if progress is not None:
                    progress(done[0], total, outcome)

            def crashed(job, exc, finished=finished):
                finished(UnitOutcome(job.name, job.source, "failed",
                                     f"internal error: {type(exc).__name__}: {exc}"))

            eng.run(calibrate_unit, round_jobs, finished, crashed, batch)
            outcomes = [got[j.name] for j in jobs]
            prior = learn_prior(robot, outcomes, "hierarchical" if r else "per-unit",
                                with_covariances=r > 0)
            if on_round is not None:
                on_round(r, prior)
    return FleetSummary.of(outcomes, prior, rounds)
