"""Compensated joint values: what to command so the calibrated robot reaches a target.

Two forms, one solver (:mod:`kincal.compensation.ik`) on the corrected model:

- :func:`compensate`: targets given as positions of the measured tool point in the
  measurement frame (optionally full poses), each with seed joint values (the user's
  program). For a position-only target the tool keeps the orientation the calibrated
  model gives it at the seed (the orientation the real robot has there), as a task
  below the position: met exactly on six or more joints, as closely as the chain
  allows on fewer.
- :func:`filter_program`: joint values planned on the nominal model; the compensated
  values make the calibrated model reach the pose (tool point and tip orientation) the
  nominal model predicted at them, in the robot's base frame. The measurement frame
  plays no part; only the tool point of the frames matters.

Backlash terms (FRAMES.json) are not compensated: the approach direction of a future
motion is not known from a target file, so targets are reached with every joint in the
middle of its play (the corrected URDF's model), and the summary says how large the
remaining play is.

Joints the calibration held still (FRAMES.json's ``fixed_joints``, ``--joint-value``) stay
at their held values: the calibration holds there only (and the robot may not move them).
The solver keeps them (lower = upper), the other joints reach the targets; a seed (a
program's value) elsewhere is warned about and the held value used; the summary says so.

Compliance terms (FRAMES.json, :mod:`kincal.models.compliance`) are compensated: the joint
values the solver finds are where the joints must *be*; the commanded values are those
less the deflection the gravity torque causes there (q_cmd + c tau(q_cmd) = q, solved by
a few fixed-point steps), and the summary says by how much the largest moved. A position
target keeps the orientation the tool has where the seed's command puts it, deflected.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from kincal.frames_file import CellFrames
from kincal.compensation.ik import IkOptions, IkSolution, solve
from kincal.models.kinematics import ChainKinematics
from kincal.models.workspace import CHANGE, between
from kincal.compensation.targets import Targets, joint_scales
from kincal.errors import DataError, FrameError
from kincal.measurements.checks import UNIT_RATIO, degrees_read_as_radians, spread
from kincal.measurements.csv_table import csv_line
from kincal.measurements.fixed_joints import HeldJoints, refuse_coupled
from kincal.measurements.orientation_columns import reading_doubt
from kincal.rotations import base_rotation
from kincal.tilts_in_urdf import on_urdf
from kincal.urdf_origins import check_calibrated

COMPLIANCE_STEPS = 4  # fixed-point steps of the commanded joint values under compliance
REACH_MARGIN = 1.05  # targets beyond this multiple of the chain's reach cannot be reached


@dataclass(frozen=True)
class Compensation:
    """Compensated joint values of N targets (SI inside).

    joint_names, kinds: the chain. seeds, joint_values: (N, n) [rad or m]. lines: (N,)
    line numbers of the targets in their file. position_error: (N,) distance [m] of the
    calibrated model's tool point from the target; orientation_error: (N,) [rad] of its
    tool frame's orientation (its tip's turned by the tool's) from the wanted one;
    orientation_required: (N,) whether that orientation had to be met (a full pose) or was
    only kept where possible. reached: (N,) within the tolerances. at_limit: (N, n). notes:
    what a user should know. singular: (N,) not reached, near a singular configuration.
    """

    joint_names: tuple[str, ...]
    kinds: tuple[str, ...]
    seeds: np.ndarray
    joint_values: np.ndarray
    lines: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray
    orientation_required: np.ndarray
    reached: np.ndarray
    at_limit: np.ndarray
    source: str = "<targets>"
    notes: tuple[str, ...] = ()
    singular: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.joint_values)

    def failures(self) -> list[str]:
        """One line per target not reached: where, by how much, and why if known."""
        out = []
        for k in np.flatnonzero(~self.reached):
            why = [f"the tool point stays {self.position_error[k] * 1e3:.4g} mm from the target"]
            if self.orientation_required[k]:
                why.append(f"the orientation {np.degrees(self.orientation_error[k]):.3g} deg off")
            limits = [self.joint_names[j] for j in np.flatnonzero(self.at_limit[k])]
            if limits:
                why.append(f"{', '.join(limits)} at a joint limit")
            if self.singular is not None and self.singular[k]:
                why.append("the joints end near a singular configuration (the tool cannot "
                           "move along some direction there: a stretched or folded arm, "
                           "aligned wrist axes; another seed, on another branch, may reach it)")
            out.append(f"line {self.lines[k]}: " + ", ".join(why))
        return out

    def summary(self) -> str:
        n, ok = len(self), int(self.reached.sum())
        change = np.abs(self.joint_values - self.seeds)
        rev = np.array([k != "prismatic" for k in self.kinds])
        lines = [f"compensated {ok} of {n} targets from {self.source}"
                 + ("" if ok == n else f" ({n - ok} NOT reached)")]
        if ok:
            r = self.reached
            lines.append(f"  residual of the calibrated model: position max "
                         f"{self.position_error[r].max() * 1e3:.3g} mm, orientation max "
                         f"{np.degrees(self.orientation_error[r].max()):.3g} deg")
            if rev.any():
                lines.append(f"  joint change from the seeds: max "
                             f"{np.degrees(change[r][:, rev].max()):.4g} deg (revolute)"
                             + (f", {change[r][:, ~rev].max() * 1e3:.4g} mm (prismatic)"
                                if (~rev).any() else ""))
        gave = self.reached & ~self.orientation_required & (self.orientation_error > 1e-6)
        if gave.any():
            lines.append(f"  {int(gave.sum())} targets: the orientation gave way (up to "
                         f"{np.degrees(self.orientation_error[gave].max()):.3g} deg from the "
                         "one kept: a position target's seed's, a program's nominal pose's) to "
                         "keep the joints within their limits or because fewer than six "
                         "joints are free (a shorter chain, joints held)")
        lines += [f"  {note}" for note in self.notes]
        return "\n".join(lines)

    def to_csv_text(self, length_unit: str = "m", angle_unit: str = "rad") -> str:
        """CSV: the file's line of each target, the compensated joint values in the given
        units, the residual in mm and degrees, and reached (1/0)."""
        return "".join(self.csv_blocks(length_unit, angle_unit))

    def csv_blocks(self, length_unit: str = "m", angle_unit: str = "rad", rows: int = 4096):
        """The text of :meth:`to_csv_text` in pieces of ``rows`` rows (the header first),
        made as they are written: a large file is never held as one string."""
        scale = joint_scales(self.kinds, length_unit, angle_unit)
        yield csv_line(["target_line", *self.joint_names, "position_error_mm",
                        "orientation_error_deg", "reached"]) + "\n"
        # the rows: numbers only, whose text never needs quoting (csv_line would give it
        # unchanged)
        # one %-format of a whole block (its values row after row): %r is repr, %.6g and
        # %d the f-string's formats, so the text is the per-row f-strings' to the byte
        # (tests/test_compensate_blocks.py), formatted in C instead of row by row
        row = "%d," + "%r," * len(self.kinds) + "%.6g,%.6g,%d\n"
        for s in range(0, len(self), rows):
            b = slice(s, s + rows)
            q = (self.joint_values[b] / scale).T.tolist()
            cells = zip(self.lines[b].astype(int).tolist(), *q,
                        (self.position_error[b] * 1e3).tolist(),
                        np.degrees(self.orientation_error[b]).tolist(),
                        self.reached[b].astype(int).tolist())
            yield (row * len(q[0] if q else self.lines[b])) % tuple(
                itertools.chain.from_iterable(cells))


def _reach(chain: ChainKinematics, tool: np.ndarray, lower, upper) -> tuple[np.ndarray, float]:
    """(first joint's origin in B, an upper bound of the tool point's distance from it) [m]."""
    lengths = np.linalg.norm(chain.placements[1:, :3, 3], axis=1).sum()
    travel = np.where(chain.prismatic, np.maximum(np.abs(lower), np.abs(upper)), 0.0)
    bound = lengths + np.where(np.isfinite(travel), travel, 0.0).sum() + np.linalg.norm(
        chain.T_last_tip[:3, 3]) + np.linalg.norm(tool)
    if not np.all(np.isfinite(travel)):
        bound = np.inf  # a prismatic joint without limits reaches anywhere along its axis
    return chain.placements[0, :3, 3], float(bound)


def _check_units(chain, tool, lower, upper, targets_B, targets_M, at_seeds_M, source, unit):
    """Refuse targets in the wrong length unit, with the likely cause (nothing is solved).

    The plausibility gate of the measurements (:mod:`kincal.measurements.checks`): the
    targets should spread about as much as the calibrated model's tool point at the
    seeds, and lie within the chain's reach."""
    s_t, s_q = spread(targets_M), spread(at_seeds_M)
    if len(targets_M) >= 3 and s_q > 1e-3:
        if s_t > UNIT_RATIO * s_q:
            raise DataError(f"{source}: the targets spread {s_t:.4g} m while the tool point at the "
                            f"seeds moves by {s_q:.3g} m: were they millimetres? Read them with "
                            "--length-unit mm (Python: length_unit='mm')")
        if s_t < s_q / (10 * UNIT_RATIO):
            raise DataError(f"{source}: the targets spread only {s_t * 1e3:.3g} mm while the tool "
                            f"point at the seeds moves by {s_q * 1e3:.3g} mm: "
                            + ("were they metres read as millimetres? Drop --length-unit mm"
                               if unit == "mm" else "check their unit and the frames file"))
    origin, bound = _reach(chain, tool, lower, upper)
    far = np.linalg.norm(targets_B - origin, axis=1) / bound
    if far.size and far.min() > UNIT_RATIO:
        raise DataError(f"{source}: every target is at least {far.min():.0f} times farther from "
                        f"the robot than it can reach ({bound:.3g} m): "
                        + ("were they millimetres? Read them with --length-unit mm (Python: "
                           "length_unit='mm')" if unit == "m" else "check their unit and the "
                           "frames file"))


def _solution(chain_robot, sol: IkSolution, seeds, lines, required, source, notes):
    g = chain_robot.geometry
    return Compensation(tuple(g.joint_names), tuple(g.kinds), np.array(seeds, float), sol.q,
                        np.asarray(lines), sol.position_error, sol.orientation_error,
                        np.asarray(required, bool), sol.reached, sol.at_limit, source,
                        tuple(notes), sol.singular)


def _backlash_notes(frames: CellFrames | None, robot) -> list[str]:
    if frames is None or not frames.backlash:
        return []
    kinds = dict(zip(robot.joint_names, robot.geometry.kinds))
    # +- half the play, |b|: b's sign says which flank the joint sits on, not the play
    parts = [f"{j} +-{np.degrees(abs(b)):.3g} deg" if kinds[j] != "prismatic"
             else f"{j} +-{abs(b) * 1e3:.3g} mm" for j, b in frames.backlash.items()]
    return [f"backlash not compensated ({', '.join(parts)}): every joint is taken in the middle "
            "of its play, the side it is approached from moves the tool by up to that much"]


def _held(robot, frames: CellFrames | None, seeds, source: str, lines):
    """(seeds, lower, upper, notes): the joints ``frames`` records as held (module notes)
    set to their values in the seeds (warned where the file has others) and held by the
    limits (lower = upper), the other joints' URDF limits."""
    g = robot.geometry
    seeds = np.array(seeds, dtype=float)
    lower, upper = np.array(g.lower, dtype=float), np.array(g.upper, dtype=float)
    # degrees read as radians: the seeds (a program's values) far outside the limits; a
    # program so read is commanded nonsense, the targets' branches a guess: solve nothing
    degrees = degrees_read_as_radians(g.joint_names, g.kinds, lower, upper, seeds, lines)
    if degrees:
        raise DataError(f"{source}: {degrees}; nothing is compensated")
    held = HeldJoints() if frames is None else HeldJoints.of(frames, robot)
    if not held.values:
        return seeds, lower, upper, []
    kinds = dict(zip(g.joint_names, g.kinds))
    held.warn_off(source, g.joint_names, kinds, seeds, "the held value is used", lines)
    for j, v in held.values:
        k = list(g.joint_names).index(j)
        seeds[:, k] = lower[k] = upper[k] = v
    return seeds, lower, upper, [
        f"held where the calibration held them ({held.text(kinds)}, as {held.source} "
        "records): the calibration holds there only, the other joints reach the targets"]


def _compliances(frames: CellFrames | None, robot, lower, upper) -> np.ndarray | None:
    """(n,) each chain joint's compliance [rad/(N m)] from ``frames`` (0 for a held joint,
    lower = upper: it is not commanded, it keeps its value); None without compliance terms."""
    if frames is None or not frames.compliance:
        return None
    names = list(robot.joint_names)
    c = np.zeros(len(names))
    for j, v in frames.compliance.items():
        c[names.index(j)] = v
    c[np.asarray(lower) >= np.asarray(upper)] = 0.0
    return c


def _where_it_is(frames: CellFrames | None, robot, commands, lower, upper) -> np.ndarray:
    """(N, n) where the joints are when ``commands`` are commanded: deflected by the
    gravity torques under compliance terms (``commands`` unchanged without)."""
    c = _compliances(frames, robot, lower, upper)
    commands = np.asarray(commands, float)
    return commands if c is None else commands + c * robot.gravity_torques(commands)


def _deflected(frames: CellFrames | None, robot, sol: IkSolution, lower, upper
               ) -> tuple[IkSolution, list[str]]:
    """(the solution with commanded joint values that the gravity torques deflect onto the
    solver's, notes) for frames with compliance terms; (sol, []) without. A held joint
    (lower = upper) is not commanded: it keeps its value."""
    c = _compliances(frames, robot, lower, upper)
    if frames is None or c is None:
        return sol, []
    names = list(robot.joint_names)
    q = np.asarray(sol.q, float)
    cmd = q.copy()
    for _ in range(COMPLIANCE_STEPS):  # a contraction: |c dtau/dq| << 1
        cmd = q - c * robot.gravity_torques(cmd)
    moved = np.abs(cmd - q).max(axis=0) if len(q) else np.zeros(len(names))
    k = int(np.argmax(moved))
    return replace(sol, q=cmd), [
        f"compliance compensated ({', '.join(frames.compliance)}): each command is the "
        f"solution less its gravity deflection, at most {np.degrees(moved[k]):.3g} deg "
        f"on {names[k]}"]


# what a chain holding a mimic joint and its master is refused for (fixed_joints)
COUPLED = "compensation (its joint values solved for)"


def compensate(robot, frames: CellFrames, targets: Targets, point: int = 0,
               options: IkOptions = IkOptions(), length_unit: str = "m") -> Compensation:
    """Joint values with which the calibrated ``robot`` reaches each target.

    robot: the corrected :class:`kincal.robot.Robot` (e.g. ``result.corrected`` or the
    corrected URDF). frames: its measurement frame and tool points. targets: seeds and
    positions (poses) in the measurement frame. point: which measured point is targeted
    (0 = point 1). length_unit: the unit the targets were read in, for the message when
    they look like another one. Raises DataError for frames of another chain or targets
    in the wrong unit, OptionError for a chain holding a mimic joint and its master (the
    joints solved for as free would break the URDF's rule); targets that cannot be
    reached are flagged (``reached``), see :meth:`Compensation.failures`.
    """
    refuse_coupled(robot, COUPLED)
    frames.check_chain(robot)
    check_calibrated(frames, robot)  # not the nominal URDF with the calibrated frames
    if not 0 <= point < len(frames.tools):
        raise FrameError(f"measured point {point + 1} asked for, {frames.source} has "
                         f"{len(frames.tools)} tool point(s)")
    g = robot.geometry
    chain = ChainKinematics.of(g)
    tool = frames.tools[point]
    frames, tilts = on_urdf(frames, robot)  # a contact face's tilt this URDF lacks
    seeds, lower, upper, held = _held(robot, frames, targets.seeds, targets.source,
                                      targets.lines)
    R_MB = base_rotation(*frames.base[3:])
    # a pose calibration's tool frame is turned on the tip: the wanted orientations are the
    # tool frame's, as its data measured them (the tip's own for points: identity)
    R_tool = frames.tool_rotation if point == 0 else np.eye(3)
    t_MB = frames.base[:3]
    positions_B = (targets.positions - t_MB) @ R_MB  # R_MB^T (p - t) row-wise
    # the tool where the robot is when the seeds are commanded: deflected by the gravity
    # torques under compliance terms (the orientation a position target keeps is the one the
    # real robot has there, the solver's joints are where the joints must be)
    R_seed, p_seed = chain.tool_poses(_where_it_is(frames, robot, seeds, lower, upper), tool)
    _check_units(chain, tool, lower, upper, positions_B, targets.positions,
                 p_seed @ R_MB.T + t_MB, targets.source, length_unit)
    if targets.rotations is None:
        rotations, required = R_seed, np.zeros(len(targets), bool)
        notes = ["position targets: the tool keeps the orientation it has at the seed"
                 + ("" if g.n >= 6 else f" as far as the {g.n} joints allow")]
    else:
        doubt = reading_doubt(R_MB @ R_seed @ R_tool, targets.rotations,
                              targets.orientation_format,
                              f"{targets.source}: the wanted orientations",
                              "the calibrated model's at the seeds")
        if doubt:  # the seeds (the program) are near the targets: so are their orientations
            raise DataError(doubt + "; nothing is compensated")
        rotations = R_MB.T @ targets.rotations @ R_tool.T  # the tip's, in the base frame
        required, notes = np.ones(len(targets), bool), []
    sol = solve(chain, tool, positions_B, rotations, required, seeds, lower, upper, options)
    sol, soft = _deflected(frames, robot, sol, lower, upper)
    return _solution(robot, sol, seeds, targets.lines, required, targets.source,
                     notes + list(tilts) + held + _backlash_notes(frames, robot) + soft)


def _same_model(nominal, calibrated, tool) -> None:
    """Refuse a nominal robot farther from the calibrated one than the gate lets a
    calibration move the tool point (:data:`kincal.models.workspace.CHANGE`; another model
    of the same chain, a UR5 for a UR10, moves it by decimetres)."""
    L, d = between(nominal, calibrated, tool)
    rms, limit = float(np.sqrt(np.mean(d ** 2))), CHANGE * L * 1e3
    if rms > limit:
        raise DataError(f"the nominal robot {nominal.source} and the calibrated one "
                        f"{calibrated.source} put the tool point {rms:.4g} mm RMS apart (max "
                        f"{d.max():.4g} mm) over the joint range, more than the gate lets a "
                        f"calibration move it ({limit:.3g} mm, {CHANGE:.0%} of "
                        "the reach): give as --nominal the description the calibration "
                        "started from (the same model and xacro arguments)")


def filter_program(nominal, calibrated, program: np.ndarray, frames: CellFrames | None = None,
                   lines=None, point: int = 0, options: IkOptions = IkOptions(),
                   source: str = "<program>") -> Compensation:
    """Correct joint values planned on the ``nominal`` robot for the ``calibrated`` one.

    program: (N, n) joint values [rad or m]. The compensated values put the tool point
    (of ``frames``, or the tip origin without frames) where the nominal model puts it at
    the program's values, with the tip orientation the nominal model gives (required on
    six or more free joints, kept as closely as possible on fewer: the joints ``frames``
    records as held stay at their values and do not count). Both robots must have the
    same chain joints, without a mimic joint and its master (refused, as by
    :func:`compensate`).
    """
    if tuple(nominal.joint_names) != tuple(calibrated.joint_names):
        raise DataError(f"the nominal robot's chain ({', '.join(nominal.joint_names)}) differs "
                        f"from the calibrated one's ({', '.join(calibrated.joint_names)})")
    refuse_coupled(calibrated, COUPLED)
    tool = np.zeros(3)
    tilts: tuple[str, ...] = ()
    if frames is not None:
        frames.check_chain(calibrated)
        check_calibrated(frames, calibrated)
        tools = frames.located(frame=False).tools  # distances and contacts have one too
        if not 0 <= point < len(tools):
            raise FrameError(f"measured point {point + 1} asked for, {frames.source} has "
                             f"{len(tools)} tool point(s)")
        tool = tools[point]
        frames, tilts = on_urdf(frames, calibrated)  # a contact face's tilt it lacks
    _same_model(nominal, calibrated, tool)
    lines = np.arange(2, len(program) + 2) if lines is None else lines
    # the held joints at their values before the nominal poses are made: the targets too
    program, lower, upper, held = _held(calibrated, frames, np.atleast_2d(program), source,
                                        lines)
    R_nom, p_nom = ChainKinematics.of(nominal.geometry).tool_poses(program, tool)
    g = calibrated.geometry
    # a full pose needs six joints the solver may move: a held one (lower = upper) is not
    required = np.full(len(program), int(np.sum(lower < upper)) >= 6)
    sol = solve(ChainKinematics.of(g), tool, p_nom, R_nom, required, program, lower, upper,
                options)
    notes = ["program filter: each pose of the nominal model at the program's joint values "
             "(tool point and orientation, base frame) is reached by the calibrated model",
             *tilts]
    sol, soft = _deflected(frames, calibrated, sol, lower, upper)
    return _solution(calibrated, sol, program, lines, required, source,
                     notes + held + _backlash_notes(frames, calibrated) + soft)
