"""The calibration report: every number of a result as plain JSON-ready data.

Deterministic: the same result gives the same text (no time stamps, no wall times),
so the same inputs and seed give byte-identical report files. SI values carry their
unit in the key (``_m``, ``_rad``); human figures are in mm and degrees, labelled.
"""

from __future__ import annotations

import json
import math

import numpy as np

from kincal.identification.result import CalibrationResult
from kincal.identification.selection import Identifiability
from kincal.identification.statistics import AngleStats, ErrorStats

FORMAT = "kincal-report-1"


def _clean(value, keep_arrays: bool = False):
    """JSON-safe: numpy to Python, NaN and inf to None; with ``keep_arrays`` the arrays
    are left as they are (for :func:`dump_pieces`, which makes each when it is written)."""
    if isinstance(value, dict):
        return {k: _clean(v, keep_arrays) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v, keep_arrays) for v in value]
    if isinstance(value, np.ndarray):
        return value if keep_arrays else _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def stats_dict(stats: ErrorStats) -> dict:
    return {f"{k}_mm" if k != "n" else k: v for k, v in stats.as_dict().items()}


def angle_dict(stats: AngleStats) -> dict:
    """Orientation-error statistics [deg] with the unit in the keys."""
    return {f"{k}_deg" if k != "n" else k: v for k, v in stats.as_dict().items()}


def identifiability_dict(ident: Identifiability) -> dict:
    return {
        "rank": ident.rank,
        "condition_number": ident.condition_number,
        "rank_tolerance": ident.rank_tol,
        "singular_values": ident.singular_values,
        "free": list(ident.free),
        "kept": list(ident.kept),
        "dropped": [{"name": d.name, "reproduced_by": [{"name": n, "coefficient": c}
                                                       for n, c in d.combination],
                     "amplification": d.amplification, "why": d.describe()}
                    for d in ident.duplicates],
        "stand_in_note": ident.stand_in_note(),
        "fixed": list(ident.fixed),
        "weak": [{"name": w.name, "independence": w.independence,
                  "sensitivity_mm_per_unit": w.sensitivity, "why": w.describe()}
                 for w in ident.weak],
    }


def set_dict(s) -> dict:
    """One measurement set of a result: kind, source, frames, errors and residuals."""
    return {"kind": s.kind, "source": s.source, "samples": int(len(s.errors_after)),
            "frames": dict(zip(s.frame_names, map(float, s.frames))),
            "errors": {"before": stats_dict(s.before), "after": stats_dict(s.after)},
            "orientation_after_mean_deg": s.orientation_after_deg,
            "fixed_joints": dict(getattr(s.data, "fixed_joints", ())),
            "orientation_errors": None if s.orientation_after is None else {
                "before": angle_dict(s.orientation_before),
                "after": angle_dict(s.orientation_after)},
            "residuals": {"row": s.rows, "error_mm": s.errors_after * 1e3,
                          **_angles(s), "residual_rows_m": s.residuals}}


def _angles(s) -> dict:
    """A pose or flush set's per-sample orientation error after calibration [deg] and its
    angles [rad] (the rotation vector; the roll and pitch against the plane), for the
    residuals of REPORT.json; nothing for other kinds."""
    if s.angle_rows_after is None:
        return {}
    return {"orientation_error_deg": np.degrees(s.angles_after),
            "orientation_rows_rad": s.angle_rows_after}


def residuals_dict(result: CalibrationResult) -> dict:
    """Every sample's error after calibration [mm], with its file line (``row``): one set as
    it always was (its ``point`` per sample, and for points the components); several sets
    one after the other, each sample's ``set`` (1-based, as ``robot.chains``) beside it, so
    that no reader takes the first set's for the whole (each set's own are in ``sets``)."""
    first = result.sets[0]
    if len(result.sets) == 1:
        return {"row": first.rows, "point": result.points, "error_mm": first.errors_after * 1e3,
                **({"dx_dy_dz_mm": first.residuals * 1e3} if first.kind == "point" else {}),
                **{k: v for k, v in _angles(first).items() if k == "orientation_error_deg"}}
    points = [getattr(s.data, "points", None) for s in result.sets]
    return {"set": np.concatenate([np.full(len(s.errors_after), i + 1)
                                   for i, s in enumerate(result.sets)]),
            "row": np.concatenate([np.asarray(s.rows) for s in result.sets]),
            "point": None if all(p is None for p in points) else [  # None: a set without
                v for s, p in zip(result.sets, points)                  # measured points
                for v in ([None] * len(s.errors_after) if p is None else np.asarray(p).tolist())],
            "error_mm": np.concatenate([s.errors_after for s in result.sets]) * 1e3}


def result_dict(result: CalibrationResult, data_source: str | None = None) -> dict:
    """The whole result (REPORT.json), JSON-ready."""
    return _clean(result_tree(result, data_source))


def result_tree(result: CalibrationResult, data_source: str | None = None) -> dict:
    """:func:`result_dict` before its numbers are made Python ones (numpy arrays kept: a
    300,000-pose result's residuals as Python numbers took some 300 MB), for
    :func:`dump_pieces`."""
    from kincal import __version__
    from kincal.identification.diagnosis import diagnose

    finding = diagnose(result)  # a pattern a missing term would explain

    o = result.options
    params = []
    for p in result.parameters:
        nom, dev, se, unit = p.reported()
        si = ("m" if p.is_length else "rad") + ("/(N m)" if unit.endswith("/(N m)") else "")
        params.append({"name": p.name, "status": p.status, "unit": unit,
                       f"nominal_{si}": p.nominal, f"estimate_{si}": p.estimate,
                       f"deviation_{si}": p.deviation, f"std_error_{si}": p.std_error,
                       f"nominal_{unit}": nom, f"deviation_{unit}": dev,
                       f"std_error_{unit}": se,
                       # a frame parameter has no nominal: its "nominal" is the start
                       **({f"start_{si}": p.nominal}
                          if result.layout.is_frame[result.layout.index(p.name)] else {})})
    first = result.sets[0]
    out = {
        "format": FORMAT,
        "kincal_version": __version__,
        "robot": {"name": result.robot.name, "urdf": str(result.robot.source),
                  "base": result.robot.base, "tip": result.robot.tip,
                  "joints": list(result.robot.joint_names),
                  "chains": [{"set": i + 1, "base": s.base_frame, "tip": s.tip_frame}
                             for i, s in enumerate(result.sets)],
                  "error_model": result.error_model.name,
                  "model_notes": [n for n in result.error_model.notes]},
        "data": {"source": data_source if data_source is not None else first.source,
                 "samples": int(sum(len(s.errors_after) for s in result.sets)),
                 "points_per_pose": int(getattr(first.data, "n_points", 1)),
                 "acquisition_order": result.order_source},
        "sets": [set_dict(s) for s in result.sets],
        "options": {"method": o.method, "lambda": o.lam, "folds": o.fold_count, "seed": o.seed,
                    "prior_mm": o.prior_mm, "prior_deg": o.prior_deg, "noise_mm": o.noise_mm,
                    "lambda_grid": [o.lambda_min, o.lambda_max, o.n_lambdas],
                    "penalty_length_scale_m": o.length_scale,
                    "penalty_angle_scale_rad": o.angle_scale,
                    "fix": list(o.fix), "free": list(o.free), "backlash": list(o.backlash),
                    "compliance": list(o.compliance),
                    "tool_guess_m": o.tool_guess, "rank_tolerance": o.rank_tol,
                    "solver": {"rule": o.solver.rule, "rel_tol": o.solver.rel_tol,
                               "cost_rtol": o.solver.cost_rtol,
                               "max_iterations": o.solver.max_iterations,
                               "cost_tol_mm2": o.solver.cost_tol,
                               "cost_window": o.solver.cost_window,
                               "step_tol": o.solver.step_tol}},
        "lambda": result.lam,
        "cross_validation": None if result.cv is None else result.cv.as_dict(),
        "evidence": None if result.evidence is None else result.evidence.as_dict(),
        "penalty_choice": result.penalty_choice,
        "model_choice": None if result.model_choice is None else result.model_choice.as_dict(),
        "diagnosis": None if finding is None else finding.as_dict(),
        "term_evidence": (None if result.term_evidence is None
                          else result.term_evidence.as_dict()),
        "identifiability": identifiability_dict(result.identifiability),
        "parameters": params,
        "frames": result.frames_dict(),
        "errors": {"before": stats_dict(result.before), "after": stats_dict(result.after)},
        "convergence": {"converged": result.converged, "reason": result.solve.reason,
                        "iterations": result.solve.iterations,
                        "objective_mm2": result.solve.cost,
                        "damping": result.solve.damping},
        "robust": {"loss": o.robust, "scale_mm": o.robust_scale_mm,
                   "downweighted": [{"row": d.row, "error_mm": d.error_mm, "weight": d.weight}
                                    for d in result.downweighted]},
        "residuals": residuals_dict(result),
        "plausibility": None if result.plausibility is None else result.plausibility.as_dict(),
    }
    return out


def dumps(data: dict) -> str:
    return json.dumps(_clean(data), indent=2, allow_nan=False) + "\n"


def dump_pieces(data: dict, size: int = 1 << 16):
    """:func:`dumps`'s text, the same bytes, in pieces of about ``size`` characters for the
    writer (REPORT.json): at many poses the text is never held whole, nor the encoder's
    list of its millions of tokens, nor the arrays as Python numbers but one at a time
    (a 300,000-pose REPORT.json took 909 MB made at once)."""
    buf: list[str] = []
    n = 0

    def array(value):  # each array made Python numbers as the encoder reaches it
        if isinstance(value, np.ndarray):
            return _clean(value.tolist())
        raise TypeError(f"{type(value).__name__} is not JSON serializable")

    encoder = json.JSONEncoder(indent=2, allow_nan=False, default=array)
    for token in encoder.iterencode(_clean(data, keep_arrays=True)):
        buf.append(token)
        n += len(token)
        if n >= size:
            yield "".join(buf)
            buf, n = [], 0
    buf.append("\n")
    yield "".join(buf)
