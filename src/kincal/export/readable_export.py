"""Corrected URDF text whose rpy stay readable, also next to gimbal lock.

A URDF origin is exact in rpy, but where the original pitch is +-90 deg a correction
about the one axis rpy cannot follow there forces roll and yaw to swing together. When
the offending part of a correction is a turn of a joint about its own axis (a joint
offset), it can be moved instead into the origins of that joint's child joints: the
kinematics stay exact (every frame beyond the joint is where it was), only the link's
own frame turns by that offset about the joint axis, so its mesh is drawn off by the
offset angle. kincal does this only where it removes a swing, and reports each case.

A tilt of a joint axis at such an origin (an alpha correction there) cannot be moved
anywhere: the exact URDFs that change only joint origins differ from one another by turns
of link frames about their own joint axes, and none of those reaches the lost axis. The
exact triple is kept (the closest one to the original) and the swing is reported
(:class:`RpySwing`), so nobody mistakes it for a large correction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kincal.export.urdf_export import EditResult, edit_joint_origins
from kincal.robot import Robot
from kincal.rotations import axis_rotation, rotation_angle, transform

SWING = 0.05  # [rad] an rpy component moving this much more than the rotation itself


@dataclass(frozen=True)
class Regauged:
    """A joint offset moved into the child origins: joint name, angle [rad], children."""

    joint: str
    angle: float
    children: tuple[str, ...]

    def describe(self) -> str:
        return (f"{self.joint}: its offset of {np.degrees(self.angle):+.4f} deg was written into "
                f"the origins of {', '.join(self.children)} to keep the rpy of {self.joint} "
                "readable (pitch near +-90 deg); its link frame turns by that angle")


def regauged_joints(moved) -> set[str]:
    """The joints whose origins :func:`corrected_text` re-expressed (its ``moved``: a joint
    offset moved into its child joints): those joints and their children."""
    return {n for m in moved if isinstance(m, Regauged) for n in (m.joint, *m.children)}


@dataclass(frozen=True)
class RpySwing:
    """A corrected origin whose exact rpy moved much more than its rotation did."""

    joint: str
    old_rpy: str
    new_rpy: str
    rotation: float  # [rad] angle of the correction's rotation
    largest_change: float  # [rad] largest change of an rpy component

    def describe(self) -> str:
        return (f"{self.joint}: rpy \"{self.old_rpy}\" -> \"{self.new_rpy}\": a correction "
                f"of only {np.degrees(self.rotation):.3f} deg turns this frame about the one "
                f"axis rpy cannot follow at pitch +-90 deg, so roll and yaw move together (by up "
                f"to {np.degrees(self.largest_change):.1f} deg); the triple is exact and the "
                "closest to the original, and no edit of joint origins alone avoids it")


def _swing(edit, R_old: np.ndarray, R_new: np.ndarray) -> float:
    """How much more the rpy numbers moved than the rotation did [rad]."""
    return float(np.max(np.abs(edit.rpy_change)) - rotation_angle(R_old.T @ R_new))


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    return transform(axis_rotation(axis, angle))


def corrected_text(nominal: Robot, corrected: Robot, readable: bool = True,
                   source: str = "<string>", joints=None, ends=()
                   ) -> tuple[EditResult, tuple[Regauged | RpySwing, ...]]:
    """The corrected URDF text, and what a reader should know about its rpy: the joints
    whose offset was moved into the child origins, and the swings that remain. joints: the
    movable joints whose origins may have changed (default: the nominal robot's chain; the
    union of several chains'). ends: the chains' base and tip frames (link or joint names):
    a joint whose child link is one of theirs keeps its offset (its link's frame, which the
    move would turn, is where a set's frames hang)."""
    origins = nominal.changed_origins(corrected, joints=joints)
    result = edit_joint_origins(nominal.urdf_text, origins, source=source)
    if not readable:
        return result, ()
    old = nominal.urdf_origins(joints)
    fixed_links = {nominal.link_of(f)[0] for f in ends}
    moved: list[Regauged | RpySwing] = []
    for name, T_new in list(origins.items()):
        edit = result.for_joint(name)
        if (_swing(edit, old[name][:3, :3], T_new[:3, :3]) < SWING
                or nominal.link_of(name)[0] in fixed_links):
            continue
        axis = nominal.joint_axis(name)  # its sign does not matter: angle flips with it
        # the part of the correction that turns the joint about its own axis
        dR = old[name][:3, :3].T @ T_new[:3, :3]
        w = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]]) / 2
        angle = float(np.arcsin(np.clip(w @ axis, -1, 1)))
        trial = dict(origins)
        trial[name] = T_new @ _rot(axis, -angle)
        children = corrected.child_joint_origins(name)
        for child, T_child in children.items():
            trial[child] = _rot(axis, angle) @ trial.get(child, T_child)
        # the children's nominal origins: those off the chain (a sensor's fixed frame, a
        # gripper's joints) are not among the chain's, ``old``
        was = {**nominal.child_joint_origins(name), **old}
        candidate = edit_joint_origins(nominal.urdf_text, trial, source=source)
        after = _swing(candidate.for_joint(name), old[name][:3, :3], trial[name][:3, :3])
        child_ok = all(_swing(candidate.for_joint(c), was[c][:3, :3], trial[c][:3, :3]) < SWING
                       for c in children)
        if after < SWING and child_ok:  # only where it removes the swing altogether
            origins, result, old = trial, candidate, was
            moved.append(Regauged(name, angle, tuple(children)))
    for name, T_new in origins.items():
        T_old = old[name]
        edit = result.for_joint(name)
        if edit.changed and _swing(edit, T_old[:3, :3], T_new[:3, :3]) >= SWING:
            moved.append(RpySwing(name, edit.old_rpy or "0 0 0", edit.new_rpy or "0 0 0",
                                  rotation_angle(T_old[:3, :3].T @ T_new[:3, :3]),
                                  float(np.max(np.abs(edit.rpy_change)))))
    return result, tuple(moved)
