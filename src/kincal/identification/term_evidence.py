"""A compliance term the evidence favours, for data too few for the residual diagnosis.

The residual diagnosis (:mod:`kincal.identification.diagnosis`) tests the residuals of a
point set with an F test; on a few dozen contact touches (TALOS's 21 flush touches: 63
equations, 53 identifiable parameters, 10 degrees of freedom left) no F test can see a
missing term, yet the marginal likelihood can: the fitted model, linearised at the
solution, against the same with one compliance term (a joint turning by its compliance
times the gravity torque it carries, :mod:`kincal.models.compliance`), the term's prior
scale and every class's and noise group's maximised again. A term is reported when it
raises the log evidence by more than ``PER_JOINT_NATS`` + ln(candidates): a Bayes factor
above e^7 (about 1100) with the prior odds shared among the joints tried. The threshold
is measured, not textbook: linearised and with every scale maximised, the gain under no
such effect has a heavy tail on few touches; on simulated TALOS touches without
compliance (21, as the real ones, 70 seeds) the largest gain was 8.4 nats against a
threshold of 9.7, on simulated EC66 flush, plane, distance and pose sets (30 poses, 40
seeds each) 5.0 against 8.1-8.4; the real TALOS touches give 18.6 (leg_left_5_joint).
``python scripts/term_evidence_null.py`` measures it (about 80 s).

It is reported, not chosen: the URDF cannot hold a deflection that follows each
posture's gravity torque (FRAMES.json carries compliance terms, ``--compliance``), and on
TALOS the URDF of a compliant fit alone holds out worse than the geometric default
(docs/results.md). The summary says which joint, by how much, and what to try. Runs after a
fit by the evidence (the penalty chosen so, the default on contacts and small volumes) on
one chain with at most ``MAX_ROWS`` residual rows.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import KincalWarning
from kincal.identification import evidence

if TYPE_CHECKING:
    from kincal.identification.problem import CalibrationProblem

PER_JOINT_NATS = 7.0  # with ln(candidates): the threshold (module notes)
MAX_ROWS = 20_000  # residual rows beyond which the residual diagnosis has the power


@dataclass(frozen=True)
class TermEvidence:
    """The compliance term the evidence favours most. gain_nats: its log evidence minus
    the fitted model's, both linearised at the solution; threshold_nats: what it had to
    exceed; candidates: the joints tried; deflection_deg: the term's posterior mean, the
    deflection at the samples' RMS gravity torque [deg]."""

    joint: str
    gain_nats: float
    threshold_nats: float
    candidates: int
    deflection_deg: float

    def line(self) -> str:
        return (f"diagnosis: the evidence favours a compliance of {self.joint} (about "
                f"{self.deflection_deg:+.3g} deg at the RMS gravity torque) by "
                f"{self.gain_nats:.1f} nats over the geometric model ({self.candidates} joints "
                f"tried, threshold {self.threshold_nats:.1f}): part of the error follows the "
                f"load, which no URDF can hold; --compliance {self.joint} fits it into "
                "FRAMES.json, and a held-out set (--validate) tells whether it predicts")

    def as_dict(self) -> dict:
        return {"joint": self.joint, "cause": "compliance", "gain_nats": self.gain_nats,
                "threshold_nats": self.threshold_nats, "candidates": self.candidates,
                "deflection_deg": self.deflection_deg}


def favoured(problem: CalibrationProblem, u: np.ndarray, fit: evidence.EvidenceFit
             ) -> TermEvidence | None:
    """The compliance term whose log evidence gain over ``problem``'s fit (at ``u``, the
    solution in the fit's units, with the evidence ``fit``) passes the threshold, the
    largest; None when none does or the check does not apply (module notes)."""
    found = gains(problem, u, fit)
    if not found:
        return None
    gain, joint, size = max(found)
    threshold = PER_JOINT_NATS + math.log(len(found))
    return TermEvidence(joint, gain, threshold, len(found), size) if gain > threshold else None


def gains(problem: CalibrationProblem, u: np.ndarray, fit: evidence.EvidenceFit
          ) -> list[tuple[float, str, float]]:
    """[(log evidence gain [nats], joint, deflection at the RMS torque [deg])] of every
    compliance term tried (see :func:`favoured`); empty where the check does not apply."""
    from kincal.identification.model_choice import compliance_joints
    from kincal.identification.penalty_choice import noise_groups, prior_classes

    o = problem.options
    if (problem.chains.several or problem.prior is not None or o.noise_mm is not None
            or sum(km.N * km.dim for km in problem.kinds) > MAX_ROWS):
        return []
    pool = [j for j in compliance_joints(problem)[0] if j not in o.compliance]
    if not pool:
        return []
    with warnings.catch_warnings():  # the problem itself gave the data's warnings
        warnings.simplefilter("ignore", KincalWarning)
        wide = type(problem)(list(problem.robots), [km.data for km in problem.kinds],
                             replace(o, compliance=(*o.compliance, *pool), fix=(), free=()))
    names = problem.layout.names
    free = problem.free_mask()
    xw = wide.x_nominal
    xw[[wide.layout.index(n) for n in names]] = u * problem.scale
    uw = xw / wide.scale
    r, J = wide.residual_function()(uw, True)
    base = np.array([wide.layout.index(n) for n in np.array(names)[free]], dtype=np.intp)
    classes = prior_classes(problem)
    present = list(fit.classes) + (["compliance"] if "compliance" not in fit.classes else [])
    groups = np.array([-1 if (c := classes[i]) is None else present.index(c)
                       for i in np.flatnonzero(free)], dtype=np.intp)
    prior = (problem.start() / problem.scale)[free]  # nominal kinematics; frames: flat
    y = -(r + J[:, base] @ np.where(groups < 0, 0.0, prior - u[free]))
    rows = noise_groups(problem, J[:, base])[0]
    rows = np.unique(rows, return_inverse=True)[1]
    more = len(present) - len(fit.classes)
    alpha0 = np.array([1.0 / s ** 2 for s in fit.scales] + [1.0] * more)
    given = np.array([bool(g) for g in fit.given] + [False] * more)
    beta0 = 1.0 / np.maximum(np.asarray(fit.row_noise, float), 1e-12) ** 2
    if beta0.size != int(rows.max()) + 1:
        beta0 = np.full(int(rows.max()) + 1, float(np.mean(beta0)))

    gauges = evidence.exact_directions(J[:, base], r, rows)  # as the fit's evidence does

    def best(columns, g):
        A = J[:, columns]
        for e in gauges:  # the base columns come first
            d = np.zeros(len(columns))
            d[:base.size] = e
            A = A - np.outer(A @ d, d)
        linear = evidence.LinearEvidence.of(A, y, g, rows)
        alpha, beta, history, _ = evidence.maximise(linear, len(present), alpha0, beta0, given)
        return float(history[-1]), linear.posterior(alpha, beta)[0]

    h0, _ = best(base, groups)
    term = present.index("compliance")
    out = []
    for j in pool:
        k = wide.layout.index(f"{j}.compliance")
        h, w = best(np.append(base, k), np.append(groups, term))
        out.append((h - h0, j, float(w[-1])))
    return out
