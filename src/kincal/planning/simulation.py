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
from kincal.measurements.fixed_joints import refuse_coupled
from kincal.measurements.point import MeasurementModel
from kincal.models.backlash import approach_directions
from kincal.models.kinematics import ChainKinematics
from kincal.models.base import ErrorModel
from kincal.robot import Robot
from kincal.rotations import axis_rotations, rotx

# poses solved (and their orientations drawn) per round of cube_poses: a pose that needs
# random restarts makes the poses after it draw and solve again, so rounds over all the
# remaining poses made a million poses cost (restarts x poses); a multiple of 1024
WINDOW = 16384
LONG_PATH = 150  # Newton steps of the last random restarts (the first ones take 60)


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
    robot: Robot | None = None

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
    return _rotations_near(R0, max_angle, rng, 1)[0]


def _rotations_near(R0: np.ndarray, max_angle: float, rng, count: int,
                    marks: dict | None = None) -> np.ndarray:
    """(count, 3, 3): ``count`` draws of :func:`random_rotation_near`, the random numbers
    taken in the same order as ``count`` calls of it, the rotations made at once. marks:
    filled with {k: the generator's state before draw k} every 1024 draws."""
    axes, angles = np.empty((count, 3)), np.empty(count)
    for k in range(count):
        if marks is not None and k % 1024 == 0:
            marks[k] = rng.bit_generator.state
        axes[k] = rng.normal(size=3)
        angles[k] = rng.uniform(0, max_angle)
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    return axis_rotations(axes, angles) @ R0


def cube_poses(robot: Robot, n: int, center, size: float, tool, rng: np.random.Generator,
               orientation=None, max_tilt: float | None = np.radians(30), lhs: bool = True,
               attempts: int = 40, progress=None) -> np.ndarray:
    """(n, dof) joint values putting the tool point at points of a cube [m].

    center: (3,) cube centre in the base frame; size: edge length. Points are a Latin
    hypercube (or uniform) sample. orientation: (3, 3) mean tip orientation (default:
    tool z pointing down), varied by up to ``max_tilt`` per pose; None orientation with
    max_tilt=None leaves the orientation free (position-only IK). progress:
    callback(done, n) about every 1 % of the poses, or None.

    The poses are solved from the centre out, each from the solution of the nearest
    point solved before it (as a real robot program moves), then from the centre's: all
    poses at once on the vectorised chain (:meth:`ChainKinematics.damped_step`), each
    entering as soon as the pose it starts from is solved; then, for the few poses that
    neither reaches, from random starts one after the other (:func:`_random_restarts`).
    The same solutions (to rounding) and the same random numbers as solving the poses
    one after the other with :meth:`Robot.inverse_kinematics`, as kincal did before.
    """
    refuse_coupled(robot, "drawing simulated poses")
    if n < 1:
        raise OptionError(f"need at least one pose, got {n}")
    if max_tilt is not None and orientation is None and max_tilt >= np.pi:
        max_tilt = None  # every orientation is within 180 deg of pointing down: free
    center = np.asarray(center, float)
    pts = center + (latin_hypercube(n, rng) if lhs else rng.random((n, 3)) - 0.0) * size - size / 2
    R0 = rotx(np.pi) if orientation is None else np.asarray(orientation, float)
    g = robot.geometry
    lo, hi = g.ranges()
    tool = np.asarray(tool, float)
    # One arm branch for every pose, whatever the seed: the solution at the centre, in the
    # mean orientation, comes from a fixed-seed search (so calibration and validation sets
    # made with different seeds share it), and each pose starts from the nearest pose
    # already solved, never from a random restart first.
    search = np.random.default_rng(0)
    home = None
    for _ in range(attempts):
        home, ok = robot.inverse_kinematics(center, tool, None if max_tilt is None else R0,
                                            start=search.uniform(lo, hi))
        if ok:
            break
    chain = ChainKinematics.of(g)
    order = np.argsort(np.linalg.norm(pts - center, axis=1))  # centre out
    P = pts[order]
    parent = nearest_earlier(center, P)
    solved = np.empty((n, g.n))  # in the order solved
    first, done = 0, [0, 0]  # poses solved, multiples of 1 % reported
    report = None
    if progress is not None:
        progress(0, n)
        report = lambda k: progress(k, n)  # noqa: E731
    while first < n:  # a window of poses at a time: a restart redoes only its window's rest
        stop = min(n, first + WINDOW)
        done[0] = first
        marks = {0: rng.bit_generator.state}
        R = None if max_tilt is None else _rotations_near(R0, max_tilt, rng, stop - first, marks)
        bad = _solve_from_parents(chain, P, R, tool, parent, first, stop, home, solved,
                                  lo, hi, report, done)
        if bad == stop:
            first = stop
            continue
        # pose `bad` needs random restarts: its random numbers come after the rotations of
        # the poses before it and its own, and every later pose draws anew after them
        mark = (bad - first) // 1024 * 1024 if max_tilt is not None else 0
        rng.bit_generator.state = marks[mark]  # the state before the draws up to `bad`'s
        R_bad = None if max_tilt is None else _rotations_near(R0, max_tilt, rng,
                                                              bad - first - mark + 1)[-1]
        solved[bad] = _random_restarts(robot, P[bad], tool, R_bad, R0, max_tilt, home,
                                       solved[parent[bad]] if parent[bad] >= 0 else home,
                                       rng, lo, hi, attempts, size, center)
        first = bad + 1
    if progress is not None:
        progress(n, n)
    out = np.empty((n, g.n))
    out[order] = solved
    return out


def _solve_from_parents(chain, P, R, tool, parent, first, stop, home, solved, lo, hi, report,
                        done, max_iterations: int = 60, tolerance: float = 1e-10) -> int:
    """Solve the poses ``first`` ... ``stop - 1`` of P (in the order of solving) into
    ``solved``, each from its parent's solution (parent -1: ``home``), then from ``home``;
    R: the orientations of poses first ... stop - 1 (or None). Returns the first pose that
    neither start solves (``stop`` if none): later poses are then to be solved again."""
    n = len(P)
    later = np.flatnonzero(parent[first:stop] >= first) + first
    kids = later[np.argsort(parent[later], kind="stable")]
    edges = np.searchsorted(parent[kids], np.arange(stop + 1))
    idx = np.flatnonzero(parent[first:stop] < first) + first  # their starts are solved
    q = np.where((parent[idx] >= 0)[:, None], solved[np.maximum(parent[idx], 0)], home)
    q = np.clip(q, lo, hi)
    steps = np.zeros(len(idx), int)
    from_home = np.zeros(len(idx), bool)
    bad = stop
    every = max(1, n // 100)
    while idx.size:
        err, q_next = chain.damped_step(q, tool, P[idx], None if R is None else R[idx - first],
                                        lo, hi)
        ok = err < tolerance
        solved[idx[ok]] = q[ok]
        out_of_steps = ~ok & (steps + 1 == max_iterations)
        lost = out_of_steps & from_home
        if lost.any():
            bad = min(bad, int(idx[lost].min()))
        retry = out_of_steps & ~from_home  # from the centre's solution next
        q_next[retry], steps[retry], from_home[retry] = np.clip(home, lo, hi), -1, True
        go = ~ok & ~lost & (idx < bad)  # poses after `bad` draw anew: solved again later
        new = np.concatenate([kids[edges[k]:edges[k + 1]] for k in idx[ok]]) if ok.any() \
            else np.empty(0, int)
        new = new[new < bad]
        done[0] += int(ok.sum())
        while report is not None and (done[1] + 1) * every <= min(done[0], n - 1):
            done[1] += 1  # every multiple of ``every`` poses once, as one by one would
            report(done[1] * every)
        idx = np.concatenate([idx[go], new])
        q = np.concatenate([q_next[go], np.clip(solved[parent[new]], lo, hi)])
        steps = np.concatenate([steps[go] + 1, np.zeros(len(new), int)])
        from_home = np.concatenate([from_home[go], np.zeros(len(new), bool)])
    return bad


def _random_restarts(robot, p, tool, R, R0, max_tilt, home, near, rng, lo, hi, attempts,
                     size, center) -> np.ndarray:
    """The joint values of a pose that neither its nearest solved pose's solution nor
    the centre's reach: from random starts (a new orientation every other one), one
    after the other on Pinocchio's solver. A random start's path passes near singular
    configurations (Jacobians with condition numbers up to 1e17) where the last bit of
    a rounding decides where it goes: solved as before, a seed gives the same poses."""
    for attempt in range(2, attempts):
        start = rng.uniform(lo, hi)
        if attempt % 2 == 0 and max_tilt is not None:
            R = random_rotation_near(R0, max_tilt, rng)  # that orientation may be out of reach
        q, ok = robot.inverse_kinematics(p, tool, R, start=start, max_iterations=60)
        if ok:
            return q
    # none did: as many again, each path given more steps (one from far away can need more
    # than 60; seen on OpenBLAS's Prescott kernels at a cube's edge). Only before giving up,
    # so every pose the first round solves keeps its numbers.
    for attempt in range(attempts):
        start = rng.uniform(lo, hi)
        if attempt % 2 == 0 and max_tilt is not None:
            R = random_rotation_near(R0, max_tilt, rng)
        q, ok = robot.inverse_kinematics(p, tool, R, start=start, max_iterations=LONG_PATH)
        if ok:
            return q
    where = (f"the point {np.round(p, 4)} m of the {size * 1e3:g} mm cube at "
             f"{np.round(center, 4)} m")
    starts = [s for s in (home, near) if s is not None] + [rng.uniform(lo, hi) for _ in range(8)]
    if max_tilt is not None and any(  # the position alone, from several starts
            robot.inverse_kinematics(p, tool, None, start=s0)[1] for s0 in starts):
        # the position is reachable: the asked orientation is what fails
        raise OptionError(f"no joint solution reaches {where} with the tool within "
                          f"{np.degrees(max_tilt):g} deg of pointing down: the tip's "
                          "orientation is the cause (an arm that cannot point its tip "
                          "down there); allow a larger --tilt-deg (180: any orientation) or "
                          "choose another --tip"
                          + (f" (a chain of {robot.geometry.n} joints cannot give the tool a "
                             "chosen orientation at a chosen point)" if robot.geometry.n < 6
                             else ""))
    raise OptionError(f"no joint solution reaches {where}; move the cube")


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
        if truth.robot is None:
            raise ValueError("a Truth with joint_compliance needs its robot (the inertials "
                             "that give the gravity torques)")
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


def nearest_earlier(center, P: np.ndarray) -> np.ndarray:
    """(N,) for each point of P (N, 3) the nearest of ``center`` and the points before it
    in P: its index, -1 for the centre (the first of equals).

    Through grids of cubes of edge h, about two points a cube at first: the nearest
    earlier point among the 27 cubes around a point is the nearest of all when it is
    within h (any other is farther). The points without one go to a grid of twice the
    edge, and so on; the last few (the first points, mostly) are scanned. The same
    answer as a scan of all."""
    A = np.vstack([np.asarray(center, float)[None], P])  # A[i + 1] is P[i]
    N = len(P)
    out = np.full(N, -2)
    todo = np.arange(N)
    span = np.ptp(A, axis=0)
    h = (float(np.prod(np.maximum(span, 1e-3 * span.max()))) / max(N, 1)) ** (1 / 3) * 1.25
    while len(todo) > 256 and h < span.max():
        found, arg = _nearest_earlier_in_grid(A, todo, h)
        out[todo[found]] = arg[found] - 1
        todo, h = todo[~found], 2 * h
    for s in range(0, len(todo), 256):  # a block of points against all before its last
        rows = todo[s:s + 256]
        d = np.linalg.norm(A[None, :rows[-1] + 1] - P[rows, None], axis=2)
        d[np.arange(A.shape[0])[None, :rows[-1] + 1] > rows[:, None]] = np.inf
        out[rows] = np.argmin(d, axis=1) - 1
    return out


def _nearest_earlier_in_grid(A: np.ndarray, todo: np.ndarray, h: float):
    """For the points P[todo] (A[todo + 1]): whether the nearest of the earlier points of
    A lies within h, found among the 27 cubes of edge h around each, and its index in A."""
    cell = np.floor((A - A.min(axis=0)) / h).astype(np.int64) + 1  # a margin of empty cubes
    dims = cell.max(axis=0) + 2
    key = np.ravel_multi_index(cell.T, dims)
    order = np.argsort(key, kind="stable")  # the points cube by cube, in order within one
    counts = np.bincount(key, minlength=int(np.prod(dims)))
    starts = np.cumsum(counts) - counts
    me = todo + 1
    best, arg = np.full(len(todo), np.inf), np.full(len(todo), len(A))
    for off in np.ndindex(3, 3, 3):
        k = np.ravel_multi_index((cell[me] + np.array(off) - 1).T, dims)
        first, count = starts[k], counts[k]
        for m in range(int(count.max(initial=0))):
            has = np.flatnonzero(count > m)
            j = order[first[has] + m]
            d = np.linalg.norm(A[j] - A[me[has]], axis=1)
            better = (j < me[has]) & ((d < best[has]) | ((d == best[has]) & (j < arg[has])))
            best[has[better]], arg[has[better]] = d[better], j[better]
    return best <= h, arg
