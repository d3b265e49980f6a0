"""How far a calibration moves a chain's base against the URDF's root: a note on the URDF.

A chain from a link that is not above its tip (a humanoid's sole) climbs through joints whose
origins it corrects before it comes down to the tip. The corrected URDF then holds that base
link at another pose against the root, and so every other branch of the tree (the other
leg, the head), which hangs from the root, at another pose against the base link. The data
see the chain only: its predictions are what they say, the rest of the tree is not in them.
A move of degrees or centimetres there is worth a line, measured at the data's own joint
values: a model that stands the robot on that link puts every other branch that far off,
and a controller that reads the robot from its root puts the link that far off. On the
TALOS flush touches from the left sole, the geometric model reads the stance leg bending
under the body as a 7 deg turn of its hip: the sole moves 7.1 deg and 88 mm against the
pelvis, and a right sole flat on the same floor sits 7 deg off it.
"""

from __future__ import annotations

import numpy as np

TURN_DEG = 2.0  # [deg] RMS turn of the base against the root above which a note is made
MOVE_MM = 20.0  # [mm] RMS move, likewise
MAX_SAMPLES = 2000  # an RMS over at most this many samples, evenly spaced (a million poses)


def root_link(text: str) -> str:
    """The URDF's root link: the one link that is no joint's child."""
    from kincal.urdf_source import urdf_tree

    tree = urdf_tree(text)
    children = {c.get("link") for j in tree.findall("joint") for c in j.findall("child")}
    return next(str(link.get("name")) for link in tree.findall("link")
                if link.get("name") not in children)


def motion(nominal, corrected, base: str, q: np.ndarray, joints) -> tuple[float, float, tuple]:
    """(RMS turn [deg], RMS move [mm], the joints between) of the link ``base`` against the
    root on ``corrected`` against ``nominal`` (Robots of one URDF), at the joint values q
    (N, len(joints)) of the chain joints ``joints``; joints between the root and ``base``
    that are not among them (above the chain's turning point: not corrected) stay at zero,
    which the relative pose does not depend on."""
    from kincal.robot import Robot

    root = root_link(nominal.urdf_text)
    if base == root:  # the chain hangs from the root: nothing of it is between
        return 0.0, 0.0, ()
    up = [Robot(r.model, r.urdf_text, r.name, root, base, r.source, None, r.xacro_args)
          for r in (nominal, corrected)]
    between = up[0].joint_names
    if not between:
        return 0.0, 0.0, ()
    cols = [list(joints).index(j) if j in joints else -1 for j in between]
    qb = np.where(np.array(cols) >= 0, np.asarray(q)[:, np.maximum(cols, 0)], 0.0)
    T0, T1 = (r.tip_poses(qb) for r in up)
    D = np.linalg.solve(T0, T1)  # the corrected base in the nominal base frame
    cos = np.clip((np.trace(D[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    turn = np.degrees(np.arccos(cos))
    move = np.linalg.norm(D[:, :3, 3], axis=1) * 1e3
    return (float(np.sqrt(np.mean(turn ** 2))), float(np.sqrt(np.mean(move ** 2))),
            tuple(between))


def notes(result) -> tuple[str, ...]:
    """A line for each chain of ``result`` whose base the corrections move against the URDF's
    root by more than TURN_DEG or MOVE_MM (RMS over its sets' samples)."""
    from kincal.export.readback import chain_robots

    out = []
    for cor in chain_robots(result):
        sets = [s for s in result.sets if (getattr(s, "base_frame", "") or cor.base,
                                           getattr(s, "tip_frame", "") or cor.tip)
                == (cor.base, cor.tip)]
        nominal = next((r for r in (result.chains.robots if result.chains else [result.robot])
                        if (r.base, r.tip) == (cor.base, cor.tip)), result.robot)
        q = np.vstack([s.data.joint_values for s in sets])
        n = len(q)
        q = q[np.unique(np.linspace(0, n - 1, min(n, MAX_SAMPLES)).astype(int))]
        turn, move, between = motion(nominal, cor, cor.base, q, nominal.joint_names)
        if turn <= TURN_DEG and move <= MOVE_MM:
            continue
        root = root_link(nominal.urdf_text)
        through = between[0] if len(between) == 1 else f"{between[0]} ... {between[-1]}"
        out.append(
            f"the corrections move the chain's base {cor.base} {turn:.3g} deg and {move:.3g} mm "
            f"against the URDF's root {root} (RMS at the "
            + (f"{n} samples'" if len(q) == n else f"{len(q):,} of the {n:,} samples'")
            + " joint values, "
            f"through {len(between)} joint(s) {through}), which the data do not see: the "
            f"other branches hang from {root}, so standing on {cor.base} the URDF puts them "
            f"that far off (a second foot on the floor), and read from {root} it puts "
            f"{cor.base} that far off; a turn this large where the chain carries the robot is "
            "more often its load than its geometry (--compliance)")
    return tuple(out)
