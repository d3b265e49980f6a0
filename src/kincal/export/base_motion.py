"""How far a calibration moves a chain's base against the link where the chain turns toward
its tip: a note on the URDF.

A chain from a link that is not above its tip (a humanoid's sole) climbs through joints whose
origins it corrects before it turns down toward the tip, at their common ancestor link (the
URDF's root for a sole and a gripper). The corrected URDF then holds the base link at another
pose against that link, and so every branch that leaves the chain there or above (the other
leg, the head) at another pose against the base link. The data see the chain only: its
predictions are what they say, the rest of the tree is not in them. A move of degrees or
centimetres there is worth a line, measured at the data's own joint values (every joint of
the climb is a chain joint): a model that stands the robot on that link puts those branches
that far off, and a controller that reads the robot from the root puts the link that far
off. Joints above the turning link are not the chain's (another chain may correct them, seen
by its own data). On the TALOS flush touches from the left sole, the geometric model reads
the stance leg bending under the body as a 7 deg turn of its hip: the sole moves 7.1 deg and
88 mm against the pelvis, and a right sole flat on the same floor sits 7 deg off it.
"""

from __future__ import annotations

import numpy as np

TURN_DEG = 2.0  # [deg] RMS turn of the base against the turning link: a note above it
MOVE_MM = 20.0  # [mm] RMS move, likewise
MAX_SAMPLES = 2000  # an RMS over at most this many samples, evenly spaced (a million poses)


def motion(nominal, corrected, q: np.ndarray) -> tuple[float, float, tuple[str, ...], str]:
    """(RMS turn [deg], RMS move [mm], the joints the chain climbs, the link where it turns
    toward its tip) of the chain's base against that link on ``corrected`` against
    ``nominal`` (Robots of one chain, base -> tip), at the chain joint values q (N, n).
    Only the climb is between the two: every joint on it is a chain joint, its value in q.
    A chain that does not climb (its base above its tip): (0, 0, (), "")."""
    from kincal.robot import Robot

    climb = [j for j, up in zip(nominal.joint_names, nominal.geometry.is_reversed) if up]
    if not climb:
        return 0.0, 0.0, (), ""
    top = nominal.parent_link(climb[-1])
    down = [Robot(r.model, r.urdf_text, r.name, top, r.base, r.source, None, r.xacro_args)
            for r in (nominal, corrected)]
    cols = [nominal.joint_names.index(j) for j in down[0].joint_names]
    T0, T1 = (r.tip_poses(np.asarray(q)[:, cols]) for r in down)
    D = np.linalg.solve(T0, T1)  # the corrected base in the nominal base frame
    cos = np.clip((np.trace(D[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    turn = np.degrees(np.arccos(cos))
    move = np.linalg.norm(D[:, :3, 3], axis=1) * 1e3
    return (float(np.sqrt(np.mean(turn ** 2))), float(np.sqrt(np.mean(move ** 2))),
            tuple(climb), top)


def notes(result) -> tuple[str, ...]:
    """A line for each chain of ``result`` whose base the corrections of its climb move
    against the link where it turns toward its tip by more than TURN_DEG or MOVE_MM (RMS
    over its sets' samples)."""
    from kincal.export.readback import chain_robots
    from kincal.urdf_source import urdf_tree

    out = []
    for cor in chain_robots(result):
        sets = [s for s in result.sets if (getattr(s, "base_frame", "") or cor.base,
                                           getattr(s, "tip_frame", "") or cor.tip)
                == (cor.base, cor.tip)]
        nominal = next((r for r in (result.chains.chain_robots if result.chains else
                                    [result.robot]) if (r.base, r.tip) == (cor.base, cor.tip)),
                       result.robot)
        if not nominal.geometry.is_reversed.any():  # no climb: nothing to stack (a hot path)
            continue
        q = np.vstack([s.data.joint_values for s in sets])
        n = len(q)
        q = q[np.unique(np.linspace(0, n - 1, min(n, MAX_SAMPLES)).astype(int))]
        turn, move, climb, top = motion(nominal, cor, q)
        if turn <= TURN_DEG and move <= MOVE_MM:
            continue
        tree = urdf_tree(nominal.urdf_text)
        children = {c.get("link") for j in tree.findall("joint") for c in j.findall("child")}
        root = " (the URDF's root)" if top not in children else ""
        through = climb[0] if len(climb) == 1 else f"{climb[0]} ... {climb[-1]}"
        out.append(
            f"the corrections move the chain's base {cor.base} {turn:.3g} deg and {move:.3g} mm "
            f"against {top}{root}, where it turns toward its tip (RMS at the "
            + (f"{n} samples'" if len(q) == n else f"{len(q):,} of the {n:,} samples'")
            + f" joint values, through the {len(climb)} joint(s) it climbs, {through}), which "
            f"the data do not see: every branch that leaves the chain at {top} or above moves "
            f"that far against {cor.base} (standing on it, a second foot on the floor), and "
            f"read from {top} the URDF puts {cor.base} that far off; a turn this large where "
            "the chain carries the robot is more often its load than its geometry "
            "(--compliance)")
    return tuple(out)
