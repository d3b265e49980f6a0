"""Chain joints absent from a data file, held at one value during the measurements.

A tool changer's joint, a gripper's wrist roll that never moves: the URDF has the joint on
the chain, the logger has no column for it. ``--joint-value NAME=VALUE`` gives its value
(in the file's units); the samples are read without it and get it as a constant column,
and the set records it (``fixed_joints``), so FRAMES.json and the report say under which
values the calibration holds. A joint the file has a column for is refused: two sources
for one value.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kincal.errors import DataError


def check_absent(path, header, fixed: dict, joint_columns=None) -> None:
    """Refuse a held joint that the file has a column for."""
    mapping = dict(joint_columns or {})
    both = [j for j in fixed if mapping.get(j, j) in header]
    if both:
        raise DataError(f"{path}: the file has a column for {', '.join(both)}, also given "
                        "with --joint-value: drop one (--joint-value is for chain joints the "
                        "file has no column for)")


def with_fixed_joints(data, joint_names, fixed: dict):
    """``data`` (read on the chain without the ``fixed`` joints) on the whole chain
    ``joint_names``: each fixed joint a constant column {name: value [SI]}, approach
    direction 0 (it never moved)."""
    joint_names = tuple(joint_names)
    n = len(data.joint_values)
    q = np.zeros((n, len(joint_names)))
    g = np.zeros((n, len(joint_names)))
    for k, j in enumerate(joint_names):
        if j in fixed:
            q[:, k] = fixed[j]
        else:
            i = data.joint_names.index(j)
            q[:, k] = data.joint_values[:, i]
            g[:, k] = data.approach[:, i]
    held = tuple((j, float(fixed[j])) for j in joint_names if j in fixed)
    return dataclasses.replace(data, joint_names=joint_names, joint_values=q, approach=g,
                               fixed_joints=held)
