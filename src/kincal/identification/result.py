"""The outcome of a calibration: parameter table, frames, statistics, predictions, export."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import KincalWarning
from kincal.identification.cross_validation import (
    CrossValidation,
)
from kincal.identification.evidence import EvidenceFit
from kincal.identification.options import CalibrationOptions
from kincal.identification.parameters import ParameterSpace
from kincal.identification.plausibility import Plausibility
from kincal.identification.robust import Downweighted
from kincal.identification.selection import Identifiability
from kincal.identification.solver import SolveSummary
from kincal.identification.statistics import ErrorStats
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.models.base import ErrorModel
from kincal.models.backlash import CONVENTION as BACKLASH_CONVENTION
from kincal.robot import Robot
from kincal.rotations import base_rotation

if TYPE_CHECKING:
    from kincal.identification.calibration import CalibrationProblem


@dataclass(frozen=True)
class ParameterEstimate:
    """One row of the parameter table (SI units; ``deviation = estimate - nominal``).

    status: "identified", "dropped" (redundant on these data), "fixed" (by the user).
    is_length: True for lengths [m], False for angles [rad].
    std_error: NaN unless identified.
    """

    name: str
    is_length: bool
    nominal: float
    estimate: float
    std_error: float
    status: str

    @property
    def deviation(self) -> float:
        return self.estimate - self.nominal

    def reported(self) -> tuple[float, float, float, str]:
        """(nominal, deviation, std_error) in mm or deg, and the unit."""
        k, unit = (1e3, "mm") if self.is_length else (180.0 / math.pi, "deg")
        return self.nominal * k, self.deviation * k, self.std_error * k, unit



def _std_errors(sol: SolveSummary, free: np.ndarray, penalised: np.ndarray, lam,
                scale: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Sandwich standard errors [SI] of the free parameters (NaN for the others), and their
    (p, p) covariance [SI] (zero rows and columns for the parameters held fixed), or None
    when it cannot be estimated.

    lam: one weight, or (p,) weights per parameter (evidence priors)."""
    J = sol.jacobian[:, free]
    H = J.T @ J + np.diag((np.broadcast_to(lam, penalised.shape) * penalised)[free])
    out = np.full(scale.size, np.nan)
    try:
        Hi = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return out, None
    JtJ = J.T @ J
    dof = float(np.trace(Hi @ JtJ))  # effective number of parameters, trace of the hat matrix
    m = J.shape[0]
    if m - dof <= 0.5:
        return out, None
    s2 = float(sol.residual @ sol.residual) / (m - dof)
    cov = s2 * Hi @ JtJ @ Hi
    out[free] = np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale[free]
    # cov is of u = x / scale (the solver's variables): the SI one is S cov S, S = diag(scale)
    full = np.zeros((scale.size, scale.size))
    full[np.ix_(free, free)] = cov * np.outer(scale[free], scale[free])
    full.flags.writeable = False
    return out, full


def frame_transforms(base: np.ndarray, tools: np.ndarray) -> dict:
    """The frames as 4x4 matrices and quaternions, for cells that take those.

    ``T_measurement_base``: pose of the base frame B in the measurement frame M (P_M =
    T P_B); ``T_tip_tool``, ``T_tip_tool_<k>``: the tool points as translations in the tip
    frame; ``pose_measurement_base``: the same as x, y, z [m] and a unit quaternion qx, qy,
    qz, qw (scalar last)."""
    from kincal.rotations import matrix_to_quaternion, transform

    T = transform(base_rotation(*base[3:]), base[:3])
    out = {"T_measurement_base": T.tolist(),
           "pose_measurement_base": dict(zip(("x", "y", "z", "qx", "qy", "qz", "qw"),
                                             [*map(float, base[:3]),
                                              *map(float, matrix_to_quaternion(T[:3, :3]))]))}
    for k, t in enumerate(np.atleast_2d(tools), start=1):
        out["T_tip_tool" + ("" if k == 1 else f"_{k}")] = transform(None, t).tolist()
    return out


@dataclass(frozen=True)
class CalibrationResult:
    """Everything a calibration produced. Values in SI; reports in mm and degrees.

    robot: the nominal robot; corrected: the robot with identified joint placements.
    parameters: one ParameterEstimate per parameter (kinematic, base, tool).
    x_nominal / x_start / x: parameter vectors (nominal; nominal kinematics with fitted
    frames; identified). lam: the penalty weight used (0 for LS; NaN with evidence
    priors, whose weights differ per class). cv: the CV curve or None. evidence: the
    prior scales and noise chosen by evidence (lam "evidence"), or None. before / after: position errors on the calibration data [mm] with the start
    and the identified parameters. residuals: (N, 3) after calibration [m].
    solve: the final solve's summary (cost history, convergence).
    """

    robot: Robot
    corrected: Robot
    options: CalibrationOptions
    space: ParameterSpace
    parameters: tuple[ParameterEstimate, ...]
    x_nominal: np.ndarray
    x_start: np.ndarray
    x: np.ndarray
    lam: float
    cv: CrossValidation | None
    before: ErrorStats
    after: ErrorStats
    residuals: np.ndarray
    solve: SolveSummary
    identifiability: Identifiability
    error_model: ErrorModel
    rows: np.ndarray  # (N,) line numbers of the samples in their source file
    downweighted: tuple[Downweighted, ...] = ()  # samples a robust loss trusted less
    residuals_before: np.ndarray | None = None  # (N, 3) with the start parameters [m]
    order_source: str = ""  # how the samples' acquisition order was known (backlash terms)
    points: np.ndarray | None = None  # (N,) the measured point of each sample (0 = point 1)
    # (p, p) read-only sandwich covariance of the parameters [SI, in the order of
    # space.names]; rows and columns of the parameters not identified are zero (held at
    # their values). None when the data leave no degrees of freedom to estimate it.
    covariance: np.ndarray | None = None
    joint_values: np.ndarray | None = None  # (N, n) chain joint values of the samples [rad, m]
    approach: np.ndarray | None = None  # (N, n) approach directions of the samples (+1/-1/0)
    evidence: EvidenceFit | None = None
    penalty_choice: str = ""  # with lambda "auto": which estimator ran, and why
    plausibility: Plausibility | None = None  # the gate's verdict (identification.plausibility)

    @classmethod
    def _build(cls, problem: CalibrationProblem, sol: SolveSummary, lam, cv, ident,
               evidence: EvidenceFit | None = None):
        sp = problem.space
        x = sol.u * problem.scale
        free = problem.free_mask()
        se, covariance = _std_errors(sol, free, sp.is_penalised, lam, problem.scale)
        fixed = set(ident.fixed)
        x_nom = problem.x_nominal.copy()
        x_start = problem.start()
        # base and tool have no nominal: their "nominal" is the fitted starting value
        x_nom[sp.is_frame] = x_start[sp.is_frame]
        rows = []
        for i, name in enumerate(sp.names):
            status = "identified" if free[i] else ("fixed" if name in fixed else "dropped")
            rows.append(ParameterEstimate(name, bool(sp.is_length[i]), float(x_nom[i]),
                                          float(x[i]), float(se[i]), status))
        kin, _, _ = sp.split(x)
        corrected = problem.robot.with_joint_frames(problem.error_model.joint_frames(kin))
        res_before = problem.position_errors(x_start)
        res = problem.position_errors(x)
        return cls(problem.robot, corrected, problem.options, sp, tuple(rows), x_nom, x_start,
                   x, float(lam) if evidence is None else math.nan, cv, ErrorStats.from_errors(res_before),
                   ErrorStats.from_errors(res), res, sol, ident, problem.error_model,
                   np.asarray(problem.data.rows), residuals_before=res_before,
                   order_source=problem.data.order_source, points=problem.data.points,
                   covariance=covariance, joint_values=problem.data.joint_values,
                   approach=problem.data.approach, evidence=evidence)

    # ------------------------------------------------------------ accessors
    @property
    def converged(self) -> bool:
        return self.solve.converged

    def parameter(self, name: str) -> ParameterEstimate:
        return self.parameters[self.space.index(name)]

    @property
    def base(self) -> np.ndarray:
        """(6,) measurement frame: x, y, z [m], rx, ry, rz [rad]."""
        return self.space.split(self.x)[1].copy()

    @property
    def tool(self) -> np.ndarray:
        """(3,) tool point (point 1) in the tip frame [m]."""
        return self.space.split(self.x)[2].copy()

    @property
    def tools(self) -> np.ndarray:
        """(K, 3) every measured point in the tip frame [m]."""
        return self.space.tools(self.x).copy()

    @property
    def backlash(self) -> dict[str, float]:
        """Half the play of each joint with a backlash term [rad, or m if prismatic]."""
        return dict(zip(self.space.backlash, map(float, self.space.backlash_values(self.x))))

    def frames_dict(self) -> dict:
        """The FRAMES.json content: measurement frame and tool point (and backlash) in SI.

        Backlash is not a property of a URDF, so it travels with the frames: ``kincal
        evaluate --frames`` applies it."""
        b, t = self.base, self.tool
        out = {"base": dict(zip(("x", "y", "z", "rx", "ry", "rz"), map(float, b))),
               "tool": dict(zip(("x", "y", "z"), map(float, t))),
               "convention": "P_measured = R_base (p_tip + R_tip t_tool) + t_base, "
                             "R_base = rotx(rx) roty(ry) rotz(rz); metres and radians",
               "base_frame": self.robot.base, "tip_frame": self.robot.tip,
               "joints": list(self.robot.joint_names)}
        out.update(frame_transforms(b, self.tools))
        if self.space.n_points > 1:
            out["tool_points"] = [dict(zip(("x", "y", "z"), map(float, t))) for t in self.tools]
        if self.space.n_backlash:
            out["backlash"] = self.backlash
            out["backlash_convention"] = BACKLASH_CONVENTION
        return out

    def predict(self, joint_values: np.ndarray, approach: np.ndarray | None = None,
                points=0) -> np.ndarray:
        """(N, 3) predicted positions in the measurement frame [m] of measured points.

        approach: (N, n) approach directions for the backlash terms (e.g. the
        ``approach`` of a Measurements); None: every joint in the middle of its play.
        points: which measured point (0 = point 1), one for all or (N,) per row.
        """
        q = np.atleast_2d(joint_values)
        g = np.zeros(q.shape) if approach is None else np.atleast_2d(approach)
        idx = np.broadcast_to(np.asarray(points, dtype=int), (len(q),))
        return MeasurementModel(self.error_model, q, g, self.space.backlash, idx,
                                self.space.n_points).predict(self.x)

    def predict_data(self, data: Measurements) -> np.ndarray:
        """(N, 3) predictions for the samples of ``data``: its poses, approach directions
        and measured points [m]."""
        data = data.for_chain(self.robot.joint_names)
        return self.predict(data.joint_values, data.approach, data.points)

    def corrected_urdf_text(self, readable: bool = True) -> str:
        """The corrected URDF; see :mod:`kincal.readable_export` for ``readable``."""
        return self.export_edits(readable)[0].text

    def export_edits(self, readable: bool = True):
        """(EditResult, joint offsets moved to child origins) of the corrected URDF."""
        from kincal.export.readable_export import corrected_text

        return corrected_text(self.robot, self.corrected, readable, source=str(self.robot.source))

    def urdf_with_frames(self, text: str) -> str:
        """``text`` plus fixed frames: ``kincal_measurement_frame`` (child of the base link,
        the pose of the measurement frame M in the base frame) and ``kincal_tool_point``
        (child of the tip link, at the tool point; ``kincal_tool_point_<k>`` for point k >= 2
        when several are measured)."""
        from kincal.export.urdf_export import add_fixed_frame
        from kincal.rotations import inverse, transform

        base_link, T_bl = self.robot.link_of(self.robot.base)
        tip_link, T_tl = self.robot.link_of(self.robot.tip)
        b = self.base
        T_MB = transform(base_rotation(*b[3:]), b[:3])  # base frame expressed in M
        text = add_fixed_frame(text, base_link, "kincal_measurement_frame",
                               "kincal_measurement_frame_joint", T_bl @ inverse(T_MB))
        for k, t in enumerate(self.tools, start=1):
            name = "kincal_tool_point" + ("" if k == 1 else f"_{k}")
            text = add_fixed_frame(text, tip_link, name, name + "_joint", T_tl @ transform(None, t))
        return text

    def export_urdf(self, path, overwrite: bool = False, accept_implausible: bool = False,
                    accept_unconverged: bool = False):
        """Write the corrected URDF (only chain joint origins differ from the input).

        An implausible result (see ``plausibility``) raises ImplausibleResultError, an
        unconverged one NotConvergedError, and nothing is written, unless accepted."""
        from kincal.export.safe_write import write_text_atomic

        if self.plausibility is not None:
            for message in self.plausibility.check(accept_implausible, accept_unconverged):
                warnings.warn(message, KincalWarning)
        protect = (self.robot.source,) if self.robot.source is not None else ()
        return write_text_atomic(path, self.corrected_urdf_text(), overwrite=overwrite,
                                 protect=protect)

    def summary(self) -> str:
        ev = self.evidence
        lines = [f"kincal calibration of {self.robot.name} ({self.robot.base} -> {self.robot.tip}), "
                 f"method {self.options.method}, "
                 + (f"lambda = {self.lam:.4g}" if ev is None else "priors toward nominal per "
                    "class, " + ("given" if ev.given.all() and ev.noise_given
                                 else "chosen by maximum evidence"))
                 + (" (chosen by cross-validation)" if self.cv is not None else "")
                 + (" on a random {} of the {} poses".format(*self.cv.subsample)
                    if self.cv is not None and self.cv.subsample else ""),
                 *([f"  penalty: {self.penalty_choice}"] if self.penalty_choice else []),
                 *([f"  {ev.line()}"
                    + ("" if ev.converged else f" [NOT SETTLED in {ev.iterations} rounds]")]
                   if ev is not None else []),
                 f"  {self.identifiability.summary().splitlines()[0]}",
                 *([f"  {self.space.n_points} measured points per pose: statistics are over "
                    "every point"] if self.space.n_points > 1 else []),
                 f"  before: {self.before.line()}",
                 f"  after:  {self.after.line()}",
                 f"  solver: {self.solve.iterations} iterations, {self.solve.reason}"
                 + ("" if self.converged else "  [NOT CONVERGED]"),
                 *(["  plausibility gate: IMPLAUSIBLE (" + ", ".join(
                     f.kind for f in self.plausibility.findings if f.kind != "not_converged")
                    + "); result.plausibility has the evidence"]
                   if self.plausibility is not None and not self.plausibility.plausible else []),
                 *([f"  robust loss {self.options.robust}: {len(self.downweighted)} samples "
                    "down-weighted below 0.5: " + ", ".join(
                        f"line {d.row} ({d.error_mm:.3g} mm, weight {d.weight:.2f})"
                        for d in self.downweighted[:10])
                    + (" ..." if len(self.downweighted) > 10 else "")]
                   if self.options.robust else []),
                 *([f"  backlash terms ({', '.join(self.space.backlash)}): approach directions "
                    f"from {self.order_source}; the URDF models the middle of the play"]
                   if self.space.n_backlash else []),
                 "  parameter                 nominal      deviation    std.err  unit"]

        def z(v):  # no "-0.0000" for values that are zero to the digits shown
            return 0.0 if abs(v) < 5e-6 else v

        frames = []
        for p, is_frame in zip(self.parameters, self.space.is_frame):
            nom, dev, se, unit = p.reported()
            flag = "" if p.status == "identified" else f"  ({p.status})"
            if is_frame:
                frames.append(f"  {p.name:<24} {z(nom + dev):>14.4f} {z(se):>10.5f}  {unit}{flag}")
            elif p.status != "dropped":
                lines.append(f"  {p.name:<24} {z(nom):>10.4f} {z(dev):>+13.5f} {z(se):>10.5f}  "
                             f"{unit}{flag}")
        lines.append("  measurement frame and tool point   estimate    std.err  unit")
        return "\n".join(lines + frames)
