"""The one Pinocchio boundary: a robot loaded from URDF and the chain from base to tip.

:class:`Robot` owns the ``pin.Model`` and answers kinematic questions by frame name.
Everything else in kincal (MD-H layer, identification, statistics) is plain numpy and
talks to Pinocchio only through this class.

Frames: the *base frame* B is a link or joint frame of the URDF (default: the root
link); the *tip frame* E is any frame below it. Chain joints are the movable joints on
the path from B down to E, root first. Joint values are in the joint's own unit:
radians for revolute and continuous joints, metres for prismatic ones.
"""

from __future__ import annotations

import os
import re
import sys
import tempfile
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from kincal import descriptions
from kincal.errors import (ChainError, DataError, FrameError, KincalWarning, UrdfError,
                           listing, suggest)
from kincal.rotations import inverse
from kincal.urdf_source import read_urdf_text

_REVOLUTE = {"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"}
_CONTINUOUS = {"JointModelRUBX", "JointModelRUBY", "JointModelRUBZ",
               "JointModelRevoluteUnboundedUnaligned"}
_PRISMATIC = {"JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"}


@dataclass(frozen=True)
class ChainGeometry:
    """The chain at zero joint values, expressed in the base frame B.

    joint_names: the n movable chain joints, root first.
    kinds: "revolute" (revolute or continuous) or "prismatic", per joint.
    joint_frames: (n, 4, 4) T_B_Ji, pose of joint frame i (= its child link frame) [m].
    axes: (n, 3) unit joint axis of joint i in its own frame.
    T_base_tip: (4, 4) pose of the tip frame at zero joint values [m].
    lower, upper: (n,) joint limits [rad or m]; +-inf when the URDF gives none.
    parent_frames: (n, 4, 4) pose of each joint's parent link frame (the frame its URDF
        ``<origin>`` is written in) at zero joint values [m].
    """

    joint_names: tuple[str, ...]
    kinds: tuple[str, ...]
    joint_frames: np.ndarray
    axes: np.ndarray
    T_base_tip: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    parent_frames: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.joint_names)


@contextmanager
def _stderr_captured():
    """Collect what C++ code writes to file descriptor 2 (urdfdom's multi-line messages).

    Yields a list that receives the captured text when the block ends; fd 2 is restored
    whatever happens (an exception or a signal included).
    """
    sys.stderr.flush()
    out: list[str] = []
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield out
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            out.append(tmp.read(65536).decode("utf-8", errors="replace"))


def _build_model(text: str, path) -> pin.Model:
    """Pinocchio's model of the URDF ``text``; urdfdom's failure becomes one UrdfError line.

    urdfdom prints its reason on stderr (several lines, with a C++ source location) and
    Pinocchio raises a generic "not a valid URDF model"; the message here gives the
    reason, and the URDF line of the joint or link it names when that can be found.
    """
    try:
        with _stderr_captured() as captured:
            model = pin.buildModelFromXML(text)
    except Exception as exc:  # Pinocchio raises plain ValueError/RuntimeError
        said = " ".join(captured[0].split()) if captured else ""
        reason = re.sub(r"^(Error|Warning):\s*", "", said)
        reason = re.sub(r"\s*at line \d+ in \S+", "", reason)  # urdfdom's C++ source line
        # the first sentence of the first message: the later ones follow from it
        reason = re.split(r"\s(?:Error|Warning):\s", reason)[0].split(". ")[0].rstrip(".")
        reason = reason or str(exc)
        where = ""
        for name in re.findall(r"\[([^\]]+)\]", reason):  # the first named element found
            hit = re.search(r'<(?:joint|link)\s[^>]*name\s*=\s*["\']' + re.escape(name) + "[\"']",
                            text)
            if hit:
                where = f":{text.count(chr(10), 0, hit.start()) + 1}"
                break
        raise UrdfError(f"{path}{where}: not a valid URDF model: {reason}") from None
    said = " ".join(captured[0].split()) if captured else ""
    if said:  # a warning of urdfdom on a model it accepted: passed on, as one line
        said = re.sub(r"\s*at line \d+ in \S+", "", said)
        warnings.warn(f"{path}: the URDF parser says: {said}", KincalWarning)
    return model


def _se3(T: np.ndarray) -> pin.SE3:
    return pin.SE3(np.array(T[:3, :3]), np.array(T[:3, 3]))


def _mat(M: pin.SE3) -> np.ndarray:
    return np.array(M.homogeneous)


class Robot:
    """A URDF robot in Pinocchio with a chosen chain from ``base`` to ``tip``.

    Build with :meth:`load`. A Robot is never modified: :meth:`with_joint_frames`
    returns a corrected copy that shares the original URDF text.
    """

    def __init__(self, model: pin.Model, urdf_text: str, name: str, base: str, tip: str,
                 source: Path | None = None, joint_values: dict | None = None):
        self.model = model
        self.urdf_text = urdf_text
        self.name = name
        self.source = source
        self._data = model.createData()
        self.base = base
        self.tip = tip
        self._base_id = self._frame_id(base, "base")
        self._tip_id = self._frame_id(tip, "tip")
        self._chain = self._find_chain()
        self.geometry = self._compute_geometry()
        self.off_chain = self._check_off_chain(joint_values or {})

    @property
    def model_name(self) -> str:
        """The robot's name in its URDF (``<robot name=...>``), whatever the file is called."""
        return str(self.model.name)

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, robot: str | Path, tip: str | None = None, base: str | None = None,
             joint_values: dict | None = None) -> "Robot":
        """Load a URDF path, ``"ec66"``, or an example-robot-data name (``"ur10"``, ...).

        ``tip`` defaults to the description's usual tip frame when known; ``base`` to the
        URDF root link. ``joint_values``: {name: value} for joints off the chain.
        """
        desc = descriptions.resolve(robot)
        text = read_urdf_text(desc.urdf)
        model = _build_model(text, desc.urdf)
        root = next((f.name for f in model.frames if f.type == pin.FrameType.BODY), None)
        if root is None:
            raise UrdfError(f"{desc.urdf}: the URDF has no link")
        tip = tip or desc.default_tip
        if tip is None:
            leaves = cls._leaf_links(model)
            raise FrameError(f"{desc.urdf}: no tip frame given; choose one with --tip, e.g. one "
                             f"of the leaf links: {listing(leaves)}", valid=tuple(leaves))
        return cls(model, text, desc.name, base or root, tip, source=desc.urdf,
                   joint_values=joint_values)

    @staticmethod
    def _leaf_links(model: pin.Model) -> list[str]:
        parents = {f.parentFrame for f in model.frames}
        return [f.name for i, f in enumerate(model.frames)
                if f.type == pin.FrameType.BODY and i not in parents]

    def frame_names(self) -> list[str]:
        """Names usable as base or tip: links and joints of the URDF."""
        return [f.name for f in self.model.frames
                if f.type in (pin.FrameType.BODY, pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT)]

    def _frame_id(self, name: str, role: str) -> int:
        if not isinstance(name, str) or not self.model.existFrame(name):
            valid = self.frame_names()
            raise FrameError(f"unknown {role} frame {name!r} in robot {self.name!r}."
                             + suggest(str(name), valid) + f" Valid frames: {listing(valid)}",
                             valid=tuple(valid))
        return self.model.getFrameId(name)

    def _frames_below(self, joint: int) -> list[str]:
        below = []
        for f in self.model.frames:
            j = f.parentJoint
            while j not in (0, joint):
                j = self.model.parents[j]
            if j == joint and f.type in (pin.FrameType.BODY, pin.FrameType.JOINT):
                below.append(f.name)
        return below

    def _find_chain(self) -> list[int]:
        m = self.model
        jb = m.frames[self._base_id].parentJoint
        je = m.frames[self._tip_id].parentJoint
        chain, j = [], je
        while j != jb:
            if j == 0:
                valid = self._frames_below(jb)
                raise FrameError(f"tip frame {self.tip!r} is not below base frame {self.base!r}; "
                                 f"frames below the base: {listing(valid)}", valid=tuple(valid))
            chain.append(j)
            j = m.parents[j]
        chain.reverse()
        if not chain:
            raise ChainError(f"no movable joint between base {self.base!r} and tip {self.tip!r}")
        for j in reversed(chain):
            kind = m.joints[j].shortname()
            if kind not in _REVOLUTE | _CONTINUOUS | _PRISMATIC:
                valid = [f.name for f in m.frames if f.parentJoint == j
                         and f.type in (pin.FrameType.BODY, pin.FrameType.JOINT)]
                raise ChainError(f"joint {m.names[j]!r} on the chain {self.base!r} -> {self.tip!r} "
                                 f"is a {kind}; kincal models revolute, continuous and prismatic "
                                 f"joints only: choose a base below it, e.g. {listing(valid)}")
        return chain

    def _check_off_chain(self, values: dict) -> dict:
        """Values [rad or m] for joints off the chain; the others stay at neutral."""
        movable = [n for j, n in enumerate(self.model.names) if j > 0]
        if not hasattr(values, "items"):
            raise FrameError(f"joint_values must be a dict {{joint name: value}}, got "
                             f"{type(values).__name__}", valid=tuple(movable))
        off = {}
        for name, value in values.items():
            if name not in movable:
                raise FrameError(f"unknown joint {name!r} in joint values." + suggest(name, movable)
                                 + f" Joints: {listing(movable)}", valid=tuple(movable))
            if name in self.joint_names:
                raise FrameError(f"joint {name!r} is on the chain {self.base!r} -> {self.tip!r}; "
                                 "its values come with each sample, not as a fixed value")
            try:
                off[name] = float(value)
            except (TypeError, ValueError):
                raise FrameError(f"joint {name!r}: value {value!r} is not a number") from None
        return off

    # ----------------------------------------------------------------- geometry
    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.model.names[j] for j in self._chain)

    def _compute_geometry(self) -> ChainGeometry:
        m = self.model
        T_jb_B = _mat(m.frames[self._base_id].placement)
        T = inverse(T_jb_B)  # base joint frame expressed in B
        frames, axes, kinds, parents = [], [], [], []
        for j in self._chain:
            fid = m.getFrameId(m.names[j], pin.FrameType.JOINT)
            parents.append(T @ _mat(m.frames[m.frames[fid].parentFrame].placement))
            T = T @ _mat(m.jointPlacements[j])
            frames.append(T.copy())
            axis, kind = self._axis(j)
            axes.append(axis)
            kinds.append(kind)
        T_tip = T @ _mat(m.frames[self._tip_id].placement)
        lower, upper = [], []
        for j in self._chain:
            iq = m.joints[j].idx_q
            if m.joints[j].nq == 2:  # continuous: no limit
                lower.append(-np.inf), upper.append(np.inf)
            else:
                lo, hi = float(m.lowerPositionLimit[iq]), float(m.upperPositionLimit[iq])
                # Pinocchio stores "no limit" as +-max double
                lower.append(lo if lo > -1e300 else -np.inf)
                upper.append(hi if hi < 1e300 else np.inf)
        return ChainGeometry(self.joint_names, tuple(kinds), np.array(frames), np.array(axes),
                             T_tip, np.array(lower), np.array(upper), np.array(parents))

    def _axis(self, j: int) -> tuple[np.ndarray, str]:
        """Unit axis of joint j in its own frame, read from its motion subspace."""
        m, d = self.model, self._data
        q = pin.neutral(m)
        # 6 x nv in the joint frame; a model with nv = 1 comes back as a flat (6,) array
        J = np.asarray(pin.computeJointJacobian(m, d, q, j)).reshape(6, -1)
        col = J[:, m.joints[j].idx_v]
        kind = "prismatic" if m.joints[j].shortname() in _PRISMATIC else "revolute"
        axis = col[:3] if kind == "prismatic" else col[3:]
        return axis / np.linalg.norm(axis), kind

    # --------------------------------------------------------------- kinematics
    def configuration(self, joint_values) -> np.ndarray:
        """Pinocchio q for chain joint values (n,) [rad or m].

        Joints off the chain take the values given at load time (``joint_values``), or
        their neutral value. They cannot move the tip relative to the base, but they
        place the chain in the world (e.g. for a viewer).
        """
        q = pin.neutral(self.model)
        values = np.asarray(joint_values, dtype=float)
        if values.shape != (len(self._chain),):  # zip below would truncate silently
            raise DataError(f"joint values must be ({len(self._chain)},) for "
                            f"{', '.join(self.joint_names)}, got shape {values.shape}")
        ids = [self.model.getJointId(n) for n in self.off_chain]
        for j, v in zip(self._chain + ids, list(values)
                        + list(self.off_chain.values())):
            jm = self.model.joints[j]
            if jm.nq == 2:
                q[jm.idx_q:jm.idx_q + 2] = (np.cos(v), np.sin(v))
            else:
                q[jm.idx_q] = v
        return q

    def tip_poses(self, joint_values) -> np.ndarray:
        """(N, 4, 4) poses of the tip frame in the base frame for (N, n) joint values.

        Reference implementation through Pinocchio (a loop over samples); the
        identification uses the vectorised MD-H model, which tests check against this.
        """
        Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
        out = np.empty((len(Q), 4, 4))
        for k, qk in enumerate(Q):
            pin.framesForwardKinematics(self.model, self._data, self.configuration(qk))
            oMb = self._data.oMf[self._base_id]
            oMe = self._data.oMf[self._tip_id]
            out[k] = _mat(oMb.actInv(oMe))
        return out

    def tip_jacobian(self, joint_values) -> np.ndarray:
        """(6, n) Pinocchio frame Jacobian of the tip for chain joint values (n,): rows 0-2
        the velocity of the tip origin, rows 3-5 the angular velocity, both in base-frame
        axes, per chain joint velocity. The reference for the vectorised numpy kinematics
        of :mod:`kincal.models.kinematics`."""
        m, d = self.model, self._data
        qp = self.configuration(joint_values)
        pin.framesForwardKinematics(m, d, qp)
        J = np.asarray(pin.computeFrameJacobian(m, d, qp, self._tip_id, pin.LOCAL_WORLD_ALIGNED))
        J = J.reshape(6, -1)[:, [m.joints[j].idx_v for j in self._chain]]
        Rb = d.oMf[self._base_id].rotation.T
        return np.vstack([Rb @ J[:3], Rb @ J[3:]])

    # -------------------------------------------------------------- correction
    def with_joint_frames(self, joint_frames: np.ndarray) -> "Robot":
        """A copy whose chain joint frames at zero joint values are ``joint_frames``.

        joint_frames: (n, 4, 4) T_B_Ji in the base frame. Only the placements of the
        chain joints change; every link stays rigidly attached to its joint frame.
        """
        m = pin.Model(self.model)
        T_prev = inverse(_mat(m.frames[self._base_id].placement))
        for j, T in zip(self._chain, np.asarray(joint_frames)):
            m.jointPlacements[j] = _se3(inverse(T_prev) @ T)
            T_prev = T
        return Robot(m, self.urdf_text, self.name, self.base, self.tip, self.source, self.off_chain)

    def urdf_origins(self) -> dict[str, np.ndarray]:
        """URDF ``<origin>`` (pose of the joint in its parent link) of every chain joint."""
        m = self.model
        out = {}
        for j in self._chain:
            fid = m.getFrameId(m.names[j], pin.FrameType.JOINT)
            parent_link = m.frames[m.frames[fid].parentFrame]
            out[m.names[j]] = inverse(_mat(parent_link.placement)) @ _mat(m.jointPlacements[j])
        return out

    def __repr__(self) -> str:
        return (f"Robot({self.name!r}, base={self.base!r}, tip={self.tip!r}, "
                f"joints={list(self.joint_names)})")

    # ---------------------------------------------------------- inverse kinematics
    def inverse_kinematics(self, position, tool=(0.0, 0.0, 0.0), rotation=None, start=None,
                           max_iterations: int = 200, tolerance: float = 1e-10):
        """Chain joint values putting the tool point at ``position`` in the base frame.

        position: (3,) [m]; tool: (3,) tool point in the tip frame [m]; rotation: optional
        (3, 3) orientation of the tip frame in the base frame; start: (n,) first guess.
        Damped least squares, clipped to the joint limits. Returns (q (n,), converged).
        """
        m, d = self.model, self._data
        chain_v = [m.joints[j].idx_v for j in self._chain]
        g = self.geometry
        lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
        hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
        q = np.clip(np.zeros(g.n) if start is None else np.asarray(start, float), lo, hi)
        target = np.asarray(position, float)
        tool = np.asarray(tool, float)
        oMb = None
        for _ in range(max_iterations):
            qp = self.configuration(q)
            pin.framesForwardKinematics(m, d, qp)
            oMb = d.oMf[self._base_id]
            bMe = oMb.actInv(d.oMf[self._tip_id])
            R, p = bMe.rotation, bMe.translation
            pt = p + R @ tool
            err = [target - pt]
            Jw = np.asarray(pin.computeFrameJacobian(m, d, qp, self._tip_id,
                                                     pin.LOCAL_WORLD_ALIGNED)).reshape(6, -1)
            Jw = Jw[:, chain_v]
            Rb = oMb.rotation.T
            Jv, Jo = Rb @ Jw[:3], Rb @ Jw[3:]  # in base-frame axes
            rt = R @ tool
            Jp = Jv - np.cross(rt, Jo.T).T  # point velocity v + w x (R t)
            rows = [Jp]
            if rotation is not None:
                err.append(pin.log3(np.asarray(rotation) @ R.T))
                rows.append(Jo)
            e = np.concatenate(err)
            if np.linalg.norm(e) < tolerance:
                return q, True
            A = np.vstack(rows)
            dq = A.T @ np.linalg.solve(A @ A.T + 1e-8 * np.eye(len(e)), e)
            q = np.clip(q + dq, lo, hi)
        return q, False

    def changed_origins(self, corrected: "Robot", tol: float = 1e-14) -> dict[str, np.ndarray]:
        """URDF origins of ``corrected`` that differ from this robot's by more than ``tol``.

        Both sides come out of the same arithmetic, so a joint whose placement did not
        change compares equal to roundoff and its text in the URDF is left untouched.
        """
        mine, theirs = self.urdf_origins(), corrected.urdf_origins()
        return {name: T for name, T in theirs.items() if np.abs(T - mine[name]).max() > tol}

    def child_joint_origins(self, joint: str) -> dict[str, np.ndarray]:
        """URDF origins of the joints (movable or fixed) whose parent link is ``joint``'s child."""
        m = self.model
        jid = m.getFrameId(joint, pin.FrameType.JOINT)
        link = next(i for i, f in enumerate(m.frames)
                    if f.type == pin.FrameType.BODY and f.parentFrame == jid)
        L = _mat(m.frames[link].placement)
        out = {}
        for f in m.frames:
            if f.parentFrame != link or f.type not in (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT):
                continue
            if f.type == pin.FrameType.JOINT:
                T = _mat(m.jointPlacements[f.parentJoint])  # relative to the parent joint
            else:
                T = _mat(f.placement)
            out[f.name] = inverse(L) @ T
        return out

    def link_of(self, frame: str) -> tuple[str, np.ndarray]:
        """(URDF link, pose of ``frame`` in that link) for a link or joint frame name."""
        m = self.model
        fid = self._frame_id(frame, "frame")
        f = m.frames[fid]
        if f.type == pin.FrameType.BODY:
            return f.name, np.eye(4)
        # a joint frame coincides with its child link's frame
        child = next(i for i, g in enumerate(m.frames)
                     if g.type == pin.FrameType.BODY and g.parentFrame == fid)
        return m.frames[child].name, np.eye(4)

    # ---------------------------------------------------------------- collisions
    def collision_checker(self, floor_z: float | None = None) -> "CollisionChecker":
        """Self-collision (and floor) checks of chain configurations; see CollisionChecker."""
        return CollisionChecker(self, floor_z)


class CollisionChecker:
    """Which chain configurations collide, from the URDF's ``<collision>`` geometry (coal).

    Pairs checked: two geometries of links that the chain moves relative to each other
    (at least one below a chain joint), except links attached to the same joint or to a
    parent and child joint (adjacent links touch by design), and except pairs already in
    contact at zero joint values (overlapping meshes, which an SRDF would disable). With
    ``floor_z`` [m], also a floor: the half-space below z = floor_z of the base frame,
    against every geometry the chain moves except the first chain link (it stands on
    the base).
    Meshes are checked as their convex hulls.
    ``has_geometry`` is False when the URDF has no collision geometry; nothing is then
    checked here and :meth:`colliding` is all False (callers say so).
    """

    def __init__(self, robot: Robot, floor_z: float | None = None):
        try:
            import coal
        except ImportError:  # Pinocchio 2.x ships the same library as hppfcl
            import hppfcl as coal

        m = robot.model
        self.robot = robot
        dirs = [str(p) for p in robot.source.parents] if robot.source is not None else []
        try:
            geom = pin.buildGeomFromUrdfString(m, robot.urdf_text, pin.COLLISION,
                                               package_dirs=dirs)
        except (ValueError, RuntimeError) as exc:
            raise UrdfError(f"{robot.source}: the collision geometry could not be loaded: {exc}"
                            ) from None
        self.has_geometry = geom.ngeoms > 0
        for obj in geom.geometryObjects:
            # meshes become their convex hulls: ~100x faster, and conservative (a pose the
            # hulls find free is free; one they find colliding may be a near miss)
            if isinstance(obj.geometry, coal.BVHModelBase):
                obj.geometry.buildConvexRepresentation(False)
                obj.geometry = obj.geometry.convex
        moved = set()
        for j in range(1, m.njoints):
            k = j
            while k > 0 and k not in robot._chain:
                k = m.parents[k]
            if k > 0:
                moved.add(j)
        objs = list(geom.geometryObjects)
        pairs = []
        for a in range(len(objs)):
            for b in range(a + 1, len(objs)):
                ja, jb = objs[a].parentJoint, objs[b].parentJoint
                if ja == jb or (ja not in moved and jb not in moved):
                    continue
                if m.parents[ja] == jb or m.parents[jb] == ja:
                    continue
                pairs.append((a, b))
        self.floor_z = floor_z
        if floor_z is not None and self.has_geometry:
            d = m.createData()
            pin.framesForwardKinematics(m, d, robot.configuration(np.zeros(robot.geometry.n)))
            oMb = d.oMf[robot._base_id]
            n_world = oMb.rotation @ np.array([0.0, 0.0, 1.0])
            # the solid is {x: n.x <= d}: everything below the floor plane
            half = coal.Halfspace(n_world, float(n_world @ oMb.translation) + float(floor_z))
            floor = geom.addGeometryObject(pin.GeometryObject("kincal_floor", 0, pin.SE3.Identity(),
                                                              half))
            # the first chain link stands on the base, and so on the floor
            pairs += [(k, floor) for k, o in enumerate(objs)
                      if o.parentJoint in moved and o.parentJoint != robot._chain[0]]
        for a, b in pairs:
            geom.addCollisionPair(pin.CollisionPair(a, b))
        self._geom, self._gdata, self._data = geom, pin.GeometryData(geom), m.createData()
        zero = self._pair_hits(np.zeros(robot.geometry.n))
        zero &= np.array([self._geom.geometryObjects[int(cp.second)].name != "kincal_floor"
                          for cp in geom.collisionPairs], dtype=bool)
        self.excluded = tuple(self._pair_name(k) for k in np.flatnonzero(zero))
        for k in sorted(np.flatnonzero(zero), reverse=True):
            geom.removeCollisionPair(geom.collisionPairs[int(k)])
        self._gdata = pin.GeometryData(geom)
        self.pairs = tuple(self._pair_name(k) for k in range(len(geom.collisionPairs)))

    def _pair_name(self, k: int) -> str:
        cp = self._geom.collisionPairs[int(k)]
        names = [self._geom.geometryObjects[i].name for i in (cp.first, cp.second)]
        return " / ".join(names)

    def _pair_hits(self, joint_values) -> np.ndarray:
        pin.computeCollisions(self.robot.model, self._data, self._geom, self._gdata,
                              self.robot.configuration(joint_values), False)
        return np.array([r.isCollision() for r in self._gdata.collisionResults], dtype=bool)

    def colliding(self, joint_values) -> np.ndarray:
        """(N,) True where the configuration (N, n) [rad or m] has a checked pair in contact."""
        Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
        out = np.zeros(len(Q), dtype=bool)
        if not self.pairs:
            return out
        m, d, g, gd = self.robot.model, self._data, self._geom, self._gdata
        for k, q in enumerate(Q):
            out[k] = pin.computeCollisions(m, d, g, gd, self.robot.configuration(q), True)
        return out
