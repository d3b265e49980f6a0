"""Chain joints absent from a data file: held at one value during the measurements, or
following another joint by the URDF's ``<mimic>``.

A tool changer's joint, a gripper's wrist roll that never moves: the URDF has the joint on
the chain, the logger has no column for it. ``--joint-value NAME=VALUE`` gives its value
(in the file's units); the samples are read without it and get it as a constant column,
and the set records it (``fixed_joints``), so FRAMES.json and the report say under which
values the calibration holds. A joint the file has a column for is refused: two sources
for one value.

A mimic joint (``<mimic joint="M" multiplier="k" offset="o"/>``: its value is k M + o) is
no degree of freedom of its own, but Pinocchio reads it as one, so the chain has it. A file
without its column gets it from its master's column (the master on the chain); a file with
its column is read as it is, and warned about where the column differs from k M + o (a
reader of the corrected URDF computes it from M). Held with ``--joint-value`` while its
master moves, or with neither column nor master on the chain: refused.

A calibration holds only at the values its held joints had: :class:`HeldJoints` reads them
back from FRAMES.json (each set's ``fixed_joints``), for ``kincal evaluate`` (a file of the
same logger, without the column, gets them) and ``kincal compensate`` (the inverse
kinematics keeps them there).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from kincal.errors import DataError


def held_values(items, robots, length_unit: str = "m", angle_unit: str = "rad") -> dict:
    """{joint: value [rad or m]} of ``--joint-value NAME=VALUE`` items (values in the
    file's units), each a joint of the chain of one of ``robots`` and within its URDF
    limits (it held there while the robot was measured; a joint without limits within the
    magnitudes of a data file's values, :data:`~kincal.measurements.data.MAX_ABS_VALUE`);
    OptionError otherwise."""
    from kincal.errors import OptionError, listing, suggest
    from kincal.measurements.data import MAX_ABS_VALUE, unit_factors

    L, A = unit_factors(length_unit, angle_unit, OptionError)
    joints = {j: (g.kinds[k], g.lower[k], g.upper[k]) for r in robots
              for g in [r.geometry] for k, j in enumerate(g.joint_names)}
    out: dict[str, float] = {}
    for item in items:
        name, eq, text = item.partition("=")
        name = name.strip()
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not eq or not name or not math.isfinite(value):
            raise OptionError(f"--joint-value expects NAME=VALUE (a chain joint and a "
                              f"finite number), got {item!r}")
        if name not in joints:
            raise OptionError(f"--joint-value {name}: not a joint of the chain."
                              f"{suggest(name, list(joints))} Chain joints: "
                              f"{listing(tuple(joints))}")
        if name in out:
            raise OptionError(f"--joint-value {name} given twice")
        kind, lo, hi = joints[name]
        scale, unit = (L, length_unit) if kind == "prismatic" else (A, angle_unit)
        out[name] = value * scale
        # a joint without limits (continuous): the magnitudes a data file's column may hold
        limits = "URDF limits" if math.isfinite(lo) and math.isfinite(hi) else \
            "accepted range (the URDF gives no limits: a data file's magnitudes)"
        lo, hi = max(lo, -MAX_ABS_VALUE), min(hi, MAX_ABS_VALUE)
        if not lo - 1e-6 <= out[name] <= hi + 1e-6:  # the slack of the data's limit check
            raise OptionError(f"--joint-value {item}: outside {name}'s {limits} "
                              f"[{lo / scale:.4g}, {hi / scale:.4g}] {unit} (values in the "
                              "files' units, --angle-unit and --length-unit)")
    return out


def check_absent(path, header, fixed: dict, joint_columns=None) -> None:
    """Refuse a held joint that the file has a column for."""
    mapping = dict(joint_columns or {})
    both = [j for j in fixed if mapping.get(j, j) in header]
    if both:
        raise DataError(f"{path}: the file has a column for {', '.join(both)}, also given "
                        "with --joint-value: drop one (--joint-value is for chain joints the "
                        "file has no column for)")


MIMIC_TOLERANCE = 1e-6  # [rad or m] a mimic joint's column off k M + o by more is warned


def mimicked(path, header, robot, fixed: dict, joint_columns=None) -> dict:
    """{joint: (master, multiplier, offset)} of the mimic joints of ``robot``'s chain that
    the file has no column for, each filled from its master (module notes); DataError for
    one that cannot be (its master off the chain without a column, or held while its
    master moves)."""
    mapping, chain = dict(joint_columns or {}), robot.joint_names
    out = {}
    for j in chain:
        if j not in robot.mimics:
            continue
        m, k, o = robot.mimics[j]
        rule = f"{j} = {k:g} {m} {'+' if o >= 0 else '-'} {abs(o):g}"
        if j in fixed and m in chain and m not in fixed:
            raise DataError(f"--joint-value {j}: {j} mimics {m} in the URDF ({rule}), which "
                            f"moves in {path}: it cannot be held; drop --joint-value {j} "
                            "(kincal gives it its value from its master's)")
        if j in fixed or mapping.get(j, j) in header:
            continue
        if m not in chain:
            raise DataError(f"{path}: no column for chain joint {j}, which mimics {m} in the "
                            f"URDF ({rule}), a joint off the chain: give {j}'s column (or "
                            f"--joint-value {j}=VALUE if it did not move)")
        out[j] = (m, k, o)
    chained = [j for j, (m, _, _) in out.items() if m in out]
    if chained:
        raise DataError(f"{path}: no column for {chained[0]} nor for {out[chained[0]][0]}, the "
                        f"joint it mimics in the URDF: give {chained[0]}'s column")
    return out


def refuse_coupled(robot, what: str) -> None:
    """OptionError when ``robot``'s chain has a mimic joint whose master is on it too:
    ``what`` (joint values solved for or drawn as independent ones) would break the
    URDF's rule, which a reader of the URDF (and the robot) follows."""
    from kincal.errors import OptionError

    for j in robot.joint_names:
        m = robot.mimics.get(j)
        if m is not None and m[0] in robot.joint_names:
            raise OptionError(f"{j} mimics {m[0]} in the URDF ({j} = {m[1]:g} {m[0]} + "
                              f"{m[2]:g}), both on the chain {robot.base} -> {robot.tip}: "
                              f"{what} treats every chain joint as free and would break that "
                              "rule; choose a chain without the mimic joint (e.g. a tip "
                              f"before {j})")


def check_mimics(data, robot, path) -> None:
    """Warn where a mimic joint's column differs from its master's value by the URDF's rule
    (both on the chain)."""
    import warnings

    from kincal.errors import KincalWarning

    names = list(data.joint_names)
    for j, (m, k, o) in robot.mimics.items():
        if j in names and m in names and j not in dict(data.fixed_joints):
            q = data.joint_values
            off = np.abs(q[:, names.index(j)] - (k * q[:, names.index(m)] + o))
            if off.size and off.max() > MIMIC_TOLERANCE:
                warnings.warn(
                    f"{path}: column {j} differs from what the URDF's <mimic> makes of {m} "
                    f"({j} = {k:g} {m} + {o:g}) by up to {off.max():.3g} (rad or m, sample "
                    f"{int(off.argmax()) + 1}): kincal calibrates with the column, a reader of "
                    f"the corrected URDF computes {j} from {m}", KincalWarning)


def with_fixed_joints(data, joint_names, fixed: dict, follow: dict | None = None):
    """``data`` (read on the chain without the ``fixed`` and ``follow`` joints) on the whole
    chain ``joint_names``: each fixed joint a constant column {name: value [SI]}, approach
    direction 0 (it never moved); each joint of ``follow`` {name: (master, multiplier,
    offset)} its master's value by that rule (its approach direction the master's, times
    the multiplier's sign)."""
    follow = follow or {}
    joint_names = tuple(joint_names)
    n = len(data.joint_values)
    q = np.zeros((n, len(joint_names)))
    g = np.zeros((n, len(joint_names)))
    for k, j in enumerate(joint_names):
        if j in fixed:
            q[:, k] = fixed[j]
        elif j in follow:
            m, mult, off = follow[j]
            if m in fixed:
                q[:, k] = mult * fixed[m] + off
            else:
                i = data.joint_names.index(m)
                q[:, k] = mult * data.joint_values[:, i] + off
                g[:, k] = np.sign(mult) * data.approach[:, i]
        else:
            i = data.joint_names.index(j)
            q[:, k] = data.joint_values[:, i]
            g[:, k] = data.approach[:, i]
    held = tuple((j, float(fixed[j])) for j in joint_names if j in fixed)
    return dataclasses.replace(data, joint_names=joint_names, joint_values=q, approach=g,
                               fixed_joints=held)


HELD_TOLERANCE = 1e-5  # [rad or m] a held joint's value farther from the recorded one: warned


def held_text(joint: str, value: float, kind: str) -> str:
    """``joint = value`` in mm (prismatic) or deg (revolute) of a value [m or rad]."""
    return (f"{joint} = {value * 1e3:g} mm" if kind == "prismatic"
            else f"{joint} = {math.degrees(value):g} deg")


@dataclasses.dataclass(frozen=True)
class HeldJoints:
    """The chain joints a calibration held still, as FRAMES.json records them (each set's
    ``fixed_joints``): the values at which alone the calibration holds.

    values: ((joint, value [rad or m]), ...), chain order; a joint counts when every set of
    the chain records it held at one value (a set that moved it, or two held values: the
    calibration is not bound to one; two held values are warned about, :meth:`of`).
    source: the FRAMES.json, for messages.
    """

    values: tuple[tuple[str, float], ...] = ()
    source: str = "FRAMES.json"

    @classmethod
    def of(cls, frames, robot) -> "HeldJoints":
        """The held joints of ``frames`` (a :class:`~kincal.frames_file.CellFrames`, of one
        chain or several) on ``robot``'s chain (its base, tip and joints)."""
        joints = tuple(robot.joint_names)
        mine = frames.for_chain(robot.base, robot.tip)
        sets = [s for s in mine.sets if tuple(s.joints or mine.joints) == joints]
        held = [dict(s.fixed_joints) for s in sets]
        values = tuple((j, float(held[0][j])) for j in joints
                       if held and all(j in h and abs(h[j] - held[0][j]) <= HELD_TOLERANCE
                                       for h in held))
        out = cls(values, str(frames.source))
        kinds = dict(zip(joints, robot.geometry.kinds))
        for j in joints:  # held by every set, but not at one value: not held, and why
            if held and j not in dict(values) and all(j in h for h in held):
                out._warn_two_values(j, kinds[j], [(k, s.source, h[j]) for k, (s, h)
                                                   in enumerate(zip(sets, held))])
        return out

    def _warn_two_values(self, joint: str, kind: str, sets) -> None:
        """Warn that ``joint`` was held at different values in the calibration's sets
        ``sets`` ((index, source, value [rad or m]), ...): it is not taken as held."""
        import warnings

        from kincal.errors import KincalWarning

        where = ", ".join(f"{held_text(joint, v, kind)} in set {k + 1}"
                          + (f" ({source})" if source else "") for k, source, v in sets)
        warnings.warn(f"{joint} was held still at different values in the calibration's sets "
                      f"({where}, as {self.source} records): the calibration holds at neither "
                      f"alone, so {joint} is not taken as held at a recorded value; give its "
                      f"value explicitly (its column in the file, or --joint-value "
                      f"{joint}=VALUE where the command takes it)", KincalWarning)

    def as_dict(self) -> dict[str, float]:
        return dict(self.values)

    def joint_values(self, table, joint_names, scale, columns=None) -> np.ndarray:
        """(N, n) joint values [SI] of a read table (:class:`~kincal.measurements.csv_table.
        Columns`, the held joints' columns read as optional ones): each joint's column times
        its ``scale`` (n,), a held joint without a column at its held value. columns:
        {joint: CSV column} where they differ."""
        held, columns = self.as_dict(), dict(columns or {})
        n = len(table.lines)
        return np.column_stack([
            np.full(n, held[j]) if j in held and columns.get(j, j) not in table.values
            else table.values[columns.get(j, j)] * u for j, u in zip(joint_names, scale)])

    def text(self, kinds: dict) -> str:
        """``joint = value unit, ...`` (mm, deg); ``kinds``: {joint: kind}."""
        return ", ".join(held_text(j, v, kinds.get(j, "revolute")) for j, v in self.values)

    def warn_given(self, given: dict, kinds: dict) -> None:
        """Warn where a ``--joint-value`` (``given`` {joint: value [SI]}) differs from the value
        FRAMES.json records the joint held at: the given one is used."""
        import warnings

        from kincal.errors import KincalWarning

        for j, v in self.values:
            if j in given and abs(given[j] - v) > HELD_TOLERANCE:
                warnings.warn(f"--joint-value {held_text(j, given[j], kinds[j])} differs from "
                              f"its value held during the calibration ({held_text(j, v, kinds[j])}"
                              f", as {self.source} records): the given value is used, the "
                              "calibration holds at the recorded one only", KincalWarning)

    def warn_off(self, path, joint_names, kinds, q, then: str, lines=None) -> None:
        """Warn where the column of a held joint in ``q`` (N, n) [SI], a file's values for
        ``joint_names``, strays from its held value by more than :data:`HELD_TOLERANCE`;
        ``then``: what is done with them. lines: (N,) the file's line numbers."""
        import warnings

        from kincal.errors import KincalWarning

        names = list(joint_names)
        for j, v in self.values:
            if j not in names or not len(q):
                continue
            off = np.abs(np.asarray(q)[:, names.index(j)] - v)
            k = int(off.argmax())
            if off[k] > HELD_TOLERANCE:
                where = f"line {lines[k]}" if lines is not None else f"sample {k + 1}"
                big = (f"{off[k] * 1e3:.4g} mm" if kinds[j] == "prismatic"
                       else f"{math.degrees(off[k]):.4g} deg")
                warnings.warn(f"{path}: column {j} differs from its value held during the "
                              f"calibration ({held_text(j, v, kinds[j])}, as {self.source} "
                              f"records) in {int((off > HELD_TOLERANCE).sum())} of {len(off)} "
                              f"rows, by up to {big} ({where}): {then}", KincalWarning)
