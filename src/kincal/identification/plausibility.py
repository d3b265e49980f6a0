"""The plausibility gate: is a finished calibration one a URDF should be written from?

Plain numpy. :func:`gather` collects the evidence of a calibration (sizes, residuals, how
far the corrections move the tool, unit clues) into an :class:`Evidence`; :func:`judge`
turns it into a frozen :class:`Plausibility` whose findings say what broke which
threshold, by how much, and the likely causes. The one writer refuses an implausible or
unconverged result unless the user accepts it knowingly.

The yardstick is the arm's **reach** L: the length of the chain at zero joint values
(first joint origin -> ... -> tip frame origin, summed) plus the distance of the measured
point from the tip frame, the latter at most max(chain, 1 m) so that a tool point fitted
from positions in the wrong unit cannot inflate the yardstick.

Criteria (defaults in :class:`Thresholds`), and why:

- **Residual**: the median position error after calibration above 2 % of L. A geometric
  calibration leaves what the model cannot express plus the instrument's noise: about
  0.08 mm (6e-5 L) on every simulated arm and design (``kincal simulate``, ec66, ur10,
  panda, ur3, seeds 0-2, l2 and ls), 1.4 mm median (1.8 mm RMS) on the TIAGo with motion
  capture and 1.6-2 deg of gear play (0.12 % of L). The broken cases measured leave
  2.4 % of L or more: UR10 data with a tip two or three links short (2.4 %, 3.6 %), 100 mm
  noise (7.7-9.4 %), rows shuffled against the positions (8.7-13 %), degrees read as
  radians (9.3-13 %), millimetres read as metres (over 1000 %). The median, not the RMS,
  so that a few gross outliers do not refuse a run (they are for ``--robust``).
- **Unexplained motion**: the model explains less than 40 % of the measured positions'
  motion (1 - e_rms^2 / spread^2) while the error after calibration is above 0.5 mm RMS.
  The reach is the wrong yardstick for data from a small volume: positions shuffled against
  their joint rows inside a 20 mm cube leave 12.8 mm RMS, under 2 % of a 1 m reach, yet the
  data spread only 15 mm: nothing was explained. Good calibrations explain over 99 % (R-test
  cube: 0.09 mm left of 15 mm; TIAGo motion capture: 1.8 mm of several hundred).
- **Corrections**: the tool point of the corrected model, compared with the nominal one
  over 300 seeded configurations spread over the joint limits (each set rigidly aligned
  to the other, as the measurement frame is free), moves by more than 10 % of L (RMS).
  Single parameter deviations are not a usable criterion: plain least squares on good
  data drifts along weakly determined combinations to 123 mm and 34 deg per parameter
  while its predictions move by about 1 mm, and the worst good run (ls on 20 mm R-test
  data, the paper's over-fit) moves the tool by 20 mm RMS = 1.9 % of L over the joint
  range (TIAGo: 1.0-1.3 %). A UR5 URDF fitted to UR10 data moves it by 21 % (with a
  0.06 mm residual: only this criterion sees it), degrees read as radians by 45-51 %,
  shuffled rows by 38-56 % (``python scripts/plausibility_cases.py``). One
  parameter check remains: an identified length correction above half of L, which no
  drift measured comes near (9.5 %).
- **Orientation**: the median orientation error after calibration (a pose's; a flush
  touch's tilt against its plane, which the residual's heights do not hold) above 5 deg.
  Real data leave about half a degree (TALOS flush touches 0.49 deg median, TIAGo's motion
  capture poses 0.50 deg RMS, 0.91 held out); TALOS's touches on a tip two or one joints
  short of the gripper (``--tip arm_left_5_link``, ``arm_left_6_link``) leave 36 and 24 deg
  with heights the residual lets through (9.2 and 2.7 mm of a 2.2 m reach).
- **Tool point**: a set's identified tool point more than 3 chain lengths from its tip
  frame (:data:`kincal.measurements.checks.TOOL_RATIO`): the data did not fix it. TALOS's
  flush touches read as plane contacts (``--flush`` forgotten): 10.1 m, std error 3 m,
  with corrections and residual that pass; real tools sit within one chain length.
- **Units** (from :mod:`kincal.measurements.checks`, confident cases only): the measured
  positions spread 300 times more (or less) than the nominal tip motion (millimetres read
  as metres gives about 1000; the warning level stays at 30); revolute joint values read
  as radians beyond 4 pi, or beyond 2 pi + 0.5 and outside the joint's URDF limits
  (degrees read as radians: the usual 90-180 "rad").
- **Convergence**: a solver that stopped at its iteration limit. It is reported apart
  (``accept_unconverged``), because the iterate may fit well (plain LS drifting along a
  weak direction) or not at all.

Likely causes are inferred, not certain, and messages say so (the order and the texts:
:mod:`kincal.identification.gate_causes`): unit clues first (even below the confident
level); columns named after URDF joints off the chain (a tip frame that does not match
the data) or on other branches (a base that moves with them); then how much of the
measured motion the model explains (below 0.4: rows shuffled, or another data file;
above: noise, a wrong tip, a URDF of another robot).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import ImplausibleResultError, NotConvergedError
from kincal.identification.orientation_convention import checked
from kincal.identification.gate_causes import (duplicate_cause, duplicate_notes, fit_causes,
                                                moving_base_cause, names_text,
                                                orientation_causes, overfit_cause, tool_causes,
                                                unit_causes, weak_cause)
from kincal.identification.statistics import angle_label, error_label
from kincal.measurements.checks import (DEGREES_AS_RADIANS, TOOL_RATIO, UNIT_RATIO, distance_ratio,
                                        duplicate_samples, millimetres_read_as_metres, spread)
from kincal.identification.tool_motion import change, farthest_tool, n_chains
from kincal.models.workspace import CHANGE, tool_points

if TYPE_CHECKING:
    from kincal.identification.problem import CalibrationProblem
    from kincal.identification.result import CalibrationResult

MAX_UNIT_POSES = 500  # poses for the unit clue (forward kinematics through the robot)


@dataclass(frozen=True)
class Thresholds:
    """Where the gate refuses; see the module notes for the measurements behind each.

    residual: median error after calibration, as a fraction of the reach.
    change: RMS movement of the tool point by the corrections over the joint range, as a
        fraction of the reach.
    length_correction: one identified length correction, as a fraction of the reach.
    length_ratio: measured / nominal spread of positions beyond which (or below whose
        inverse) the length unit is surely wrong.
    explained: fraction of the measured motion the model explains below which the
        positions are said not to follow the joint values: a refusal of its own (whatever
        the reach) when the error after calibration is also above unexplained_floor_mm.
    unexplained_floor_mm: RMS error [mm] below which a low explained fraction is left
        alone (a nearly still point measured with a fine instrument).
    orientation_deg: median orientation error after calibration [deg] (a pose's, a flush
        touch's tilt against its plane) above which the model does not describe the data.
    """

    residual: float = 0.02
    change: float = CHANGE
    length_correction: float = 0.5
    length_ratio: float = 10 * UNIT_RATIO
    explained: float = 0.4
    unexplained_floor_mm: float = 0.5
    orientation_deg: float = 5.0


@dataclass(frozen=True)
class Evidence:
    """The numbers the gate judges (lengths in mm unless named _m, angles in rad).

    corrections: the identified kinematic corrections, largest first (in reach fraction
        for lengths, in degrees for angles): (name, value in mm or deg, unit).
    length_ratio: spread of the measured positions / spread of the nominal tool point over
        the same poses (NaN when the poses barely move it).
    angle_max: largest |value| of a revolute joint [rad, as read]; angle_outside: whether
        that value lies outside its joint's URDF limits.
    off_chain_columns: columns of the data file named after URDF joints off the chain that
        can move the measured point (below the tip or above the base, Robot.off_chain_movers);
        other_branch_columns: those on other branches, which cannot (ignored, one note), the
        first ``at_base`` of them hanging from a base's own link; bases: the chains' bases.
    weak_corrections: when the largest correction is a parameter the data barely tell
        apart (the identifiability report's weak ones), the weak ones among the largest
        four; weak_scales: their prior classes' scales where the evidence estimated them,
        or the penalty's one lambda (:mod:`kincal.identification.gate_causes`).
    """

    reach_m: float
    residual_median_mm: float
    residual_rms_mm: float
    before_rms_mm: float
    spread_mm: float
    change_rms_mm: float
    change_max_mm: float
    corrections: tuple[tuple[str, float, str], ...] = ()
    length_ratio: float = float("nan")
    length_unit: str = "m"
    length_source: str = ""  # the file of length_ratio when several sets measure positions
    length_what: str = "positions"  # what length_ratio measures: positions or distances
    angle_max: float = 0.0
    angle_outside: bool = False
    prismatic_mm: str = ""  # a prismatic value in metres far beyond its limits (checks.
    #                         millimetres_read_as_metres): lengths in mm, the file's positions too
    angle_unit: str = "rad"
    off_chain_columns: tuple[str, ...] = ()
    other_branch_columns: tuple[str, ...] = ()
    at_base: int = 0
    bases: tuple[str, ...] = ()
    converged: bool = True
    iterations: int = 0
    method: str = "l2"
    equations: int = 0  # rows of the fit (3 per point, 3 per flush touch, ...); identified:
    identified: int = 0  # parameters the fit moved (plain LS on few equations per one: a cause)
    weak_corrections: tuple[str, ...] = ()  # the largest corrections if the largest is weak
    weak_scales: str = ""  # their classes' prior scales as the evidence estimated them, or
    #                        the one penalty weight ("lambda 0.001 chosen by cross-validation")
    convention_doubts: tuple[str, ...] = ()  # pose files read in a convention in doubt
    orientation_angle_max: float = 0.0  # [rad] largest orientation angle read (PoseData's)
    duplicates: tuple[str, ...] = ()  # samples repeated exactly (checks.duplicate_samples)
    orientation_median_deg: float | None = None  # the worst set's orientation errors after
    orientation_rms_deg: float | None = None  # calibration (poses; flush: the tilts) [deg]
    orientation_what: str = ""  # what they are ("tilt against the plane", "orientation")
    tool_far: tuple = ()  # (m, chain m, set, kind) of the tool point farthest from its tip
    residual_what: str = "position"  # what the worst set's errors are ("distance", ...)

    @property
    def explained(self) -> float:
        """Fraction of the measured motion (variance about the centroid) the model explains."""
        return (float("nan") if self.spread_mm <= 0
                else 1.0 - (self.residual_rms_mm / self.spread_mm) ** 2)


@dataclass(frozen=True)
class Finding:
    """One broken criterion: what, how large, against which threshold, and why (likely).

    kind: "residual", "orientation", "unexplained", "corrections", "length_correction",
    "length_unit", "angle_unit", "not_converged" or "orientation_convention" (a pose file's
    convention in doubt). value
    and threshold share ``unit`` (NaN where no one number is judged: a convention in doubt,
    whose two readings' errors its message gives). parameters: those the finding is about (largest first).
    causes: likely causes, most likely first."""

    kind: str
    message: str
    value: float
    threshold: float
    unit: str
    parameters: tuple[str, ...] = ()
    causes: tuple[str, ...] = ()

    def line(self) -> str:
        text = self.message
        if self.causes:
            text += "; likely cause: " + "; or ".join(self.causes)
        return text


@dataclass(frozen=True)
class Plausibility:
    """The gate's verdict on one calibration, with its evidence."""

    evidence: Evidence
    findings: tuple[Finding, ...]
    thresholds: Thresholds = Thresholds()
    notes: tuple[str, ...] = ()  # observations that do not refuse (printed as warnings)

    @property
    def plausible(self) -> bool:
        """No finding other than non-convergence."""
        return not any(f.kind != "not_converged" for f in self.findings)

    @property
    def converged(self) -> bool:
        return self.evidence.converged

    def as_dict(self) -> dict:
        """For REPORT.json: verdict, findings, evidence and thresholds."""
        return {"plausible": self.plausible, "converged": self.converged,
                "findings": [asdict(f) for f in self.findings],
                "evidence": {**asdict(self.evidence), "explained": self.evidence.explained},
                "thresholds": asdict(self.thresholds)}

    @property
    def causes(self) -> tuple[str, ...]:
        """The likely causes over all findings, most likely first, each once."""
        out: list[str] = []
        for f in self.findings:
            out += [c for c in f.causes if c not in out]
        return tuple(out)

    def describe(self, n_causes: int = 3) -> str:
        """The implausibility findings and the likely causes, as one line."""
        text = "; ".join(f.message for f in self.findings if f.kind != "not_converged")
        # a confident unit clue explains everything else: name it alone
        units = [f for f in self.findings if f.kind in ("length_unit", "angle_unit")]
        causes = [c for f in (units or self.findings) if f.kind != "not_converged"
                  for c in f.causes]
        causes = list(dict.fromkeys(causes))[:n_causes]
        return text + (". Likely cause: " + "; or ".join(causes) if causes else "")

    def check(self, accept_implausible: bool = False, accept_unconverged: bool = False,
              refused: str = "the corrected URDF is not written") -> list[str]:
        """Raise unless acceptable; return warnings for what was accepted knowingly.

        Raises ImplausibleResultError (checked first) or NotConvergedError, each carrying
        this Plausibility; ``refused`` says what the refusal means for the caller."""
        accepted = []
        if not self.plausible:
            if not accept_implausible:
                raise ImplausibleResultError(
                    f"implausible calibration, {refused}: {self.describe()}. If you are sure, "
                    "pass --accept-implausible (Python: accept_implausible=True)", self)
            accepted.append(f"accepted an implausible calibration as asked: {self.describe()}")
        if not self.converged:
            nc = next(f for f in self.findings if f.kind == "not_converged")
            if not accept_unconverged:
                raise NotConvergedError(
                    f"{nc.line()}; {refused}. Pass --accept-unconverged (Python: "
                    "accept_unconverged=True) to keep the best iterate", self)
            accepted.append(f"accepted an unconverged calibration as asked: {nc.message}")
        return accepted


# ------------------------------------------------------------------- judge
def judge(ev: Evidence, th: Thresholds = Thresholds()) -> Plausibility:
    """The findings of the gate on ``ev`` (see the module notes for the criteria)."""
    L_mm = ev.reach_m * 1e3
    out = []
    r = ev.length_ratio
    if math.isfinite(r) and (r > th.length_ratio or r < 1.0 / th.length_ratio):
        of = f" of {ev.length_source}" if ev.length_source else ""
        out.append(Finding("length_unit", f"the measured {ev.length_what}{of} spread {r:.4g}x "
                           "as much as the robot's tip moves", r, th.length_ratio, "ratio",
                           causes=tuple(unit_causes(ev)[:1])))
    if ev.angle_unit == "rad" and (ev.angle_max > 4 * math.pi or (
            ev.angle_max > DEGREES_AS_RADIANS and ev.angle_outside)):
        out.append(Finding("angle_unit", f"revolute joint values reach {ev.angle_max:.4g} rad"
                           + (", outside the URDF limits" if ev.angle_outside else ""),
                           ev.angle_max, 4 * math.pi, "rad",
                           causes=tuple(c for c in unit_causes(ev) if "degrees" in c)))
    if ev.orientation_angle_max > DEGREES_AS_RADIANS:  # no rpy or rotvec writer goes there
        out.append(Finding("angle_unit", f"orientation angles reach "
                           f"{ev.orientation_angle_max:.4g} rad", ev.orientation_angle_max,
                           DEGREES_AS_RADIANS, "rad",
                           causes=tuple(c for c in unit_causes(ev) if "orientation" in c)))
    if ev.residual_median_mm > th.residual * L_mm:
        out.append(Finding(
            "residual", f"the {ev.residual_what} error after calibration is "
            f"{ev.residual_median_mm:.4g} mm "
            f"(median; RMS {ev.residual_rms_mm:.4g} mm), above {th.residual:.0%} of the arm's "
            f"reach ({th.residual * L_mm:.3g} mm of {L_mm:.0f} mm): a geometric calibration "
            "leaves a fraction of a millimetre to a few", ev.residual_median_mm,
            th.residual * L_mm, "mm", causes=tuple(fit_causes(ev, th))))
    if ev.orientation_median_deg is not None and ev.orientation_median_deg > th.orientation_deg:
        out.append(Finding(
            "orientation", f"the {ev.orientation_what} after calibration is "
            f"{ev.orientation_median_deg:.4g} deg (median; RMS {ev.orientation_rms_deg:.4g} "
            f"deg), above {th.orientation_deg:g} deg: a geometric calibration leaves a fraction "
            "of a degree", ev.orientation_median_deg, th.orientation_deg, "deg",
            causes=orientation_causes(ev)))
    if ev.tool_far and ev.tool_far[0] > TOOL_RATIO * ev.tool_far[1]:
        far, length, source, kind = ev.tool_far
        out.append(Finding(
            "tool_point", f"the tool point of {source} is identified {far:.4g} m from the tip "
            f"frame, {far / length:.0f} times the chain's length ({length:.3g} m)", far,
            TOOL_RATIO * length, "m", causes=tool_causes(ev)))
    e = ev.explained
    if (not out or out[-1].kind != "residual") and math.isfinite(e) and e < th.explained \
            and ev.residual_rms_mm > th.unexplained_floor_mm:
        out.append(Finding(
            "unexplained", f"the model explains only {max(e, 0.0):.0%} of the measured motion: "
            f"the position error after calibration ({ev.residual_rms_mm:.4g} mm RMS) is nearly "
            f"as large as the data's own spread ({ev.spread_mm:.4g} mm RMS about their centre)",
            max(e, 0.0), th.explained, "fraction", causes=tuple(fit_causes(ev, th))))
    big = ", ".join(f"{n} {v:+.4g} {u}" for n, v, u in ev.corrections[:4])
    names = tuple(n for n, _, _ in ev.corrections[:4])
    if ev.change_rms_mm > th.change * L_mm:
        out.append(Finding(
            "corrections", f"the corrections move the tool point by {ev.change_rms_mm:.4g} mm "
            f"RMS (max {ev.change_max_mm:.4g} mm) over the joint range, above {th.change:.0%} of "
            f"the reach ({th.change * L_mm:.3g} mm); largest: {big}", ev.change_rms_mm,
            th.change * L_mm, "mm", names,
            causes=duplicate_cause(ev) + tuple(unit_causes(ev)) + overfit_cause(ev)
            + weak_cause(ev) + moving_base_cause(ev) + (
                "a URDF that does not describe the measured robot or a tip frame that does "
                "not match the data",)))
    lengths = [(n, v) for n, v, u in ev.corrections if u == "mm"]
    if lengths and abs(lengths[0][1]) > th.length_correction * L_mm:
        n, v = lengths[0]
        out.append(Finding(
            "length_correction", f"{n} is corrected by {v:+.4g} mm, more than "
            f"{th.length_correction:.0%} of the reach ({L_mm:.0f} mm)", abs(v),
            th.length_correction * L_mm, "mm", (n,), causes=tuple(fit_causes(ev, th))))
    for doubt in ev.convention_doubts:  # another convention: two readings' errors, said in
        out.append(Finding("orientation_convention", doubt, math.nan, math.nan, "", causes=(
            "orientations read in another convention than the file's",)))  # the message
    if not ev.converged:
        out.append(Finding(
            "not_converged", f"the solver did not converge in {ev.iterations} iterations",
            float(ev.iterations), float(ev.iterations), "iterations",
            causes=(("plain least squares on data that determine some parameters weakly "
                     "(use --method l2)") if ev.method == "ls" else
                    "data that do not fit the model (see the residual), or a very "
                    "ill-conditioned problem",)))
    notes: tuple[str, ...] = ()
    beyond = ev.off_chain_columns if not any(f.kind == "residual" for f in out) else ()
    elsewhere = ev.other_branch_columns
    if beyond or elsewhere:
        # a whole robot's log names joints on other branches: they move nothing measured.
        # Joints beyond the tip (or above the base) while the data fit: a tip short of the
        # data's, harmless only if they cannot move the measured point (e.g. a tool on the
        # last axis), so say it without refusing
        said = [f"{len(elsewhere)} on other branches of the tree move neither the tip nor "
                f"the base ({names_text(elsewhere)})"] if elsewhere else []
        said += [f"{names_text(beyond)} beyond the chain's ends: if "
                 f"{'they move' if len(beyond) > 1 else 'it moves'} the measured point, the "
                 "tip frame does not match the data (check --tip)"] if beyond else []
        count = len(elsewhere) + len(beyond)
        notes = (f"the data file's columns for {count} URDF joint{'s' * (count > 1)} off the chain "
                 "are ignored: " + "; ".join(said),)
    return Plausibility(ev, tuple(out), th, notes + duplicate_notes(ev))


# ------------------------------------------------------------------ gather
def gather(problem: CalibrationProblem, result: CalibrationResult) -> Evidence:
    """The evidence of ``result``, calibrated by ``problem`` (one or many sets of any kind).

    The kinematics are read through the robots themselves (nominal and corrected, the
    latter being what a URDF export writes), whatever error model was identified. The
    residual is the worst set's (median and RMS of its sample errors); the spread and the
    unit clue come from the first set that measures positions."""
    lay = result.layout
    L, d, rms = max((change(problem, result, k) for k in range(n_chains(problem))),
                    key=lambda c: c[2] / c[0])  # the worst chain's
    corrections = []
    for p, kinematic in zip(result.parameters, lay.is_kinematic.tolist(), strict=True):
        if p.status == "identified" and kinematic:
            factor, unit = (1e3, "mm") if p.is_length else (180.0 / math.pi, "deg")
            corrections.append((p.name, p.deviation * factor, unit))
    # largest first, lengths against the reach and angles in degrees on one footing
    corrections.sort(key=lambda c: -abs(c[1]) / (L * 1e3 if c[2] == "mm" else 180.0))
    weak_top, weak_scales = _weak_corrections(result, corrections)
    worst = result.sets[0] if len(result.sets) == 1 else max(
        result.sets, key=lambda s: float(np.median(s.errors_after)))
    datas = [km.data for km in problem.kinds]
    # unit clue: the measured spread against the nominal tip's with the tool guess, on at
    # most MAX_UNIT_POSES poses spread through the file (a reference forward kinematics),
    # of every set that measures positions, each on its own chain: the clue is the set
    # farthest off (a second file in mm beside one in m), the spread the worst set's
    ratio, spread_mm, unit_set, length_what = float("nan"), float("nan"), datas[0], "positions"
    guess = np.zeros(3) if problem.options.tool_guess is None else np.asarray(
        problem.options.tool_guess, float)
    clues = []
    for dt, robot in zip(datas, problem.robots):
        if getattr(dt, "distances", None) is not None:  # no wider than the tool point moves
            k = np.linspace(0, len(dt) - 1, min(len(dt), MAX_UNIT_POSES)).astype(int)
            clues.append((distance_ratio(dt.distances[k], tool_points(
                robot, dt.joint_values[k], guess)), float("nan"), dt, "distances"))
            continue
        if getattr(dt, "positions", None) is None:
            continue
        points = getattr(dt, "points", None)
        first = np.arange(len(dt)) if points is None else np.flatnonzero(points == 0)
        if len(first) > MAX_UNIT_POSES:
            first = first[np.linspace(0, len(first) - 1, MAX_UNIT_POSES).astype(int)]
        s_pred = spread(tool_points(robot, dt.joint_values[first], guess))
        s_all = spread(dt.positions)  # = the subset's when that is every row (in order)
        s_meas = s_all if len(first) == len(dt) else spread(dt.positions[first])
        clues.append((s_meas / s_pred if s_pred >= 1e-3 else float("nan"), s_all * 1e3, dt,
                      "positions"))
        if dt is worst.data:
            spread_mm = s_all * 1e3
    if clues:
        ratio, _, unit_set, length_what = max(clues, key=lambda c: abs(math.log(
            c[0])) if math.isfinite(c[0]) and c[0] > 0 else -1.0)
    angle_max, outside = 0.0, False
    for dt, robot in zip(datas, problem.robots):  # each set against its own chain
        gi = robot.geometry  # continuous joints (no limits) may turn many times: no clue
        rev = [j for j, k in enumerate(gi.kinds) if k == "revolute"
               and (np.isfinite(gi.lower[j]) or np.isfinite(gi.upper[j]))]
        if not rev:
            continue
        # the first largest |value| in row-major order over the revolute columns, a column
        # at a time (no copy of the whole set's joint values)
        tops = [(int(np.argmax(np.abs(dt.joint_values[:, c]))), c) for c in rev]
        top = max(abs(float(dt.joint_values[i, c])) for i, c in tops)
        i, c = min((i, c) for i, c in tops if abs(float(dt.joint_values[i, c])) == top)
        if top >= angle_max:
            v = dt.joint_values[i, c]
            angle_max = top
            outside = bool(v < gi.lower[c] - 1e-6 or v > gi.upper[c] + 1e-6)
    prismatic_mm = next((f"{getattr(dt, 'source', '')}: {clue}" for dt, g in zip(
        datas, (r.geometry for r in problem.robots)) if getattr(dt, "length_unit", "m") == "m"
        and (clue := millimetres_read_as_metres(g.joint_names, g.kinds, g.lower, g.upper,
                                                dt.joint_values, dt.rows))), "")
    off_chain, elsewhere, at_base = problem.chains.off_chain_columns(datas)
    # the worst set's orientation errors after calibration (poses; flush: the tilts)
    turned = [(a.median, a.rms, angle_label(s.kind)) for s in result.sets
              if (a := s.orientation_after) is not None]
    o_median, o_rms, o_what = max(turned) if turned else (None, None, "")
    return Evidence(
        reach_m=L, residual_median_mm=worst.after.median, residual_rms_mm=worst.after.rms,
        before_rms_mm=worst.before.rms,
        spread_mm=spread_mm,
        change_rms_mm=rms, change_max_mm=float(d.max()),
        corrections=tuple(corrections), length_ratio=float(ratio),
        length_unit=getattr(unit_set, "length_unit", "m"), angle_max=angle_max,
        length_source=str(getattr(unit_set, "source", "")) if len(clues) > 1 else "",
        length_what=length_what,
        angle_outside=outside, angle_unit=getattr(datas[0], "angle_unit", "rad"),
        prismatic_mm=prismatic_mm,
        off_chain_columns=off_chain, other_branch_columns=elsewhere, at_base=at_base,
        bases=tuple(dict.fromkeys(r.base for r in problem.robots)),
        converged=bool(result.converged),
        iterations=int(result.solve.iterations), method=problem.options.method,
        equations=int(sum(km.N * km.dim for km in problem.kinds)),
        identified=sum(p.status == "identified" for p in result.parameters),
        weak_corrections=weak_top, weak_scales=weak_scales,
        convention_doubts=tuple(d for d in (getattr(checked(type(problem), robot, dt),
                                                    "convention_doubt", "")
                                            for dt, robot in zip(datas, problem.robots)) if d),
        orientation_angle_max=max(float(getattr(dt, "angles_read_max", 0.0)) for dt in datas),
        duplicates=tuple(duplicate_samples(datas)), orientation_median_deg=o_median,
        orientation_rms_deg=o_rms, orientation_what=o_what, residual_what=error_label(worst.kind),
        tool_far=farthest_tool(problem, result) or ())


def _weak_corrections(result: CalibrationResult, corrections) -> tuple[tuple[str, ...], str]:
    """(the weak ones among the four largest corrections if the largest is weak, their
    classes' estimated prior scales as text): see Evidence."""
    weak = {w.name for w in result.identifiability.weak}
    if not corrections or corrections[0][0] not in weak:
        return (), ""
    names = tuple(n for n, _, _ in corrections[:4] if n in weak)
    fit, lay = result.evidence, result.layout
    if fit is None:  # one lambda for every parameter
        how = " chosen by cross-validation" if result.cv is not None else ""
        return names, (f"lambda {result.lam:.3g}{how}" if math.isfinite(result.lam) else "")
    classes = dict.fromkeys(c for n, c in zip(lay.names, lay.classes) if n in names)
    return names, ", ".join(fit.scale_text(c) for c in classes
                            if c in ("length", "twist", "offset") and c in fit.classes
                            and not fit.given[fit.classes.index(c)])
