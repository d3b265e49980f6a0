"""Candidate poses inside a measurement volume: where an R-test or a small tracker sees the tool.

The instrument fixes where the measured point may be and how the tool may be tilted;
:func:`volume_candidates` makes joint configurations that respect that, for
:func:`kincal.planning.pose_selection.select_poses` to choose among. A candidate

- puts the tool point (tip frame plus ``tool``) inside the :class:`Volume` (an
  axis-aligned cube or a sphere of the base frame);
- has the tip frame's z axis within ``max_tilt`` of ``tilt_direction`` (base frame;
  default -z, the tool pointing down into a nest); the spin about that axis is free;
- is inside the joint limits;
- is on the arm branch of ``home`` (see below);
- is free of self-collision and of the floor (z = ``floor_z`` of the base frame) where
  the URDF has collision geometry (:class:`kincal.collision.CollisionChecker`). Without
  collision geometry only the tool point and the tip frame origin are kept above the
  floor, and :attr:`VolumeCandidates.collision_note` says so. With
  ``self_collision=False`` (``--no-collision``: a URDF whose meshes cannot be found) the
  geometry is not loaded and the same holds: only the tool point and tip are kept above
  the floor, and the note says that self-collision was NOT checked.

Generation. Targets are drawn at random: a point uniform in the volume, a z direction
uniform on the spherical cap of half-angle ``max_tilt``, and a start that is ``home``
with its last joint turned at random (that spreads the spin, which the 5-dimensional
task leaves free). Damped Gauss-Newton on the residual (point - target, (z - u) * L),
vectorised over all targets, with the analytic Jacobian of the MD-H forward kinematics
(exact for the URDF; L is the arm's reach); joints are clipped to their limits at every
step. Batches are drawn until ``m`` candidates pass every check, or a bound on the
attempts is met, in which case the error says which constraint rejected most.

Branches. A 6-axis arm reaches most poses in several ways (shoulder left/right, elbow
up/down, wrist flipped or not); they are separated by singular configurations, where the
6 x n Jacobian of the tip (linear part divided by the arm's reach) loses rank. A
candidate is on the branch of ``home`` when the straight joint-space path from ``home``
to it (the last joint held: the Jacobian's rank does not depend on it, as every joint
screw is set by the joints before it) keeps the smallest singular value of that Jacobian
above ``BRANCH_MARGIN`` times its value at ``home``, checked at steps of at most
``BRANCH_STEP`` rad. So no configuration sign (elbow, wrist, shoulder) can flip without
the path coming near a singularity, whatever the arm. The default home is found once,
deterministically: the solution at the volume's centre, pointing along
``tilt_direction``, from a fixed set of starts, that is farthest from singularity
(largest smallest singular value) among those inside the limits and free of collision.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from kincal.collision import CollisionChecker
from kincal.errors import KincalWarning, OptionError
from kincal.frames_file import MAX_LENGTH
from kincal.identification import blas_threads
from kincal.measurements.fixed_joints import refuse_coupled
from kincal.planning.batch_ik import BatchKinematics

if TYPE_CHECKING:
    from kincal.robot import Robot

BRANCH_MARGIN = 0.1  # smallest singular value on the path, relative to home's
BRANCH_STEP = 0.05  # [rad or m] largest joint change between checks on the path
HOME_STARTS = 64  # starts of the home search (fixed seed 0)
MAX_ATTEMPTS = 20  # draws per candidate asked for, at most, before giving up
BLAME_SAMPLE = 64  # colliding configurations looked at to name what they hit
# the default working volume (working_volume): the 400 mm validation cube of the paper and
# of kincal's studies, with the tool at most 30 deg from the tilt direction (the default
# --max-tilt); docs/results.md ("The default beyond its twin") measures other choices
WORKING_EDGE = 0.4
WORKING_TILT = math.radians(30.0)
MAX_TILT_DEG = 180.0  # [deg] a tilt is an angle between two directions: 0 to 180


# ------------------------------------------------------------------ values
@dataclass(frozen=True)
class Volume:
    """Where the tool point may be: an axis-aligned cube or a sphere of the base frame.

    shape: "cube" or "sphere"; center: (3,) [m]; size: the cube's edge or the sphere's
    radius [m].
    """

    shape: str
    center: tuple[float, float, float]
    size: float

    def __post_init__(self):
        if self.shape not in ("cube", "sphere"):
            raise OptionError(f"unknown volume shape {self.shape!r}; expected cube or sphere")
        c = np.asarray(self.center, float)
        if c.shape != (3,) or not np.all(np.isfinite(c)) or np.abs(c).max() > MAX_LENGTH:
            raise OptionError(f"the {self.shape} centre needs 3 finite numbers [m] within "
                              f"{MAX_LENGTH:g} m of the base frame, got {self.center!r}")
        if not (math.isfinite(self.size) and 0 < self.size <= MAX_LENGTH):
            what = "edge" if self.shape == "cube" else "radius"
            raise OptionError(f"the {self.shape} {what} must be a positive number up to "
                              f"{MAX_LENGTH:g} [m], got {self.size!r}")
        object.__setattr__(self, "center", tuple(float(v) for v in c))

    @classmethod
    def cube(cls, center, edge: float) -> "Volume":
        return cls("cube", tuple(center), float(edge))

    @classmethod
    def sphere(cls, center, radius: float) -> "Volume":
        return cls("sphere", tuple(center), float(radius))

    def sample(self, m: int, rng: np.random.Generator) -> np.ndarray:
        """(m, 3) points uniform in the volume [m]."""
        c = np.asarray(self.center)
        if self.shape == "cube":
            return c + (rng.random((m, 3)) - 0.5) * self.size
        v = rng.normal(size=(m, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return c + v * self.size * rng.random((m, 1)) ** (1 / 3)

    def contains(self, points, tol: float = 1e-9) -> np.ndarray:
        """(N,) True for points (N, 3) [m] inside, up to ``tol`` [m]."""
        d = np.atleast_2d(points) - np.asarray(self.center)
        if self.shape == "cube":
            return np.all(np.abs(d) <= self.size / 2 + tol, axis=1)
        return np.linalg.norm(d, axis=1) <= self.size + tol

    def describe(self) -> str:
        c = ", ".join(f"{v:g}" for v in self.center)
        if self.shape == "cube":
            return f"{self.size * 1e3:g} mm cube at ({c}) m"
        return f"sphere of radius {self.size * 1e3:g} mm at ({c}) m"


@dataclass(frozen=True)
class VolumeSpec:
    """What a candidate must satisfy (see the module notes). SI units, base frame.

    volume: where the tool point may be. tool: (3,) tool point in the tip frame [m].
    max_tilt: largest angle [rad] between the tip z axis and ``tilt_direction`` (3,).
    home: (n,) joint values [rad or m] giving the arm branch, or None to find one.
    floor_z: height of the floor [m] in the base frame, or None for no floor.
    self_collision: check the URDF's collision geometry (self-collision, links against the
        floor; True, the default); False (``--no-collision``) does not load it, and only
        the tool point and tip are kept above the floor.
    """

    volume: Volume
    tool: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max_tilt: float = math.radians(30.0)
    tilt_direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    home: tuple[float, ...] | None = None
    floor_z: float | None = 0.0
    self_collision: bool = True

    def __post_init__(self):
        if not isinstance(self.self_collision, (bool, np.bool_)):
            raise OptionError(f"self_collision is True or False, got {self.self_collision!r}")
        object.__setattr__(self, "self_collision", bool(self.self_collision))
        t = np.asarray(self.tool, float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise OptionError(f"tool needs 3 finite numbers (tip frame) [m], got {self.tool!r}")
        if not (math.isfinite(self.max_tilt) and 0 <= self.max_tilt <= math.radians(MAX_TILT_DEG)):
            raise OptionError(f"the largest tilt must be between 0 and {MAX_TILT_DEG:g} deg, got "
                              f"{math.degrees(self.max_tilt):g} deg")
        u = np.asarray(self.tilt_direction, float)
        if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) < 1e-9:
            raise OptionError(f"the tilt direction needs 3 finite numbers, not all zero, got "
                              f"{self.tilt_direction!r}")
        object.__setattr__(self, "tool", tuple(float(v) for v in t))
        u = u / np.abs(u).max()  # a direction: its length does not count (1e308 would overflow)
        object.__setattr__(self, "tilt_direction", tuple(float(v) for v in u / np.linalg.norm(u)))
        if self.home is not None:
            try:
                h = np.asarray(self.home, float)
            except (TypeError, ValueError):
                h = np.full((1, 1), np.nan)
            if h.ndim != 1 or not np.all(np.isfinite(h)):
                shown = (" ".join(f"{v:g}" for v in h) if h.ndim == 1 and h.size
                         and not np.isnan(h).all() else repr(self.home))
                raise OptionError(f"home needs finite joint values [rad or m] (--home), got "
                                  f"{shown}")
            object.__setattr__(self, "home", tuple(float(v) for v in h))


def working_volume(spec: VolumeSpec, home, edge: float = WORKING_EDGE,
                   tilt: float = WORKING_TILT) -> VolumeSpec:
    """Where the calibrated robot is assumed to work when the user does not say (``kincal
    plan``'s default I-optimal targets): the cube of ``edge`` [m] centred on the
    measurement volume, the tool within ``tilt`` [rad] (at most the measurement's
    max_tilt) of its tilt direction, its floor and the branch of ``home`` (the
    candidates'). The measurement volume is where the user put the instrument, near the
    work: the calibration should serve the space around it, not only the instrument's few
    centimetres; and a tilt wider than the default is asked for to gain information (the
    tilt carries it in a small volume), not because the tool works that way."""
    return replace(spec, volume=Volume.cube(spec.volume.center, edge),
                   max_tilt=min(spec.max_tilt, tilt), home=tuple(float(v) for v in home))


@dataclass(frozen=True)
class Rejections:
    """How many drawn targets each check turned down (in this order: the first failed)."""

    not_reached: int = 0  # the IK found no configuration inside the limits
    branch: int = 0       # reached, but on another branch than home
    collision: int = 0    # self-collision or the floor

    def total(self) -> int:
        return self.not_reached + self.branch + self.collision


@dataclass(frozen=True)
class VolumeCandidates:
    """The outcome of :func:`volume_candidates`.

    joint_values: (m, n) candidates [rad or m], chain order, read-only.
    points: (m, 3) their tool points in the base frame [m]; tilts: (m,) angles [rad]
        between the tip z axis and the tilt direction.
    home: (n,) the branch's home configuration; home_found: True if kincal found it.
    attempts: targets drawn; rejections: why the others were turned down.
    collision_note: what the collision check covered.
    """

    spec: VolumeSpec
    joint_values: np.ndarray
    points: np.ndarray
    tilts: np.ndarray
    home: np.ndarray
    home_found: bool
    attempts: int
    rejections: Rejections
    collision_note: str
    joint_names: tuple[str, ...] = field(default=())

    def summary(self) -> str:
        s, r = self.spec, self.rejections
        lines = [f"{len(self.joint_values)} candidates in the {s.volume.describe()}, tilt <= "
                 f"{math.degrees(s.max_tilt):g} deg from {np.round(s.tilt_direction, 3).tolist()}"
                 f" ({self.attempts} targets drawn: {r.not_reached} not reached within the "
                 f"limits, {r.branch} on another branch, {r.collision} colliding)",
                 f"  home ({'found' if self.home_found else 'given'}): "
                 + " ".join(f"{v:.4g}" for v in self.home) + " rad/m",
                 f"  {self.collision_note}"]
        return "\n".join(lines)


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _cap_directions(u, max_tilt: float, m: int, rng) -> np.ndarray:
    """(m, 3) unit vectors uniform on the cap of half-angle max_tilt around u."""
    u = np.asarray(u, float)
    cos_t = 1.0 - rng.random(m) * (1.0 - math.cos(max_tilt))
    phi = rng.random(m) * 2 * math.pi
    a = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    sin_t = np.sqrt(1 - cos_t ** 2)
    return (cos_t[:, None] * u + sin_t[:, None] * (np.cos(phi)[:, None] * e1
                                                   + np.sin(phi)[:, None] * e2))


def _on_branch(kin: BatchKinematics, home, sigma_home: float, Q) -> np.ndarray:
    """(N,) True where the joint path from home to Q stays clear of singularities."""
    if len(Q) == 0:
        return np.zeros(0, dtype=bool)
    D = Q - home
    D[:, -1] = 0.0  # the last joint turns the whole Jacobian rigidly: no rank change
    steps = max(2, int(np.ceil(np.max(np.abs(D)) / BRANCH_STEP)))
    t = np.linspace(0.0, 1.0, steps + 1)[1:]
    path = home + t[None, :, None] * D[:, None, :]                      # (N, s, n)
    s = kin.sigma_min(path.reshape(-1, kin.n)).reshape(len(Q), -1)
    return s.min(axis=1) > BRANCH_MARGIN * sigma_home


class _Collisions:
    """Collision geometry when the URDF has it and the spec asks for it; tool point and tip
    above the floor always."""

    def __init__(self, robot, spec: VolumeSpec):
        floor_z = spec.floor_z
        # not loaded at all without the check: its meshes may be missing (--no-collision)
        self.checker = CollisionChecker(robot, floor_z) if spec.self_collision else None
        self.floor_z = floor_z
        self.tool = np.asarray(spec.tool, float)
        if self.checker is not None and self.checker.has_geometry:
            what = f"{len(self.checker.pairs)} collision pairs checked (self"
            what += f" and a floor at z = {floor_z:g} m)" if floor_z is not None else ")"
            if self.checker.excluded:
                what += (f"; {len(self.checker.excluded)} pairs in contact at zero joint values "
                         "left out")
            self.note = what
        else:
            self.note = ("self-collision NOT checked (--no-collision)" if self.checker is None
                         else "the URDF has no collision geometry: self-collision NOT checked")
            self.note += (f"; only the tool point and tip kept above the floor at z = "
                          f"{floor_z:g} m" if floor_z is not None else "")

    def blame(self, Q, R, P) -> tuple[str, str]:
        """(what the colliding configurations Q (N, n) hit, what to relax: "" when no
        advice of its own): the floor when every one of them meets it (the tool point or
        tip below it, or a link the floor cuts in every one, as a floor above a UR10's
        shoulder cuts its upper arm, where no volume or tilt helps), else the pair hit
        most. R, P: their tip rotations and tool points (base frame)."""
        Q, R, P = Q[:BLAME_SAMPLE], R[:BLAME_SAMPLE], P[:BLAME_SAMPLE]
        floor = f"the floor at z = {self.floor_z:g} m" if self.floor_z is not None else ""
        if floor and len(Q):
            tip = P - R @ self.tool
            if np.all((P[:, 2] <= self.floor_z) | (tip[:, 2] <= self.floor_z)):
                return (f"the tool point or the tip is below {floor} in every one",
                        "move the volume above the floor or lower --floor")
        if self.checker is None or not self.checker.has_geometry or not len(Q):
            return "", ""
        hits = self.checker.pair_hits(Q)
        always = [p for k, p in enumerate(self.checker.pairs) if hits[:, k].all()]
        cut = [p.split(" / ")[0] for p in always if p.endswith(" / kincal_floor")]
        if cut and floor:
            return (f"{floor} cuts {', '.join(cut)} in every one of the {len(Q)} looked at "
                    "(it is above part of the arm)", "lower --floor (or --no-floor)")
        k = int(np.argmax(hits.sum(axis=0)))
        return (f"most often {self.checker.pairs[k].replace('kincal_floor', 'the floor')} "
                f"({int(hits[:, k].sum())} of {len(Q)} looked at)"), ""

    def hits_of(self, q, R, P) -> list[str]:
        """What one configuration q (n,) hits (R, P: its tip rotation (3, 3) and tool point
        (3,), base frame): the floor under its tool point or tip, the pairs in contact."""
        out = []
        if self.floor_z is not None and min(P[2], (P - R @ self.tool)[2]) <= self.floor_z:
            out.append(f"the tool point or tip below the floor at z = {self.floor_z:g} m")
        if self.checker is not None and self.checker.has_geometry:
            hits = self.checker.pair_hits(np.asarray(q, float)[None])[0]
            out += [p.replace("kincal_floor", "the floor")
                    for k, p in enumerate(self.checker.pairs) if hits[k]]
        return out

    def free(self, Q, R, P) -> np.ndarray:
        ok = np.ones(len(Q), dtype=bool)
        if self.floor_z is not None:
            tip = P - R @ self.tool
            ok &= (P[:, 2] > self.floor_z) & (tip[:, 2] > self.floor_z)
        if self.checker is not None and self.checker.has_geometry and ok.any():
            ok[ok] = ~self.checker.colliding(Q[ok])
        return ok


# ------------------------------------------------------------------ generation
def find_home(robot: "Robot", spec: VolumeSpec, kin: BatchKinematics | None = None,
              collisions: _Collisions | None = None) -> np.ndarray:
    """(n,) a home configuration for ``spec`` (see the module notes); raises OptionError."""
    kin = kin or BatchKinematics(robot, spec.tool)
    collisions = collisions or _Collisions(robot, spec)
    rng = np.random.default_rng(0)
    c = np.asarray(spec.volume.center)[None]
    u = np.asarray(spec.tilt_direction)[None]
    starts = rng.uniform(kin.lo, kin.hi, size=(HOME_STARTS, kin.n))
    Q, ok = kin.solve(np.repeat(c, HOME_STARTS, 0), np.repeat(u, HOME_STARTS, 0), starts)
    if not ok.any():
        _explain_unreachable(kin, spec, starts)
    Q = Q[ok]
    R, P = kin.poses(Q)
    free = collisions.free(Q, R, P)
    if not free.any():
        why, advice = collisions.blame(Q, R, P)
        raise OptionError(f"every configuration that reaches the centre of the "
                          f"{spec.volume.describe()} pointing along "
                          f"{np.round(spec.tilt_direction, 3).tolist()} collides "
                          f"({collisions.note}){': ' + why if why else ''}: "
                          + (advice or "move the volume or change --tilt-direction"))
    Q = Q[free]
    home = Q[int(np.argmax(kin.sigma_min(Q)))].copy()
    # a revolute joint turned by a full turn gives the same pose: take the turn nearest zero
    for i, kind in enumerate(robot.geometry.kinds):
        if kind == "revolute":
            turns = home[i] + 2 * np.pi * np.arange(-3, 4)
            turns = turns[(turns >= kin.lo[i]) & (turns <= kin.hi[i])]
            home[i] = turns[np.argmin(np.abs(turns))]
    return home


def _explain_unreachable(kin, spec, starts):
    n = len(starts)
    c = np.repeat(np.asarray(spec.volume.center)[None], n, 0)
    free_dirs = _cap_directions(spec.tilt_direction, math.pi, n, np.random.default_rng(1))
    _, ok = kin.solve(c, free_dirs, starts)
    where = f"the centre {np.round(spec.volume.center, 4).tolist()} m of the {spec.volume.shape}"
    if ok.any():
        raise OptionError(f"the arm reaches {where}, but not with the tip z axis along "
                          f"{np.round(spec.tilt_direction, 3).tolist()}: change --tilt-direction "
                          "(or --home)")
    raise OptionError(f"the arm cannot reach {where} (within its joint limits, tool point "
                      f"{np.round(spec.tool, 4).tolist()} m in the tip frame): move the volume "
                      "(its centre) nearer the arm")


def volume_candidates(robot: "Robot", spec: VolumeSpec, m: int, seed: int = 0,
                      batch: int = 512, what: str = "candidates") -> VolumeCandidates:
    """``m`` candidate configurations satisfying ``spec`` (see the module notes); ``what``
    they are, as the error for too few names them ("target poses (--target-poses)").

    Deterministic for a given seed. Raises OptionError naming the constraint to relax
    when the arm cannot reach the volume, the tilt range has no solution, or fewer than
    ``m`` candidates are found within MAX_ATTEMPTS * m draws, and for a chain holding a
    mimic joint and its master (:func:`kincal.measurements.fixed_joints.refuse_coupled`).
    """
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
        raise OptionError(f"the number of candidates must be an integer >= 1, got {m!r}")
    refuse_coupled(robot, "drawing volume candidates")
    # small batched matrices: BLAS threads only wait for each other (see blas_threads)
    with blas_threads.limited(1):
        return _generate(robot, spec, int(m), seed, batch, what)


def _generate(robot, spec, m, seed, batch, what) -> VolumeCandidates:
    kin = BatchKinematics(robot, spec.tool)
    collisions = _Collisions(robot, spec)
    if spec.home is None:
        home, found = find_home(robot, spec, kin, collisions), True
    else:
        home, found = np.asarray(spec.home, float), False
        if home.shape != (kin.n,):
            raise OptionError(f"home needs {kin.n} joint values ({', '.join(robot.joint_names)}), "
                              f"got {home.size}")
        if np.any(home < kin.lo - 1e-12) or np.any(home > kin.hi + 1e-12):
            raise OptionError("home is outside the joint limits: give values within "
                              + ", ".join(f"{n} [{a:.4g}, {b:.4g}]" for n, a, b in
                                          zip(robot.joint_names, kin.lo, kin.hi)))
        R_h, P_h = kin.poses(home[None])
        touched = collisions.hits_of(home, R_h[0], P_h[0])
        if touched:  # a planned pose never: they are all checked; but no start for the robot
            more = f"; and {len(touched) - 3} more" if len(touched) > 3 else ""
            warnings.warn(f"the home given (--home) collides ({'; '.join(touched[:3])}{more}): "
                          "it only marks the arm branch, every planned pose is checked, but "
                          "the robot cannot start there; give a home clear of collisions",
                          KincalWarning)
    sigma_home = float(kin.sigma_min(home[None])[0])
    if sigma_home < 1e-6:
        raise OptionError("home is a singular configuration: its branch is undefined; give "
                          "another --home")
    rng = np.random.default_rng(seed)
    u = np.asarray(spec.tilt_direction)
    found_q, found_p, found_t = [], [], []
    counts = dict(not_reached=0, branch=0, collision=0)
    attempts, have = 0, 0
    hit = [np.empty((0, kin.n)), np.empty((0, 3, 3)), np.empty((0, 3))]  # colliding Q, R, P
    while have < m and attempts < MAX_ATTEMPTS * m:
        k = min(batch, MAX_ATTEMPTS * m - attempts)
        attempts += k
        pts = spec.volume.sample(k, rng)
        dirs = _cap_directions(u, spec.max_tilt, k, rng)
        start = np.repeat(home[None], k, 0)
        start[:, -1] = rng.uniform(kin.lo[-1], kin.hi[-1], size=k)
        Q, ok = kin.solve(pts, dirs, start)
        counts["not_reached"] += int((~ok).sum())
        Q = Q[ok]
        on = _on_branch(kin, home, sigma_home, Q)
        counts["branch"] += int((~on).sum())
        Q = Q[on]
        R, P = kin.poses(Q)
        free = collisions.free(Q, R, P)
        counts["collision"] += int((~free).sum())
        if len(hit[0]) < BLAME_SAMPLE:  # kept to name what they hit, if too few are free
            hit = [np.concatenate([h, x[~free]]) for h, x in zip(hit, (Q, R, P))]
        Q, R, P = Q[free], R[free], P[free]
        found_q.append(Q)
        found_p.append(P)
        found_t.append(np.arccos(np.clip(R[:, :, 2] @ u, -1, 1)))
        have += len(Q)
    rej = Rejections(**counts)
    if have < m:
        _too_few(spec, m, have, attempts, rej, collisions.note, what, collisions.blame(*hit))
    Qa = np.concatenate(found_q)[:m]
    return VolumeCandidates(spec, _readonly(Qa), _readonly(np.concatenate(found_p)[:m]),
                            _readonly(np.concatenate(found_t)[:m]), _readonly(home), found,
                            attempts, rej, collisions.note, tuple(robot.joint_names))


def _too_few(spec, m, have, attempts, rej, note, what, blame=("", "")):
    worst = max(("not_reached", rej.not_reached), ("branch", rej.branch),
                ("collision", rej.collision), key=lambda kv: kv[1])[0]
    advice = {"not_reached": "most targets are out of reach: shrink the volume or move it "
                             "nearer the arm, or lower --max-tilt",
              "branch": "most solutions lie on another arm branch: lower --max-tilt, shrink the "
                        "volume, or give a --home farther from singular configurations",
              "collision": f"most solutions collide ({note}"
                           + (f"; {blame[0]}" if blame[0] else "") + "): "
                           + (blame[1] or "move the volume away from the floor and the "
                                           "robot, or lower --max-tilt")}[worst]
    raise OptionError(f"only {have} of the {m} {what} asked for satisfy the constraints "
                      f"after {attempts} targets drawn in the {spec.volume.describe()} with tilt "
                      f"<= {math.degrees(spec.max_tilt):g} deg ({rej.not_reached} not reached, "
                      f"{rej.branch} on another branch, {rej.collision} colliding): {advice}; "
                      f"or ask for fewer {what}")
