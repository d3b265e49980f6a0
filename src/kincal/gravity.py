"""The gravity torque each joint of a robot's chain carries (Pinocchio, from the URDF's
inertials): what a compliance term (:mod:`kincal.models.compliance`) multiplies.

The base frame is the link held fixed (a robot's base, a humanoid's stance sole), gravity
points along its -z. A chain joint carries the weight of every link beyond it as seen from
the base: its URDF subtree for a joint the chain traverses downward, everything but that
subtree for one it climbs. The torque is that weight's moment about the joint's axis line
in the chain's positive direction (for a prismatic joint: its force along the axis), so a
joint with compliance c sits at q + c * tau. Equal to minus the gradient of the links'
potential energy in the base frame (tests/test_compliance.py checks it).

Many poses are computed in blocks of ``BLOCK`` rows with numpy, each Pinocchio joint's
placement composed from its parent's as the joint's screw motion: one Pinocchio pass per
pose (a Python loop) took 0.2 ms a pose, 25 s of a 30,000-pose calibration (four calls).
Joints other than one-axis revolute or prismatic ones (a free flyer, a spherical joint on
the way to a body) keep that loop (``gravity_torques_per_pose``, the reference).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from kincal.models.compliance import GRAVITY
from kincal.rotations import axis_rotations

BLOCK = 4096  # poses at once (bounds the (poses x bodies) placements held)


def _weights(robot):
    """(n, bodies) the masses each chain joint carries, (n,) their sums, prismatic (n,)."""
    m, g = robot.model, robot.geometry
    ids = [m.getJointId(name) for name in g.joint_names]
    mass = np.array([inertia.mass for inertia in m.inertias])               # (bodies,)
    beyond = np.zeros((len(ids), m.njoints))
    for k, (j, climbed) in enumerate(zip(ids, g.is_reversed)):
        beyond[k, list(m.subtrees[j])] = 1.0
        if climbed:
            beyond[k] = 1.0 - beyond[k]
    weight = beyond * mass                                                   # (n, bodies)
    return ids, weight, weight.sum(axis=1), np.array([k == "prismatic" for k in g.kinds])


def _torques(g, ids, weight, M, prismatic, R, t, com, R_base, gravity):
    """(N, n) torques from (N, joints, 3, 3) rotations R, (N, joints, 3) origins t and
    (N, bodies, 3) centres of mass com of every Pinocchio joint, base rotations (N, 3, 3)."""
    down = R_base @ np.array([0.0, 0.0, -gravity])                          # (N, 3)
    C = np.einsum("kb,sbi->ski", weight, com)                                # (N, n, 3)
    axis = np.einsum("skij,kj->ski", R[:, ids], np.asarray(g.axes, float))   # (N, n, 3)
    moment = np.cross(C - M[None, :, None] * t[:, ids], down[:, None, :])
    along = np.einsum("ski,si->sk", axis, down)
    return np.where(prismatic, M * along, np.sum(axis * moment, axis=2))


def gravity_torques_per_pose(robot, joint_values, gravity: float = GRAVITY) -> np.ndarray:
    """:func:`gravity_torques` one Pinocchio pass per pose: the reference."""
    m = robot.model
    d = m.createData()
    ids, weight, M, prismatic = _weights(robot)
    Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
    out = np.zeros((len(Q), len(ids)))
    if not weight.any():
        return out
    for s, qs in enumerate(Q):
        pin.forwardKinematics(m, d, robot.configuration(qs))
        pin.updateFramePlacement(m, d, robot.base_id)
        R = np.array([o.rotation for o in d.oMi])[None]
        t = np.array([o.translation for o in d.oMi])[None]
        com = np.array([d.oMi[b].act(inertia.lever) for b, inertia in enumerate(m.inertias)])
        out[s] = _torques(robot.geometry, ids, weight, M, prismatic, R, t, com[None],
                          d.oMf[robot.base_id].rotation[None], gravity)[0]
    return out


def _screws(robot):
    """Each Pinocchio joint's motion: (kind, parent placement (4, 4), axis) with kind
    "fixed" (held where the robot puts it), "revolute" or "prismatic"; None if a chain
    joint moves otherwise."""
    m = robot.model
    chain = {m.getJointId(name): k for k, name in enumerate(robot.geometry.joint_names)}
    d0, d1 = m.createData(), m.createData()
    n = robot.geometry.n
    pin.forwardKinematics(m, d0, robot.configuration(np.zeros(n)))
    pin.forwardKinematics(m, d1, robot.configuration(np.ones(n)))
    out = []
    for j in range(1, m.njoints):
        if j not in chain:
            out.append(("fixed", d0.liMi[j].homogeneous, None))
            continue
        if m.joints[j].nv != 1:
            return None
        place = m.jointPlacements[j]
        w = pin.log6(place.inverse() * d1.liMi[j])                           # at 1 rad / 1 m
        lin, ang = np.asarray(w.linear), np.asarray(w.angular)
        if abs(np.linalg.norm(ang) - 1) < 1e-9 and np.linalg.norm(lin) < 1e-9:
            out.append(("revolute", place.homogeneous, ang / np.linalg.norm(ang)))
        elif np.linalg.norm(ang) < 1e-12 and abs(np.linalg.norm(lin) - 1) < 1e-9:
            out.append(("prismatic", place.homogeneous, lin / np.linalg.norm(lin)))
        else:
            return None
    return out


def gravity_torques(robot, joint_values, gravity: float = GRAVITY) -> np.ndarray:
    """(N, n) gravity torque of each chain joint of ``robot`` (a :class:`kincal.robot.Robot`)
    at (N, n) joint values [N m, or N for a prismatic joint]; zeros without inertials.
    Joints off the chain stay where the robot puts them (:meth:`Robot.configuration`)."""
    m = robot.model
    Q = np.atleast_2d(np.asarray(joint_values, dtype=float))
    ids, weight, M, prismatic = _weights(robot)
    screws = _screws(robot) if weight.any() else None
    if screws is None:
        return gravity_torques_per_pose(robot, Q, gravity)
    column = {m.getJointId(name): k for k, name in enumerate(robot.geometry.joint_names)}
    lever = np.array([inertia.lever for inertia in m.inertias])             # (bodies, 3)
    frame = m.frames[robot.base_id]
    out = np.empty((len(Q), len(ids)))
    for start in range(0, len(Q), BLOCK):
        q = Q[start:start + BLOCK]
        N = len(q)
        R = np.empty((N, m.njoints, 3, 3))
        t = np.empty((N, m.njoints, 3))
        R[:, 0], t[:, 0] = np.eye(3), 0.0
        for j, (kind, place, axis) in enumerate(screws, start=1):
            Rl, tl = np.broadcast_to(place[:3, :3], (N, 3, 3)), np.broadcast_to(place[:3, 3],
                                                                                  (N, 3))
            if kind == "revolute":
                Rl = Rl @ axis_rotations(axis, q[:, column[j]])
            elif kind == "prismatic":
                tl = tl + (place[:3, :3] @ axis) * q[:, column[j], None]
            p = m.parents[j]
            R[:, j] = R[:, p] @ Rl
            t[:, j] = t[:, p] + np.einsum("sij,sj->si", R[:, p], tl)
        com = t + np.einsum("sbij,bj->sbi", R, lever)
        R_base = R[:, frame.parentJoint] @ frame.placement.rotation
        out[start:start + N] = _torques(robot.geometry, ids, weight, M, prismatic, R, t, com,
                                        R_base, gravity)
    return out
