"""What every error model provides: the shared interface of :mod:`kincal.models`.

An error model describes a serial chain as a product of *placements* and *joint motions*

    T_base_tip(q; x) = T_first  P_1(x) M_1(q_1)  P_2(x) M_2(q_2) ... P_n(x) M_n(q_n)  T_last_tip

where P_i(x) is the placement of joint i's *placed frame* relative to the frame before it
(the previous joint's frame after its motion, or T_first for joint 1), and M_i(q_i) is
joint i's motion: a turn about (or a slide along) its axis line, given in the placed frame
by ``screw_axes[i]`` and ``screw_points[i]``. The models differ only in how P_i depends
on the kinematic parameters x and in which frame they call "placed": MD-H frames for
``mdh`` and ``complete``, the URDF joint frames for ``placement`` and ``offsets``.

Each model gives, for a parameter vector x (absolute values, SI: metres, radians):

- ``placements(x)`` -> (n, 4, 4) the P_i;
- ``twists(x)`` -> (w, v), each (p, 3): parameter k changes P_{j(k)} by the small motion
  (w, v) expressed in the frame *before* it (``joint_of[k]`` = j(k)): a point X there moves
  by dX = (w x X + v) dx_k. Placements do not depend on q, so these twists are constants
  per x; :mod:`kincal.models.chain` carries them to the base frame for every pose;
- ``joint_frames(x)`` -> (n, 4, 4) the URDF joint frames at zero joint values in the base
  frame, what the exporter writes (each URDF joint frame is rigidly attached to its
  placed frame by ``joint_offsets[i]``);
- names, units and nominal values of its parameters.

A model is plain numpy and never imports Pinocchio: it is built once from the robot's
:class:`kincal.models.geometry.ChainGeometry`.

Tree paths (a base anywhere in the URDF tree): a joint traversed against its URDF
direction (on the way up from the base) is a joint like the others here, with its
placed frame at its URDF joint frame and its screw axis the geometry's chain axis (the
URDF axis negated), so a positive joint value still turns the tip side. Its URDF origin
lies *after* its motion, in the next placement; a model whose parameters correct URDF
origins (``placement``) sets ``joint_of`` to that placement. ``placement`` and ``offsets``
support tree paths; ``complete`` and ``mdh`` refuse them (see :mod:`kincal.models`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LENGTH, TWIST, OFFSET = "length", "twist", "offset"  # parameter classes (penalty, priors)


@dataclass(frozen=True)
class ErrorModel:
    """Fields shared by every error model (see the module notes).

    name: the model's name ("mdh", "complete", "placement", "offsets").
    joint_names, kinds: the chain's joints, "revolute" or "prismatic".
    names: (p,) kinematic parameter names, ``<joint>.<field>``.
    nominal: (p,) nominal values [m, rad] (zero errors reproduce the URDF exactly).
    is_length: (p,) True for lengths [m], False for angles [rad].
    classes: (p,) parameter class: "length", "twist" (an angle that tilts an axis or a
        frame) or "offset" (a joint's zero: a turn about, or slide along, its own axis).
    joint_of: (p,) chain index of the joint whose placement each parameter changes.
    T_first: (4, 4) fixed frame before joint 1's placement, in the base frame.
    screw_axes, screw_points: (n, 3) each joint's axis direction and a point of its axis
        line, in its placed frame.
    joint_offsets: (n, 4, 4) the URDF joint frame in the placed frame.
    T_last_tip: (4, 4) the tip frame in the last placed frame (after its motion).
    notes: one line per joint on the degenerate cases met ("" if none).
    """

    name: str
    joint_names: tuple[str, ...]
    kinds: tuple[str, ...]
    names: tuple[str, ...]
    nominal: np.ndarray
    is_length: np.ndarray
    classes: tuple[str, ...]
    joint_of: np.ndarray
    T_first: np.ndarray
    screw_axes: np.ndarray
    screw_points: np.ndarray
    joint_offsets: np.ndarray
    T_last_tip: np.ndarray
    notes: tuple[str, ...]

    @property
    def n(self) -> int:
        return len(self.joint_names)

    @property
    def size(self) -> int:
        return len(self.names)

    # -- to be provided by each model ------------------------------------------------
    def placements(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def twists(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
        raise NotImplementedError

    # -- shared ----------------------------------------------------------------------
    def joint_frames(self, x: np.ndarray | None = None) -> np.ndarray:
        """(n, 4, 4) URDF joint frames T_B_Ji at zero joint values for parameters x
        (default: nominal, which gives back the URDF's own joint frames)."""
        P = self.placements(self.nominal if x is None else np.asarray(x, dtype=float).ravel())
        out = np.empty((self.n, 4, 4))
        G = self.T_first
        for i in range(self.n):
            G = G @ P[i]
            out[i] = G @ self.joint_offsets[i]
        return out

    def last_axis_distance(self, tool) -> float | None:
        """Distance [m] of a tool point (tip frame) from the last joint's axis line, or None
        if the last joint is prismatic. Near 0, turning that joint barely moves the point:
        its offset (and the tilt of its axis) are weak or unidentifiable."""
        if self.kinds[-1] != "revolute":
            return None
        p = self.T_last_tip[:3, :3] @ np.asarray(tool, float) + self.T_last_tip[:3, 3]
        # the cross product written out (np.cross's products and differences, a twentieth
        # of its cost on one vector: this runs at every fit)
        (x, y, z), (u, v, w) = (p - self.screw_points[-1]).tolist(), self.screw_axes[-1].tolist()
        return float(np.linalg.norm([y * w - z * v, z * u - x * w, x * v - y * u]))

    def last_axis_parameters(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The last joint's parameters a tool point on its axis cannot see, by this model's
        names: (its offsets: the turn about the axis, its twists: the tilt of the axis);
        e.g. (("joint_6.theta",), ("joint_6.alpha",)) for MD-H, no twist for offsets."""
        last = self.joint_names[-1] + "."

        def of(cls: str) -> tuple[str, ...]:
            return tuple(n for n, c in zip(self.names, self.classes)
                         if n.startswith(last) and c == cls)

        return of(OFFSET), of(TWIST)

    def last_axis_weak_text(self) -> str:
        """What a tool point on the last axis leaves weak, in this model's names."""
        off, tilt = self.last_axis_parameters()
        if not tilt and len(off) == 1:
            return (f"{off[0]} is weak or redundant; an offset tool point (>= 20 mm off the "
                    "axis) makes it identifiable")
        return (", ".join(off) + (f" and the tilt of that axis ({', '.join(tilt)})" if tilt
                                  else "") + " are weak or redundant; an offset tool point "
                "(>= 20 mm off the axis) makes them identifiable")

    def describe(self) -> str:
        """One paragraph: the model, its parameter count and the classes it uses."""
        counts = {c: self.classes.count(c) for c in (LENGTH, TWIST, OFFSET)}
        return (f"error model {self.name}: {self.size} kinematic parameters on {self.n} joints "
                f"({counts[LENGTH]} lengths, {counts[TWIST]} twists, {counts[OFFSET]} "
                "joint offsets)")


def rotation_twist(axis: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w, v) of a unit turn about the line through ``point`` along ``axis``."""
    return axis, np.cross(point, axis)


def translation_twist(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w, v) of a unit slide along ``direction``."""
    return np.zeros(3), direction
