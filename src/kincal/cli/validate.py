"""``kincal calibrate --validate HELD.csv``: the held-out errors of a calibration.

The held-out file is evaluated the way ``kincal evaluate --frames`` evaluates one
(:func:`kincal.cli.evaluate.with_frames`): frames from the training, nothing refitted.
Before: the nominal kinematics with the frames fitted on the training data with them
(the start of the calibration); after: the calibrated kinematics and frames.
"""

from __future__ import annotations

import dataclasses

from kincal.errors import OptionError


def one_chain(several: bool) -> None:
    """Refuse --validate for a calibration of several chains, saying what to do instead."""
    if several:
        raise OptionError("--validate evaluates one chain; this calibration has several "
                          "(one --base/--tip per file): judge each chain's held-out file with "
                          "kincal evaluate CAL.urdf HELD.csv --frames FRAMES.json --base B "
                          "--tip T (the frames of that chain's sets are taken)")


def held_out(result, inputs, path: str):
    """The :class:`~kincal.export.validation.Validation` of ``result`` on ``path``, read as
    the training files are (``inputs``: their reading options)."""
    import numpy as np

    from kincal.cli.evaluate import with_frames
    from kincal.export.validation import Validation
    from kincal.identification.statistics import angle_stats

    one_chain(result.chains is not None and result.chains.several)
    reading = dataclasses.replace(inputs, files=(path,), set_sigma_mm=None)
    sets = reading.read_sets(result.robot)
    after_frames = result.frames()
    lay = result.layout
    start = [tuple(float(v) for v in result.x_start[lay.frame_slices[i]])
             for i in range(len(result.sets))]
    before_frames = dataclasses.replace(
        after_frames, backlash={},
        sets=tuple(dataclasses.replace(s, values=v) for s, v in zip(after_frames.sets, start)))
    out = []
    for robot, frames in ((result.robot, before_frames), (result.corrected, after_frames)):
        problem, x = with_frames(robot, sets, frames, inputs.tool_guess)
        (_, errors), = problem.sample_errors(x)
        out.append((problem.residuals(x, 0), errors))
    km = problem.kinds[0]
    per_axis = km.kind == "pose" or (km.kind == "point" and getattr(km.data, "n_points", 1) == 1)
    before, after = (angle_stats(km, r) for r, _ in out)
    angles = None if before is None or after is None else (before, after)
    return Validation(str(path), km.kind, np.asarray(km.data.rows), out[0][0], out[1][0],
                      out[0][1], out[1][1], per_axis, angles)
