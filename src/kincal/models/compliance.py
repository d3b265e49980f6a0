"""Joint compliance: a joint turns in proportion to the gravity torque it carries.

A joint's gears and shaft are springs: under load the link sits a little away from where
the motor encoder says, by the torque over the joint's stiffness. kincal models the
static part, the load gravity puts on each joint, with one coefficient c per chosen joint:

    q_effective = q_measured + c * tau,   tau: the gravity torque the joint carries

c is the compliance (1 / stiffness) [rad/(N m)]; revolute joints only (a prismatic joint's
sag is a force over a stiffness in m/N, not modelled). tau is the
moment, about the joint's axis in the chain's positive direction, of the weight of every
link beyond the joint as seen from the base (the base is the link held fixed: the floor, a
humanoid's stance sole), computed from the URDF's inertials at the measured joint values
(:meth:`kincal.robot.Robot.gravity_torques`), with gravity along -z of the base frame. The
payload (a tool the URDF does not carry) is not in tau: its torque scales differently.
The solver and the penalty see c times the joint's RMS torque over the samples (the
deflection it causes, an angle), so one scale (1 deg) fits every robot's size. A joint
that carries no torque whatever the pose (the URDF has no inertials beyond it, or
its axis is vertical) has no compliance term.
"""

from __future__ import annotations

import numpy as np

GRAVITY = 9.81  # [m/s^2], along -z of the base frame
MIN_TORQUE = 1e-3  # [N m] RMS below which a joint carries no torque worth a term


def loaded(kinds, tau) -> np.ndarray:
    """(n,) bool: the joints a compliance term can describe on samples whose gravity
    torques are ``tau`` (N, n) [N m]: revolute, carrying an RMS torque above MIN_TORQUE
    (a joint with no inertials beyond it in the URDF, or an axis along gravity, carries
    none). The model choice's candidates and the residual diagnosis's patterns."""
    return np.array([k == "revolute" for k in kinds], dtype=bool) & (torque_rms(tau) > MIN_TORQUE)


def torque_rms(tau) -> np.ndarray:
    """(n,) RMS over the samples of gravity torques ``tau`` (N, n) [N m]: what a joint carries
    (above :data:`MIN_TORQUE`, a compliance term's reporting unit)."""
    return np.sqrt(np.mean(np.asarray(tau, dtype=float) ** 2, axis=0))


CONVENTION = ("q_effective = q + compliance * tau, tau the gravity torque the joint "
              "carries [N m] (URDF inertials, gravity along -z of the base frame, the links "
              "beyond the joint seen from the base); rad/(N m), revolute joints")
