"""The plausibility gate's likely causes: what a refusal names, most likely first.

Inferred from the gate's :class:`kincal.identification.plausibility.Evidence`, never
certain, and the messages say so (see that module's notes for the order). Two more causes
than the data themselves. A penalty too weak to hold what the data barely tell apart:
when the largest correction is a parameter the data barely tell from others (a ``weak``
one of the identifiability report), the prior toward nominal alone held it, and a prior
scale the evidence estimated large (the same data read three times: an offset scale of
46 deg, a wrist turned by 79 deg against the contact face's tilt) lets it drift along
what the data do not see, rather than the URDF or the tip being wrong. And what made
that scale large there, named first: samples given more than once, whose copies make the
noise look smaller than it is (:func:`duplicate_cause`). And a base frame that moves in the
world with joints the data log on other branches (:func:`moving_base_cause`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from kincal.measurements.checks import DEGREES_AS_RADIANS, DUPLICATE_WHY, UNIT_RATIO

if TYPE_CHECKING:
    from kincal.identification.plausibility import Evidence, Thresholds

OVERFIT_RATIO = 3  # plain LS with fewer equations per identified parameter: a likely cause


def names_text(names, shown: int = 6) -> str:
    """The first ``shown`` names, and how many more."""
    more = len(names) - shown
    return ", ".join(names[:shown]) + (f" and {more} more" if more > 0 else "")


def unit_causes(ev: Evidence) -> list[str]:
    out = []
    if ev.prismatic_mm:  # the positions' spread grows with such joints: no ratio shows it
        out.append(f"lengths in millimetres read as metres ({ev.prismatic_mm}; --length-unit "
                   "mm reads the positions and the prismatic joints in millimetres)")
    r = ev.length_ratio
    if math.isfinite(r) and r > UNIT_RATIO:
        out.append(f"{ev.length_what} in millimetres read as metres (they spread {r:.0f}x "
                   "more than the robot's tip moves; --length-unit mm)")
    elif math.isfinite(r) and 0 < r < 1.0 / (10 * UNIT_RATIO):
        out.append(f"positions in metres read as millimetres (they spread {1 / r:.0f}x less "
                   "than the robot's tip moves)" if ev.length_unit == "mm" else
                   f"positions in the wrong unit (they spread {1 / r:.0f}x less than the "
                   "robot's tip moves)")
    if ev.angle_unit == "rad" and ev.angle_max > DEGREES_AS_RADIANS:
        out.append(f"joint values in degrees read as radians (a revolute joint reaches "
                   f"{ev.angle_max:.4g} rad; --angle-unit deg)")
    if ev.orientation_angle_max > DEGREES_AS_RADIANS:
        out.append(f"orientation angles in degrees read as radians (they reach "
                   f"{ev.orientation_angle_max:.4g} rad; --angle-unit deg reads the joints and "
                   "the angles in degrees: a file of joints in radians and angles in degrees "
                   "must be converted to one unit)")
    return out


def fit_causes(ev: Evidence, th: Thresholds) -> list[str]:
    out = unit_causes(ev)
    if ev.off_chain_columns:
        out.append("a tip (or base) frame that does not match the data: the file has columns "
                   f"for URDF joints beyond the chain's ends ({names_text(ev.off_chain_columns)}); "
                   "check --tip")
    e = ev.explained
    if math.isfinite(e) and e < th.explained:
        out.append(f"positions that do not match the joint rows (rows shuffled or a different "
                   f"data file): the model explains only {max(e, 0.0):.0%} of their motion")
        out.append("noise as large as the motion itself")
    else:
        out.append("measurement noise far above a calibration's (the model explains "
                   f"{e:.0%} of the motion, the rest is error)" if math.isfinite(e) else
                   "measurement noise far above a calibration's")
        if not ev.off_chain_columns:
            out.append("a tip frame that does not match the data (check --tip and "
                       "--tool-offset)")
        out += moving_base_cause(ev)
        out.append("a URDF of another robot, or positions not matching the joint rows")
    return out


def orientation_causes(ev: Evidence) -> tuple[str, ...]:
    """Why orientations (a pose's, a flush face's tilt) stay far off after calibration: the
    clues in the file first (units; a base that moves with the logged legs: TALOS's touches
    from the pelvis, 13 deg median; columns beyond the tip: with --tip arm_left_5_link, two
    joints short of the gripper, 36 deg; arm_left_6_link 24 deg), then the tip."""
    beyond = (f"a tip frame that does not match the data: the file has columns for URDF "
              f"joints beyond the chain's ends ({names_text(ev.off_chain_columns)}); check --tip",
              ) if ev.off_chain_columns else ()
    return (*unit_causes(ev), *moving_base_cause(ev), *beyond,  # the clues the file gives
            *(() if beyond else ("a tip frame that does not match the data (check --tip)",)),
            "orientations in another convention or frame than the file's, or a face that does "
            "not lie flush at every touch", "a URDF of another robot")


def tool_causes(ev: Evidence) -> tuple[str, ...]:
    """Why a tool point is identified several chain lengths from its tip: data that do not
    fix it (TALOS's flush touches read as plane contacts, without --flush: 10.1 m, std error
    3 m), or a unit slip."""
    flush = ("contacts of a flat face read as plane contacts (one distance per touch): with "
             "--flush each touch also gives the face's two tilts",
             ) if ev.tool_far[3] == "plane" else ()
    return (*flush, "data that do not fix the tool point: give --tool-offset and hold it "
            "(--fix tool.x tool.y tool.z)", *unit_causes(ev),
            "--tool-offset or the positions in another length unit than the data's")


def moving_base_cause(ev: Evidence) -> tuple[str, ...]:
    """A base that moves against the instrument: the data log joints of other branches that
    hang from the base's own link (a whole robot's log), and the base moves with them in
    the world if the robot stands or rolls on them, as a standing humanoid's pelvis does
    with its legs while no chain joint sees it (the URDF root, the default base: TALOS's
    flush touches from ``base_link`` move the tool by 548 mm; from the sole on the floor
    they calibrate). The instrument (a tracker, a table) must stay fixed in the base."""
    if not ev.at_base:
        return ()
    base = " and ".join(ev.bases) or "the base frame"
    return (f"a base frame that moves against the instrument: the file logs joints of other "
            f"branches that hang from {base} "
            f"({names_text(ev.other_branch_columns[:ev.at_base], 3)}); if the robot stands or "
            f"rolls on them, {base} moves with them and the instrument is not fixed in it: "
            "give as --base the link that stays fixed to the instrument (for a robot standing "
            "on a foot, that foot's sole)",)


def overfit_cause(ev: Evidence) -> tuple[str, ...]:
    return (f"plain least squares on {ev.equations} equations for {ev.identified} identified "
            "parameters, which fits the noise (measure more, or use the default --method l2, "
            "which pulls what the data barely determine toward nominal)",) if (
        ev.method == "ls" and 0 < ev.equations < OVERFIT_RATIO * ev.identified) else ()


def weak_cause(ev: Evidence) -> tuple[str, ...]:
    """The penalty too weak for a weak parameter that moved most (see the module notes)."""
    if ev.method == "ls" or not ev.weak_corrections:
        return ()
    one = ev.weak_scales.startswith("lambda")
    scales = ("" if not ev.weak_scales else f" ({ev.weak_scales})" if one
              else f", whose scale the evidence estimated at {ev.weak_scales}")
    remedy = ("choose the penalty by the evidence (--lambda evidence) or a larger lambda"
              if one else "state the prior scales (--prior-mm, --prior-deg)")
    return (f"a penalty too weak for what the data barely tell apart: the largest "
            f"corrections ({', '.join(ev.weak_corrections)}) are weak parameters (their "
            f"effect is nearly that of others), held only by the penalty toward nominal"
            f"{scales}; {remedy}, or measure more varied poses",)


def duplicate_cause(ev: Evidence) -> tuple[str, ...]:
    """Samples given more than once (:func:`kincal.measurements.checks.duplicate_samples`):
    the copies count as measurements, the noise looks smaller than it is and the penalty
    toward nominal holds less than it should (the TALOS touches read three times: an offset
    prior scale of 46 deg)."""
    more = "; ".join(ev.duplicates[:2]) + ("; ..." if len(ev.duplicates) > 2 else "")
    return (f"the same samples given more than once ({more}): the copies make the noise look "
            "smaller than it is, and the penalty toward nominal holds less than it should",
            ) if ev.duplicates else ()


def duplicate_notes(ev: Evidence) -> tuple[str, ...]:
    """The copies' findings with what they do: notes of a result the gate lets through."""
    return tuple(f"{d}: {DUPLICATE_WHY}" for d in ev.duplicates)
