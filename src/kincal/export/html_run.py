"""The HTML report's parts about the run rather than the model: the gate's refusal (a
banner with its evidence), the held-out validation, and the provenance."""

from __future__ import annotations

import html
import math


def _e(text) -> str:
    from kincal.export.writer import printable  # a file name's undecoded bytes too

    return html.escape(printable(str(text)), quote=True)


def _n(v, fmt: str = ".4g") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return format(v, fmt) if isinstance(v, (int, float)) else str(v)


REFUSED_STYLE = """
.refused { border: 3px solid #b00020; background: #fdecee; padding: 0.4em 1em;
           margin: 0.8em 0; }
.refused h2 { color: #b00020; border: none; margin: 0.2em 0; }
"""


def refused_banner(result, message: str) -> str:
    """What the gate refused and on which evidence: the findings with their values and
    thresholds, and the numbers it judged."""
    p = result.plausibility
    out = ['<div class="refused" id="refused"><h2>REFUSED by the plausibility gate</h2>',
           f"<p>{_e(message)}</p>",
           "<p>This page is the diagnosis of a calibration kincal refused: no corrected URDF, "
           "frames or cell file was written. The numbers below are those of the refused "
           "result.</p>"]
    if p is not None and p.findings:
        out.append('<table><tr><th class="name">finding</th><th>value</th><th>threshold</th>'
                   '<th class="name">unit</th><th class="name">likely cause</th></tr>')
        out += [f'<tr><td class="name">{_e(f.message)}</td><td>{_n(f.value)}</td>'
                f'<td>{_n(f.threshold)}</td><td class="name">{_e(f.unit)}</td>'
                f'<td class="name">{_e("; or ".join(f.causes))}</td></tr>' for f in p.findings]
        out.append("</table>")
    if p is not None:
        ev = p.evidence
        rows = [("residual median / rms [mm]",
                 f"{ev.residual_median_mm:.4g} / {ev.residual_rms_mm:.4g}"),
                ("error before (rms) [mm]", f"{ev.before_rms_mm:.4g}"),
                ("spread of the measured positions [mm]", f"{ev.spread_mm:.4g}"),
                ("motion explained by the model", _n(ev.explained, ".4f")),
                ("tool point moved by the correction, rms / max [mm]",
                 f"{ev.change_rms_mm:.4g} / {ev.change_max_mm:.4g}"),
                ("reach [m]", f"{ev.reach_m:.4g}"),
                ("measured spread / tool spread (length unit check)", _n(ev.length_ratio)),
                ("largest joint value [as read]", f"{ev.angle_max:.4g} {ev.angle_unit}"),
                ("converged", f"{ev.converged} ({ev.iterations} iterations)")]
        rows += [(f"correction {name}", f"{v:+.4g} {unit}") for name, v, unit in
                 ev.corrections[:6]]
        if ev.off_chain_columns:
            rows.append(("columns of joints beyond the chain's ends",
                         ", ".join(ev.off_chain_columns)))
        out.append("<table>" + "".join(f'<tr><th class="name">{_e(k)}</th><td>{_e(v)}</td>'
                                       "</tr>" for k, v in rows) + "</table>")
    return "\n".join(out) + "</div>\n"


def provenance_section(provenance) -> str:
    """The provenance as a table."""
    if provenance is None:
        return "<p>No provenance (this page was not made by the one writer).</p>"
    return ("<table>" + "".join(f'<tr><td class="name">{_e(line)}</td></tr>'
                                for line in provenance.lines()) + "</table>")


def validation_section(validations) -> str:
    """Held-out errors before and after, per axis, of each held-out file."""
    if not validations:
        return "<p>No held-out data in this run (<code>--validate HELD.csv</code>).</p>"
    head = ('<tr><th class="name">held-out error [mm, deg]</th><th>before</th>'
            "<th>after</th></tr>")
    tables = "".join(
        f"<p>{_e(v.headline())}</p><table>{head}" + "".join(
            f'<tr><td class="name">{_e(name)}</td><td>{b:.4f}</td><td>{a:.4f}</td></tr>'
            for name, b, a in v.table()) + "</table>" for v in validations)
    axes = ("Per axis: root mean square of the residual component in the measurement frame; "
            if any(v.per_axis for v in validations) else "")  # not for contacts, distances
    return (tables + "<p class=\"muted\">Frames from the calibration (not refitted on the "
            f"held-out data), as <code>kincal evaluate --frames</code> does. {axes}norm: mean, "
            "rms and max of the error per sample.</p>")
