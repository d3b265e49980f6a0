"""The corrected URDF read back by a second, independent parser before it is written.

kincal's models live in Pinocchio; the corrected URDF is text edited in place. Before the
one writer commits it, :func:`check_readback` parses that text with yourdfpy (its own
URDF reader and kinematics, no Pinocchio) and compares the forward kinematics of every
calibrated chain with the calibrated model at seeded joint values spread over the limits.
A difference above :data:`TOLERANCE_M` means the text does not say what was calibrated:
nothing is written (one ExportError line with the largest difference and where).
"""

from __future__ import annotations

import io
import warnings

import numpy as np

from kincal.errors import ExportError

TOLERANCE_M = 1e-9  # [m] largest position difference accepted (and 1e-9 in rotation)
N_CONFIGURATIONS = 12


def _chains(result):
    """The calibrated robots of every distinct chain of ``result`` (Pinocchio models)."""
    from kincal.robot import Robot

    c = result.corrected
    seen, out = set(), []
    for s in result.sets:
        base = getattr(s, "base_frame", "") or c.base
        tip = getattr(s, "tip_frame", "") or c.tip
        if (base, tip) in seen:
            continue
        seen.add((base, tip))
        out.append(c if (base, tip) == (c.base, c.tip) else
                   Robot(c.model, c.urdf_text, c.name, base, tip, c.source, c.off_chain))
    return out


def check_readback(result, text: str) -> None:
    """ExportError unless yourdfpy's reading of ``text`` gives every chain of ``result``
    its calibrated forward kinematics to :data:`TOLERANCE_M`."""
    import yourdfpy

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            urdf = yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), load_meshes=False,
                                      build_collision_scene_graph=False,
                                      load_collision_meshes=False)
    except Exception as exc:  # yourdfpy raises its own and lxml's errors
        raise ExportError(f"the corrected URDF could not be read back by yourdfpy "
                          f"({type(exc).__name__}: {exc}); nothing is written") from None
    rng = np.random.default_rng(0)
    for robot in _chains(result):
        g = robot.geometry
        lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
        hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
        q = np.vstack([np.zeros(g.n), rng.uniform(lo, hi, size=(N_CONFIGURATIONS - 1, g.n))])
        want = robot.tip_poses(q)
        base_link, T_lb = robot.link_of(robot.base)
        tip_link, T_lt = robot.link_of(robot.tip)
        worst, where = 0.0, 0
        for k, qk in enumerate(q):
            urdf.update_cfg({**dict(robot.off_chain), **dict(zip(robot.joint_names, qk))})
            T = np.linalg.inv(T_lb) @ urdf.get_transform(frame_to=tip_link,
                                                         frame_from=base_link) @ T_lt
            d = max(float(np.abs(T[:3, 3] - want[k][:3, 3]).max()),
                    float(np.abs(T[:3, :3] - want[k][:3, :3]).max()))
            if d > worst:
                worst, where = d, k
        if not worst <= TOLERANCE_M:
            raise ExportError(
                f"the corrected URDF, read back by a second parser (yourdfpy), differs from "
                f"the calibrated model of {robot.base} -> {robot.tip} by {worst:.3g} (m or "
                f"rotation entry) at joint values {np.round(q[where], 4).tolist()}; nothing "
                "is written (please report this: the URDF text does not say what was "
                "calibrated)")
