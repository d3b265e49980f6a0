"""The human summary of a calibration result (mm and degrees, labelled)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from kincal.identification.result import CalibrationResult

WHAT = {"point": "position", "pose": "position and orientation", "distance": "distance",
        "plane": "distance to the plane", "flush": "height above the plane"}


def _z(v: float, digits: int = 5) -> float:
    """No "-0.0000" for values that are zero to the ``digits`` decimals shown."""
    return 0.0 if abs(v) < 0.5 * 10.0 ** -digits else v


def header(result: CalibrationResult) -> list[str]:
    r, ev, n = result, result.evidence, len(result.sets)
    how = (f"lambda = {r.lam:.4g}" if ev is None else "priors toward nominal per class, "
           + ("given" if ev.given.all() and ev.noise_given else "chosen by maximum evidence"))
    cv = ""
    if r.cv is not None:
        cv = " (chosen by cross-validation)"
        if r.cv.subsample:
            cv += " on a random {} of the {} poses".format(*r.cv.subsample)
    sets = f"{n} measurement set(s), " if n > 1 else ""
    return [f"kincal calibration of {r.robot.name} ({r.chains_text()}), {sets}"
            f"method {r.options.method}, {how}{cv}",
            *([f"  penalty: {r.penalty_choice}"] if r.penalty_choice else []),
            *([f"  fleet prior: {r.options.prior.n_units} units ({r.options.prior.method}); "
               "the kinematic penalty is centred on the fleet mean, shaped by its covariance"]
              if r.options.prior is not None else []),
            *([f"  {ev.line()}" + ("" if ev.converged
                                    else f" [NOT SETTLED in {ev.iterations} rounds]")]
              if ev is not None else [])]


def held(result: CalibrationResult) -> list[str]:
    """The chain joints a set's file had no column for, and the values they were held at."""
    from kincal.measurements.fixed_joints import held_text

    out = []
    for k, s in enumerate(result.sets, start=1):
        fixed = getattr(s.data, "fixed_joints", ())
        if fixed:  # in the units of the set's own chain's joints
            robot = result.robot if result.chains is None else result.chains.robots[k - 1]
            kinds = dict(zip(robot.joint_names, robot.geometry.kinds))
            out.append(("  " if len(result.sets) == 1 else f"  set {k}: ")
                       + "joints held during the measurements (not in the file): " + ", ".join(
                           held_text(j, v, kinds.get(j, "revolute")) for j, v in fixed))
    return out


def errors(result: CalibrationResult) -> list[str]:
    r = result
    if len(r.sets) == 1:
        s = r.sets[0]
        K = getattr(s.data, "n_points", 1) if s.kind == "point" else 1
        out = ([f"  {K} measured points per pose: statistics are over every point"]
               if K > 1 else [])
        if s.kind != "point":
            out.append(f"  set 1: {s.kind} ({s.source}), {WHAT.get(s.kind, s.kind)} errors")
        out += [f"  before: {s.before.line()}", f"  after:  {s.after.line()}"]
        return out + _angle_lines(s, "  ")
    out = []
    for k, s in enumerate(r.sets, start=1):
        out.append(f"  set {k}: {s.kind} ({s.source}), {WHAT.get(s.kind, s.kind)} errors")
        out.append(f"    before: {s.before.line()}")
        out.append(f"    after:  {s.after.line()}")
        out += _angle_lines(s, "    ")
    return out


def _angle_lines(s, indent: str) -> list[str]:
    """The orientation errors of a pose (or flush) set before and after, in degrees."""
    if s.orientation_after is None:
        return []
    from kincal.identification.statistics import angle_label

    label = angle_label(s.kind)
    return [f"{indent}{label} before: {s.orientation_before.line()}",
            f"{indent}{label} after:  {s.orientation_after.line()}"]


def status(result: CalibrationResult) -> list[str]:
    r = result
    if r.solve.iterations == 0 and r.converged:  # the penalty's own fits reached the optimum
        line = ("  solver: converged in the penalty's fits (the final fit started at the "
                f"optimum: 0 further iterations), {r.solve.reason}")
    else:
        line = (f"  solver: {r.solve.iterations} iterations, {r.solve.reason}"
                + ("" if r.converged else "  [NOT CONVERGED]"))
    out = [line]
    p = r.plausibility
    if p is not None and not p.plausible:
        out.append("  plausibility gate: IMPLAUSIBLE (" + ", ".join(
            f.kind for f in p.findings if f.kind != "not_converged")
            + "); result.plausibility has the evidence")
    if r.options.robust:
        d = r.downweighted
        out.append(f"  robust loss {r.options.robust}: " + (
            "no sample down-weighted below 0.5" if not d else
            f"{len(d)} samples down-weighted below 0.5: " + ", ".join(
                f"line {w.row} ({w.error_mm:.3g} mm, weight {w.weight:.2f})" for w in d[:10])
            + (" ..." if len(d) > 10 else "")))
    from kincal.identification.diagnosis import diagnose

    finding = diagnose(r)  # a pattern a missing term would explain, with its size
    if finding is not None:
        out.append(f"  {finding.line()}")
    if r.term_evidence is not None:  # one the evidence favours, on data too few for that
        out.append(f"  {r.term_evidence.line()}")
    if r.layout.n_backlash:
        out.append(f"  backlash terms ({', '.join(r.layout.backlash)}): approach directions "
                   f"from {r.order_source}; the URDF models the middle of the play")
    if r.layout.compliance:
        out.append("  compliance terms: " + ", ".join(
            f"{j} {math.degrees(c) * t:.3g} deg at its RMS gravity torque {t:.3g} N m"
            for (j, c), t in zip(r.compliance.items(), r.layout.torque_rms))
                   + "; FRAMES.json carries them, the URDF stays geometric")
    return out


def table(result: CalibrationResult) -> list[str]:
    r = result
    lines = ["  parameter                 nominal      deviation    std.err  unit"]
    frames = []
    for p, is_frame in zip(r.parameters, r.layout.is_frame):
        nom, dev, se, unit = p.reported()
        flag = "" if p.status == "identified" else f"  ({p.status})"
        if is_frame:
            # a frame has no nominal: its start (fitted with the nominal kinematics) instead
            frames.append(f"  {p.name:<24} {_z(nom, 4):>10.4f} {_z(nom + dev, 4):>13.4f} "
                          f"{_z(se):>10.5f}  {unit}{flag}")
        elif p.status != "dropped":
            lines.append(f"  {p.name:<24} {_z(nom, 4):>10.4f} {_z(dev):>+13.5f} {_z(se):>10.5f}  "
                         f"{unit}{flag}")
    one_point = len(r.sets) == 1 and r.sets[0].kind == "point"
    label = "measurement frame, tool" if one_point else "frames of the sets"
    lines.append(f"  {label:<24} {'start':>10} {'estimate':>13} {'std.err':>10}  unit")
    return lines + frames


def summary(result: CalibrationResult) -> str:
    """Header, penalty, identifiability, errors per set, solver and gate, parameter table."""
    i = result.identifiability
    # its notes, one set or many (what the data leave at the start, kept parameters standing
    # in for dropped ones amplified), less those given as warnings; the dropped and weak
    # lists are the caller's to add (the command line: the weak ones, all with -v)
    stand_in = i.stand_in_note()
    notes = [f"  note: {n}" for n in (*i.notes, *([stand_in] if stand_in else []))
             if n not in i.warned]
    models = result.model_choice.lines() if result.model_choice is not None else []
    return "\n".join(header(result) + models + held(result) + [f"  {i.headline()}"] + notes
                     + errors(result)
                     + status(result) + table(result))
