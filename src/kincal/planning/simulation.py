"""Synthetic measurements: a robot with planted errors, a pose design and sensor noise.

Used by the demo, the paper reproduction, the benchmarks and the tests. The "true" robot
is the nominal MD-H model with a perturbed table, plus optionally a non-geometric error
that no MD-H model can absorb: a gravity-like compliance that bends joints 2 and 3 by
``compliance * cos`` of their angle sums (radians), as a loaded shoulder and elbow do;
and joint backlash (:mod:`kincal.backlash`), which kincal can model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kincal.errors import OptionError
from kincal.measurements.point_space import ParameterSpace
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.models.backlash import approach_directions
from kincal.models.base import ErrorModel
from kincal.robot import Robot
from kincal.rotations import rotx


@dataclass(frozen=True)
class Truth:
    """The simulated robot and sensor setup (SI units).

    table: (p,) true kinematic parameters of the simulating error model (an MD-H
        model without beta also takes its (n, 4) table). base: (6,) true measurement frame. tool: (3,) true
    tool point in the tip frame, or (K, 3) for K points measured at each pose.
    compliance: [rad] amplitude of the non-geometric error.
    backlash: {joint: half the play [rad or m]} (see kincal.backlash); the poses are
    taken in the order given.
    joint_compliance: {joint: compliance [rad/(N m)]} (see kincal.models.compliance), with
    ``robot`` the Robot whose inertials give the gravity torques (its chain is the model's).
    """

    table: np.ndarray
    base: np.ndarray
    tool: np.ndarray
    compliance: float = 0.0
    backlash: dict = field(default_factory=dict)
    joint_compliance: dict = field(default_factory=dict)
    robot: object = None

    @property
    def n_points(self) -> int:
        return np.asarray(self.tool).size // 3

    def x(self, space: ParameterSpace) -> np.ndarray:
        return space.join(self.table, self.base, self.tool)


def planted_table(mdh: ErrorModel, rng: np.random.Generator, length_sd: float = 0.3e-3,
                  angle_sd: float = np.radians(0.03), names=None) -> np.ndarray:
    """The error model's nominal parameters plus Gaussian errors [m, rad] on ``names``
    (default: all), as a flat kinematic vector."""
    space = ParameterSpace.of_model(mdh)
    x = space.join(mdh.nominal, np.zeros(6), np.zeros(3))
    idx = np.arange(space.n_kinematic) if names is None else space.indices(names)
    sd = np.where(space.is_length[idx], length_sd, angle_sd)
    x[idx] += rng.normal(size=idx.size) * sd
    return space.split(x)[0].copy()


def latin_hypercube(n: int, rng: np.random.Generator, dim: int = 3) -> np.ndarray:
    """(n, dim) Latin-hypercube sample of the unit cube."""
    u = (rng.random((n, dim)) + np.arange(n)[:, None]) / n
    for k in range(dim):
        u[:, k] = u[rng.permutation(n), k]
    return u


def random_rotation_near(R0: np.ndarray, max_angle: float, rng) -> np.ndarray:
    """R0 turned by a uniformly random axis and an angle uniform in [0, max_angle]."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0, max_angle)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return (np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K) @ R0


def cube_poses(robot: Robot, n: int, center, size: float, tool, rng: np.random.Generator,
               orientation=None, max_tilt: float = np.radians(30), lhs: bool = True,
               attempts: int = 40, progress=None) -> np.ndarray:
    """(n, dof) joint values putting the tool point at points of a cube [m].

    center: (3,) cube centre in the base frame; size: edge length. Points are a Latin
    hypercube (or uniform) sample. orientation: (3, 3) mean tip orientation (default:
    tool z pointing down), varied by up to ``max_tilt`` per pose; None orientation with
    max_tilt=None leaves the orientation free (position-only IK). progress:
    callback(done, n) about every 1 % of the poses, or None.
    """
    if n < 1:
        raise OptionError(f"need at least one pose, got {n}")
    center = np.asarray(center, float)
    pts = center + (latin_hypercube(n, rng) if lhs else rng.random((n, 3)) - 0.0) * size - size / 2
    R0 = rotx(np.pi) if orientation is None else np.asarray(orientation, float)
    g = robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    out = np.empty((n, g.n))
    # One arm branch for every pose, whatever the seed: the solution at the centre, in the
    # mean orientation, comes from a fixed-seed search (so calibration and validation sets
    # made with different seeds share it), and each pose starts from the nearest pose
    # already solved, as a real robot program moves, never from a random restart first.
    search = np.random.default_rng(0)
    home = None
    for _ in range(attempts):
        home, ok = robot.inverse_kinematics(center, tool, None if max_tilt is None else R0,
                                            start=search.uniform(lo, hi))
        if ok:
            break
    solved = _Solved(center, home, n + 1)
    every = max(1, n // 100)
    for done, k in enumerate(np.argsort(np.linalg.norm(pts - center, axis=1))):  # centre out
        if progress is not None and done % every == 0:
            progress(done, n)
        p = pts[k]
        R = None if max_tilt is None else random_rotation_near(R0, max_tilt, rng)
        near = solved.nearest(p)
        for attempt in range(attempts):
            start = near if attempt == 0 else home if attempt == 1 else rng.uniform(lo, hi)
            if attempt >= 2 and attempt % 2 == 0 and max_tilt is not None:
                R = random_rotation_near(R0, max_tilt, rng)  # that orientation may be out of reach
            q, ok = robot.inverse_kinematics(p, tool, R, start=start, max_iterations=60)
            if ok:
                out[k] = q
                solved.add(p, q)
                break
        else:
            where = (f"the point {np.round(p, 4)} m of the {size * 1e3:g} mm cube at "
                     f"{np.round(center, 4)} m")
            starts = [s for s in (home, solved.nearest(p)) if s is not None] + [
                rng.uniform(lo, hi) for _ in range(8)]
            if max_tilt is not None and any(  # the position alone, from several starts
                    robot.inverse_kinematics(p, tool, None, start=s0)[1] for s0 in starts):
                # the position is reachable: the asked orientation is what fails
                raise OptionError(f"no joint solution reaches {where} with the tool within "
                                  f"{np.degrees(max_tilt):g} deg of pointing down: the tip's "
                                  "orientation is the cause (an arm that cannot point its tip "
                                  "down there); allow a larger --tilt-deg or choose another --tip")
            raise OptionError(f"no joint solution reaches {where}; move the cube")
    if progress is not None:
        progress(n, n)
    return out


def true_positions(mdh: ErrorModel, truth: Truth, q: np.ndarray, points=0) -> np.ndarray:
    """(N, 3) exact positions of measured points in the measurement frame [m].

    points: which of the truth's points (0 = the first), one for all or (N,) per row.
    """
    q_eff = np.array(q, dtype=float)
    if truth.compliance and q_eff.shape[1] >= 3:
        q_eff[:, 1] += truth.compliance * np.cos(q_eff[:, 1])
        q_eff[:, 2] += truth.compliance * np.cos(q_eff[:, 1] + q_eff[:, 2])
    if truth.backlash:
        g = approach_directions(q)
        for joint, b in truth.backlash.items():
            i = mdh.joint_names.index(joint)
            q_eff[:, i] += b * g[:, i]
    if truth.joint_compliance:
        tau = truth.robot.gravity_torques(q)
        for joint, c in truth.joint_compliance.items():
            i = mdh.joint_names.index(joint)
            q_eff[:, i] += c * tau[:, i]
    idx = np.broadcast_to(np.asarray(points, dtype=int), (len(q_eff),))
    model = MeasurementModel(mdh, q_eff, points=idx, n_points=truth.n_points)
    return model.predict(truth.x(model.space))


def measure(mdh: ErrorModel, truth: Truth, q: np.ndarray, noise_sd: float,
            rng: np.random.Generator, source: str = "<simulated>") -> Measurements:
    """Measurements of ``truth`` at joint values ``q`` with Gaussian noise [m] per axis:
    one sample per pose and measured point (pose-major)."""
    K, n = truth.n_points, len(q)
    if K == 1:
        P = true_positions(mdh, truth, q) + rng.normal(size=(n, 3)) * noise_sd
        return Measurements(mdh.joint_names, q, P, source=source)
    points = np.tile(np.arange(K), n)
    true = true_positions(mdh, truth, np.repeat(q, K, axis=0), points)
    g = np.repeat(approach_directions(q), K, axis=0)
    return Measurements(mdh.joint_names, np.repeat(q, K, axis=0),
                        true + rng.normal(size=(n * K, 3)) * noise_sd, source=source,
                        approach=g, points=points, poses=np.repeat(np.arange(n), K))


class _Solved:
    """The points solved so far and their joint values; the nearest one to a new point.

    A k-d tree over the older points, rebuilt as they double, plus a plain scan of the
    newer ones: the same nearest point (first of equals) as a scan of all, without its
    n^2 cost (200,000 poses: hours before, seconds now).
    """

    def __init__(self, point, q, capacity: int):
        self.pts = np.empty((capacity, 3))
        self.q = np.empty((capacity, np.size(q)))
        self.count, self.tree, self.in_tree = 0, None, 0
        self.add(point, q)

    def add(self, point, q):
        self.pts[self.count], self.q[self.count] = point, q
        self.count += 1
        if self.count - self.in_tree > max(256, self.in_tree):
            from scipy.spatial import cKDTree

            self.tree, self.in_tree = cKDTree(self.pts[:self.count]), self.count

    def nearest(self, p) -> np.ndarray:
        d = np.linalg.norm(self.pts[self.in_tree:self.count] - p, axis=1)
        k, best = (self.in_tree + int(np.argmin(d)), d.min()) if d.size else (-1, np.inf)
        if self.tree is not None:
            dt, kt = self.tree.query(p)
            if dt <= best:  # ties go to the older point, as a scan from the first would
                k = int(kt)
        return self.q[k]
