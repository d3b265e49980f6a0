"""The outcome of a calibration from several measurement sets (or one of a kind other than
points): parameter table, per-set frames and statistics, evaluation on other data, export."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kincal.identification.cross_validation import CrossValidation
from kincal.identification.options import CalibrationOptions
from kincal.identification.result import ParameterEstimate, _std_errors
from kincal.identification.selection import Identifiability
from kincal.identification.solver import SolveSummary
from kincal.identification.statistics import ErrorStats
from kincal.models.base import ErrorModel
from kincal.robot import Robot

if TYPE_CHECKING:
    from kincal.identification.multiset import MultiSetProblem


@dataclass(frozen=True)
class SetReport:
    """One measurement set in a result: its kind, source, frame names and values [SI],
    errors before (start) and after calibration (per sample: position, distance or
    distance to the plane [mm]); for poses also the orientation errors [deg]."""

    kind: str
    source: str
    frame_names: tuple[str, ...]
    frames: np.ndarray
    before: ErrorStats
    after: ErrorStats
    orientation_after_deg: float | None = None  # mean orientation error (pose kind)


@dataclass(frozen=True)
class MultiSetResult:
    """Everything a calibration from several sets produced (values SI, reports mm/deg).

    names / parameters: every parameter (kinematic, each set's frames, backlash);
    x_nominal / x_start / x: nominal, start (fitted frames) and identified vectors; sets:
    one :class:`SetReport` per set; the rest as :class:`CalibrationResult`.
    """

    robot: Robot
    corrected: Robot
    options: CalibrationOptions
    names: tuple[str, ...]
    parameters: tuple[ParameterEstimate, ...]
    x_nominal: np.ndarray
    x_start: np.ndarray
    x: np.ndarray
    lam: float
    cv: CrossValidation | None
    sets: tuple[SetReport, ...]
    solve: SolveSummary
    identifiability: Identifiability
    error_model: ErrorModel
    backlash_joints: tuple[str, ...]
    evidence: object | None = None  # the evidence fit (lambda "evidence"), or None
    penalty_choice: str = ""  # with lambda "auto": which estimator ran, and why

    @classmethod
    def _build(cls, problem: "MultiSetProblem", sol, lam, cv, ident, evidence=None,
               penalty_choice: str = ""):
        x = sol.u * problem.scale
        free = problem.free_mask()
        se = _std_errors(sol, free, ~problem.is_frame, lam, problem.scale)
        if isinstance(se, tuple):  # newer result.py also returns the covariance
            se = se[0]
        x_start = problem.start()
        x_nom = problem.x_nominal
        x_nom[problem.is_frame] = x_start[problem.is_frame]
        fixed = set(ident.fixed)
        rows = tuple(ParameterEstimate(n, bool(problem.is_length[i]), float(x_nom[i]),
                                       float(x[i]), float(se[i]),
                                       "identified" if free[i] else
                                       ("fixed" if n in fixed else "dropped"))
                     for i, n in enumerate(problem.names))
        kin = x[:problem.n_kinematic]
        corrected = problem.robot.with_joint_frames(problem.error_model.joint_frames(kin))
        before = dict(problem.sample_errors(x_start))
        after = dict(problem.sample_errors(x))
        reports = []
        for i, km in enumerate(problem.kinds):
            ori = None
            if km.kind == "pose":
                r = km.residuals(*problem.split(x, i))
                ori = float(np.mean(km.orientation_errors(r)) * 180.0 / math.pi)
            reports.append(SetReport(km.kind, km.data.source, tuple(km.frame_names),
                                     x[problem.frame_slices[i]].copy(),
                                     ErrorStats.from_errors(before[i]),
                                     ErrorStats.from_errors(after[i]), ori))
        return cls(problem.robot, corrected, problem.options, problem.names, rows, x_nom,
                   x_start, x, float(lam) if evidence is None else math.nan, cv,
                   tuple(reports), sol, ident, problem.error_model, problem.backlash,
                   evidence, penalty_choice)

    @property
    def converged(self) -> bool:
        return self.solve.converged

    @property
    def kinematic(self) -> np.ndarray:
        return self.x[:self.error_model.size].copy()

    @property
    def backlash(self) -> np.ndarray:
        return self.x[len(self.x) - len(self.backlash_joints):].copy()

    def parameter(self, name: str) -> ParameterEstimate:
        return self.parameters[self.names.index(name)]

    def errors(self, data, set_index: int = 0, kinematic: np.ndarray | None = None):
        """(N,) sample errors [m] of other data of set ``set_index``'s kind, with the
        identified kinematics (or ``kinematic``) and that set's identified frames."""
        from kincal.measurements.sets import kind_model

        km = kind_model(self.error_model, data, tuple(
            self.error_model.joint_names.index(j) for j in self.backlash_joints))
        if km.kind != self.sets[set_index].kind or km.n_frames != len(self.sets[set_index].frames):
            raise ValueError(f"set {set_index + 1} is a {self.sets[set_index].kind} set with "
                             f"{len(self.sets[set_index].frames)} frame parameters; the data "
                             f"are {km.kind} with {km.n_frames}")
        kin = self.kinematic if kinematic is None else kinematic
        b = self.backlash if kinematic is None else np.zeros(len(self.backlash_joints))
        return km.sample_errors(km.residuals(kin, self.sets[set_index].frames, b))

    def corrected_urdf_text(self, readable: bool = True) -> str:
        from kincal.export.readable_export import corrected_text

        return corrected_text(self.robot, self.corrected, readable,
                              source=str(self.robot.source))[0].text

    def export_urdf(self, path, overwrite: bool = False):
        """Write the corrected URDF (only chain joint origins differ from the input)."""
        from kincal.export.safe_write import write_text_atomic

        protect = (self.robot.source,) if self.robot.source is not None else ()
        return write_text_atomic(path, self.corrected_urdf_text(), overwrite=overwrite,
                                 protect=protect)

    def frames_dict(self) -> dict:
        """Each set's frame parameters by name [m, rad], and the backlash values."""
        out = {"sets": [{"kind": s.kind, "source": s.source,
                         "frames": dict(zip(s.frame_names, map(float, s.frames)))}
                        for s in self.sets]}
        if self.backlash_joints:
            out["backlash"] = dict(zip(self.backlash_joints, map(float, self.backlash)))
        return out

    def summary(self) -> str:
        o = self.options
        if self.evidence is not None:
            lam = f", priors toward nominal per class by maximum evidence: {self.evidence.line()}"
        else:
            lam = (f", lambda = {self.lam:.4g}" + (" (chosen by cross-validation)" if self.cv
                                                    else "")) if o.method == "l2" else ""
        lines = [f"kincal calibration of {self.robot.name} ({self.robot.base} -> "
                 f"{self.robot.tip}), {len(self.sets)} measurement set(s), method "
                 f"{o.method}{lam}",
                 *([f"  penalty: {self.penalty_choice}"] if self.penalty_choice else []),
                 "  " + self.identifiability.summary().replace("\n", "\n  ")]
        for k, s in enumerate(self.sets, start=1):
            what = {"point": "position", "pose": "position", "distance": "distance",
                    "plane": "distance to the plane"}[s.kind]
            lines.append(f"  set {k}: {s.kind} ({s.source}), {what} errors")
            lines.append(f"    before: {s.before.line()}")
            lines.append(f"    after:  {s.after.line()}")
            if s.orientation_after_deg is not None:
                lines.append(f"    orientation after: mean {s.orientation_after_deg:.4f} deg")
        status = "converged" if self.converged else "NOT CONVERGED"
        lines.append(f"  solver: {self.solve.iterations} iterations, {status}")
        lines.append(f"  {'parameter':24s}{'nominal':>12s}{'deviation':>14s}{'std.err':>11s}"
                     "  unit")
        for p in self.parameters:
            if p.status != "identified":
                continue
            nom, dev, se, unit = p.reported()
            lines.append(f"  {p.name:24s}{nom:12.4f}{dev:+14.5f}{se:11.5f}  {unit}")
        return "\n".join(lines)
