"""One self-contained HTML page per calibration: numbers, tables and figures.

Everything is inside the file: figures are PNGs embedded as base64 ``data:`` URIs, the
style sheet is inline, there is no script and no link to any network resource, so the
page opens offline and can be mailed or archived as it is. Deterministic apart from the
PNG bytes matplotlib writes (no time stamps in the text).

Sections (their ``id`` in brackets, see ``SECTIONS``): summary, what was identified and
dropped and why, the parameter table with standard errors, residuals per sample before
and after, residuals against each joint, the cross-validation curve, the predicted
accuracy map, and the warnings of the run.
"""

from __future__ import annotations

import base64
import html
import math


SECTIONS = (("summary", "Summary"), ("identification", "What the data identify"),
            ("parameters", "Parameters"), ("residuals", "Residuals per measurement set"),
            ("joints", "Residuals against the joints"), ("cv", "Choice of lambda"),
            ("accuracy", "Predicted accuracy"), ("validation", "Held-out validation"),
            ("warnings", "Warnings and notes"), ("provenance", "Provenance"))

_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 1em auto; padding: 0 1em;
       color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0; }
th, td { border: 1px solid #ddd; padding: 2px 8px; text-align: right; }
th { background: #f0f0f0; } td.name, th.name { text-align: left; font-family: monospace; }
tr.dropped, tr.fixed { color: #888; background: #f7f7f7; }
tr.weak { background: #fff6e0; }
pre { background: #f6f6f6; padding: 0.6em; white-space: pre-wrap; font-size: 0.85em; }
img { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
nav a { margin-right: 1em; } .muted { color: #777; }
"""


def _e(text) -> str:
    from kincal.export.writer import printable  # a file name's undecoded bytes too

    return html.escape(printable(str(text)), quote=True)


def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{data}">'


def _num(v, fmt: str) -> str:
    """``v`` formatted, "" for None or not finite; never "-0.00000" (a value that is zero
    to the digits shown is written as zero)."""
    if v is None or not math.isfinite(v):
        return ""
    text = format(v, fmt)
    return format(0.0, fmt) if float(text) == 0.0 else text


def _frame_value(name: str, value: float) -> str:
    """A frame parameter in mm or degrees."""
    angle = name.rsplit(".", 1)[-1] in ("rx", "ry", "rz")
    return _num(math.degrees(value) if angle else value * 1e3, ".4f")


def _section(sid: str, body: str) -> str:
    title = dict(SECTIONS)[sid]
    return f'<section id="{sid}">\n<h2>{_e(title)}</h2>\n{body}\n</section>\n'


def _summary(result, data_source) -> str:
    r, o = result.robot, result.options
    rows = [("robot", f"{r.name} ({result.chains_text()})"), ("URDF", r.source),
            ("data", data_source or "(not given)"),
            *[(f"set {k}" if len(result.sets) > 1 else "samples",
               (f"{s.kind}, {s.source}: " if len(result.sets) > 1 else "")
               + f"{len(s.errors_after)} samples"
               + (f" ({s.data.n_points} point(s) per pose)" if s.kind == "point" else "")
               + (f"; before {s.before.line()}; after {s.after.line()}"
                  if len(result.sets) > 1 else ""))
              for k, s in enumerate(result.sets, start=1)],
            ("method", o.method + (f", lambda = {result.lam:.4g}" if o.method == "l2"
                                   and math.isfinite(result.lam) else "")
             + (" (chosen by cross-validation)" if result.cv is not None else "")),
            ("identifiable", result.identifiability.headline()
             .removeprefix("identifiable: ")),
            ("before", result.before.line()), ("after", result.after.line()),
            *_angle_rows(result),
            ("solver", f"{result.solve.iterations} iterations, {result.solve.reason}"
             + ("" if result.converged else "  [NOT CONVERGED]"))]
    table = "<table>" + "".join(f'<tr><th class="name">{_e(k)}</th><td class="name">{_e(v)}'
                                "</td></tr>" for k, v in rows) + "</table>"
    # the console summary's other lines (robust loss, backlash, several points), without
    # what the table shows and without its parameter table (the Parameters section has it)
    text = result.summary().splitlines()
    cut = next((i for i, line in enumerate(text) if line.startswith("  parameter ")), len(text))
    extra = [line.strip() for line in text[1:cut]
             if not line.strip().startswith(("identifiable:", "before:", "after:", "solver:"))
             and not (len(result.sets) == 1 and _is_angle_line(line))]
    return table + "".join(f"<p>{_e(line)}</p>" for line in extra)


def _angle_rows(result) -> list[tuple[str, str]]:
    """The orientation errors of a single pose (or flush) set, before and after [deg]."""
    s = result.sets[0]
    if len(result.sets) > 1 or s.orientation_after is None:
        return []
    from kincal.identification.statistics import angle_label

    label = angle_label(s.kind, short=True)
    return [(f"{label} before", s.orientation_before.line()),
            (f"{label} after", s.orientation_after.line())]


def _is_angle_line(line: str) -> bool:
    return line.strip().startswith(("orientation before:", "orientation after:",
                                     "tilt against the plane before:",
                                     "tilt against the plane after:"))


def _angle_html(s) -> str:
    """'<br>orientation before: ...<br>... after: ...' of a pose (or flush) set, or ''."""
    if s.orientation_after is None:
        return ""
    from kincal.identification.statistics import angle_label

    label = angle_label(s.kind)
    return (f"<br>{label} before: {_e(s.orientation_before.line())}"
            f"<br>{label} after: {_e(s.orientation_after.line())}")


def _identification(result) -> str:
    from kincal.identification.selection import grouped

    ident = result.identifiability
    out = [f"<p>{_e(ident.headline())}. Kept (identified): "
           f"{_e(grouped(ident.kept))}.</p>"]
    if ident.duplicates:
        out.append("<p>Dropped as redundant on these data: each is held at its nominal "
                   "value, and the kept parameters on the right absorb its effect (one "
                   "unit, mm or deg, of it acts like the combination shown):</p><table>"
                   '<tr><th class="name">dropped</th><th class="name">why</th></tr>')
        out += [f'<tr><td class="name">{_e(d.name)}</td><td class="name">{_e(d.describe())}'
                "</td></tr>" for d in ident.duplicates]
        out.append("</table>")
    else:
        out.append("<p>No parameter was dropped.</p>")
    if ident.fixed:
        out.append(f"<p>Fixed by the user: {_e(', '.join(ident.fixed))}.</p>")
    if ident.weak:
        out.append("<p>Weak (kept, but barely told apart from the others by these poses; "
                   "their estimates trade off against each other):</p><ul>")
        out += [f"<li><code>{_e(w.describe())}</code></li>" for w in ident.weak]
        out.append("</ul>")
    out += [f"<p>Note: {_e(n)}</p>" for n in ident.notes]
    return "\n".join(out)


def _parameters(result, png) -> str:
    weak = {w.name for w in result.identifiability.weak}
    why = {d.name: d.describe() for d in result.identifiability.duplicates}
    head = ('<tr><th class="name">parameter</th><th class="name">status</th><th>nominal</th>'
            "<th>deviation</th><th>estimate</th><th>std. error</th><th class=\"name\">unit</th>"
            "</tr>")
    rows = []
    for p, is_frame in zip(result.parameters, result.layout.is_frame):
        nom, dev, se, unit = p.reported()
        status = p.status + (" (weak)" if p.name in weak else "")
        cls = p.status if p.status != "identified" else ("weak" if p.name in weak else "")
        title = f' title="{_e(why[p.name])}"' if p.name in why else ""
        shown_dev = "" if p.status != "identified" or is_frame else _num(dev, "+.5f")
        rows.append(f'<tr class="{cls}"{title}><td class="name">{_e(p.name)}</td>'
                    f'<td class="name">{_e(status)}</td>'
                    f"<td>{'' if is_frame else _num(nom, '.5f')}</td><td>{shown_dev}</td>"
                    f"<td>{_num(nom + dev, '.5f')}</td><td>{_num(se, '.5f')}</td>"
                    f'<td class="name">{unit}</td></tr>')
    note = ("<p class=\"muted\">Lengths in mm, angles in degrees. Dropped and fixed parameters "
            "are held at their nominal value (no deviation, no standard error). The "
            "measurement frame and tool point have no nominal: their estimate is shown. "
            "Standard errors: sandwich estimate from the residuals.</p>")
    img = _img(png, "identified parameter deviations") if png else ""
    return note + img + f"<table>{head}{''.join(rows)}</table>"


def _cv(result, png) -> str:
    # the evidence estimator (lam "evidence") sets result.evidence where it is available
    ev = getattr(result, "evidence", None)
    if ev is not None:
        trace = ", ".join(f"{v:.2f}" for v in ev.log_evidence)
        return (f"<p>Pull toward nominal chosen by maximum evidence: {_e(ev.line())}. "
                f"{ev.iterations} outer iterations"
                + ("" if ev.converged else " (hyperparameters not settled)")
                + f"; log evidence per iteration [nats]: {_e(trace)}.</p>")
    if result.cv is None:
        how = ("least squares: no penalty, no lambda" if result.options.method != "l2"
               else f"lambda = {result.lam:.4g} given by the user")
        return f"<p>No cross-validation in this run ({_e(how)}).</p>"
    cv = result.cv
    return (f"<p>{len(cv.lambdas)} candidates, {cv.fold_errors.shape[1]}-fold cross-validation "
            f"(seed {cv.seed}); chosen lambda = {cv.best_lambda:.4g} with mean validation "
            f"error {cv.mean_error[cv.best_index]:.4f} mm.</p>" + _img(png, "CV curve"))


def _models(result) -> str:
    """The candidate structures ``model="auto"`` compared, as a table ("" without)."""
    mc = getattr(result, "model_choice", None)
    if mc is None:
        return ""
    head = (f"<p>Model chosen automatically: <b>{_e(mc.chosen_label)}</b> ({_e(mc.reason)}).</p>")
    if mc.criterion != "cv":
        return head
    rows = "".join(
        f'<tr><td class="name">{"<b>" if c.chosen else ""}{_e(c.label)}'
        f'{"</b>" if c.chosen else ""}</td><td>{c.free}</td>'
        f"<td>{_num(c.cv_error_mm, '.4f') if c.fold_errors.size else '-'}</td>"
        f"<td>{'chosen' if c.chosen else _e(c.note)}</td></tr>" for c in mc.candidates)
    return (head + "<table><tr><th class=\"name\">candidate</th><th>free parameters</th>"
            f"<th>{mc.folds}-fold CV error [mm]</th><th></th></tr>{rows}</table>")


def _accuracy(amap, png) -> str:
    if amap is None:
        return "<p>No accuracy map in this run.</p>"
    text = (f"<pre>{_e(amap.summary())}</pre><p class=\"muted\">One standard deviation of "
            "the predicted tool point from the parameter covariance (the scatter repeated "
            "calibrations with these poses would show), not the bias of the model.</p>")
    return text + (_img(png, "accuracy map") if png is not None else "")


def _warnings(result, warnings, notes) -> str:
    items = [f"<li>warning: {_e(w)}</li>" for w in warnings]
    items += [f"<li>{_e(n)}</li>" for n in notes]
    if not result.converged:
        items.insert(0, "<li>warning: the solver did not converge; the result is the best "
                        "iterate</li>")
    if not items:
        return "<p>No warnings.</p>"
    return "<ul>" + "".join(items) + "</ul>"


def html_report(result, *, accuracy=None, warnings=(), notes=(), data_source=None,
                source: str = "kincal", provenance=None, refused: str | None = None,
                validations=()) -> str:
    """The report of ``result`` (a CalibrationResult) as one HTML document.

    accuracy: an :class:`~kincal.planning.accuracy_map.AccuracyMap` (e.g. from
    ``result_accuracy_map``) or None. warnings: messages of the run (kincal's warnings are
    not stored in the result: pass the ones you caught). notes: further lines (e.g. the
    export notes of the corrected URDF). data_source: the data file's name, for the page.
    provenance: the run's :class:`~kincal.export.provenance.Provenance`. refused: the
    gate's refusal message (the page is then a refused run's diagnosis, marked at its
    top). validations: held-out errors, one :class:`~kincal.export.validation.Validation`
    per held-out file.
    """
    from kincal.export import html_run
    from kincal.export import diagnostic_plots as dp
    from kincal.export import plots

    kin = list(result.parameters[:result.layout.n_kinematic])
    weak = {w.name for w in result.identifiability.weak}
    how = result.options.method + (f", lambda = {result.lam:.3g}" if result.lam and
                                   math.isfinite(result.lam) else "")
    par_png = (plots._plot_estimates(kin, None, False, source,
                                     f"Identified deviations from nominal ({how})", weak)
               if any(p.status == "identified" for p in kin) else None)
    cv_png = None
    if result.cv is not None:
        cv = result.cv
        cv_png = plots.plot_cv_curve(cv.lambdas, cv.mean_error, cv.best_lambda, None,
                                     fold_errors_mm=cv.fold_errors, source=source)
    title = f"kincal calibration of {result.robot.name} ({result.chains_text()})"
    nav = "".join(f'<a href="#{sid}">{_e(t)}</a>' for sid, t in SECTIONS)
    residuals = ""
    for i, s in enumerate(result.sets):  # a part per measurement set
        if len(result.sets) > 1:
            residuals += (f"<h3>Set {i + 1}: {_e(s.kind)} ({_e(s.source)})</h3>"
                          f"<p>before: {_e(s.before.line())}<br>after: {_e(s.after.line())}"
                          + _angle_html(s) + "</p>"
                          + "<table><tr><th class=\"name\">frame parameter</th><th>value</th>"
                          "<th>unit</th></tr>" + "".join(
                              f'<tr><td class="name">{_e(n)}</td><td>{_frame_value(n, v)}</td>'
                              f"<td>{'deg' if n.rsplit('.', 1)[-1] in ('rx', 'ry', 'rz') else 'mm'}"
                              "</td></tr>" for n, v in zip(s.frame_names, s.frames))
                          + "</table>")
        residuals += _img(dp.plot_residuals_per_pose(result, source=source, set_index=i),
                          f"residuals per sample of set {i + 1}")
    residuals += ("<p class=\"muted\">Before: nominal kinematics with the sets' frames "
                  "fitted; after: the identified model. Distances in mm.</p>")
    if result.joint_values is not None:
        joints = _img(dp.plot_residuals_by_joint(result, source=source),
                      "residuals against each joint")
        joints += ("<p class=\"muted\">A trend or a step against one joint points to an "
                   "error the model lacks (compliance, backlash, a wrong joint scale).</p>")
    else:
        joints = "<p>The result carries no joint values.</p>"
    acc_png = dp.plot_accuracy_map(accuracy, source=source) if accuracy is not None and len(
        accuracy.std) else None
    body = (_section("summary", _summary(result, data_source))
            + _section("identification", _identification(result))
            + _section("parameters", _parameters(result, par_png))
            + _section("residuals", residuals)
            + _section("joints", joints)
            + _section("cv", _cv(result, cv_png) + _models(result))
            + _section("accuracy", _accuracy(accuracy, acc_png))
            + _section("validation", html_run.validation_section(validations))
            + _section("warnings", _warnings(result, warnings, notes))
            + _section("provenance", html_run.provenance_section(provenance)))
    if refused is not None:
        title = "REFUSED: " + title
        body = html_run.refused_banner(result, refused) + body
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<meta name=\"generator\" content=\"{_e(source)}\">\n<title>{_e(title)}</title>\n"
            f"<style>{_STYLE}{html_run.REFUSED_STYLE if refused else ''}</style>\n</head>\n<body>\n<h1>{_e(title)}</h1>\n"
            f"<nav>{nav}</nav>\n{body}</body>\n</html>\n")


def section_ids() -> tuple[str, ...]:
    return tuple(sid for sid, _ in SECTIONS)
