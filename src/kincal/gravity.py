"""The gravity torque each joint of a robot's chain carries (Pinocchio, from the URDF's
inertials): what a compliance term (:mod:`kincal.models.compliance`) multiplies.

The base frame is the link held fixed (a robot's base, a humanoid's stance sole), gravity
points along its -z. A chain joint carries the weight of every link beyond it as seen from
the base: its URDF subtree for a joint the chain traverses downward, everything but that
subtree for one it climbs. The torque is that weight's moment about the joint's axis line
in the chain's positive direction (for a prismatic joint: its force along the axis), so a
joint with compliance c sits at q + c * tau. Equal to minus the gradient of the links'
potential energy in the base frame (tests/test_compliance.py checks it).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from kincal.models.compliance import GRAVITY


def gravity_torques(robot, joint_values, gravity: float = GRAVITY) -> np.ndarray:
    """(N, n) gravity torque of each chain joint of ``robot`` (a :class:`kincal.robot.Robot`)
    at (N, n) joint values [N m, or N for a prismatic joint]; zeros without inertials.
    Joints off the chain stay where the robot puts them (:meth:`Robot.configuration`)."""
    m = robot.model
    d = m.createData()
    g = robot.geometry
    Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
    ids = [m.getJointId(name) for name in g.joint_names]
    mass = np.array([inertia.mass for inertia in m.inertias])               # (bodies,)
    beyond = np.zeros((len(ids), m.njoints))
    for k, (j, climbed) in enumerate(zip(ids, g.is_reversed)):
        beyond[k, list(m.subtrees[j])] = 1.0
        if climbed:
            beyond[k] = 1.0 - beyond[k]
    weight = beyond * mass                                                   # (n, bodies)
    M = weight.sum(axis=1)                                                   # (n,) [kg]
    prismatic = np.array([kind == "prismatic" for kind in g.kinds])
    out = np.zeros((len(Q), len(ids)))
    if not mass.any():
        return out
    for s, qs in enumerate(Q):
        pin.forwardKinematics(m, d, robot.configuration(qs))
        pin.updateFramePlacement(m, d, robot.base_id)
        down = d.oMf[robot.base_id].rotation @ np.array([0.0, 0.0, -gravity])
        com = np.array([d.oMi[b].act(inertia.lever) for b, inertia in enumerate(m.inertias)])
        C = weight @ com                                                     # (n, 3) sum m c
        pos = np.array([d.oMi[j].translation for j in ids])
        axis = np.array([d.oMi[j].rotation @ a for j, a in zip(ids, g.axes)])
        moment = np.cross(C - M[:, None] * pos, down)                        # (n, 3) [N m]
        out[s] = np.where(prismatic, M * (axis @ down), np.sum(axis * moment, axis=1))
    return out
