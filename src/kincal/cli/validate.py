"""``kincal calibrate --validate HELD.csv``: the held-out errors of a calibration.

The held-out file is evaluated the way ``kincal evaluate --frames`` evaluates one
(:func:`kincal.cli.evaluate.with_frames`): frames from the training, nothing refitted; the
joints the training held (``--joint-value``) at the values its frames record.
Before: the nominal kinematics with the frames fitted on the training data with them
(the start of the calibration); after: the calibrated kinematics and frames.
"""

from __future__ import annotations

import dataclasses
import warnings

from kincal.errors import DataError, KincalWarning, OptionError


def check_count(n_held: int, n_files: int, several: bool) -> None:
    """Refuse a count of --validate files that is neither one (one chain) nor one per data
    file, before any work."""
    if n_held == 1 and several:
        raise OptionError("--validate HELD.csv judges one chain; this calibration has several "
                          "(one --base/--tip per file): give one held-out file per data file "
                          f"(here {n_files}), each judged on its file's chain")
    if n_held > 1 and n_held != n_files:
        raise OptionError(f"--validate takes one held-out file, or one per data file (each "
                          f"judged on its file's chain with its set's frames): {n_files} data "
                          f"file(s), {n_held} --validate files")


def held_out(result, inputs, path: str, k: int | None = None):
    """The :class:`~kincal.export.validation.Validation` of ``result`` on ``path``, read as
    the training files are (``inputs``: their reading options). k: judged on the chain of
    training set k with that set's frames (None: the calibration's one chain, every set's
    frames as evaluate --frames takes them)."""
    import numpy as np

    from kincal.cli.evaluate import with_frames
    from kincal.export.validation import Validation
    from kincal.identification.statistics import angle_stats
    from kincal.measurements.checks import repeated_samples, repeats_all
    from kincal.measurements.sets import CONTACT_KINDS, kind_of
    from kincal.measurements.fixed_joints import HeldJoints

    several = result.chains is not None and result.chains.several
    if k is None:
        check_count(1, len(result.sets), several)
    nominal, corrected = result.robot, result.corrected
    if k is not None and several:  # the chain of set k, with every corrected origin
        nominal = result.chains.robots[k]
        corrected = result.chains.corrected(result.layout.kinematic(result.x), k)
    after_frames = result.frames()
    # the joints the training held come from its frames, as evaluate --frames takes them: a
    # held-out file with their columns is read as it is (warned where they stray)
    reading = dataclasses.replace(inputs, files=(path,), set_sigma_mm=None, joint_value=())
    held = dataclasses.replace(HeldJoints.of(after_frames, nominal), source="the calibration")
    sets = reading.read_sets(nominal, held, whole=False)  # --on-plane: the training's
    for data in sets:  # another file holding training samples: not held out either
        for trained in result.sets:
            found = repeated_samples(data, trained.data)
            if found is None:
                continue
            if kind_of(data) in CONTACT_KINDS and not repeats_all(data, trained.data):
                # a contact holds joint values alone: a touch program run again with
                # commanded joints repeats some exactly, and its touches are measured anew
                warnings.warn(f"--validate {found}: some held-out touches have exactly the "
                              "joint values of training touches (a program run again with "
                              "commanded joints?); they are judged as held out",
                              KincalWarning)
                continue
            raise DataError(f"--validate {found}: held-out errors judge a calibration on "
                            "samples it did not see; give measurements kept out of the "
                            "training files")
    lay = result.layout
    start = [tuple(float(v) for v in result.x_start[lay.frame_slices[i]])
             for i in range(len(result.sets))]
    before_frames = dataclasses.replace(  # the nominal model: no joint terms
        after_frames, backlash={}, compliance={},
        sets=tuple(dataclasses.replace(s, values=v) for s, v in zip(after_frames.sets, start)))
    if k is not None:  # that set's frames alone, the joint terms of its chain's joints
        mine = set(nominal.joint_names)
        after_frames, before_frames = (dataclasses.replace(
            f, sets=(f.sets[k],), backlash={j: v for j, v in f.backlash.items() if j in mine},
            compliance={j: v for j, v in f.compliance.items() if j in mine})
            for f in (after_frames, before_frames))
    out = []
    for robot, frames in ((nominal, before_frames), (corrected, after_frames)):
        problem, x, _ = with_frames(robot, sets, frames, inputs.tool_guess)
        (_, errors), = problem.sample_errors(x)
        out.append((problem.residuals(x, 0), errors))
    km = problem.kinds[0]
    per_axis = km.kind == "pose" or (km.kind == "point" and getattr(km.data, "n_points", 1) == 1)
    before, after = (angle_stats(km, r) for r, _ in out)
    angles = None if before is None or after is None else (before, after)
    return Validation(str(path), km.kind, np.asarray(km.data.rows), out[0][0], out[1][0],
                      out[0][1], out[1][1], per_axis, angles,
                      f"{nominal.base} -> {nominal.tip}" if several else "",
                      km.angle_rows(out[0][0]), km.angle_rows(out[1][0]))
