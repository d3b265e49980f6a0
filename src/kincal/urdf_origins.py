"""FRAMES.json's ``urdf_origins``: the calibrated joints' origins as the URDF written beside
it has them, checked against the URDF a reader is given.

A calibration's frames (measurement frame, tool point, planes) were identified together
with its corrected joint origins: they belong to the URDF written beside them. Compensating
with another URDF, the nominal one above all (``kincal compensate ec66 targets.csv --frames
FRAMES.json``, the robot named as it was for ``calibrate``), gives joint values for the
nominal kinematics with the calibration's frames: a cell program no better than the
uncorrected one, without a word. So when ``write_calibration`` writes a URDF and FRAMES.json
together, FRAMES.json records every calibrated joint's origin as written (xyz [m], rpy
[rad]), and :func:`differences` compares them with the URDF a reader builds its model from:

- ``kincal compensate`` (and the API's ``compensate``, ``filter_program``) refuses a URDF
  whose origins differ (:func:`check_calibrated`): its joint values would be for another
  robot;
- ``kincal evaluate`` says so in a note (:func:`note`): judging the nominal URDF with the
  calibration's frames is a comparison a user may want (docs/cli.md), and its figures are
  labelled as that.

Origins equal to :data:`TOLERANCE` (1 um, or 1e-6 in a rotation entry) are the same: a URDF
re-saved by a tool printing 6 decimals stays the calibrated one, while a calibration moves
origins by far more. FRAMES.json without the record (written without a URDF, or by an older
kincal) is not checked. The contact faces' tilts folded into a fixed joint have their own
record (:mod:`kincal.tilts_in_urdf`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import DataError
from kincal.tilts_in_urdf import Origin, joint_origins

if TYPE_CHECKING:
    from kincal.frames_file import CellFrames

TOLERANCE = 1e-6  # [m or rotation entry] origins this close are the same


def as_dict(record) -> dict:
    """FRAMES.json's ``urdf_origins`` object: {joint: {"xyz": [...], "rpy": [...]}}."""
    return {j: o.as_dict() for j, o in record}


def from_dict(value) -> tuple[tuple[str, Origin], ...]:
    """The record of FRAMES.json's ``urdf_origins`` (TypeError for another shape)."""
    if not isinstance(value, dict):
        raise TypeError("urdf_origins is an object {joint: {\"xyz\": [3 numbers], \"rpy\": "
                        "[3 numbers]}}")
    return tuple((str(j), Origin.from_dict(o, f"urdf_origins, joint {j}"))
                 for j, o in value.items())


def differences(frames: "CellFrames", robot) -> list[tuple[str, float, float]]:
    """[(joint, position difference [m], rotation difference [rad])] for each joint of
    ``robot``'s chain whose origin in its URDF differs from the one FRAMES.json records
    (beyond :data:`TOLERANCE`); empty when they agree or nothing is recorded."""
    mine = [(j, o) for j, o in frames.urdf_origins if j in robot.joint_names]
    if not mine:
        return []
    given = dict(joint_origins(robot.urdf_text, [j for j, _ in mine]))
    out = []
    for j, o in mine:
        g = given.get(j)
        if g is None:
            out.append((j, math.inf, math.inf))
            continue
        A, B = o.matrix, g.matrix
        if float(np.abs(A - B).max()) <= TOLERANCE:
            continue
        c = (np.trace(A[:3, :3].T @ B[:3, :3]) - 1.0) / 2.0
        out.append((j, float(np.linalg.norm(A[:3, 3] - B[:3, 3])),
                    float(math.acos(min(1.0, max(-1.0, c))))))
    return out


def _listing(diff) -> str:
    shown = "; ".join(f"{j} {d * 1e3:.3f} mm, {math.degrees(a):.4f} deg" if math.isfinite(d)
                      else f"{j} (no such joint or origin)" for j, d, a in diff[:3])
    return shown + (f"; and {len(diff) - 3} more" if len(diff) > 3 else "")


def check_calibrated(frames: "CellFrames", robot) -> None:
    """DataError unless ``robot``'s URDF has the calibrated origins FRAMES.json records for
    its chain joints (module notes)."""
    diff = differences(frames, robot)
    if diff:
        urdf = robot.source or robot.name
        raise DataError(f"{urdf} is not the calibrated URDF {frames.source} was written "
                        f"with: {len(diff)} of its chain's joint origins differ from the "
                        f"calibrated ones ({_listing(diff)}); compensating with it would give "
                        "joint values for other kinematics (the nominal ones?) with the "
                        "calibration's frames: give the URDF written beside these frames")


def note(frames: "CellFrames", robot) -> str | None:
    """The evaluation's note when ``robot``'s URDF is not the one FRAMES.json was written
    with (None when it is, or nothing is recorded)."""
    diff = differences(frames, robot)
    if not diff:
        return None
    urdf = robot.source or robot.name
    return (f"{urdf} is not the calibrated URDF {frames.source} was written with "
            f"({len(diff)} joint origins differ: {_listing(diff)}): the figures are this "
            "URDF's kinematics with the calibration's frames")
