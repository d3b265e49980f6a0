"""Which chain configurations collide, from the URDF's ``<collision>`` geometry (coal).

The second module allowed to import Pinocchio (beside :mod:`kincal.robot`, whose model
it reads): Pinocchio places the geometry, coal tests it.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from kincal.errors import UrdfError


def _unloadable(source, dirs, exc) -> str:
    """The one-line refusal of collision geometry Pinocchio could not load (a mesh file
    missing, as in a description package checked out or exported without its meshes):
    what was expected, where package:// paths were looked for (``dirs``, then the
    variables Pinocchio reads itself), and the way to plan without the check."""
    why = " ".join(str(exc).split()).rstrip(".")
    above = f"the folders above the URDF ({dirs[0]} up to {dirs[-1]}), " if dirs else ""
    return (f"{source}: the collision geometry could not be loaded ({why}); expected each "
            f"mesh file where the URDF names it, package://PKG/FILE as PKG/FILE under "
            f"{above}ROS_PACKAGE_PATH or AMENT_PREFIX_PATH/share: put the meshes there, or "
            "give --no-collision to draw poses without the self-collision check")


class CollisionChecker:
    """Self-collision (and floor) checks of a robot's chain configurations.

    Pairs checked: two geometries of links that the chain moves relative to each other
    (chain joints on the tree path between them), except links attached to the same
    joint or to a parent and child joint (adjacent links touch by design), and except
    pairs already in contact at zero joint values (overlapping meshes, which an SRDF
    would disable). With ``floor_z`` [m], also a floor: the half-space below z = floor_z
    of the base frame, carried with the base frame, against every geometry the chain
    moves relative to the base except the first link that moves (it stands on the base).
    Meshes are checked as their convex hulls.
    ``has_geometry`` is False when the URDF has no collision geometry; nothing is then
    checked here and :meth:`colliding` is all False (callers say so).
    """

    def __init__(self, robot, floor_z: float | None = None):
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
            raise UrdfError(_unloadable(robot.source, dirs, exc)) from None
        self.has_geometry = geom.ngeoms > 0
        for obj in geom.geometryObjects:
            # meshes become their convex hulls: ~100x faster, and conservative (a pose the
            # hulls find free is free; one they find colliding may be a near miss)
            if isinstance(obj.geometry, coal.BVHModelBase):
                obj.geometry.buildConvexRepresentation(False)
                obj.geometry = obj.geometry.convex
        base = robot.model.frames[robot.base_id]
        moved = {j for j in range(m.njoints) if robot.chain_joints_between(base.parentJoint, j)}
        objs = list(geom.geometryObjects)
        pairs = []
        for a in range(len(objs)):
            for b in range(a + 1, len(objs)):
                ja, jb = objs[a].parentJoint, objs[b].parentJoint
                if ja == jb or not robot.chain_joints_between(ja, jb):
                    continue
                if m.parents[ja] == jb or m.parents[jb] == ja:
                    continue
                pairs.append((a, b))
        self.floor_z = floor_z
        if floor_z is not None and self.has_geometry:
            # the solid is {x: z <= floor_z} in the base frame, attached to the base's joint
            half = coal.Halfspace(np.array([0.0, 0.0, 1.0]), float(floor_z))
            floor = geom.addGeometryObject(pin.GeometryObject(
                "kincal_floor", base.parentJoint, base.placement, half))
            first = robot.first_moving_joint()  # its link stands on the base, so on the floor
            pairs += [(k, floor) for k, o in enumerate(objs)
                      if o.parentJoint in moved and o.parentJoint != first]
        for a, b in pairs:
            geom.addCollisionPair(pin.CollisionPair(a, b))
        self._geom, self._gdata, self._data = geom, pin.GeometryData(geom), m.createData()
        zero = self._pair_hits(np.zeros(robot.geometry.n))
        zero &= np.array([self._geom.geometryObjects[int(cp.second)].name != "kincal_floor"
                          for cp in geom.collisionPairs], dtype=bool)
        self.excluded = tuple(self._pair_name(int(k)) for k in np.flatnonzero(zero))
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

    def pair_hits(self, joint_values) -> np.ndarray:
        """(N, P) True where configuration k (N, n) [rad or m] has pair p of :attr:`pairs`
        in contact: which pairs a refusal names."""
        Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
        return np.array([self._pair_hits(q) for q in Q], dtype=bool).reshape(len(Q), -1)

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
