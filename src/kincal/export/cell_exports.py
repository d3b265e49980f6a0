"""Exports for robot cells whose software does not read URDF.

- :func:`kinematics_yaml`: the corrected joint origins as a YAML overlay keyed by URDF
  joint name, ``x, y, z`` [m] and ``roll, pitch, yaw`` [rad] (URDF rpy) per joint, the
  layout of ur_description's ``default_kinematics.yaml`` (there keyed by its own segment
  names). Every chain joint is listed, changed or not, so the file is the whole chain; so
  is a fixed joint a flush face's tilt is written into (as the corrected URDF has it).
- :func:`ur_kinematics_yaml`: the same values as ur_description's own file (segment keys
  and the robot's ``hash``, :func:`ur_hash_of`), which its ``ur.urdf.xacro`` reads back.
- :func:`mdh_table_csv`: the corrected chain as a modified Denavit-Hartenberg (Craig)
  table, extracted afresh from the corrected geometry (:func:`kincal.models.mdh.extract`),
  with the convention and the two fixed transforms stated in its header.

Numbers are written with ``repr`` (17 significant digits), so a file read back gives the
corrected model to machine precision; tests check it through an independent product.
YAML is written by hand: the file is flat, and PyYAML is not a dependency.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np

from kincal.errors import ExportError
from kincal.measurements.csv_table import csv_line
from kincal.models.mdh import extract
from kincal.rotations import matrix_to_rpy, rpy_to_matrix

EXACT = 1e-12  # [m] or [rad]: how far an MD-H screw may leave the z axis and stay exact


def _num(v: float) -> str:
    v = float(v)
    return repr(0.0 if v == 0.0 else v)  # no "-0.0"


# a key YAML reads back as this very string when written plain: a letter or underscore,
# then letters, digits, _ . / -, and none of YAML 1.1's booleans and nulls (a joint named
# "on" would read back as True); any other name goes in double quotes (JSON's escapes, which
# YAML's double-quoted style shares)
_PLAIN_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_./-]*")
_YAML_WORDS = {"y", "n", "yes", "no", "true", "false", "on", "off", "null"}


def _key(name: str) -> str:
    """``name`` as a YAML mapping key (or value) that reads back as this string."""
    if _PLAIN_KEY.fullmatch(name) and name.lower() not in _YAML_WORDS:
        return name
    return json.dumps(name)


def kinematics_yaml(nominal, corrected, joints=None, chains: str | None = None,
                    fixed=()) -> str:
    """The corrected URDF origins of every chain joint as YAML text.

    nominal: the robot the calibration started from (its rpy are the reference the
    corrected triples stay closest to); corrected: ``result.corrected``. joints: the
    movable URDF joints to list (default: the chain's; with several chains, the union of
    theirs, ``result.error_model.joint_names``); chains: how the title names the chains
    (default "base -> tip"). fixed: (name, nominal origin, corrected origin) [(4, 4)] of
    fixed joints the corrected URDF changes too (a flush face's tilt,
    :mod:`kincal.export.contact_fold`), listed after them. Applying the values to the
    nominal URDF's ``<origin>`` elements reproduces the corrected model.
    """
    names = tuple(corrected.joint_names if joints is None else joints)
    old, new = nominal.urdf_origins(names), corrected.urdf_origins(names)
    for name, before, after in fixed:
        names, old[name], new[name] = names + (name,), before, after
    lines = [f"# kincal: corrected joint origins of {corrected.name} "
             f"({chains or f'{corrected.base} -> {corrected.tip}'})",
             "# per joint: the <origin> of the URDF joint, the pose of the joint frame in its",
             "# parent link: x, y, z [m]; roll, pitch, yaw [rad], R = Rz(yaw) Ry(pitch) Rx(roll)",
             "kinematics:"]
    for name in names:
        T = new[name]
        rpy = matrix_to_rpy(T[:3, :3], near=matrix_to_rpy(old[name][:3, :3]))
        lines.append(f"  {_key(name)}:")
        lines += [f"    {k}: {_num(v)}" for k, v in zip(("x", "y", "z"), T[:3, 3])]
        lines += [f"    {k}: {_num(v)}" for k, v in zip(("roll", "pitch", "yaw"), rpy)]
    return "\n".join(lines) + "\n"


# ur_description's segment keys and the URDF joint each one sets (ur_macro.xacro: the
# joint's <origin> is ${segment_x ...} rpy ${segment_roll ...}); joint names may carry tf_prefix.
UR_SEGMENTS = (("shoulder", "shoulder_pan_joint"), ("upper_arm", "shoulder_lift_joint"),
               ("forearm", "elbow_joint"), ("wrist_1", "wrist_1_joint"),
               ("wrist_2", "wrist_2_joint"), ("wrist_3", "wrist_3_joint"))
_HASH = re.compile(r"^\s*hash:\s*['\"]?([^'\"#\s]+)", re.MULTILINE)


def ur_joints(joint_names) -> tuple[str, ...] | None:
    """The chain's URDF joint of each UR segment, in UR_SEGMENTS order, or None when the
    chain's joints are not the six UR joints (one shared tf_prefix allowed)."""
    names = tuple(joint_names)
    if len(names) != 6:
        return None
    prefix = names[0][: len(names[0]) - len(UR_SEGMENTS[0][1])]
    if names != tuple(prefix + j for _, j in UR_SEGMENTS):
        return None
    return names


def ur_hash_problem(ur_hash, what: str = "ur_hash") -> str | None:
    """Why ``ur_hash`` cannot be the hash of a UR kinematics file (none, empty or blank: no
    controller's hash is, and ur_robot_driver would find the file not the robot's), or
    None. what: its name in the message (the command line's option)."""
    if isinstance(ur_hash, str) and ur_hash.strip():
        return None
    return (f"{what} is empty; give the hash of the robot's kinematics file (calib_...)"
            if isinstance(ur_hash, str) else
            f"{what} must be the hash of the robot's kinematics file (calib_...), got "
            f"{ur_hash!r}")


def ur_layout_problem(robot) -> str | None:
    """Why ``robot``'s six UR joints are not in ur_description's layout, or None if they
    are. ur_description (ROS 2) builds every joint from its segment of the kinematics file,
    turning about its own z axis, the first under ``<prefix>base_link_inertia``; only then
    does a file of the URDF's joint origins give the xacro the calibrated robot. Another
    layout (example-robot-data's and ROS 1's UR URDFs: shoulder_lift about y, the first
    joint under base_link) read by the xacro is another robot, metres off."""
    joints = ur_joints(robot.joint_names)
    if joints is None:
        return None  # refused as not the six UR joints
    tilted = [n for n in joints if not np.allclose(robot.joint_axis(n), (0.0, 0.0, 1.0),
                                                   atol=1e-9)]
    parent = robot.parent_link(joints[0])
    prefix = joints[0][: len(joints[0]) - len(UR_SEGMENTS[0][1])]
    if not tilted and parent == prefix + "base_link_inertia":
        return None
    why = (f"{', '.join(tilted)} turn{'s' * (len(tilted) == 1)} about another axis than z"
           if tilted else f"{joints[0]} hangs under {parent!r}, not "
           f"{prefix + 'base_link_inertia'!r}")
    return (f"--yaml-format ur: this URDF is not in ur_description's layout ({why}; e.g. the "
            "ROS 1 or example-robot-data UR descriptions): ur_description would build "
            "another robot from its joint origins; calibrate the URDF that ur_description's "
            "xacro makes (ur.urdf.xacro with --xacro-arg ur_type:=...), or write "
            "--yaml-format kincal")


def ur_hash_of(source, xacro_args: dict | None) -> str | None:
    """The ``hash`` of the kinematics file a ur_description xacro was expanded with: the file
    xacro read (:func:`kincal.xacro_source.files_read`) for the ``kinematics_params``
    argument (a relative name is joined to the folder of the xacro file that loads it, as
    xacro does, not to the working folder), else the first file read with a ``hash:`` line
    (the xacro's default ``config/<ur_type>/default_kinematics.yaml``). None for a plain
    URDF, or when no such file or hash is found."""
    if source is None or not str(source).endswith(".xacro"):
        return None
    from kincal.xacro_source import files_read

    wanted = dict(xacro_args or {}).get("kinematics_params")

    def kinematics_file(path: Path) -> bool:
        if wanted is None:
            return path.suffix in (".yaml", ".yml")
        # xacro joins a relative name to its folder: the path read ends with the name given
        return str(path) == wanted or str(path).endswith(os.sep + wanted)

    for path in filter(kinematics_file, files_read(source, xacro_args)):
        try:
            found = _HASH.search(path.read_text(encoding="utf-8", errors="replace"))
        except OSError:
            continue
        if found:
            return found.group(1)
    return None


def _written_rpy(nominal, origins: dict) -> dict[str, np.ndarray]:
    """{joint: rpy as the nominal URDF text spells it}: the triple the corrected rpy stay
    closest to, as in the corrected URDF (ur_description writes wrist_3 as r, pi, pi; the
    canonical triple of that rotation is -r, 0, 0)."""
    from kincal.export.urdf_export import edit_joint_origins

    out = {}
    for edit in edit_joint_origins(nominal.urdf_text, origins).edits:
        try:
            out[edit.joint] = np.array([float(v) for v in (edit.old_rpy or "0 0 0").split()])
        except ValueError:  # an rpy text that is not three numbers: the canonical triple
            continue
    return {k: v for k, v in out.items() if v.shape == (3,)}


def ur_kinematics_yaml(nominal, corrected, ur_hash: str) -> str:
    """The corrected origins as ur_description's ``default_kinematics.yaml``: segment keys
    (shoulder .. wrist_3) of x, y, z [m], roll, pitch, yaw [rad] (the URDF joint <origin>,
    rpy kept closest to the nominal), then ``hash:`` (the robot's calibration id, which
    ur_robot_driver compares with the controller's). Raises ExportError for a chain that
    is not the six UR joints or not in ur_description's layout (:func:`ur_layout_problem`),
    or an empty hash (:func:`ur_hash_problem`)."""
    joints = ur_joints(corrected.joint_names)
    if joints is None:
        raise ExportError("--yaml-format ur needs a chain of the six UR joints ("
                          + ", ".join(j for _, j in UR_SEGMENTS) + "); this chain has "
                          + ", ".join(corrected.joint_names))
    problem = ur_layout_problem(nominal) or ur_hash_problem(ur_hash)
    if problem is not None:
        raise ExportError(problem)
    old, new = nominal.urdf_origins(), corrected.urdf_origins()
    near = _written_rpy(nominal, {name: new[name] for name in joints})
    lines = [f"# kincal: corrected kinematics of {corrected.name} ({corrected.base} -> "
             f"{corrected.tip}), ur_description's layout; hash: the robot's calibration id, "
             "which ur_robot_driver compares with the controller's (the kinematics_params "
             "file's, or --ur-hash)",
             "kinematics:"]
    for (segment, _), name in zip(UR_SEGMENTS, joints):
        T = new[name]
        rpy = matrix_to_rpy(T[:3, :3], near=near.get(name, matrix_to_rpy(old[name][:3, :3])))
        lines.append(f"  {segment}:")
        lines += [f"    {k}: {_num(v)}" for k, v in zip(("x", "y", "z"), T[:3, 3])]
        lines += [f"    {k}: {_num(v)}" for k, v in zip(("roll", "pitch", "yaw"), rpy)]
    lines.append(f"  hash: {_key(ur_hash)}")  # "a: b", "12345", "on" read back as given
    return "\n".join(lines) + "\n"


def read_kinematics_yaml(text: str) -> dict[str, np.ndarray]:
    """{joint: (4, 4) origin} from :func:`kinematics_yaml` text (this flat layout only)."""
    values: dict[str, dict[str, float]] = {}
    joint = None
    for raw in text.splitlines():
        line = raw.strip()
        if line.startswith('"'):  # a quoted joint name (:func:`_key`), then its colon
            joint = json.JSONDecoder().raw_decode(line)[0]
            values[joint] = {}
            continue
        line = line.split("#", 1)[0].rstrip()
        if not line or line == "kinematics:":
            continue
        key, _, value = line.partition(":")
        if not value.strip():
            joint = key
            values[joint] = {}
        elif joint is not None:
            values[joint][key] = float(value)
    out = {}
    for joint, v in values.items():
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix([v["roll"], v["pitch"], v["yaw"]])
        T[:3, 3] = [v["x"], v["y"], v["z"]]
        out[joint] = T
    return out


def _xyz_rpy(T: np.ndarray) -> str:
    return " ".join(_num(v) for v in (*T[:3, 3], *matrix_to_rpy(T[:3, :3])))


def mdh_table_problem(robot) -> str | None:
    """Why no MD-H table describes ``robot``'s chain (a base off the tip's branch: joints
    traversed upward, which no MD-H row holds), or None."""
    up = int(robot.geometry.is_reversed.sum())
    if not up:
        return None
    return (f"an MD-H table describes a chain down from its base, which a chain from a base "
            f"off the tip's branch ({robot.base} -> {robot.tip}: {up} joints traversed "
            "upward) is not; the corrected URDF and the YAML hold its origins")


def mdh_table_csv(corrected, tip_change=None) -> str:
    """The corrected chain as an MD-H table with Hayati's beta (CSV text, SI units): the
    ``complete`` model's form, so nearly parallel axes (UR, EC66 joints 2-3-4) get a beta
    and finite lengths instead of MD-H's common normal thousands of metres away.
    tip_change: (4, 4) the tip frame's change the corrected URDF makes beyond the chain (a
    flush face's tilt, :mod:`kincal.export.contact_fold`), in ``T_n_tip``.

    Raises ExportError where the table cannot describe the corrected chain exactly, or a
    length in it exceeds ten times the chain's own length (a description no controller
    should be given), or a chain no MD-H table describes (:func:`mdh_table_problem`).
    """
    import math

    from kincal.models.complete import NEARLY_PARALLEL_DEG

    why = mdh_table_problem(corrected)
    if why is not None:
        raise ExportError(why)

    m = extract(corrected.geometry, beta_below=math.sin(math.radians(NEARLY_PARALLEL_DEG)))
    off_axis = np.abs(m.screw_axes - [0.0, 0.0, 1.0]).max(axis=1)
    off_line = np.abs(m.screw_points[:, :2]).max(axis=1)
    bad = np.flatnonzero((off_axis > EXACT) | (off_line > EXACT))
    if bad.size:
        raise ExportError("an MD-H table cannot describe the corrected chain exactly: the axis of "
                          + ", ".join(m.joint_names[i] for i in bad) + " is parallel to the next "
                          "one only to within the extraction tolerance; use the URDF or the YAML "
                          "overlay instead")
    g = corrected.geometry
    chain = float(np.sum(np.linalg.norm(np.diff(np.concatenate(
        [g.joint_frames[:, :3, 3], g.T_base_tip[None, :3, 3]]), axis=0), axis=1)))
    lengths = np.abs(m.table[:, [0, 2]])
    if lengths.max() > 10 * max(chain, 1e-3):
        i, j = np.unravel_index(int(np.argmax(lengths)), lengths.shape)
        raise ExportError(f"the MD-H table of the corrected chain has {m.joint_names[i]}."
                          f"{'ad'[j]} = {m.table[i, 2 * j]:.4g} m, more than ten times the chain's "
                          f"length ({chain:.3g} m): not a table to give a controller; use the URDF "
                          "or the YAML overlay instead")
    lines = [f"# kincal: corrected modified Denavit-Hartenberg table (Craig) with Hayati's beta "
             f"of {corrected.name}, {corrected.base} -> {corrected.tip}",
             "# A_i = Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i + q_i) Tz(d_i) for a revolute "
             "joint, Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i) Tz(d_i + q_i) for a prismatic "
             "one;",
             "# a_i, alpha_i of row i are Craig's a_(i-1), alpha_(i-1); beta_i is 0 except where "
             f"two consecutive axes are within {NEARLY_PARALLEL_DEG:g} deg of parallel (Hayati); "
             "q_i is the URDF joint value, same sign; metres and radians",
             "# T_base_tip(q) = T_base_0 A_1 ... A_n T_n_tip, the fixed transforms as x y z "
             "[m] roll pitch yaw [rad] (URDF rpy):",
             f"# T_base_0: {_xyz_rpy(m.T_base_0)}",
             f"# T_n_tip: {_xyz_rpy(m.T_n_tip if tip_change is None else m.T_n_tip @ tip_change)}",
             "joint,type,a_m,alpha_rad,beta_rad,d_m,theta_rad"]
    for name, kind, row, beta in zip(m.joint_names, m.kinds, m.table, m.beta):
        a, alpha, d, theta = row
        lines.append(csv_line([name, kind, *(_num(v) for v in (a, alpha, beta, d, theta))]))
    return "\n".join(lines) + "\n"
