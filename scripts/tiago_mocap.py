#!/usr/bin/env python
"""TIAGo arm on real motion-capture data: kincal against FIGAROH's published numbers.

    python scripts/tiago_mocap.py              # the whole study (a few minutes on two cores)
    python scripts/tiago_mocap.py --quick      # one CV repetition, no stepwise selection
    python scripts/tiago_mocap.py --nested     # also the nested CV of the stepwise selection
    python scripts/tiago_mocap.py --shared /path/to/shared

Data: ../shared/data/tiago_mocap (read at run time, never copied into the repository; see
its README). Chain URDF root -> wrist_ft_tool_link (torso_lift_joint + arm_1..arm_7),
marker 1 (x1, y1, z1) as the measured point, the mocap frame an unknown rigid transform.

Protocol. Every model is fitted on the training day (2021-11-30, 37 postures) only. The
held-out day (2021-11-26, 62 postures) is predicted with the calibrated kinematics AND the
measurement frame and marker point identified on the training day (the mocap frame and the
marker are the same on both days). Every setting (lambda, model variant, extension, robust
loss, stepwise selection) is chosen by cross-validation on the training day; the criterion
is the one kincal uses for lambda: the mean Euclidean validation error of marker 1, pooled
over repeated 5-fold splits. The held-out day is used for reporting only. For information,
the held-out RMS with frames re-fitted on the held-out day is also given.

Models. Every row is fitted by this script's ExtendedProblem, built on kincal's
MeasurementModel, solver, selection and CV; the rows kincal itself offers (frames, offsets,
MD-H LS and L2 + CV, with or without backlash terms) are also fitted through the kincal API
(CalibrationProblem) and their held-out predictions cross-checked. The extensions kincal
does not offer are prototyped here (see PROPOSALS at the end of this file's output):

- joint-space error terms: the joint angle the kinematics see is q + sum c * g(q), with
  backlash g = approach direction (+1 / -1: sign of the last motion of that joint before
  the posture, from the time order of the rows; kincal.backlash, a library option) and
  compliance g = gravity torque [N m] of the joint (Pinocchio, the URDF inertias;
  a library option too now: CalibrationOptions.compliance, `--compliance JOINT`);
- the hand pose from all four markers: the markers are one rigid body (spacing constant to
  0.01 mm), so the tool becomes a marker-body pose (marker 1 point + 3 rotation angles) and
  markers 2-4 add residuals with weight MARKER_WEIGHT relative to marker 1;
- a robust loss: Huber weights per posture by iteratively reweighted least squares;
- stepwise selection: greedy forward selection, by training CV, of MD-H parameters and
  joint-space terms on top of the joint-offset model.
"""

from __future__ import annotations

import os

# Problems here have ~50 columns: multi-threaded BLAS only adds contention (15x slower on
# two busy cores), so pin it to one thread before numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import csv  # noqa: E402
import io  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from tiago_files import DEFAULT_SHARED, HELD_OUT, ORDER_COLUMN, SUBDIR, TIP, TRAIN, URDF, locate  # noqa: E402

from kincal import CalibrationOptions, CalibrationProblem, KincalWarning, Measurements, Robot  # noqa: E402
from kincal.identification.cross_validation import cross_validate, lambda_grid, make_folds  # noqa: E402
from kincal.measurements.point_space import DEG, MM  # noqa: E402
from kincal.identification.selection import RANK_TOL, analyze  # noqa: E402
from kincal.identification.solver import SolverOptions, solve  # noqa: E402
from kincal.identification.statistics import ErrorStats  # noqa: E402
from kincal.measurements.point import MeasurementModel  # noqa: E402
from kincal.rotations import base_rotation, rotx, roty, rotz  # noqa: E402

MARKERS = tuple((f"x{i}", f"y{i}", f"z{i}") for i in range(1, 5))
MARKER_WEIGHT = 1.0  # markers 2-4 relative to marker 1: equal weight on all four points
FOLDS, CV_SEEDS = 5, (0, 1, 2)
LAMBDAS = lambda_grid(1e-6, 1e3, 50)  # kincal's default grid
COMPLIANCE_UNIT = DEG / 10.0  # [rad / (N m)] reporting and penalty unit: 1 deg per 10 N m
MIN_TORQUE = 2.0  # [N m] joints with less gravity torque are not screened for compliance
HUBER_FACTOR = 2.0  # Huber threshold = this x the median per-posture distance
OFFSET_JOINTS = tuple(f"arm_{i}_joint" for i in range(2, 7))  # identifiable offsets
WRIST = ("arm_5_joint", "arm_6_joint", "arm_7_joint")

# FIGAROH 1.0.2 on exactly these files, marker 1 (README of the data), errors in mm:
# (model, parameters, training RMS, held-out RMS, mean, max)
FIGAROH = (("FIGAROH: frames only", 9, 3.37, 4.87, 4.47, 12.20),
           ("FIGAROH: joint offsets + frames", 14, 2.88, 4.23, 3.85, 11.95),
           ("FIGAROH: full 6-D joint placement + frames", 30, 1.68, 3.22, 2.67, 12.23),
           ("FIGAROH: same, priors, CV scale", 57, 1.74, 3.33, 2.69, 11.66))


# ---------------------------------------------------------------------------- data
@dataclass(frozen=True)
class Session:
    """One day of measurements.

    markers: four Measurements (marker 1..4 as the measured point), same postures.
    q: (N, n) chain joint values [rad, m]. P: (4, N, 3) marker positions [m].
    gravity: (N, n) gravity torque of each chain joint [N m] (force [N] for the torso).
    approach: (N, n) sign of the last motion (> kincal.backlash.MOVE_TOL) of each joint
        before the posture, 0 before the first motion; rows must be in time order (checked).
    """

    name: str
    markers: tuple[Measurements, ...]
    q: np.ndarray
    P: np.ndarray
    gravity: np.ndarray
    approach: np.ndarray

    @property
    def N(self) -> int:
        return len(self.q)

    def regressor(self, term: "JointTerm") -> np.ndarray:
        """(N,) g of a joint term on these postures."""
        i = self.markers[0].joint_names.index(term.joint)
        return (self.approach if term.kind == "backlash" else self.gravity)[:, i]

    def subset(self, rows) -> "Session":
        rows = np.asarray(rows)
        return Session(self.name, tuple(m.subset(rows) for m in self.markers), self.q[rows],
                       self.P[:, rows], self.gravity[rows], self.approach[rows])


def gravity_torques(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(N, n) generalized gravity of the chain joints [N m or N]; other joints neutral.

    Pinocchio through the Robot's model: the one place the script reaches past the
    kincal API (proposal: Robot.gravity_torques).
    """
    import pinocchio as pin

    model = robot.model
    data = model.createData()
    idx = [model.joints[model.getJointId(j)].idx_v for j in robot.joint_names]
    return np.array([pin.computeGeneralizedGravity(model, data, robot.configuration(qk))[idx]
                     for qk in q])


def load_session(robot: Robot, path: Path) -> Session:
    prismatic = [n for n, k in zip(robot.joint_names, robot.geometry.kinds) if k == "prismatic"]
    markers = tuple(Measurements.from_csv(path, robot.joint_names, prismatic=prismatic,
                                          position_columns=c) for c in MARKERS)
    with open(path, newline="") as fh:
        t = np.array([float(r[ORDER_COLUMN]) for r in csv.DictReader(fh)])
    if np.any(np.diff(t) <= 0):
        sys.exit(f"{path}: rows are not in time order; approach directions need the sequence")
    q = markers[0].joint_values
    return Session(path.name, markers, q, np.stack([m.positions for m in markers]),
                   gravity_torques(robot, q), markers[0].approach)


def marker_body(P: np.ndarray) -> tuple[np.ndarray, float]:
    """(4, 3) marker coordinates in the marker body frame [m] and the rigidity [m].

    Body frame: origin marker 1, x toward marker 2, y in the plane of marker 4. The
    coordinates are the mean over the postures; rigidity is the largest deviation.
    """
    e1 = P[1] - P[0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    v = P[3] - P[0]
    e2 = v - np.sum(v * e1, axis=1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    B = np.stack([e1, e2, np.cross(e1, e2)], axis=2)  # (N, 3, 3) body axes in mocap
    local = np.einsum("nji,mnj->mni", B, P - P[0])  # (4, N, 3)
    return local.mean(axis=1), float(np.abs(local - local.mean(axis=1, keepdims=True)).max())


def body_rotations(P: np.ndarray) -> np.ndarray:
    e1 = P[1] - P[0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    v = P[3] - P[0]
    e2 = v - np.sum(v * e1, axis=1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=2)


# -------------------------------------------------------------------------- models
@dataclass(frozen=True)
class JointTerm:
    """A joint-space error: the joint angle seen by the kinematics gains c * g(posture).

    kind "backlash": g = approach direction (+-1); c = half the backlash [rad].
    kind "compliance": g = gravity torque [N m]; c [rad / (N m)].
    """

    joint: str
    kind: str

    @property
    def name(self) -> str:
        return f"{self.joint}.{self.kind}"


def backlash(*joints) -> tuple[JointTerm, ...]:
    return tuple(JointTerm(j, "backlash") for j in joints)


def compliance(*joints) -> tuple[JointTerm, ...]:
    return tuple(JointTerm(j, "compliance") for j in joints)


@dataclass(frozen=True)
class Model:
    """One row of the study.

    kinematics: "frames" (nominal), "offsets" (theta of each revolute joint, d of the
        prismatic one; those the frames absorb are dropped by the analysis) or "full"
        (all identifiable MD-H parameters).
    method: "ls" or "l2" (penalty toward nominal, lambda by 5-fold CV, kincal's grid).
    terms: joint-space error terms. markers: use all four markers (hand pose).
    loss: "l2" or "huber". stepwise: forward selection, by training CV, of MD-H
        parameters and of the candidate terms ``pool`` on top of ``kinematics``.
    api: also fitted through the kincal API (CalibrationProblem) as a cross-check.
    """

    label: str
    kinematics: str = "offsets"
    method: str = "ls"
    terms: tuple[JointTerm, ...] = ()
    markers: bool = False
    loss: str = "l2"
    stepwise: bool = False
    pool: tuple[JointTerm, ...] = ()
    api: bool = False


class ExtendedProblem:
    """kincal's identification problem plus joint-space terms and the marker-body pose.

    Parameter vector v (SI): [kincal x: 4n MD-H, base (6), tool point (3) | tool rotation
    (3, with markers) | one coefficient per term]. Marker m sits at t + R0 Rx Ry Rz g_m in
    the tip frame (g_1 = 0, so t is marker 1, as in kincal). Residuals in mm; the solver
    works in reporting units u = v / scale (mm, deg, deg per 10 N m).
    """

    def __init__(self, session: Session, model: Model, body: np.ndarray, robot: Robot,
                 terms: tuple[JointTerm, ...] | None = None):
        self.session, self.model, self.body = session, model, body
        self.terms = model.terms if terms is None else terms
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", KincalWarning)  # reported once, at load
            self.base = CalibrationProblem(robot, session.markers[0],
                                           CalibrationOptions(model="mdh", method="frames"))
        self.mdh, self.space = self.base.error_model, self.base.space
        self.n_kin, self.n_x = self.space.n_kinematic, self.space.size
        self.n_rot = 3 if model.markers else 0
        self.k_terms = self.n_x + self.n_rot
        self.size = self.k_terms + len(self.terms)
        self.names = (self.space.names + (("tool.rx", "tool.ry", "tool.rz") if model.markers
                                          else ()) + tuple(t.name for t in self.terms))
        is_length = np.concatenate([self.space.is_length, np.zeros(self.size - self.n_x, bool)])
        self.report_scale = np.where(is_length, MM, DEG)
        for k, t in enumerate(self.terms):
            if t.kind == "compliance":
                self.report_scale[self.k_terms + k] = COMPLIANCE_UNIT
        self.scale = self.report_scale  # penalty units = reporting units, as in kincal
        self.joint_index = [self.mdh.joint_names.index(t.joint) for t in self.terms]
        self.R0 = np.eye(3)
        self._start = None

    # ------------------------------------------------------------------ start
    def start(self) -> np.ndarray:
        """Nominal kinematics, frames (and marker-body rotation) fitted, terms zero."""
        if self._start is not None:
            return self._start
        x = self.base.start()
        v = np.zeros(self.size)
        v[: self.n_x] = x
        if self.model.markers:
            table, frames, _ = self.space.split(x, 0)
            base = frames[:6]  # the measurement frame (x y z rx ry rz) before the tool point
            R_tip, _ = MeasurementModel(self.mdh, self.session.q).tip_poses(table)
            Rb = base_rotation(*base[3:])
            # R0: the mean of R_tip^T Rb^T B_k projected on SO(3); later angles stay small
            M = np.einsum("nji,kj,nkl->il", R_tip, Rb, body_rotations(self.session.P))
            U, _, Vt = np.linalg.svd(M)
            self.R0 = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        self._start = v
        return v

    # --------------------------------------------------------------- residuals
    def joint_values(self, v: np.ndarray, session: Session) -> np.ndarray:
        q = session.q.copy()
        for k, (t, i) in enumerate(zip(self.terms, self.joint_index)):
            q[:, i] += v[self.k_terms + k] * session.regressor(t)
        return q

    def marker_points(self, v: np.ndarray) -> list[np.ndarray]:
        t = v[self.n_x - 3: self.n_x]
        if not self.model.markers:
            return [t]
        R = self.R0 @ base_rotation(*v[self.n_x: self.n_x + 3])
        return [t + R @ g for g in self.body]

    def predict(self, v: np.ndarray, session: Session) -> np.ndarray:
        """(N, 3) predicted marker-1 positions in the mocap frame [m]."""
        return MeasurementModel(self.mdh, self.joint_values(v, session)).predict(v[: self.n_x])

    def errors(self, v: np.ndarray, session: Session) -> np.ndarray:
        """(N,) marker-1 distance errors [mm]."""
        return np.linalg.norm(session.P[0] - self.predict(v, session), axis=1) / MM

    def residual_function(self, session: Session, pose_weights=None):
        """residual(u, with_jacobian) [mm] on ``session`` (kincal's solver interface)."""
        n_markers = 4 if self.model.markers else 1
        weights = [1.0] + [MARKER_WEIGHT] * 3
        w_pose = np.ones(session.N) if pose_weights is None else np.asarray(pose_weights)
        G = np.stack([session.regressor(t) for t in self.terms], axis=1) if self.terms else None
        theta_cols = [4 * i + (2 if self.mdh.kinds[i] == "prismatic" else 3)
                      for i in self.joint_index]
        s, N = self.scale, session.N

        def residual(u, with_jacobian):
            v = u * s
            mm = MeasurementModel(self.mdh, self.joint_values(v, session))
            points = self.marker_points(v)
            rs, Js = [], []
            for m in range(n_markers):
                x = v[: self.n_x].copy()
                x[self.n_x - 3:] = points[m]
                w = (weights[m] * w_pose)[:, None]
                if not with_jacobian:
                    rs.append(((session.P[m] - mm.predict(x)) * w).ravel() / MM)
                    continue
                pred, J = mm.jacobian(x)
                Je = np.zeros((N, 3, self.size))
                Je[:, :, : self.n_x] = J
                if self.model.markers:
                    # d/d(rx, ry, rz) of R0 Rx Ry Rz g_m, carried to the mocap frame by the
                    # tool-point columns (= R_base R_tip)
                    a = v[self.n_x: self.n_x + 3]
                    Rx, Ry, Rz = rotx(a[0]), roty(a[1]), rotz(a[2])
                    g = self.body[m]
                    ex, ey, ez = np.eye(3)
                    dR = (self.R0 @ np.cross(ex, Rx @ Ry @ Rz @ g),
                          self.R0 @ Rx @ np.cross(ey, Ry @ Rz @ g),
                          self.R0 @ Rx @ Ry @ np.cross(ez, Rz @ g))
                    for k in range(3):
                        Je[:, :, self.n_x + k] = J[:, :, self.n_x - 3:] @ dR[k]
                for k, c in enumerate(theta_cols):
                    # a joint-space term acts like the joint's own offset, scaled by g
                    Je[:, :, self.k_terms + k] = J[:, :, c] * G[:, k, None]
                rs.append(((session.P[m] - pred) * w).ravel() / MM)
                Js.append(-(Je * w[:, :, None]).reshape(-1, self.size) * (s / MM))
            return np.concatenate(rs), (np.vstack(Js) if with_jacobian else None)

        return residual

    # ----------------------------------------------------------------- analyse
    def candidates(self, kinematics: str) -> np.ndarray:
        free = np.zeros(self.size, dtype=bool)
        free[self.n_kin:] = True  # frames, marker-body rotation, terms
        if kinematics == "full":
            free[: self.n_kin] = True
        elif kinematics == "offsets":
            for i, kind in enumerate(self.mdh.kinds):
                free[4 * i + (2 if kind == "prismatic" else 3)] = True
        return free

    def analyze(self, kinematics: str | None = None):
        """kincal's ordered rank-revealing selection on the extended Jacobian."""
        _, J = self.residual_function(self.session)(self.start() / self.scale, True)
        # extra columns come after the MD-H block, so they are preferred like the frames
        return analyze(J * (self.report_scale / self.scale), self.names, self.n_kin,
                       self.candidates(kinematics or self.model.kinematics), RANK_TOL)

    def mask(self, names) -> np.ndarray:
        return np.isin(np.arange(self.size), [self.names.index(n) for n in names])

    # --------------------------------------------------------------------- fit
    def solve(self, free: np.ndarray, lam: float = 0.0, session: Session | None = None,
              u_start=None, pose_weights=None, options: SolverOptions = SolverOptions()):
        """kincal's LM solve; MD-H pulled toward nominal, terms toward 0, frames free."""
        prior = self.start() / self.scale
        pen = np.zeros(self.size, dtype=bool)
        pen[: self.n_kin] = True
        pen[self.k_terms:] = True
        u0 = prior if u_start is None else u_start
        return solve(self.residual_function(session or self.session, pose_weights), u0, free,
                     lam=lam, penalised=pen, prior=prior, options=options)


@dataclass(frozen=True)
class Fit:
    """A model fitted on the training day.

    v: parameters (SI). free: identified ones. lam: penalty weight. dof: effective number
    of parameters (trace of the hat matrix; = free.sum() without penalty). path: the
    stepwise selection (name, mean CV error [mm]) or ().
    """

    model: Model
    problem: ExtendedProblem
    v: np.ndarray
    free: np.ndarray
    lam: float
    dof: float
    path: tuple = ()
    weights: np.ndarray | None = None

    def errors(self, session: Session) -> np.ndarray:
        return self.problem.errors(self.v, session)

    def refit_frames(self, session: Session) -> np.ndarray:
        """Marker-1 errors [mm] on ``session`` with the frames re-fitted there (information)."""
        p = ExtendedProblem(session, self.model, self.problem.body, self.problem.base.robot,
                            self.problem.terms)
        p.start()
        p.R0 = self.problem.R0  # the marker-body angles in v are relative to this R0
        v = self.v.copy()
        frames = np.zeros(p.size, dtype=bool)
        frames[p.n_kin: p.k_terms] = True
        # start from the training frames: the mocap frame is the same on both days
        sol = p.solve(frames, u_start=v / p.scale)
        return p.errors(sol.u * p.scale, session)


class Study:
    """The training and held-out sessions and everything fitted on them."""

    def __init__(self, shared: Path, seeds=CV_SEEDS):
        d = shared / SUBDIR
        self.paths = {"urdf": d / URDF, "train": d / TRAIN, "held_out": d / HELD_OUT}
        self.robot = Robot.load(self.paths["urdf"], tip=TIP)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", KincalWarning)
            self.train = load_session(self.robot, self.paths["train"])
            self.held_out = load_session(self.robot, self.paths["held_out"])
            CalibrationProblem(self.robot, self.train.markers[0])
            CalibrationProblem(self.robot, self.held_out.markers[0])
        self.warnings = sorted({str(w.message) for w in caught})
        self.body, rigid = marker_body(self.train.P)
        self.rigidity = rigid
        self.seeds = tuple(seeds)

    def problem(self, model: Model, session: Session | None = None, terms=None):
        return ExtendedProblem(session or self.train, model, self.body, self.robot, terms)

    # ------------------------------------------------------------------ fitting
    def fit(self, model: Model, session: Session | None = None, free_names=None,
            terms=None) -> Fit:
        """Fit ``model`` on ``session`` (default: the training day).

        free_names: the identified set (default: kincal's analysis on these data).
        """
        session = session or self.train
        if model.stepwise and free_names is None:
            return self.stepwise(model, session)
        p = self.problem(model, session, terms)
        free = p.mask(free_names if free_names is not None else p.analyze().kept)
        lam = self.choose_lambda(p, free) if model.method == "l2" else 0.0
        sol = p.solve(free, lam)
        weights = None
        if model.loss == "huber":
            # IRLS: per-posture weight min(1, delta / e_k), delta = HUBER_FACTOR x median
            for _ in range(20):
                e = p.errors(sol.u * p.scale, session)
                w = np.sqrt(np.minimum(1.0, HUBER_FACTOR * np.median(e) / np.maximum(e, 1e-12)))
                if weights is not None and np.max(np.abs(w - weights)) < 1e-6:
                    break
                weights = w
                sol = p.solve(free, lam, u_start=sol.u, pose_weights=weights)
        J = sol.jacobian[:, free]
        pen = np.zeros(p.size, dtype=bool)
        pen[: p.n_kin] = pen[p.k_terms:] = True
        H = J.T @ J + lam * np.diag(pen[free].astype(float))
        dof = float(np.trace(np.linalg.solve(H, J.T @ J)))
        return Fit(model, p, sol.u * p.scale, free, lam, dof, weights=weights)

    def choose_lambda(self, p: ExtendedProblem, free: np.ndarray) -> float:
        """kincal's k-fold CV of lambda (same grid, folds, seed, criterion)."""
        fold_options = SolverOptions(step_tol=1e-6)  # kincal's cv_step_tol

        def fit(train, lam, start):
            sub = p.session.subset(train)
            return p.solve(free, lam, session=sub, options=fold_options,
                           u_start=None if start is None else start.u)

        def error(sol, val):
            return float(np.mean(p.errors(sol.u * p.scale, p.session.subset(val))))

        return cross_validate(fit, error, p.session.N, LAMBDAS, FOLDS, 0).best_lambda

    # ---------------------------------------------------------------- CV errors
    def cv_errors(self, model: Model, free_names=None, session: Session | None = None,
                  terms=None, seeds=None) -> np.ndarray:
        """Pooled validation errors [mm] of marker 1 over repeated k-fold splits.

        free_names: fixed identified set for every fold (default: the analysis on the
        whole session, as kincal's own CV does); a stepwise model with free_names None
        is selected afresh inside each fold (nested CV).
        """
        session = session or self.train
        if free_names is None and not model.stepwise:
            free_names = self.problem(model, session, terms).analyze().kept
        out = []
        for seed in (self.seeds if seeds is None else seeds):
            for val in make_folds(session.N, FOLDS, seed):
                train = np.setdiff1d(np.arange(session.N), val)
                f = self.fit(model, session.subset(train), free_names, terms)
                out.append(f.errors(session.subset(val)))
        return np.concatenate(out)

    def stepwise(self, model: Model, session: Session) -> Fit:
        """Greedy forward selection by mean CV error, from the ``kinematics`` set.

        Pool: the other identifiable MD-H parameters and the terms of ``model.pool``.
        Stops when no candidate lowers the pooled mean CV error.
        """
        terms = model.terms + model.pool
        p = self.problem(model, session, terms)
        full = p.analyze("full")
        current = set(p.analyze(model.kinematics).kept) - {t.name for t in model.pool}
        pool = [n for n in full.kept if n not in current]
        best = float(np.mean(self.cv_errors(model, tuple(current), session, terms)))
        path = [("start", best)]
        while pool:
            scores = [(float(np.mean(self.cv_errors(model, tuple(current | {c}), session, terms))),
                       c) for c in pool]
            score, choice = min(scores)
            if score >= best:
                break
            best = score
            current.add(choice)
            pool.remove(choice)
            path.append((choice, score))
        chosen = tuple(n for n in p.names if n in current)
        f = self.fit(Model(model.label, model.kinematics, model.method, model.terms, model.markers,
                           model.loss), session, chosen, terms)
        return Fit(model, f.problem, f.v, f.free, f.lam, f.dof, tuple(path), f.weights)


# ----------------------------------------------------------------------- the study
def models(quick: bool) -> list[Model]:
    pool = backlash(*(f"arm_{i}_joint" for i in range(1, 8))) + compliance(
        "arm_2_joint", "arm_3_joint", "arm_4_joint")
    rows = [
        Model("frames only", "frames", api=True),
        Model("joint offsets + frames", "offsets", api=True),
        Model("full MD-H, LS", "full", api=True),
        Model("full MD-H, L2 + CV", "full", "l2", api=True),
        Model("offsets + gravity compliance arm_2-4", terms=compliance(
            "arm_2_joint", "arm_3_joint", "arm_4_joint")),
        Model("offsets + hand pose (4 markers)", markers=True),
        Model("offsets, Huber loss", loss="huber"),
        Model("offsets + backlash arm_6", terms=backlash("arm_6_joint"), api=True),
        Model("offsets + backlash arm_5-7", terms=backlash(*WRIST), api=True),
        Model("offsets + backlash arm_5-7 + hand pose", terms=backlash(*WRIST), markers=True),
        Model("full MD-H, L2 + CV + backlash arm_6", "full", "l2", terms=backlash("arm_6_joint"),
              api=True),
        Model("full MD-H, L2 + CV + backlash arm_5-7", "full", "l2", terms=backlash(*WRIST),
              api=True),
    ]
    if not quick:
        rows.append(Model("stepwise from offsets (MD-H, backlash, compliance)", "offsets",
                          stepwise=True, pool=pool))
        rows.append(Model("stepwise from frames (MD-H, backlash, compliance)", "frames",
                          stepwise=True, pool=pool))
    return rows


@dataclass
class Row:
    model: Model
    fit: Fit
    train: ErrorStats
    held: ErrorStats
    held_refit: ErrorStats
    cv: np.ndarray
    cv_nested: bool
    seconds: float
    api_check: float | None = None

    @property
    def n_params(self) -> int:
        return int(self.fit.free.sum())


def plain_options(study: Study, model: Model) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """(kincal method, parameters to fix, backlash joints) of a row kincal offers."""
    if model.markers or model.loss != "l2" or any(t.kind != "backlash" for t in model.terms):
        raise ValueError(f"{model.label}: not a model the kincal API offers")
    joints = tuple(t.joint for t in model.terms)
    if model.kinematics == "frames":
        return "frames", (), joints
    fix = ()
    if model.kinematics == "offsets":
        # everything kinematic except theta (revolute) / d (prismatic) of each joint
        fix = tuple(f"{j}.{f}" for j, k in zip(study.robot.joint_names, study.robot.geometry.kinds)
                    for f in ("a", "alpha", "d", "theta")
                    if f != ("d" if k == "prismatic" else "theta"))
    return model.method, fix, joints


def api_fit(study: Study, model: Model):
    """The same model through the kincal API; returns the CalibrationResult."""
    method, fix, joints = plain_options(study, model)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)  # reported once, at load
        return CalibrationProblem(study.robot, study.train.markers[0], CalibrationOptions(model="mdh",
            method=method, lam="cv", fix=fix, backlash=joints)).solve()


def run_row(study: Study, model: Model, nested: bool) -> Row:
    t0 = time.perf_counter()
    fit = study.fit(model)
    if model.stepwise:
        if nested:
            cv, is_nested = study.cv_errors(model, seeds=(study.seeds[0],)), True
        else:  # the errors of the selected set on the folds that selected it: optimistic
            cv, is_nested = study.cv_errors(model, tuple(np.array(fit.problem.names)[fit.free]),
                                            terms=fit.problem.terms), False
    else:
        cv, is_nested = study.cv_errors(model), model.method == "l2"
    check = None
    if model.api:
        res = api_fit(study, model)
        pred = res.predict(study.held_out.q, study.held_out.approach)
        check = float(np.abs(pred - fit.problem.predict(fit.v, study.held_out)).max() / MM)
    ms = lambda e: ErrorStats.from_errors(np.asarray(e) * MM)  # noqa: E731
    return Row(model, fit, ms(fit.errors(study.train)), ms(fit.errors(study.held_out)),
               ms(fit.refit_frames(study.held_out)), cv, is_nested,
               time.perf_counter() - t0, check)


# -------------------------------------------------------------------- reporting
def table(rows: list[Row], selected: Row) -> str:
    lines = ["| model | params | training RMS | CV mean / RMS | held-out RMS / mean / max "
             "| held-out RMS, frames re-fitted |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        p = f"{r.n_params}" + (f" (eff. {r.fit.dof:.1f})" if r.fit.lam > 0 else "")
        cv = f"{r.cv.mean():.2f} / {np.sqrt(np.mean(r.cv ** 2)):.2f}"
        if r.model.stepwise:
            cv += " (nested, 1 rep.)" if r.cv_nested else " †"
        mark = " **(selected by CV)**" if r is selected else ""
        lines.append(f"| {r.model.label}{mark} | {p} | {r.train.rms:.2f} | {cv} | "
                     f"{r.held.rms:.2f} / {r.held.mean:.2f} / {r.held.max:.2f} | "
                     f"{r.held_refit.rms:.2f} |")
    for label, n, tr, rms, mean, mx in FIGAROH:
        lines.append(f"| {label} | {n} | {tr:.2f} | - | {rms:.2f} / {mean:.2f} / {mx:.2f} | - |")
    return "\n".join(lines)


def residual_analysis(study: Study, rows: list[Row]) -> str:
    """Why the MD-H model alone stalls: backlash screen and residuals by approach direction."""
    out = []
    offsets = Model("joint offsets + frames", "offsets")
    base_cv = study.cv_errors(offsets)
    out.append("Screen: joint offsets + frames plus ONE joint-space term (training CV, mm); "
               f"without: CV mean {base_cv.mean():.2f} / RMS {np.sqrt(np.mean(base_cv ** 2)):.2f}")
    out.append("| joint | + backlash: CV mean / RMS, half-backlash [deg] | "
               "+ compliance: CV mean / RMS, [deg per 10 N m] |")
    out.append("|---|---|---|")
    for i, j in enumerate(study.robot.joint_names[1:], start=1):
        cells = []
        for kind in ("backlash", "compliance"):
            m = Model(kind, "offsets", terms=(JointTerm(j, kind),))
            p = study.problem(m)
            kept = p.analyze().kept
            torque = np.abs(study.train.gravity[:, i]).max()
            if kind == "compliance" and torque < MIN_TORQUE:
                cells.append(f"gravity torque <= {torque:.1f} N m: not a compliance candidate")
                continue
            if f"{j}.{kind}" not in kept:
                cells.append("no effect (zero or constant regressor)")
                continue
            f = study.fit(m, free_names=kept)
            e = study.cv_errors(m, kept)
            c = f.v[-1] / p.scale[-1]
            cells.append(f"{e.mean():.2f} / {np.sqrt(np.mean(e ** 2)):.2f}, {c:+.2f}")
        out.append(f"| {j} | {cells[0]} | {cells[1]} |")
    # residual of the offsets model, as an angle error of each wrist joint, by direction
    out.append("")
    out.append("Residual of 'joint offsets + frames' (training fit) read as an angle error of one "
               "wrist joint (least squares per posture on that joint's Jacobian column), grouped "
               "by the joint's approach direction; mean +- std [deg] (n):")
    out.append("| joint | day | approached from below (+) | from above (-) |")
    out.append("|---|---|---|---|")
    f = study.fit(offsets)
    p = f.problem
    for j in WRIST:
        i = p.mdh.joint_names.index(j)
        for session in (study.train, study.held_out):
            pred, J = MeasurementModel(p.mdh, session.q).jacobian(f.v[: p.n_x])
            r = session.P[0] - pred
            col = J[:, :, 4 * i + 3]
            delta = np.degrees(np.sum(col * r, axis=1) / np.sum(col * col, axis=1))
            d = session.approach[:, i]
            cells = [f"{delta[d == s].mean():+.2f} +- {delta[d == s].std():.2f} ({(d == s).sum()})"
                     for s in (1, -1)]
            out.append(f"| {j} | {session.name[9:19]} | {cells[0]} | {cells[1]} |")
    # held-out errors versus the training range of the joints
    out.append("")
    lo, hi = study.train.q.min(0), study.train.q.max(0)
    outside = (study.held_out.q < lo - 1e-9) | (study.held_out.q > hi + 1e-9)
    n_out = outside.any(axis=1)
    out.append("Held-out postures outside the training range of some joint: "
               f"{int(n_out.sum())} of {study.held_out.N}. Held-out RMS [mm] inside / outside:")
    out.append("| model | inside | outside | worst posture (line): joints outside the training range |")
    out.append("|---|---|---|---|")
    for r in rows:
        e = r.fit.errors(study.held_out)
        k = int(np.argmax(e))
        names = [study.robot.joint_names[i].replace("_joint", "") + f" {study.held_out.q[k, i]:+.2f}"
                 for i in np.flatnonzero(outside[k])]
        out.append(f"| {r.model.label} | {np.sqrt(np.mean(e[~n_out] ** 2)):.2f} | "
                   f"{np.sqrt(np.mean(e[n_out] ** 2)):.2f} | {e[k]:.1f} mm (line {k + 2}): "
                   f"{', '.join(names) or 'none'} |")
    out.append("(training ranges [rad]: " + ", ".join(
        f"{j.replace('_joint', '')} [{a:+.2f}, {b:+.2f}]"
        for j, a, b in zip(study.robot.joint_names, lo, hi)) + ")")
    return "\n".join(out)


def parameters_of(row: Row, threshold: float = 0.0) -> str:
    f = row.fit
    x0 = f.problem.start()
    dev = (f.v - x0) / f.problem.report_scale
    units = ["mm" if MM == s else ("deg" if s == DEG else "deg/10Nm")
             for s in f.problem.report_scale]
    parts = []
    for i in np.flatnonzero(f.free):
        name = f.problem.names[i]
        if name.startswith(("base.", "tool.")):
            continue
        parts.append(f"{name} {dev[i]:+.2f} {units[i]}")
    return "; ".join(parts)


def cli_demo(study: Study, shared: Path, model: Model) -> str:
    """A model kincal offers through the CLI: calibrate, then evaluate with the training
    frames (and, without backlash terms, with frames re-fitted on the held-out day)."""
    from kincal.cli.main import main

    method, fix, joints = plain_options(study, model)
    out = []
    with tempfile.TemporaryDirectory(prefix="kincal-tiago-") as tmp:
        tmp = Path(tmp)
        common = ["--tip", TIP, "--position-columns", "x1", "y1", "z1"]
        if joints:
            common += ["--order-column", ORDER_COLUMN]
        # the model api_fit gives the API (an explicit one: the CLI's default, auto, would
        # choose its own joint terms and no longer be "the same model")
        cal = ["calibrate", str(study.paths["urdf"]), str(study.paths["train"]), *common,
               "--model", "mdh", "--method", method, "--lambda", "cv",
               *(["--fix", *fix] if fix else []),
               *(["--backlash", *joints] if joints else []),
               "--out", str(tmp / "tiago_calibrated.urdf"),
               "--frames-out", str(tmp / "frames.json"), "--quiet"]
        ev = ["evaluate", str(tmp / "tiago_calibrated.urdf"), str(study.paths["held_out"]),
              *common, "--frames", str(tmp / "frames.json")]
        runs = [cal, ev] if joints else [cal, ev, ev[:-2] + ["--fit-frames"]]
        for argv in runs:
            buf_out, buf_err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(buf_out), contextlib.redirect_stderr(buf_err):
                code = main(argv)
            shown = " ".join(argv).replace(f"{tmp}/", "").replace(str(shared), "../shared")
            out.append(f"$ kincal {shown}   # exit {code}")
            text = buf_out.getvalue().strip()
            if text:
                out.append(text)
    return "\n".join(out)


PROPOSALS = """\
Model extensions

Backlash and compliance terms are kincal options (CalibrationOptions.backlash and
.compliance; `--backlash JOINT --order-column COL`, `--compliance JOINT`), and the default
`--model auto` adds those its score test finds and CV confirms (docs/results.md: arm_6's
and arm_7's backlash and arm_6's compliance, 2.16 mm held out). This script's own rows with
those terms are its ExtendedProblem's. Prototyped here only, without a held-out gain on
these data so far:
1. The hand pose as one rigid marker body (its layout fitted once, 3 rotation
   parameters); kincal itself takes the four markers as separate measured points
   (`--position-columns x1 y1 z1 ... z4`), each with its own position on the hand.
2. CalibrationOptions.selection = "stepwise": forward selection of parameters by the
   same k-fold CV that chooses lambda, with the path kept in the result.
"""


def find_shared(argv_shared: str | None) -> Path | None:
    """The shared folder holding the TIAGo files, or None if they are not all there."""
    d, missing = locate(argv_shared)
    return None if missing else d.parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", help=f"the shared folder (default {DEFAULT_SHARED})")
    ap.add_argument("--quick", action="store_true",
                    help="one CV repetition, no stepwise selection, no CLI run")
    ap.add_argument("--nested", action="store_true",
                    help="nested CV of the stepwise selection (slow: ~5 selections more)")
    args = ap.parse_args(argv)
    shared = find_shared(args.shared)
    if shared is None:
        print(f"tiago_mocap: the shared data are not present under "
              f"{Path(args.shared or DEFAULT_SHARED) / SUBDIR}; nothing to do.")
        return 0
    t_start = time.perf_counter()
    study = Study(shared, seeds=CV_SEEDS[:1] if args.quick else CV_SEEDS)
    print(f"# TIAGo arm, motion capture: {study.train.N} training postures "
          f"({TRAIN}), {study.held_out.N} held-out ({HELD_OUT})\n")
    print(f"Chain {study.robot.base} -> {TIP}: {', '.join(study.robot.joint_names)}. "
          f"Measured point: marker 1 (x1, y1, z1). The four markers are one rigid body "
          f"(largest deviation from the mean shape {study.rigidity * 1e6:.1f} um); marker "
          f"weight in the hand-pose rows: {MARKER_WEIGHT:g} (markers 2-4 vs marker 1).")
    for w in study.warnings:
        print(f"kincal warning: {w}")
    rows = []
    for model in models(args.quick):
        row = run_row(study, model, args.nested)
        rows.append(row)
        print(f"  fitted: {model.label} ({row.seconds:.1f} s)", file=sys.stderr)
    # the selection: lowest mean CV error among rows whose CV is honest (not a stepwise
    # selection scored on the folds that selected it)
    # CV errors come in blocks of one repetition (all N postures once) in seed order; the
    # nested stepwise CV has fewer, so rows are compared on the repetitions they share
    eligible = [r for r in rows if r.cv_nested or not r.model.stepwise]
    n_reps = min(r.cv.size for r in eligible) // study.train.N
    score = {id(r): float(r.cv[: n_reps * study.train.N].mean()) for r in eligible}
    selected = min(eligible, key=lambda r: score[id(r)])
    print(f"\n## Results (mm; CV: {FOLDS}-fold x {len(study.seeds)} on the training day; "
          "held-out with the training-day frames)\n")
    print(table(rows, selected))
    print("\n† CV error of the selected set on the folds that selected it (optimistic); "
          "run with --nested for the honest figure. 'eff.': effective number of parameters "
          "(trace of the hat matrix) under the L2 penalty. L2 rows choose lambda inside every CV "
          "fold (nested); 'nested' stepwise rows rerun the whole selection inside every fold.")
    for r in rows:
        if r.api_check is not None and r.api_check > 1e-3:
            print(f"WARNING: {r.model.label}: the kincal API predicts differently "
                  f"({r.api_check:.4f} mm)")
    checked = [r.api_check for r in rows if r.api_check is not None]
    if checked:
        print(f"\nPlain rows cross-checked against kincal.CalibrationProblem: held-out "
              f"predictions agree to {max(checked):.1e} mm.")
    print(f"\nSelected by training CV (mean error over the {n_reps} CV repetition(s) all "
          f"eligible rows share): {selected.model.label}: {selected.n_params} parameters, "
          f"lambda = {selected.fit.lam:.3g}; held-out RMS {selected.held.rms:.2f} mm.")
    runners = sorted(eligible, key=lambda r: score[id(r)])[:3]
    print("  CV means on those repetitions: " + "; ".join(
        f"{r.model.label} {score[id(r)]:.3f}" for r in runners))
    for r in rows:
        if r.fit.path:
            steps = " -> ".join(f"{n} ({e:.2f})" for n, e in r.fit.path)
            print(f"\nStepwise path, {r.model.label}: {steps}")
            print(f"  deviations: {parameters_of(r)}")
    for r in rows:
        if r.model.terms and r.fit.lam == 0 and not r.model.stepwise:
            print(f"\n{r.model.label}: {parameters_of(r)}")
    print("\n## Residual analysis\n")
    print(residual_analysis(study, [r for r in rows if r.model.label in (
        "joint offsets + frames", "full MD-H, L2 + CV", "offsets + backlash arm_6",
        "full MD-H, L2 + CV + backlash arm_6") or r.model.stepwise or r is selected]))
    if not args.quick:
        plain = min((r for r in rows if r.model.api), key=lambda r: r.cv.mean())
        print(f"\n## The best model kincal offers, by training CV ({plain.model.label}), through "
              "the CLI\n")
        print(cli_demo(study, shared, plain.model))
        print(f"(API, same model: held-out RMS {plain.held.rms:.3f}, mean {plain.held.mean:.3f}, "
              f"max {plain.held.max:.3f} mm; frames re-fitted: RMS {plain.held_refit.rms:.3f} mm)")
    print("\n## " + PROPOSALS)
    cmd = "python scripts/tiago_mocap.py" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:]))
    print(f"Command: {cmd}   ({time.perf_counter() - t_start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
