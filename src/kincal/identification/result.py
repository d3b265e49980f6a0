"""The outcome of a calibration: parameters, per-set frames and errors, covariance, history,
the penalty's choice and the plausibility verdict. It writes no files (:mod:`kincal.export`
does, through its one writer)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kincal.frames_file import CellFrames, SetFrames, chain_hash
from kincal.identification.cross_validation import CrossValidation
from kincal.identification.evidence import EvidenceFit
from kincal.identification.layout import ParameterLayout
from kincal.identification.options import CalibrationOptions
from kincal.identification.plausibility import Plausibility
from kincal.identification.robust import Downweighted
from kincal.identification.selection import Identifiability
from kincal.identification.solver import SolveSummary
from kincal.identification.statistics import AngleStats, ErrorStats, angle_stats
from kincal.models.base import ErrorModel
from kincal.robot import Robot

if TYPE_CHECKING:
    from kincal.identification.chains import Chains, UnionModel
    from kincal.identification.model_choice import ModelChoice
    from kincal.identification.problem import CalibrationProblem
    from kincal.identification.term_evidence import TermEvidence
    from kincal.measurements.data import Measurements
    from kincal.measurements.kind import SampleSet

@dataclass(frozen=True)
class ParameterEstimate:
    """One row of the parameter table (SI units; ``deviation = estimate - nominal``).

    status: "identified", "dropped" (redundant on these data), "fixed" (by the user).
    is_length: True for lengths [m], False for angles [rad]. std_error: NaN unless identified.
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
        if self.name.endswith(".compliance"):
            unit += "/(N m)"  # [rad/(N m)] reported in deg/(N m)
        return self.nominal * k, self.deviation * k, self.std_error * k, unit


@dataclass(frozen=True)
class SetResult:
    """One measurement set in a result.

    kind / source: the set's kind and file. data: the set (joint columns in chain order).
    frame_names: the kind's frame names (unprefixed); frames: their identified values [SI].
    residuals / residuals_before: (N, dim) measured minus predicted [m] after calibration and
    at the start (orientation rows of poses in metres through their sigma ratio).
    errors_before / errors_after: (N,) each sample's error [m] (position, distance, distance
    to the plane; poses: the position's, their orientation is apart); before / after: their
    statistics [mm]. orientation_before / orientation_after: statistics [deg] of each
    sample's orientation error (poses: the angle of the rotation between measured and
    predicted; flush contacts: the tilt against the plane), None for other kinds;
    orientation_after_deg: the mean of orientation_after [deg]. angle_rows_before /
    angle_rows_after: (N, k) each sample's orientation error as angles [rad] (poses: the
    rotation vector; flush: roll and pitch; :meth:`KindModel.angle_rows`), None for other
    kinds; :attr:`angles_before` / :attr:`angles_after` their norms.
    base_frame / tip_frame: the chain the set was measured on.
    """

    kind: str
    source: str
    data: Measurements | SampleSet
    frame_names: tuple[str, ...]
    frames: np.ndarray
    residuals: np.ndarray
    residuals_before: np.ndarray
    errors_before: np.ndarray
    errors_after: np.ndarray
    before: ErrorStats
    after: ErrorStats
    orientation_after_deg: float | None = None
    base_frame: str = ""
    tip_frame: str = ""
    orientation_before: AngleStats | None = None
    orientation_after: AngleStats | None = None
    angle_rows_before: np.ndarray | None = None
    angle_rows_after: np.ndarray | None = None

    @property
    def angles_before(self) -> np.ndarray | None:
        """(N,) each sample's orientation error at the start [rad], None without one."""
        return None if self.angle_rows_before is None else np.linalg.norm(
            self.angle_rows_before, axis=1)

    @property
    def angles_after(self) -> np.ndarray | None:
        """(N,) each sample's orientation error after calibration [rad], None without one."""
        return None if self.angle_rows_after is None else np.linalg.norm(
            self.angle_rows_after, axis=1)

    @property
    def rows(self) -> np.ndarray:
        """(N,) line numbers of the samples in their file."""
        return np.asarray(self.data.rows)

    def frame(self, name: str) -> float:
        return float(self.frames[self.frame_names.index(name)])


def _std_errors(sol: SolveSummary, free: np.ndarray, penalised: np.ndarray, lam,
                scale: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Sandwich standard errors [SI] of the free parameters (NaN for the others), and their
    (p, p) covariance [SI] (zero rows and columns for the parameters held fixed), or None
    when it cannot be estimated. lam: one weight, or (p,) weights per parameter."""
    JtJ = sol.normal_matrix(free)
    if np.ndim(lam) == 2:  # a fleet prior's penalty matrix
        H = JtJ + np.asarray(lam)[np.ix_(free, free)]
    else:  # lam times the mask: the products of lam broadcast to it
        H = JtJ + np.diag((np.asarray(lam, dtype=float) * penalised)[free])
    out = np.full(scale.size, np.nan)
    try:
        Hi = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return out, None
    dof = float((Hi @ JtJ).trace())  # effective number of parameters, trace of the hat matrix
    m = sol.residual.shape[0]
    if m - dof <= 0.5:
        return out, None
    s2 = float(sol.residual @ sol.residual) / (m - dof)
    cov = s2 * Hi @ JtJ @ Hi
    out[free] = np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale[free]
    # cov is of u = x / scale (the solver's variables): the SI one is S cov S, S = diag(scale)
    full = np.zeros((scale.size, scale.size))
    s = scale[free]
    full[np.ix_(free, free)] = cov * (s[:, None] * s)  # np.outer's products
    full.flags.writeable = False
    return out, full


@dataclass(frozen=True)
class CalibrationResult:
    """Everything a calibration produced. Values in SI; reports in mm and degrees.

    robot: the nominal robot; corrected: the robot with identified joint placements.
    layout: the parameter layout (names, units, slices; also ``space``). parameters: one
    ParameterEstimate per parameter. x_nominal / x_start / x: parameter vectors (nominal,
    with the frames at their start; start: nominal kinematics with fitted frames;
    identified). lam: the penalty weight (0 for LS; NaN with evidence priors, whose weights
    differ per class). cv: the CV curve or None. evidence: the evidence fit or None.
    sets: one :class:`SetResult` per measurement set. solve: the final solve's summary.
    covariance: (p, p) read-only sandwich covariance [SI] (zero rows for parameters not
    identified), or None. plausibility: the gate's verdict (solve() always sets it).
    chains: the chains of the sets (:class:`kincal.identification.chains.Chains`): robot and
    corrected are the first set's chain; with several chains, corrected carries every
    corrected URDF origin and error_model is the union's names (no kinematics of its own).
    model_choice: with model "auto", the structures compared and the one chosen
    (:class:`kincal.identification.model_choice.ModelChoice`), else None. term_evidence:
    a compliance term the evidence favours over the fit (reported, not fitted:
    :class:`kincal.identification.term_evidence.TermEvidence`), else None.
    """

    robot: Robot
    corrected: Robot
    options: CalibrationOptions
    layout: ParameterLayout
    parameters: tuple[ParameterEstimate, ...]
    x_nominal: np.ndarray
    x_start: np.ndarray
    x: np.ndarray
    lam: float
    cv: CrossValidation | None
    sets: tuple[SetResult, ...]
    solve: SolveSummary
    identifiability: Identifiability
    error_model: ErrorModel | UnionModel  # several chains: the union of their models
    downweighted: tuple[Downweighted, ...] = ()
    covariance: np.ndarray | None = None
    evidence: EvidenceFit | None = None
    penalty_choice: str = ""
    plausibility: Plausibility | None = None
    chains: Chains | None = None
    model_choice: ModelChoice | None = None
    term_evidence: TermEvidence | None = None

    @classmethod
    def build(cls, problem: CalibrationProblem, sol: SolveSummary, lam, cv, ident,
              evidence: EvidenceFit | None = None, penalty_choice: str = "",
              downweighted=()) -> "CalibrationResult":
        lay = problem.layout
        x_start = problem.start()
        x = lay.wrap_frame_angles(sol.u * problem.scale, near=x_start)  # turns: the same frames
        free = problem.free_mask()
        se, covariance = _std_errors(sol, free, lay.is_penalised, lam if problem.prior is None
                                     else problem.prior.penalty(lam), problem.scale)
        fixed = set(ident.fixed)
        x_nom = problem.x_nominal
        x_nom[lay.is_frame] = x_start[lay.is_frame]  # frames have no nominal: their start
        # Python numbers first (the same values as float() of each element): 45 rows of
        # numpy scalar reads were a tenth of the result's cost
        rows = tuple(ParameterEstimate(n, length, nominal, value, error, "identified" if f else
                                       ("fixed" if n in fixed else "dropped"))
                     for n, length, nominal, value, error, f in zip(
                         lay.names, lay.is_length.tolist(), x_nom.tolist(), x.tolist(),
                         se.tolist(), free.tolist()))
        corrected = problem.chains.corrected(lay.kinematic(x))
        sets = []
        for i, km in enumerate(problem.kinds):
            r = problem.residuals(x, i)  # first: the fit's last evaluation was there
            r0 = problem.residuals(x_start, i)
            o0, o = angle_stats(km, r0), angle_stats(km, r)
            ori = None if o is None else o.mean
            e0, e = km.sample_errors(r0), km.sample_errors(r)  # points: the rows' norms,
            sets.append(SetResult(km.kind, km.data.source, km.data, tuple(km.frame_names),
                                  np.array(lay.frames(x, i)), r, r0, e0, e,  # as from_errors'
                                  ErrorStats.from_errors(e0), ErrorStats.from_errors(e), ori,
                                  problem.robots[i].base, problem.robots[i].tip, o0, o,
                                  km.angle_rows(r0), km.angle_rows(r)))
        return cls(problem.robot, corrected, problem.options, lay, rows, x_nom, x_start, x,
                   float(lam) if evidence is None else math.nan, cv, tuple(sets), sol, ident,
                   problem.error_model, tuple(downweighted), covariance, evidence,
                   penalty_choice, chains=problem.chains,
                   model_choice=getattr(problem, "model_choice", None))

    # ------------------------------------------------------------ accessors
    @property
    def space(self) -> ParameterLayout:
        return self.layout

    @property
    def names(self) -> tuple[str, ...]:
        return self.layout.names

    @property
    def converged(self) -> bool:
        return self.solve.converged

    def parameter(self, name: str) -> ParameterEstimate:
        return self.parameters[self.layout.index(name)]

    @property
    def kinematic(self) -> np.ndarray:
        """The identified error-model vector [SI]."""
        return self.layout.kinematic(self.x).copy()

    @property
    def backlash_joints(self) -> tuple[str, ...]:
        return self.layout.backlash

    @property
    def backlash(self) -> dict[str, float]:
        """Half the play of each joint with a backlash term [rad, or m if prismatic]."""
        b = self.layout.backlash_values(self.x)[:self.layout.n_backlash]
        return dict(zip(self.layout.backlash, map(float, b)))

    @property
    def compliance(self) -> dict[str, float]:
        """Each compliance term: the joint's deflection per N m of gravity torque
        [rad/(N m)], revolute joints only (:mod:`kincal.models.compliance`)."""
        c = self.layout.backlash_values(self.x)[self.layout.n_backlash:]
        return dict(zip(self.layout.compliance, map(float, c)))

    def _terms(self, joints) -> tuple[tuple[str, ...], tuple[str, ...], list[float]]:
        """(backlash joints, compliance joints, their values) of this result on ``joints``."""
        b = tuple(j for j in self.layout.backlash if j in joints)
        c = tuple(j for j in self.layout.compliance if j in joints)
        return b, c, [self.backlash[j] for j in b] + [self.compliance[j] for j in c]

    def torques(self, joint_values, set_index: int = 0) -> np.ndarray | None:
        """(N, n) the gravity torques of set ``set_index``'s chain at ``joint_values`` [N m]
        (its nominal robot, as the fit used), or None without compliance terms."""
        if not self.layout.compliance:
            return None
        robot = self.chains.robots[set_index] if self.chains is not None else self.robot
        return robot.gravity_torques(np.atleast_2d(joint_values))

    @property
    def before(self) -> ErrorStats:
        """Sample errors [mm] of every set at the start (one set: that set's)."""
        if len(self.sets) == 1:
            return self.sets[0].before
        return ErrorStats.from_errors(np.concatenate([s.errors_before for s in self.sets]))

    @property
    def after(self) -> ErrorStats:
        """Sample errors [mm] of every set after calibration (one set: that set's)."""
        if len(self.sets) == 1:
            return self.sets[0].after
        return ErrorStats.from_errors(np.concatenate([s.errors_after for s in self.sets]))

    # ----------------------------------- the first set (what one-set callers read)
    @property
    def residuals(self) -> np.ndarray:
        """(N, dim) the first set's residuals after calibration [m]."""
        return self.sets[0].residuals

    @property
    def residuals_before(self) -> np.ndarray:
        return self.sets[0].residuals_before

    @property
    def rows(self) -> np.ndarray:
        return self.sets[0].rows

    @property
    def points(self) -> np.ndarray | None:
        return getattr(self.sets[0].data, "points", None)

    @property
    def joint_values(self) -> np.ndarray:
        return self.sets[0].data.joint_values

    @property
    def approach(self) -> np.ndarray:
        approach = self.sets[0].data.approach
        assert approach is not None  # filled in by the data's __post_init__
        return approach

    @property
    def order_source(self) -> str:
        return getattr(self.sets[0].data, "order_source", "the order of the rows")

    def _located(self) -> int:
        """Index of the first set with a measurement frame and tool point (points, poses)."""
        for i, s in enumerate(self.sets):
            if "base.x" in s.frame_names and "tool.x" in s.frame_names:
                return i
        raise AttributeError("no measurement set of this calibration has a measurement frame "
                             "and tool point (points or poses)")

    @property
    def base(self) -> np.ndarray:
        """(6,) measurement frame of the first point or pose set: x, y, z [m], rx, ry, rz
        [rad]."""
        s = self.sets[self._located()]
        k = s.frame_names.index("base.x")
        return s.frames[k:k + 6].copy()

    @property
    def tool(self) -> np.ndarray:
        """(3,) tool point (point 1) of the first point or pose set in the tip frame [m]."""
        return self.tools[0]

    @property
    def tools(self) -> np.ndarray:
        """(K, 3) every measured point of the first point or pose set in the tip frame [m]."""
        s = self.sets[self._located()]
        k = s.frame_names.index("tool.x")
        K = getattr(s.data, "n_points", 1) if s.kind == "point" else 1
        return s.frames[k:k + 3 * K].reshape(K, 3).copy()

    # ------------------------------------------------------------- frames
    def frames(self) -> CellFrames:
        """The cell's frames (what FRAMES.json holds, :mod:`kincal.frames_file`)."""
        return CellFrames(
            robot=self.robot.model_name, chain_hash=chain_hash(self.robot), base_frame=self.robot.base,
            tip_frame=self.robot.tip, joints=tuple(self.robot.joint_names),
            sets=tuple(SetFrames(s.kind, s.source, s.frame_names,
                                 tuple(float(v) for v in s.frames), s.base_frame or
                                 self.robot.base, s.tip_frame or self.robot.tip,
                                 tuple(s.data.joint_names),
                                 tuple(getattr(s.data, "fixed_joints", ())))
                       for s in self.sets),
            backlash=self.backlash, compliance=self.compliance)

    def frames_dict(self) -> dict:
        """The FRAMES.json content (:meth:`kincal.frames_file.CellFrames.as_dict`)."""
        return self.frames().as_dict()

    # ------------------------------------------------------------ prediction
    def predict(self, joint_values: np.ndarray, approach: np.ndarray | None = None,
                points=0) -> np.ndarray:
        """(N, 3) predicted positions in the measurement frame [m] of the first point or pose
        set's measured points. approach: (N, n) approach directions for the backlash terms
        (None: every joint in the middle of its play); points: which measured point
        (0 = point 1), one for all or (N,) per row. Compliance terms deflect the joints by
        the gravity torques at ``joint_values``."""
        from kincal.measurements.point import MeasurementModel

        q = np.atleast_2d(joint_values)
        g = np.zeros(q.shape) if approach is None else np.atleast_2d(approach)
        idx = np.broadcast_to(np.asarray(points, dtype=int), (len(q),))
        tools = self.tools
        em, kin = self.error_model, self.kinematic
        if self.chains is not None and self.chains.several:  # that set's chain
            em, k = self.chains.chain_of(self._located())
            kin = kin[k]
        assert isinstance(em, ErrorModel)  # a chain's model, not the union of several
        b, c, v = self._terms(em.joint_names)
        x = np.concatenate([kin, self.base, tools.ravel(), v])
        return MeasurementModel(em, q, g, b, idx, len(tools),
                                self.torques(q, self._located()) if c else None, c).predict(x)

    def predict_data(self, data) -> np.ndarray:
        """(N, 3) predictions for the samples of point data ``data`` (its poses, approach
        directions and measured points) [m]."""
        data = data.for_chain(self.robot.joint_names)
        return self.predict(data.joint_values, data.approach, data.points)

    def errors(self, data, set_index: int = 0, kinematic: np.ndarray | None = None):
        """(N,) sample errors [m] of other data of set ``set_index``'s kind, with the
        identified kinematics (or ``kinematic``, then without joint terms) and that set's
        identified frames."""
        from kincal.measurements.sets import kind_model

        s = self.sets[set_index]
        em, idx = ((self.error_model, slice(None)) if self.chains is None
                   else self.chains.chain_of(set_index))
        joints = tuple(em.joint_names)
        b_joints, c_joints, v = self._terms(joints)
        torque = (self.torques(data.for_chain(joints).joint_values, set_index)
                  if c_joints else None)
        km = kind_model(em, data, tuple(joints.index(j) for j in b_joints),
                        tuple(joints.index(j) for j in c_joints), torque)
        if km.kind != s.kind or tuple(km.frame_names) != s.frame_names:
            raise ValueError(f"set {set_index + 1} is a {s.kind} set with frames "
                             f"{', '.join(s.frame_names)}; the data are {km.kind} with "
                             f"{', '.join(km.frame_names)}")
        kin = (self.kinematic if kinematic is None else np.asarray(kinematic))[idx]
        b = np.array(v) if kinematic is None else np.zeros(len(v))
        return km.sample_errors(km.residuals(kin, s.frames, b))

    # --------------------------------------------------------------- summary
    def chains_text(self) -> str:
        """"base -> tip" of every chain, in set order (the titles of every report)."""
        return ", ".join(dict.fromkeys(f"{s.base_frame} -> {s.tip_frame}" for s in self.sets
                                       if s.base_frame)) or f"{self.robot.base} -> {self.robot.tip}"

    def summary(self) -> str:
        from kincal.identification.result_text import summary

        return summary(self)
