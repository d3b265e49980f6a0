"""The one Pinocchio boundary: a robot loaded from URDF and the chain from base to tip.

:class:`Robot` owns the ``pin.Model`` and answers kinematic questions by frame name.
Everything else in kincal (MD-H layer, identification, statistics) is plain numpy and
talks to Pinocchio only through this class (and :mod:`kincal.collision`, its collision
geometry, and :mod:`kincal.gravity`, its links' weights).

Frames: the *base frame* B and the *tip frame* E are any two link or joint frames of the
URDF (base default: the root link). The chain follows the tree path between them: from B
*up* to their common ancestor link, then *down* to E. Chain joints are the movable joints
on that path in that order; the ones on the way up are *reversed*: traversed against
their URDF direction, each contributes inverse(origin * motion(q)) = motion(-q) *
inverse(origin). A humanoid standing on its foot is the chain from the sole (a leaf of
the tree) up the leg and down an arm. Joint values are always the URDF's own, in the
joint's unit: radians for revolute and continuous joints, metres for prismatic ones.
"""

from __future__ import annotations

import functools
import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from kincal import descriptions
from kincal.errors import (ChainError, DataError, FrameError, KincalWarning, UrdfError,
                           listing, suggest)
from kincal.gravity import gravity_torques as _gravity_torques
from kincal.models.geometry import ChainGeometry
from kincal.rotations import inverse
from kincal.urdf_source import read_urdf_text, stderr_captured

_REVOLUTE = {"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"}
_CONTINUOUS = {"JointModelRUBX", "JointModelRUBY", "JointModelRUBZ",
               "JointModelRevoluteUnboundedUnaligned"}
_PRISMATIC = {"JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"}


def _build_model(text: str, path) -> pin.Model:
    """Pinocchio's model of the URDF ``text``; urdfdom's failure (its reason on stderr,
    Pinocchio's generic "not a valid URDF model") becomes one UrdfError line with the
    reason and the URDF line of the joint or link it names when that can be found."""
    try:
        with stderr_captured() as captured:
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
    return pin.SE3(np.ascontiguousarray(T, dtype=float))  # its [R | t] as given, to the bit


def _mat(M: pin.SE3) -> np.ndarray:
    return np.array(M.homogeneous)


class Robot:
    """A URDF robot in Pinocchio with a chosen chain from ``base`` to ``tip`` (any two
    frames: the chain follows the tree path between them, see the module notes).

    Build with :meth:`load`. A Robot is never modified: :meth:`with_joint_frames`
    returns a corrected copy that shares the original URDF text. ``xacro_args``: sorted
    (name, value) pairs a xacro source was expanded with (the files' provenance).
    """

    def __init__(self, model: pin.Model, urdf_text: str, name: str, base: str, tip: str,
                 source: Path | None = None, joint_values: dict | None = None, xacro_args=()):
        self.model, self.urdf_text, self.name, self.source = model, urdf_text, name, source
        self.xacro_args = tuple(sorted((str(k), str(v)) for k, v in dict(xacro_args).items()))
        self.base, self.tip = base, tip
        self._base_id, self._tip_id = self._frame_id(base, "base"), self._frame_id(tip, "tip")
        self._chain, self._reversed = self._find_chain()
        # (base joint frame in B, (n, 4, 4) parent links, tip frame): corrected copies share it
        self._links = (inverse(_mat(model.frames[self._base_id].placement)),
                       np.array([self._parent_link(j) for j in self._chain]),
                       _mat(model.frames[self._tip_id].placement))
        self.geometry = self._compute_geometry()
        self.off_chain = self._check_off_chain(joint_values or {})

    @functools.cached_property
    def _data(self) -> pin.Data:  # Pinocchio's workspace, when first used (not every copy is)
        return self.model.createData()

    @functools.cached_property
    def mimics(self) -> dict[str, tuple[str, float, float]]:
        """{joint: (master, multiplier, offset)} of the URDF's ``<mimic>`` tags: the joint's
        value is multiplier * master + offset. Pinocchio reads such a joint as an independent
        one; :mod:`kincal.measurements.fixed_joints` gives it its value when a file has no
        column for it, and warns when its column says otherwise."""
        from kincal.urdf_source import urdf_tree

        out = {}
        for joint in urdf_tree(self.urdf_text).findall("joint"):
            m = joint.find("mimic")
            if m is not None and m.get("joint"):
                try:
                    k, o = float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0))
                except ValueError:
                    raise UrdfError(f"{self.source}: the <mimic> of joint {joint.get('name')!r}"
                                    " needs numbers as multiplier and offset") from None
                out[str(joint.get("name"))] = (str(m.get("joint")), k, o)
        return out

    @property
    def model_name(self) -> str:
        """The robot's name in its URDF (``<robot name=...>``), whatever the file is called."""
        return str(self.model.name)

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, robot: str | Path, tip: str | None = None, base: str | None = None,
             joint_values: dict | None = None, xacro_args: dict | None = None) -> "Robot":
        """Load a URDF (or xacro: ``xacro_args`` {name: value}) path, ``"ec66"``, or an
        example-robot-data name (``"ur10"``, ...). ``tip`` defaults to the description's
        usual tip frame when known; ``base`` to the URDF root link. Any two frames of the URDF
        may be base and tip: the chain follows the tree path between them.
        ``joint_values``: {name: value} for joints off the chain."""
        desc = descriptions.resolve(robot)
        text = read_urdf_text(desc.urdf, xacro_args)
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
                   joint_values=joint_values, xacro_args=xacro_args or {})

    @staticmethod
    def _leaf_links(model: pin.Model) -> list[str]:
        parents = {f.parentFrame for f in model.frames}
        return [f.name for i, f in enumerate(model.frames)
                if f.type == pin.FrameType.BODY and i not in parents]

    def frame_names(self) -> list[str]:
        """Base or tip names: the URDF's links and joints (not Pinocchio's frame 0, universe)."""
        return [f.name for f in list(self.model.frames)[1:]
                if f.type in (pin.FrameType.BODY, pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT)]

    def _frame_id(self, name: str, role: str) -> int:
        if not isinstance(name, str) or name not in self.frame_names():
            valid = self.frame_names()
            raise FrameError(f"unknown {role} frame {name!r} in robot {self.name!r}."
                             + suggest(str(name), valid) + f" Valid frames: {listing(valid)}",
                             valid=tuple(valid))
        # a link may share its name with a joint (so100's gripper): the link is meant
        return min((i for i, f in enumerate(self.model.frames) if f.name == name),
                   key=lambda i: self.model.frames[i].type != pin.FrameType.BODY)

    def _ancestors(self, joint: int) -> list[int]:
        """``joint``, its parent joint, ..., up to the universe (0) included."""
        out = [joint]
        while out[-1]:
            out.append(self.model.parents[out[-1]])
        return out

    def _find_chain(self) -> tuple[list[int], list[bool]]:
        """Movable joints base -> common ancestor (reversed) -> tip, and reversed flags."""
        m = self.model
        if self.base == self.tip:
            raise FrameError(f"base and tip are the same frame {self.base!r}: a chain needs two "
                             "frames (the tip anywhere else on the robot)")
        up_b = self._ancestors(m.frames[self._base_id].parentJoint)
        up_e = self._ancestors(m.frames[self._tip_id].parentJoint)
        common = next(j for j in up_b if j in set(up_e))
        up, down = up_b[:up_b.index(common)], up_e[:up_e.index(common)][::-1]
        chain = up + down
        if not chain:
            raise ChainError(f"no movable joint between base {self.base!r} and tip {self.tip!r}")
        for j in chain:
            kind = m.joints[j].shortname()
            if kind not in _REVOLUTE | _CONTINUOUS | _PRISMATIC:
                valid = [f.name for f in m.frames if f.parentJoint == j
                         and f.type in (pin.FrameType.BODY, pin.FrameType.JOINT)]
                raise ChainError(f"joint {m.names[j]!r} on the chain {self.base!r} -> {self.tip!r} "
                                 f"is a {kind}; kincal models revolute, continuous and prismatic "
                                 "joints only: choose a base and a tip whose tree path avoids it "
                                 f"(e.g. both below it: {listing(valid)})")
        return chain, [True] * len(up) + [False] * len(down)

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

    def off_chain_movers(self, names) -> tuple[str, ...]:
        """Of the URDF joints ``names``, those off the chain that can move the measured
        point against the base: below the tip's link in the tree (the point lies further
        out than the tip) or above the base (the data's frame lies beyond it). A joint on
        another branch moves neither. Names that are no URDF joint are left out."""
        m = self.model
        tip = m.frames[self._tip_id].parentJoint
        above_base = set(self._ancestors(m.frames[self._base_id].parentJoint))
        chain = set(self.joint_names)
        return tuple(n for n in names if isinstance(n, str) and n not in chain
                     and m.existJointName(n) and (tip in self._ancestors(m.getJointId(n))
                                                  or m.getJointId(n) in above_base))

    @property
    def base_id(self) -> int:
        """Pinocchio frame id of the base frame."""
        return self._base_id

    def chain_joints_between(self, a: int, b: int) -> int:
        """How many chain joints (moving their links apart) lie between Pinocchio joints a, b."""
        return len((set(self._ancestors(a)) ^ set(self._ancestors(b))) & set(self._chain))

    def first_moving_joint(self) -> int:
        """Pinocchio joint whose link is the first the chain moves relative to the base."""
        return self.model.parents[self._chain[0]] if self._reversed[0] else self._chain[0]

    # ----------------------------------------------------------------- geometry
    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.model.names[j] for j in self._chain)

    def _parent_link(self, j: int) -> np.ndarray:
        """Pose of joint j's URDF parent link frame in its parent joint's frame."""
        m = self.model
        fid = m.getFrameId(m.names[j], pin.FrameType.JOINT)
        return _mat(m.frames[m.frames[fid].parentFrame].placement)

    def _compute_geometry(self, same: ChainGeometry | None = None, placements=None) -> ChainGeometry:
        """The chain's geometry from the model; ``same``: that of a model with other joint
        placements only (its axes, kinds and limits kept); ``placements``: (n, 4, 4) those
        of the chain joints just written into the model (it gives them back to the bit)."""
        m = self.model
        T, links, tip = self._links
        P = [_mat(m.jointPlacements[j]) for j in self._chain] if placements is None else placements
        frames, at = np.empty((len(P), 4, 4)), np.empty((len(P), 4, 4))  # at: before links
        for i, rev in enumerate(self._reversed):
            if rev:  # climbing: joint i's frame is where we stand; its parent joint is next
                frames[i] = T
                T = at[i] = T @ inverse(P[i])
            else:
                at[i] = T
                T = frames[i] = T @ P[i]
        parents = at @ links
        if same is not None:  # the placements alone differ
            return replace(same, joint_frames=frames, T_base_tip=T @ tip, parent_frames=parents)
        axes, kinds = zip(*[self._axis(j) for j in self._chain])  # each in its own frame
        axes = [-a if rev else a for a, rev in zip(axes, self._reversed)]
        # Pinocchio stores "no limit" as +-max double; a continuous joint (nq = 2) has none
        iq = [m.joints[j].idx_q for j in self._chain]
        free = np.array([m.joints[j].nq == 2 for j in self._chain])
        lo, hi = np.array(m.lowerPositionLimit)[iq], np.array(m.upperPositionLimit)[iq]
        lower = np.where(free | (lo <= -1e300), -np.inf, lo)
        upper = np.where(free | (hi >= 1e300), np.inf, hi)
        flips = np.array(self._reversed, dtype=bool)
        flips.flags.writeable = False
        return ChainGeometry(self.joint_names, tuple(kinds), frames, np.array(axes), T @ tip,
                             lower, upper, parents, flips if flips.any() else None)

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
        """Pinocchio q for chain joint values (n,) [rad or m]; joints off the chain take the
        values given at load time (``joint_values``), or neutral (they place the chain in
        the world, e.g. for a viewer, without moving the tip relative to the base)."""
        q = pin.neutral(self.model)
        values = np.asarray(joint_values, dtype=float)
        if values.shape != (len(self._chain),):  # zip below would truncate silently
            raise DataError(f"joint values must be ({len(self._chain)},) for "
                            f"{', '.join(self.joint_names)}, got shape {values.shape}")
        ids = [self.model.getJointId(n) for n in self.off_chain]
        for j, v in zip(self._chain + ids, list(values) + list(self.off_chain.values())):
            jm = self.model.joints[j]
            if jm.nq == 2:
                q[jm.idx_q:jm.idx_q + 2] = (np.cos(v), np.sin(v))
            else:
                q[jm.idx_q] = v
        return q

    def tip_poses(self, joint_values) -> np.ndarray:
        """(N, 4, 4) poses of the tip frame in the base frame for (N, n) joint values: the
        Pinocchio reference (a loop) that tests check the vectorised models against."""
        Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
        out = np.empty((len(Q), 4, 4))
        for k, qk in enumerate(Q):
            pin.framesForwardKinematics(self.model, self._data, self.configuration(qk))
            out[k] = _mat(self._data.oMf[self._base_id].actInv(self._data.oMf[self._tip_id]))
        return out

    gravity_torques = _gravity_torques  # (N, n) per chain joint [N m]: kincal.gravity

    def tip_jacobian(self, joint_values) -> np.ndarray:
        """(6, n) Pinocchio Jacobian of the tip relative to the base for chain joint values
        (n,): rows 0-2 the velocity of the tip origin, rows 3-5 the angular velocity, both
        relative to the base frame and in its axes, per chain joint velocity. The reference
        for the vectorised numpy kinematics of :mod:`kincal.models.kinematics`."""
        return self._relative(self.configuration(joint_values))[1]

    def _relative(self, qp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T_B_E (4, 4), J (6, n)) at the Pinocchio configuration qp: the tip pose in the
        base frame and its Jacobian as in :meth:`tip_jacobian`. On a path that climbs the
        tree the base moves in Pinocchio's world too: its motion is subtracted."""
        m, d = self.model, self._data
        pin.computeJointJacobians(m, d, qp)
        pin.updateFramePlacements(m, d)
        cols = [m.joints[j].idx_v for j in self._chain]
        J = [np.asarray(pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED)).reshape(6, -1)[:, cols]
             for f in (self._base_id, self._tip_id)]
        oMb, oMe = d.oMf[self._base_id], d.oMf[self._tip_id]
        r = oMe.translation - oMb.translation
        v = J[1][:3] - J[0][:3] - np.cross(J[0][3:].T, r).T  # v_E - v_B - w_B x (p_E - p_B)
        Rb = oMb.rotation.T
        return _mat(oMb.actInv(oMe)), np.vstack([Rb @ v, Rb @ (J[1][3:] - J[0][3:])])

    # -------------------------------------------------------------- correction
    def with_joint_frames(self, joint_frames: np.ndarray) -> "Robot":
        """A copy whose chain joint frames at zero joint values are ``joint_frames`` (n, 4,
        4) T_B_Ji: only the chain joints' placements change (the original tree, never
        re-rooted). On a tree path a reversed joint's frame is its child link (base side): a
        change of its zero (a turn about, slide along, its axis) commutes with its motion and
        goes into its own origin; the first joint's link holds the base frame, any other
        change there is refused. The transform through the common ancestor link goes into
        the first down joint's origin (the top reversed joint's keeps its own, plus its zero).
        """
        m = pin.Model(self.model)
        C = np.array(joint_frames, dtype=float)
        N, r = self.geometry.joint_frames, int(self.geometry.is_reversed.sum())
        G = C.copy()  # the chain links' frames after moving own-axis parts up (reversed joints)
        for i in range(r):
            P_nom = N[i] if i == 0 else inverse(N[i - 1]) @ N[i]
            P_new = C[i] if i == 0 else inverse(C[i - 1]) @ C[i]
            D = inverse(P_nom) @ P_new  # change of the base-side link, in joint i's frame
            if self._is_offset(i, D):
                G[i] = C[i] @ inverse(D)
            elif i == 0:
                raise ChainError(f"the corrected frame of {self.joint_names[0]!r} moves the base "
                                 f"frame {self.base!r} within its link, which no URDF joint origin "
                                 "holds; an error model must leave the link of a reversed first "
                                 "joint in place")
        P = np.empty_like(C)  # the chain joints' new placements, in chain order
        T_prev = self._links[0]  # the base joint frame, or (r > 0) the common ancestor joint's
        if r:
            P[:r - 1] = inverse(G[1:r]) @ G[:r - 1]
            T_prev = C[r - 1] @ inverse(_mat(self.model.jointPlacements[self._chain[r - 1]]))
            P[r - 1] = inverse(T_prev) @ G[r - 1]
        P[r:] = inverse(np.concatenate([T_prev[None], C[r:-1]])) @ C[r:]
        for j, X in zip(self._chain, P):
            m.jointPlacements[j] = _se3(X)
        out = object.__new__(Robot)  # the chain, its axes, kinds, limits and links are this
        out.__dict__.update({k: v for k, v in self.__dict__.items() if k != "_data"}, model=m)
        out.geometry = out._compute_geometry(self.geometry, P)  # robot's, the frames m's:
        return out  # Robot(m, ...)'s geometry to the bit (tests compare)

    def _is_offset(self, i: int, D: np.ndarray, tol: float = 1e-10) -> bool:
        """Whether the rigid change D (in joint i's frame) changes only joint i's zero: a
        turn about its axis line through the joint origin (revolute) or a slide along its
        axis (prismatic). Such a change commutes with the joint's motion."""
        a, R, t = self.geometry.axes[i], D[:3, :3], D[:3, 3]
        if self.geometry.kinds[i] == "prismatic":
            return bool(np.abs(R - np.eye(3)).max() < tol and np.abs(t - (t @ a) * a).max() < tol)
        return bool(np.abs(R @ a - a).max() < tol and np.abs(t).max() < tol)

    def urdf_origins(self, joints=None) -> dict[str, np.ndarray]:
        """URDF ``<origin>`` (pose of the joint in its parent link) of every chain joint, or
        of the movable URDF joints named in ``joints``."""
        ids = self._chain if joints is None else [self.model.getJointId(n) for n in joints]
        return {self.model.names[j]: inverse(self._parent_link(j)) @ _mat(self.model.jointPlacements[j])
                for j in ids}

    def with_origins(self, origins: dict) -> "Robot":
        """A copy whose URDF origins of the named movable joints (on this chain or not) are
        ``origins`` {joint: (4, 4) pose in its parent link} [m]: the writer of corrections
        per URDF origin, as several chains sharing joints identify them."""
        m = pin.Model(self.model)
        for name, T in origins.items():
            j = self.model.getJointId(name)
            m.jointPlacements[j] = _se3(self._parent_link(j) @ np.asarray(T, float))
        return Robot(m, self.urdf_text, self.name, self.base, self.tip, self.source, self.off_chain,
                     self.xacro_args)

    def parent_link(self, joint: str) -> str:
        """The URDF parent link of the movable joint ``joint``."""
        m = self.model
        fid = m.getFrameId(joint, pin.FrameType.JOINT)
        return m.frames[m.frames[fid].parentFrame].name

    def joint_axis(self, name: str) -> np.ndarray:
        """(3,) the URDF axis of the movable joint ``name`` in its own frame."""
        return self._axis(self.model.getJointId(name))[0]

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, base={self.base!r}, tip={self.tip!r}, joints={list(self.joint_names)})"

    # ---------------------------------------------------------- inverse kinematics
    def inverse_kinematics(self, position, tool=(0.0, 0.0, 0.0), rotation=None, start=None,
                           max_iterations: int = 200, tolerance: float = 1e-10):
        """Chain joint values putting the tool point at ``position`` in the base frame.

        position: (3,) [m]; tool: (3,) tool point in the tip frame [m]; rotation: optional
        (3, 3) orientation of the tip frame in the base frame; start: (n,) first guess.
        Damped least squares (the one step, kincal.models.kinematics.damped_least_squares),
        clipped to the joint limits. Returns (q (n,), converged)."""
        from kincal.models.kinematics import damped_least_squares
        g = self.geometry
        lo, hi = g.ranges()
        q = np.clip(np.zeros(g.n) if start is None else np.asarray(start, float), lo, hi)
        target, tool = np.asarray(position, float), np.asarray(tool, float)
        for _ in range(max_iterations):
            T, J = self._relative(self.configuration(q))
            R, rt = T[:3, :3], T[:3, :3] @ tool
            err, rows = [target - T[:3, 3] - rt], [J[:3] - np.cross(rt, J[3:].T).T]  # v + w x Rt
            if rotation is not None:
                err.append(pin.log3(np.asarray(rotation) @ R.T))
                rows.append(J[3:])
            e = np.concatenate(err)
            if np.linalg.norm(e) < tolerance:
                return q, True
            dq = damped_least_squares(np.vstack(rows)[None], e[None], 1e-8)[0]
            q = np.clip(q + dq, lo, hi)
        return q, False

    def changed_origins(self, corrected: "Robot", tol: float = 1e-14,
                        joints=None) -> dict[str, np.ndarray]:
        """URDF origins of ``corrected`` (the chain's, or ``joints``') more than ``tol`` off
        this robot's (the same arithmetic both sides: an unchanged one stays untouched)."""
        mine, theirs = self.urdf_origins(joints), corrected.urdf_origins(joints)
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
            T = f.placement if f.type == pin.FrameType.FIXED_JOINT else m.jointPlacements[
                f.parentJoint]  # a movable joint's relative to its parent joint
            out[f.name] = inverse(L) @ _mat(T)
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
