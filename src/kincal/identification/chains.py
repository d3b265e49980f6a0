"""The chains of a calibration: one robot chain, or several sharing the joints they traverse.

A humanoid's two arms share its torso; a dual-arm cell's arms share a base. Each measurement
set is measured on its own chain (a :class:`kincal.robot.Robot` of one URDF, any base and
tip), evaluated by its own chain's error model; the kinematic block of the parameter vector
is the *union* of the chains' parameter names, in order of first appearance, so a joint on
several chains has one set of parameters, and each chain's Jacobian columns land on the
union's by name (:class:`MappedKind`).

That needs parameters that belong to URDF joints whatever chain traverses them:
``placement`` (six errors per URDF origin, the default with several chains, built with
every traversed origin's errors: what is redundant over the union is left to the
rank-revealing selection of ``analyze()``) or ``offsets`` (one zero per joint). The MD-H
models (``complete``, ``mdh``) parametrise one chain's frames, base to tip: refused with
several chains. The corrected robot is the ONE original URDF with every corrected origin
(:meth:`Chains.corrected`), written through :meth:`kincal.robot.Robot.with_origins`.

One chain (the usual case) is the same object with an identity map: its kinds are the kind
models themselves and its model the chain's, any error model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal import models as error_models
from kincal.errors import ChainError, OptionError, ParameterError, listing, suggest
from kincal.measurements.sets import CONTACT_KINDS, kind_model
from kincal.models.base import ErrorModel
from kincal.robot import Robot

JOINT_MODELS = ("placement", "offsets")  # whose parameters belong to URDF joints


@dataclass(frozen=True)
class UnionModel:
    """The kinematic parameters of several chains: names, units, classes and nominal values
    (the union of the chains' error models, first appearance order) and the union of their
    joints. It has no kinematics of its own: each set is evaluated on its chain's model."""

    name: str
    joint_names: tuple[str, ...]
    kinds: tuple[str, ...]
    names: tuple[str, ...]
    nominal: np.ndarray
    is_length: np.ndarray
    classes: tuple[str, ...]
    notes: tuple[str, ...]

    @property
    def n(self) -> int:
        return len(self.joint_names)

    @property
    def size(self) -> int:
        return len(self.names)

    def describe(self) -> str:
        return (f"error model {self.name} over several chains: {self.size} kinematic parameters "
                f"on {self.n} joints")


def _corrected_joints(model) -> tuple[str, ...]:
    """The joints whose origins an error model's parameters correct, in its chain order."""
    return tuple(dict.fromkeys(n.rsplit(".", 1)[0] for n in model.names))


class MappedKind:
    """A kind model of one chain seen through the union: it takes and gives the union's
    kinematic vector and backlash values (``idx``: the chain's parameters in the union;
    ``bpos``: its backlash terms in the layout's). Everything else is the kind model's."""

    def __init__(self, inner, idx: np.ndarray, bpos: np.ndarray, p: int, nb: int):
        self.__dict__.update(inner=inner, idx=idx, bpos=bpos, p=p, nb=nb)

    def __getattr__(self, name):
        return getattr(self.__dict__["inner"], name)

    def residuals(self, kin, frames, backlash, jacobian=False, kinematic=True):
        out = self.inner.residuals(np.asarray(kin)[self.idx], frames,
                                   np.asarray(backlash)[self.bpos], jacobian, kinematic)
        if not jacobian:
            return out
        r, Jk, Jf, Jb = out
        K = np.zeros(Jk.shape[:2] + (self.p,))
        K[..., self.idx] = Jk
        B = np.zeros(Jb.shape[:2] + (self.nb,))
        B[..., self.bpos] = Jb
        return r, K, Jf, B

    def start(self, kin, *args):
        return self.inner.start(np.asarray(kin)[self.idx], *args)

    def check_fixable(self, kin, *args):
        return self.inner.check_fixable(np.asarray(kin)[self.idx], *args)

    def subset(self, rows) -> "MappedKind":
        return MappedKind(self.inner.subset(rows), self.idx, self.bpos, self.p, self.nb)


class Chains:
    """The chains of a calibration (module notes). robots: one Robot for every set, or one
    per set (``n_sets``); model: the error model's name, None for the default."""

    def __init__(self, robots, n_sets: int, model: str | None = None):
        robots = list(robots) if isinstance(robots, (list, tuple)) else [robots]
        for k, r in enumerate(robots):
            if not isinstance(r, Robot):
                raise OptionError(f"robot {k + 1} must be a Robot (Robot.load(urdf, base=, tip=))"
                                  f", got {type(r).__name__}")
        if len(robots) not in (1, n_sets):
            raise OptionError(f"{len(robots)} robots for {n_sets} measurement sets: give one "
                              "robot (every set on its chain) or one per set")
        first = robots[0]
        for k, r in enumerate(robots[1:], start=2):
            if r.urdf_text != first.urdf_text or r.model_name != first.model_name:
                raise OptionError(
                    f"the robots of several chains must come from one URDF: robot {k} is "
                    f"{r.model_name!r} from {r.source}, robot 1 {first.model_name!r} from "
                    f"{first.source}")
        self.robots = tuple(robots) * (n_sets if len(robots) == 1 else 1)
        keys = list(dict.fromkeys((r.base, r.tip) for r in self.robots))
        self.of_set = tuple(keys.index((r.base, r.tip)) for r in self.robots)
        self.chain_robots = tuple(self.robots[self.of_set.index(c)] for c in range(len(keys)))
        if len(keys) == 1:
            self.model_name = model or error_models.default_for(first.geometry)
            self.models: tuple[ErrorModel, ...] = (
                error_models.build(self.model_name, first.geometry),)
            self.model: ErrorModel | UnionModel = self.models[0]
            self.idx: tuple[np.ndarray, ...] = (np.arange(self.model.size),)
            return
        self.model_name = model or "placement"
        if self.model_name not in JOINT_MODELS:
            raise OptionError(
                f"error model {self.model_name} cannot calibrate several chains: its parameters "
                "describe one chain's frames from its base to its tip, not URDF joints that "
                f"chains share; choose one of {', '.join(JOINT_MODELS)} (default placement)")
        from kincal.models import offsets, placement

        self.models = tuple(placement.build(r.geometry, every_origin=True)
                            if self.model_name == "placement" else offsets.build(r.geometry)
                            for r in self.chain_robots)
        self._check_origins()
        names = tuple(dict.fromkeys(n for m in self.models for n in m.names))
        self.idx = tuple(np.array([names.index(n) for n in m.names], int) for m in self.models)
        joints = tuple(dict.fromkeys(j for m in self.models for j in m.joint_names))
        kinds = {j: k for m in self.models for j, k in zip(m.joint_names, m.kinds)}
        first_of: dict[str, tuple[ErrorModel, int]] = {}
        for m in self.models:
            for k, n in enumerate(m.names):
                first_of.setdefault(n, (m, k))
        self.model = UnionModel(
            self.model_name, joints, tuple(kinds[j] for j in joints), names,
            np.array([first_of[n][0].nominal[first_of[n][1]] for n in names]),
            np.array([bool(first_of[n][0].is_length[first_of[n][1]]) for n in names]),
            tuple(first_of[n][0].classes[first_of[n][1]] for n in names),
            tuple(dict.fromkeys(n for m in self.models for n in m.notes if n)))

    def _check_origins(self) -> None:
        """A chain that ends climbing (its tip above its base, on the base's way up) cannot
        correct the origin of its last joint: refused when another chain corrects it."""
        owned = {j for m in self.models for j in _corrected_joints(m)}
        for r, m in zip(self.chain_robots, self.models):
            mine = set(_corrected_joints(m))
            lost = [j for j in m.joint_names if j not in mine and j in owned]
            if lost:  # any tip still reached by climbing through it keeps the origin lost
                link = r.parent_link(lost[0])
                raise ChainError(
                    f"the chain {r.base} -> {r.tip} ends climbing through {lost[0]}, whose "
                    f"origin (in {link}) lies between its last motion and its tip: it cannot "
                    "carry that origin's errors, which another chain corrects; give it a tip "
                    f"its path reaches through a movable joint down from {link} or a link "
                    "above it (the path then corrects that origin as the others do), or "
                    "calibrate that chain on its own (its tool frame then holds those errors)")

    @property
    def several(self) -> bool:
        return len(self.models) > 1

    @property
    def shared_joints(self) -> tuple[str, ...]:
        """The joints whose origins more than one chain corrects (a humanoid's torso under
        both arms), in the union's order; () for one chain."""
        counts: dict[str, int] = {}
        for m in self.models:
            for j in _corrected_joints(m):
                counts[j] = counts.get(j, 0) + 1
        return tuple(j for j, k in counts.items() if k > 1)

    @property
    def preference(self) -> tuple[str, ...]:
        """The joints in the identifiability analysis's order of preference, the same
        whatever the order of the chains (data files): each chain's own joints from its tip
        back, the chains by their (base, tip) names, then the shared joints, deepest in the
        URDF tree first (:func:`kincal.identification.selection.preference_order`); () for
        one chain (its default order, the same)."""
        if not self.several:
            return ()
        shared = set(self.shared_joints)
        chains = sorted(zip(self.chain_robots, self.models), key=lambda rm: (rm[0].base,
                                                                             rm[0].tip))
        own = [j for _, m in chains for j in reversed(_corrected_joints(m)) if j not in shared]
        tree = list(self.robot.model.names)  # the URDF tree's joints, parents first
        return tuple(own) + tuple(sorted(shared, key=tree.index, reverse=True))

    @property
    def robot(self) -> Robot:
        """The first set's robot (what one-chain readers of a result look at)."""
        return self.robots[0]

    def off_chain_columns(self, datas) -> tuple[tuple[str, ...], tuple[str, ...], int]:
        """Of the columns the sets ``datas`` (one per set) ignore, those named after URDF
        joints off every chain: (those that can move a set's measured point, below its tip
        or above its base (:meth:`kincal.robot.Robot.off_chain_movers`); those on other
        branches of the tree, which cannot, the branches nearest a base first; how many of
        those hang from a base's own link (no chain joint between): a robot standing or
        rolling on them carries that base with them, and no chain joint sees it)."""
        on = set(self.model.joint_names)
        movers = tuple(dict.fromkeys(c for dt, r in zip(datas, self.robots)
                                     for c in r.off_chain_movers(dt.ignored_columns)
                                     if c not in on))
        names = set(self.robot.model.names)
        # the other branches' joints: how many chain joints lie between a base and each
        from_base = {c: min(r.chain_joints_between(r.model.frames[r.base_id].parentJoint,
                                                   r.model.getJointId(c)) for r in self.robots)
                     for dt in datas for c in dt.ignored_columns
                     if c in names and c not in on and c not in movers}
        ordered = tuple(sorted(from_base, key=from_base.__getitem__))
        return movers, ordered, sum(d == 0 for d in from_base.values())

    def backlash(self, joints, term: str = "backlash") -> tuple[str, ...]:
        """The backlash (or compliance) joints ``joints`` checked and in the union's joint
        order."""
        chain = tuple(self.model.joint_names)
        unknown = [j for j in joints if j not in chain]
        if unknown:
            raise ParameterError(f"no chain joint {unknown[0]!r} for a {term} term."
                                 + suggest(unknown[0], chain)
                                 + f" Chain joints: {listing(chain, 60)}", valid=chain)
        kinds = dict(zip(chain, self.model.kinds))
        sliding = [j for j in joints if kinds[j] == "prismatic"]
        if term == "compliance" and sliding:
            raise ParameterError(f"{sliding[0]} is prismatic: a compliance term turns a revolute "
                                 "joint in proportion to the gravity torque it carries; choose "
                                 "revolute joints for --compliance")
        return tuple(j for j in chain if j in set(joints))

    def kind(self, i: int, data, backlash: tuple[str, ...], compliance: tuple[str, ...] = ()):
        """The kind model of set i on its chain (mapped into the union with several); the
        joint terms are the backlash terms, then the compliance terms (their gravity
        torques from set i's robot, :meth:`kincal.robot.Robot.gravity_torques`)."""
        c = self.of_set[i]
        em = self.models[c]
        chain = tuple(em.joint_names)
        mine = tuple(j for j in backlash if j in chain)
        soft = tuple(j for j in compliance if j in chain)
        torque = (self.robots[i].gravity_torques(data.for_chain(chain).joint_values)
                  if soft else None)
        km = kind_model(em, data, tuple(chain.index(j) for j in mine),
                        tuple(chain.index(j) for j in soft), torque)
        if not self.several:
            return km
        pos = [backlash.index(j) for j in mine] + [len(backlash) + compliance.index(j)
                                                   for j in soft]
        return MappedKind(km, self.idx[c], np.array(pos, int), self.model.size,
                          len(backlash) + len(compliance))

    def torques(self, q, joints) -> np.ndarray | None:
        """(N, n) the first chain's gravity torques at joint values q [N m]; None when no
        ``joints`` have a compliance term."""
        return self.robot.gravity_torques(q) if joints else None

    @staticmethod
    def torque_rms(kinds, joints) -> tuple[float, ...]:
        """(k,) RMS gravity torque of each of ``joints`` (compliance joints) over the
        samples of ``kinds`` [N m]; OptionError for one that carries none (no inertials in
        the URDF beyond it, or an axis along gravity): its compliance is not identifiable."""
        from kincal.models.compliance import MIN_TORQUE, torque_rms

        out = []
        for j in joints:
            t = np.concatenate([km.chain.torque[:, km.error_model.joint_names.index(j)]
                                for km in kinds if j in km.error_model.joint_names])
            rms = float(torque_rms(t))
            if not rms > MIN_TORQUE:
                raise OptionError(
                    f"{j}.compliance: the joint carries no gravity torque in these samples "
                    f"(RMS {rms:.2g} N m): the URDF has no inertials beyond it, or its axis "
                    "stays along gravity; no compliance term for it")
            out.append(rms)
        return tuple(out)

    def shared_planes(self, kinds) -> tuple[tuple[int, ...], ...]:
        """The layout's aliases (:class:`kincal.identification.layout.ParameterLayout`) when
        the files touch the same physical planes: every plane or flush set's plane
        parameters (``plane.*``, or ``plane<label>.*`` per label of a ``plane`` column) are
        those of the first such set with that name. A plane is fitted in its chain's base
        frame: sets on chains with different bases are refused, and so is a request that
        shares nothing (one contact file, or no plane name in two: it would be ignored)."""
        owner: dict[str, int] = {}
        out, shared = [], False
        for i, km in enumerate(kinds):
            row = []
            for name in km.frame_names:
                j = owner.setdefault(name, i) if (km.kind in CONTACT_KINDS
                                                  and name.startswith("plane")) else i
                if j != i and self.robots[j].base != self.robots[i].base:
                    raise OptionError(
                        f"--shared-plane: set {i + 1} ({km.data.source}) is measured from base "
                        f"{self.robots[i].base!r}, set {j + 1} from {self.robots[j].base!r}; a "
                        "plane is fitted in its chain's base frame, so only sets of chains "
                        "with one base can share it (give those chains one --base)")
                row.append(-1 if j == i else j)
                shared |= j != i
            out.append(tuple(row))
        if not shared:
            named = [f"set {i + 1} ({km.data.source}): " + " ".join(
                sorted({n.split(".")[0] for n in km.frame_names if n.startswith("plane")}))
                for i, km in enumerate(kinds) if km.kind in CONTACT_KINDS]
            raise OptionError("--shared-plane: no plane is named in two contact files, "
                              "nothing to share (" + ("; ".join(named) if len(named) > 1 else
                                                      f"one contact file, {named[0]}" if named
                                                      else "no contact file")
                              + "); a plane column's numbers name the same plane in every "
                              "file, a file without one touches 'plane'")
        return tuple(out)

    def chain_of(self, i: int):
        """(error model, (p_c,) its parameters' positions in the union) of set i's chain."""
        c = self.of_set[i]
        return self.models[c], self.idx[c]

    def origins(self, kin: np.ndarray) -> dict[str, np.ndarray]:
        """{joint: (4, 4) corrected URDF origin} of every origin the chains correct [m]."""
        from kincal.models.offsets import OffsetsModel
        from kincal.models.placement import PlacementModel

        out = {}
        for m, idx in zip(self.models, self.idx):
            assert isinstance(m, (PlacementModel, OffsetsModel))  # the models of JOINT_MODELS
            out.update(m.urdf_origins(np.asarray(kin)[idx]))
        return out

    def corrected(self, kin: np.ndarray, i: int = 0) -> Robot:
        """Set i's robot (the first set's by default) with the identified kinematics ``kin``
        (the union's): one chain through its joint frames, several through every corrected
        URDF origin."""
        if not self.several:
            assert isinstance(self.model, ErrorModel)  # one chain: its own model
            return self.robot.with_joint_frames(self.model.joint_frames(kin))
        return self.robots[i].with_origins(self.origins(kin))

    def generic_poses(self, model_name: str, layout, K: int):
        """The first chain's measurement model at 2p seeded generic poses (random joint
        values over the limits, each with K measured points): the structural analysis's
        (:meth:`kincal.identification.problem.CalibrationProblem.structural`), the same for
        every fit of this robot and kept per robot (:func:`kincal.models.per_geometry`)."""
        from kincal.measurements.point import MeasurementModel

        g, lay = self.robot.geometry, layout

        def poses():
            lo, hi = g.ranges()
            rng = np.random.default_rng(0)
            q = np.repeat(rng.uniform(lo, hi, size=(2 * lay.size, g.n)), K, axis=0)
            approach = np.repeat(rng.choice([-1.0, 1.0], size=(2 * lay.size, g.n)), K, axis=0)
            points = np.tile(np.arange(K), 2 * lay.size)
            return MeasurementModel(self.models[0], q, approach, lay.backlash, points, K,
                                    self.torques(q, lay.compliance), lay.compliance)

        return error_models.per_geometry(("structural poses", model_name, lay.size, K,
                                          lay.backlash, lay.compliance), g, poses)
