"""The HTML page of the report: :func:`render_html` is pure (``ReportData`` with its figures in,
HTML text out; every piece of text goes through :func:`html.escape`); :func:`write_report`
draws the figures into ``DIR/<label>/*.png`` and writes ``DIR/report.html`` with every PNG
embedded as a base64 ``data:`` URI and the CSS inline: the page loads nothing from anywhere.
"""

from __future__ import annotations

import base64
import html
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym import __version__
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text
from pige_sym.identification import IdentificationResult
from pige_sym.kernels import load_kernels
from pige_sym.report.figures import draw_figures, draw_report_figures
from pige_sym.report.gather import (
    SOBOL_EFFECT_UM,
    UNIT_TEXT,
    MeasurementReport,
    ReportData,
    ReportFigure,
    findings_text,
    gather_report,
)
from pige_sym.report.lead import improvement, main_finding, pige_rows


def write_report(data: ReportData, out_dir: str | os.PathLike[str]) -> Path:
    """Draw the figures, write the compensated programs and ``out_dir/report.html``; returns the HTML path."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    for rep in data.measurements:
        sub = out / rep.label
        rep.figures = draw_figures(rep, sub)
        text = rep.compensated_program_text
        if text is not None and data.program is not None:
            target = sub / f"{data.program.stem}_compensated{data.program.suffix or '.mpf'}"
            with open(target, "w", encoding="utf-8", newline="") as fh:
                fh.write(text)
            rep.compensated_program = target
    data.figures = draw_report_figures(data, out / "_report")
    if data.plan is not None:
        from pige_sym.report.plan_section import plan_section

        data.plan_html, _ = plan_section(data.plan, out / "_report")
    html_path = out / "report.html"
    atomic_write_text(html_path, render_html(data, base=out))
    data.html_path = html_path
    return html_path


def build_report(measurement_paths: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str],
                 **options: Any) -> Path:
    """Build the report of measurement files into ``out_dir``; returns the path of ``report.html``.

    ``options`` are those of :func:`gather_report`; PNGs are kept in ``out_dir/<label>/``.
    """
    return write_report(gather_report(measurement_paths, **options), out_dir)


# ---------------------------------------------------------------------------------------------
# HTML

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:0;color:#1d232a;
background:#f6f7f9;line-height:1.4}
header,main,footer{max-width:1150px;margin:0 auto;padding:0 18px;box-sizing:border-box}
table{max-width:100%}
td,th{overflow-wrap:break-word}
code{overflow-wrap:break-word}
.kv td,.kv td code,code.path,nav a,h1,h2,h3,h4,figcaption,span.file{overflow-wrap:anywhere}
.meta{margin:.2em 0;color:#4a5563;font-size:.85em}
.answer{display:flex;flex-wrap:wrap;gap:6px 18px;background:#fff;border:2px solid #2b6cb0;border-radius:6px;
padding:8px 14px;margin:8px 0}
.answer .facts{flex:1 1 420px;min-width:0}
.answer .used{flex:1 1 340px;min-width:0}
.answer table{margin:.2em 0;width:100%}
.answer th{width:9em}
.cap{margin:.2em 0;font-size:.85em;color:#2b4a6f;font-weight:600}
.badge{display:inline-block;padding:1px 10px;border-radius:4px;font-weight:700;letter-spacing:.04em;color:#fff}
.badge.pass{background:#1b7f3a}
.badge.fail{background:#b00020}
.badge.undecided{background:#b26a00}
.badge.none{background:#6b7480}
.st.pass{color:#1b7f3a;font-weight:600}
.st.fail{color:#b00020;font-weight:600}
.st.undecided{color:#b26a00;font-weight:600}
.basis{display:inline-block;padding:0 6px;border-radius:3px;font-size:.8em;font-weight:700;background:#eef2f7}
.basis.measured{background:#d7f0de}
.basis.model{background:#fde7c8}
ul.rejected li{margin:.15em 0}
ul.rejected details{display:inline}
details summary{cursor:pointer;color:#2b6cb0}
header{padding-top:10px}
h1{font-size:1.35em;margin:.1em 0}
h2{font-size:1.3em;border-bottom:2px solid #2b6cb0;padding-bottom:3px;margin-top:1.6em}
h3{font-size:1.08em;margin:1.2em 0 .4em;color:#2b4a6f}
section.measurement{background:#fff;border:1px solid #d9dee5;border-radius:6px;padding:6px 18px 18px;margin:18px 0}
table{border-collapse:collapse;margin:.4em 0 .8em;font-size:.86em}
th,td{border:1px solid #d0d6de;padding:3px 7px;text-align:left;vertical-align:top}
th{background:#eef2f7}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr.unid td{background:#fde8e8}
span.unid,.bad{color:#b00020;font-weight:600}
.ok{color:#1b7f3a;font-weight:600}
.note{background:#fff8e1;border-left:4px solid #f0b400;padding:6px 10px;margin:.6em 0;font-size:.92em}
figure{margin:.8em 0}
.figrow{display:flex;flex-wrap:wrap;gap:0 14px}
.figrow figure{flex:1 1 480px;max-width:100%}
figure img{max-width:100%;height:auto;border:1px solid #e2e6ea}
figcaption{font-size:.85em;color:#4a5563}
nav a{margin-right:12px}
.nw{white-space:nowrap}
code{background:#eef2f7;padding:0 3px;border-radius:3px}
ul.verdict li{margin:.25em 0}
footer{font-size:.8em;color:#5c6670;padding-bottom:30px}
"""


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _u(unit: str) -> str:
    return UNIT_TEXT.get(unit, unit)


def _f(x: float | None, fmt: str = ".3f", none: str = "—") -> str:
    if x is None:
        return none
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return none
    if math.isnan(xf):
        return none
    if math.isinf(xf):
        return "∞" if xf > 0 else "−∞"
    return format(xf, fmt)


def _table(head: Sequence[str], rows: Iterable[Sequence[str]], *, row_classes: Sequence[str] | None = None,
           num_cols: Iterable[int] = ()) -> str:
    """An HTML table; ``head`` is escaped, cells are already HTML."""
    nums = set(num_cols)
    out = ["<table>", "<thead><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr></thead>", "<tbody>"]
    for i, row in enumerate(rows):
        cls = row_classes[i] if row_classes and row_classes[i] else ""
        attr = f' class="{_e(cls)}"' if cls else ""
        cells = "".join(f'<td class="num">{c}</td>' if j in nums else f"<td>{c}</td>" for j, c in enumerate(row))
        out.append(f"<tr{attr}>{cells}</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _kv(items: Iterable[tuple[str, str]]) -> str:
    """Two-column key/value table; keys escaped, values already HTML."""
    return '<table class="kv">' + "".join(f"<tr><th>{_e(k)}</th><td>{v}</td></tr>" for k, v in items) + "</table>"


def _img(fig: ReportFigure, base: Path | None) -> str:
    data = base64.b64encode(fig.path.read_bytes()).decode("ascii")
    shown = fig.path.relative_to(base) if base is not None and fig.path.is_relative_to(base) else fig.path
    return (f'<figure data-figure="{_e(fig.key)}"><img src="data:image/png;base64,{data}" '
            f'alt="{_e(fig.caption)}"><figcaption>{_e(fig.caption)} <span class="file">({_e(shown)})</span>'
            "</figcaption></figure>")


def _figs(rep: MeasurementReport, key: str, base: Path | None) -> str:
    return "\n".join(_img(f, base) for f in rep.figures if f.key == key)


def _summary_html(rep: MeasurementReport) -> str:
    m = rep.measurement
    kern = load_kernels(m.machine)
    dev = m.deviation_machine_um()
    norms = np.linalg.norm(dev, axis=1)
    side = {a: ("workpiece side" if a in kern.WORKPIECE_ROTARY else "tool side") for a in kern.ROTARY_AXES}
    axes = ", ".join(f"{a} ({side[a]}, {_f(m.angles_deg[:, k].min(), '.1f')} … {_f(m.angles_deg[:, k].max(), '.1f')}°)"
                     for k, a in enumerate(m.rotary_axes))
    items = [
        ("file", f"<code>{_e(rep.path)}</code>"),
        ("machine", f"<code>{_e(rep.machine)}</code>" + (f" (written as <code>{_e(m.machine)}</code>)"
                                                         if m.machine != rep.machine else "")),
        ("rotary axes", _e(axes)),
        ("ball at the reference pose", _e(", ".join(_f(x, "g") for x in m.ball_mm) + " mm")),
    ]
    if m.tool_mm is not None:
        items.append(("tool (ball from the last tool-side pivot)", _e(", ".join(_f(x, "g") for x in m.tool_mm)
                                                                      + " mm")))
    for ax, pv in m.pivots_mm.items():
        items.append((f"nominal pivot of {ax}", _e(", ".join(_f(x, "g") for x in pv) + " mm")))
    items += [
        ("trajectory", _e(m.trajectory or "not stated in the file")),
        ("points", _e(f"{m.n_rows} rows (the reference pose and {m.n_rows - 1} measured points) over "
                      f"{_f(m.t_s[-1] - m.t_s[0], '.0f')} s")),
        ("frame of the deviations", _e(m.frame)),
        ("largest deviation", _e(f"|d| max {_f(norms.max())} µm; per component max |dx| {_f(np.abs(dev[:, 0]).max())}"
                                 f", |dy| {_f(np.abs(dev[:, 1]).max())}, |dz| {_f(np.abs(dev[:, 2]).max())} µm")),
        ("RMS of |d| over the points", _e(f"{_f(math.sqrt(float((norms[1:] ** 2).mean())) if m.n_rows > 1 else 0.0)}"
                                          " µm")),
    ]
    if "source" in m.metadata:
        items.append(("source", _e(m.metadata["source"])))
    extra = [c for c in m.optional] + list(m.extra_columns)
    if extra:
        items.append(("other columns", _e(", ".join(extra))))
    items.append(("truth sidecar", _e(rep.truth.path) if rep.truth is not None else "none (real measurement or "
                                                                                     "truth unknown)"))
    return _kv(items)


def _status(res: IdentificationResult, j: int) -> tuple[str, bool]:
    """(HTML status, flagged) of parameter j."""
    if not bool(res.identifiable[j]):
        return '<span class="unid">NOT IDENTIFIABLE — no value</span>', True
    if not math.isfinite(res.values[j]):
        return '<span class="unid">not fixed by any differential — no value</span>', True
    return '<span class="ok">identified</span>', False


def _gn_rows(rep: MeasurementReport) -> tuple[list[str], list[list[str]], list[str]]:
    gn = rep.identification["gauss-newton"]
    truth = rep.truth
    ci = gn.ci95()
    head = ["parameter", "unit", "value", "std", "95 % interval", "VIF", "status"]
    if truth is not None:
        head += ["truth", "error", "|error| / std"]
    rows, classes = [], []
    for j, name in enumerate(gn.parameters):
        st, bad = _status(gn, j)
        vif = gn.vif[j] if gn.vif is not None else float("nan")
        cells = (["not identifiable", "—", "—"] if bad else
                 [_f(gn.values[j]), _f(gn.std[j]), f"[{_f(ci[j, 0])}, {_f(ci[j, 1])}]"])
        row = [f"<b>{_e(name)}</b>", _e(_u(gn.units.get(name, ""))), *cells, _f(vif, ".3g"), st]
        if truth is not None:
            t = truth.values.get(name, 0.0)
            if bad:
                row += [_f(t), "—", "—"]
            else:
                err = gn.values[j] - t
                ratio = abs(err) / gn.std[j] if gn.std[j] > 0 else float("inf")
                row += [_f(t), _f(err, "+.3f"), _f(ratio, ".2f")]
        rows.append(row)
        classes.append("unid" if bad else "")
    return head, rows, classes


def _dd_table(dd: IdentificationResult) -> str:
    ci = dd.ci95()
    fixed_at = {p: s.index for s in dd.stages for p in s.fixed}
    rows, classes = [], []
    for j, name in enumerate(dd.parameters):
        st, bad = _status(dd, j)
        cells = (["no value", "—", "—"] if bad else
                 [_f(dd.values[j]), _f(dd.std[j]), f"[{_f(ci[j, 0])}, {_f(ci[j, 1])}]"])
        rows.append([f"<b>{_e(name)}</b>", _e(_u(dd.units.get(name, ""))), *cells, _e(fixed_at.get(name, "—")), st])
        classes.append("unid" if bad else "")
    return _table(["parameter", "unit", "value", "std", "95 % interval", "fixed at stage", "status"], rows,
                  row_classes=classes, num_cols=[2, 3, 4])


def _identification_html(rep: MeasurementReport) -> str:
    gn = rep.identification["gauss-newton"]
    dd = rep.identification["double-differential"]
    head, rows, classes = _gn_rows(rep)
    num_cols = [2, 3, 4, 5] + ([7, 8, 9] if rep.truth is not None else [])
    parts = ["<h4>Gauss–Newton (all PIGEs at once)</h4>", _table(head, rows, row_classes=classes, num_cols=num_cols),
             "<h4>Double-differential scheme</h4>", _dd_table(dd)]
    n_bad = int((~gn.identifiable).sum())
    if n_bad:
        parts.append(f'<p class="note"><span class="unid">{n_bad} parameter(s) are not identifiable from these data'
                     "</span>: no value is reported for them and they are compensated as 0.</p>")
    obs = ", ".join(f"{k} = {_f(v, '.3g')}" for k, v in gn.observability.items())
    facts = [
        ("projection / loss", _e(f"{gn.projection} / {gn.loss}")),
        ("rank", _e(f"{gn.rank} of {len(gn.parameters)}") + ("" if gn.rank == len(gn.parameters)
                                                            else ' <span class="unid">(rank-deficient)</span>')),
        ("condition number (scaled)", _e(_f(gn.condition, ".4g"))),
        ("residual RMS / σ", _e(f"{_f(gn.rms_um, '.4f')} µm / {_f(gn.sigma_um, '.4f')} µm "
                                f"({gn.n_obs} observations, {gn.dof} degrees of freedom)")),
        ("observability indices", _e(obs) + " <small>(O1 Borm–Menq, O2 Driels–Pathre, O3 Nahvi, O4 noise "
                                            "amplification, O5 Sun–Hollerbach; scaled columns)</small>"),
        ("singular values (scaled)", _e(", ".join(_f(s, ".3g") for s in gn.singular_values))),
    ]
    if gn.outlier_rows:
        facts.append(("outlier rows", _e(gn.outlier_rows)))
    parts.append(_kv(facts))
    parts.append("<h4>Unidentifiable combinations</h4>")
    if gn.unidentifiable:
        parts.append('<ul class="combos">' + "".join(f'<li><span class="unid">{_e(c)}</span></li>'
                                                       for c in gn.unidentifiable) + "</ul>")
    else:
        parts.append("<p>None: every parameter combination is determined by the data.</p>")
    parts.append("<h4>Stages of the double-differential scheme</h4>")
    parts.append(_stages_html(dd))
    return "\n".join(parts)


def _stages_html(dd: IdentificationResult) -> str:
    if not dd.stages:
        return "<p>No stage.</p>"
    head = ["stage", "solved", "rank", "condition", "fixed at this stage", "values ± std (VIF)"]
    rows = []
    for s in dd.stages:
        vals = []
        for p in s.solved:
            u = _u(dd.units.get(p, ""))
            std = s.std.get(p)
            if std is None or not math.isfinite(s.vif.get(p, float("inf"))):
                vals.append(f'{_e(p)}: <span class="unid">not identifiable at this stage</span>')
            else:
                mark = "<b>" if p in s.fixed else ""
                end = "</b>" if p in s.fixed else ""
                vals.append(f"{mark}{_e(p)} = {_f(s.values[p])} ± {_f(std)} {_e(u)} (VIF {_f(s.vif[p], '.3g')})"
                            f"{end}")
        rows.append([_e(s.index), _e(len(s.solved)), _e(f"{s.rank}/{len(s.solved)}"), _e(_f(s.condition, ".4g")),
                     _e(", ".join(s.fixed) or "none"), "<br>".join(vals)])
    return _table(head, rows, num_cols=[0, 1, 3]) + (
        "<p><small>A parameter is fixed when it is individually identifiable and its variance inflation factor is "
        "at most 10; fixed parameters (bold) are substituted and the rest re-solved.</small></p>")


def _final_html(res: IdentificationResult) -> str:
    head = ["parameter", "value", "std", "unit", "status"]
    rows, classes = [], []
    for j, name in enumerate(res.parameters):
        st, bad = _status(res, j)
        rows.append([_e(name), "not identifiable" if bad else _f(res.values[j]), "—" if bad else _f(res.std[j]),
                     _e(_u(res.units.get(name, ""))), st])
        classes.append("unid" if bad else "")
    return _table(head, rows, row_classes=classes, num_cols=[1, 2])


def _diagnosis_html(rep: MeasurementReport, base: Path | None) -> str:
    d = rep.diagnosis
    if d is None:
        return (f'<p class="note"><span class="bad">The diagnosis failed on these data: {_e(rep.diagnosis_error)}'
                "</span>. The identification above does not depend on it.</p>")
    parts = [_kv([
        ("baseline PIGE fit", _e(f"residual RMS {_f(d.baseline_rms_um, '.4f')} µm, held-out RMS "
                                 f"{_f(d.baseline_heldout_rms_um, '.4f')} µm, BIC {_f(d.baseline_bic, '.1f')}")),
        ("outlier rows", _e(d.outlier_rows or "none")),
    ])]
    parts.append("<h4>Verdict</h4>")
    if d.findings:
        parts.append('<ul class="verdict">' + "".join(f"<li>{_e(f.sentence())}</li>" for f in d.findings) + "</ul>")
    else:
        parts.append(f"<p>{_e(d.verdict())}</p>")
    parts.append("<h4>Findings</h4>")
    if d.findings:
        head = ["effect", "parameters ± std", "ΔBIC", "F / p", "RMS before → after [µm]",
                "held-out RMS before → after [µm]", "explained", "PIGE shifts", "evidence"]
        rows = []
        for f in d.findings:
            opts = "".join(f" {k}={v:g}" for k, v in f.options.items())
            params = "<br>".join(f"{_e(k)} = {_f(v, '.4g')} ± {_f(f.std.get(k), '.2g')} {_e(_u(f.units.get(k, '')))}"
                                 for k, v in f.params.items())
            shifts = sorted(f.pige_shift.items(), key=lambda kv: -abs(kv[1]))
            shift_txt = "<br>".join(f'<span class="nw">{_e(k)} {_f(v, "+.3g")} {_e(_u(d.final.units.get(k, "")))}'
                                    "</span>" for k, v in shifts[:4] if abs(v) > 0) or "—"
            rows.append([f"<b>{_e(f.effect)}</b>{_e(opts)}", params, _f(f.delta_bic, ".1f"),
                         f"{_f(f.f_statistic, '.3g')} / {_f(f.p_value, '.2g')}",
                         f"{_f(f.rms_um_before, '.4f')} → {_f(f.rms_um_after, '.4f')}",
                         f"{_f(f.heldout_rms_um_before, '.4f')} → {_f(f.heldout_rms_um_after, '.4f')}",
                         _f(f.explained * 100 if math.isfinite(f.explained) else float("nan"), ".0f") + " %",
                         shift_txt, _e(f.evidence)])
        parts.append(_table(head, rows, num_cols=[2, 3, 4, 5, 6]))
        parts.append("<h4>Final estimates with the accepted extensions</h4>")
        parts.append(_final_html(d.final))
        if rep.extensions:
            ids = ", ".join(e.spec.id for e in rep.extensions)
            parts.append(f"<p><small>Compensated with the PIGEs: {_e(ids)} (pose-dependent zero errors).</small></p>")
        for why in rep.extensions_not_compensated:
            parts.append(f"<p><small>Not compensated: {_e(why)}.</small></p>")
        if not rep.extensions and not rep.extensions_not_compensated:
            parts.append("<p><small>Accepted extensions are compensated only when the report's method is "
                         "<code>diagnosis</code>.</small></p>")
    else:
        parts.append("<p>No finding: the PIGE model explains the data down to the noise.</p>")
    parts.append("<h4>Rejected candidates</h4>")
    if d.rejected:
        parts.append('<ul class="rejected">' + "".join(_rejected_item(r) for r in d.rejected) + "</ul>")
    else:
        parts.append("<p>None.</p>")
    parts.append("<h4>Residual plots</h4>")
    figs = _figs(rep, "residual", base)
    parts.append(f'<div class="figrow">{figs}</div>' if figs else "<p>No residual plot (no residuals to plot).</p>")
    return "\n".join(parts)


def _compensation_html(rep: MeasurementReport, base: Path | None) -> str:
    parts = []
    if rep.compensation_basis == "truth":
        assert rep.truth is not None
        parts.append(f"<p>Before/after <b>simulated on a known truth</b>: the machine carries the true parameters of "
                     f"<code>{_e(rep.truth.path.name)}</code> and is compensated with the {_e(rep.primary_method)} "
                     "estimate.</p>")
    else:
        parts.append(f'<p class="note">No truth sidecar: the before/after is <b>model-predicted</b>. The machine is '
                     f"assumed to carry exactly the identified errors ({_e(rep.primary_method)}), so what the "
                     "compensation leaves on that model machine says nothing about the real one and is shown only "
                     "as a check of the algorithm. Expected on the real machine: the identification uncertainty "
                     "propagated to the tool point, combined with what the model leaves unexplained; a measurement "
                     "after compensation (<code>pige compare</code>) proves it.</p>")
    if rep.not_compensated:
        unknown = (" The model-predicted machine carries 0 for them too: their real errors are unknown and not in "
                   "these numbers." if rep.compensation_basis == "model" else "")
        parts.append(f'<p class="note"><span class="unid">Not compensated (no value): '
                     f"{_e(', '.join(rep.not_compensated))}</span> — set to 0.{_e(unknown)}</p>")
    parts.append(_compensation_table(rep))
    if rep.compensated_program is not None:
        parts.append(f"<p>Compensated NC program written to <code>{_e(rep.compensated_program)}</code>.</p>")
    parts.append(_figs(rep, "compensation", base))
    return "\n".join(parts)


def _compensation_table(rep: MeasurementReport) -> str:
    from pige_sym.report.lead import unexplained_rms_um

    if rep.compensation_basis == "truth":
        head = ["test", "RMSE before [µm]", "RMSE after [µm]", "reduction", "expected after, from the std [µm]",
                "command change RMS [µm]"]
        rows = [[_e(r.trajectory), _f(r.rmse_before_um), _f(r.rmse_after_um), _f(r.reduction * 100, ".1f") + " %",
                 _f(r.predicted_after_um, ".3f", "n/a"), _f(r.command_change_rmse_mm * 1e3, ".2f")]
                for r in rep.compensation]
        return _table(head, rows, num_cols=[1, 2, 3, 4, 5])
    resid = unexplained_rms_um(rep)
    head = ["test", "RMSE of the identified errors [µm]", "expected after [µm]", "of which: uncertainty [µm]",
            "unexplained residual [µm]", "left by the algorithm on the model [µm]", "command change RMS [µm]"]
    rows = []
    for r in rep.compensation:
        u = r.predicted_after_um
        expected = math.sqrt((u if math.isfinite(u) else 0.0) ** 2 + (resid if math.isfinite(resid) else 0.0) ** 2)
        rows.append([_e(r.trajectory), _f(r.rmse_before_um), _f(expected, ".2f"), _f(u, ".3f", "n/a"),
                     _f(resid, ".3f"), _f(r.rmse_after_um, ".2g"), _f(r.command_change_rmse_mm * 1e3, ".2f")])
    return _table(head, rows, num_cols=[1, 2, 3, 4, 5, 6])


def _projection_html(rep: MeasurementReport) -> str:
    st = rep.projection
    assert st is not None
    head = ["projection", "rank", "condition", "success rate", "unobserved", "undetermined combinations",
            "determined rate per PIGE"]
    rows, classes = [], []
    for r in st.rows:
        det = ", ".join(f"{k} {v:.0%}" for k, v in r.determined_rate.items())
        und = "<br>".join(f'<span class="unid">{_e(c)}</span>' for c in r.unidentifiable) or "—"
        rows.append([_e(r.projection), _e(f"{r.rank}/{r.n_parameters}"), _f(r.condition, ".3g"),
                     _f(r.success_rate * 100, ".0f") + " %", _e(", ".join(r.unobserved) or "—"), und, _e(det)])
        classes.append("" if r.rank == r.n_parameters else "unid")
    noise = _f(rep.projection_noise_um, ".3g")
    return (f"<p>{_e(st.presets)} random presets simulated on the measured trajectory with {noise} µm noise (the "
            "Gauss–Newton σ) and identified with the double-differential scheme per projection; a preset succeeds "
            "when every PIGE gets a value within 4 standard errors of the preset.</p>"
            + _table(head, rows, row_classes=classes, num_cols=[2, 3]) + f"<p>{_e(st.verdict)}</p>")


def _sobol_html(rep: MeasurementReport, base: Path | None) -> str:
    st = rep.sobol
    assert st is not None
    if rep.sobol_same_as is not None:
        return (f'<p>Same trajectory, ball and tool as <a href="#m{rep.sobol_same_as}">measurement '
                f"{rep.sobol_same_as}</a>: the Sobol indices depend on nothing else and are shown there.</p>")
    head = ["parameter"] + [f"{p} {k}" for p in st.projections for k in ("S1", "ST")]
    rows = [[_e(name)] + [_f(v, ".3f") for i in range(len(st.projections))
                          for v in (st.first_order[i, j], st.total_order[i, j])]
            for j, name in enumerate(st.parameters)]
    return (f"<p>First-order (S1) and total (ST) indices of the mean-square projected deviation over the measured "
            f"trajectory, {st.n_samples} base samples. The parameters are scaled like the identification's "
            f"columns: each PIGE is uniform on ±h, h chosen so that its RMS effect on the ball is "
            f"{SOBOL_EFFECT_UM:g} µm ({_e(_ranges_text(rep))}), so position and orientation errors compete on "
            "equal terms.</p>"
            + _table(head, rows, num_cols=range(1, 1 + 2 * len(st.projections))) + _figs(rep, "sobol", base))


def _ranges_text(rep: MeasurementReport) -> str:
    units = load_kernels(rep.machine).UNITS
    return ", ".join(f"{k} ±{v:.3g} {_u(units.get(k, ''))}" for k, v in rep.sobol_ranges.items())


_REJECTION_SENTENCES = (
    ("unidentifiable", "{name} cannot be told apart from the PIGEs with this test."),
    ("best candidate", "{name} was the best remaining candidate, but its gain is within the noise."),
    ("not significant", "{name} does not improve the fit beyond the noise."),
    ("not supported", "{name} does not improve the fit enough to be worth its parameters."),
    ("rows ", "{name}: the rows that stand out are better kept than dropped."),
)


def _rejected_item(r: Any) -> str:
    """One plain sentence per rejected candidate; the statistics folded in a <details>."""
    opts = ", ".join(f"{k} {v:g}" for k, v in r.options.items())
    name = f"{r.effect}" + (f" ({opts})" if opts else "")
    sentence = next((t.format(name=name) for key, t in _REJECTION_SENTENCES if r.reason.startswith(key)
                     or key in r.reason[:40]), f"{name} was not accepted.")
    numbers = f"{r.reason}; ΔBIC {_f(r.delta_bic, '.1f')}, p {_f(r.p_value, '.2g')}"
    return f"<li>{_e(sentence)} <details><summary>why</summary><small>{_e(numbers)}</small></details></li>"


_BADGE = {"pass": "PASS", "fail": "FAIL", "undecided": "UNDECIDED"}


def _verdict_html(rep: MeasurementReport) -> str:
    chk = rep.check
    if chk is None:
        return ('<span data-verdict="none" class="badge none">not judged</span> <small>no tolerances given '
                "(pige report --tolerances TOL.json)</small>")
    rule = f"|v| ± {chk.k:g}u vs limit (ISO 14253-1)" if chk.rule == "guard" else "simple acceptance"
    odd = [f"{i.name} {i.status}" for i in chk.items if i.status != "pass"]
    tail = f": {', '.join(odd)}" if odd else f": all {len(chk.items)} items pass"
    return (f'<span data-verdict="{_e(chk.verdict)}" class="badge {_e(chk.verdict)}">{_BADGE[chk.verdict]}</span> '
            f"<small>{_e(rule)}{_e(tail)}</small>")


def _pige_used_html(rep: MeasurementReport) -> str:
    rows, classes = [], []
    for r in pige_rows(rep):
        val = "not identifiable" if r.value is None else f"{_f(r.value)} ± {_f(r.std, '.2g')}"
        row = [f"<b>{_e(r.name)}</b>", val, _e(r.unit)]
        if rep.check is not None:
            row += [_f(r.limit, "g"), f'<span class="st {_e(r.status or "")}">{_e(r.status or "no limit")}</span>']
        rows.append(row)
        classes.append("unid" if r.value is None else "")
    head = ["PIGE", "value ± std", "unit"] + (["limit", "status"] if rep.check is not None else [])
    return _table(head, rows, row_classes=classes, num_cols=[1, 3])


def _estimate_label(rep: MeasurementReport) -> str:
    if rep.primary_method == "diagnosis":
        found = rep.diagnosis is not None and any(f.effect != "outliers" for f in rep.diagnosis.findings)
        return ("diagnosis' final fit: PIGEs estimated jointly with the accepted effects" if found
                else "diagnosis' final fit (no effect accepted: the PIGE-only model)")
    return f"{rep.primary_method} fit"


def _answer_one(i: int, rep: MeasurementReport, data: ReportData) -> str:
    imp = improvement(rep, data)
    facts = [
        ("machine", f"<code>{_e(rep.machine)}</code>" + (f" — id <b>{_e(data.history.machine_id)}</b>"
                                                          if data.history is not None else "")),
        ("measured", _e(f"{rep.measured_at} ({rep.time_source})") + f" — <code>{_e(rep.path.name)}</code>"),
        ("verdict", _verdict_html(rep)),
        ("main finding", _e(main_finding(rep))),
        (f"improvement ({imp.label})", f'<span class="basis {_e(imp.basis)}">{_e(imp.label)}</span> {_e(imp.text)}'),
    ]
    return (f'<div class="answer" id="answer-m{i + 1}"><div class="facts">{_kv(facts)}</div>'
            f'<div class="used"><p class="cap">PIGEs used for compensation ({_e(_estimate_label(rep))})</p>'
            f"{_pige_used_html(rep)}</div></div>")


def _answer_history(data: ReportData) -> str:
    h = data.history
    assert h is not None
    last = h.runs[-1]
    verdict = (f'<span data-verdict="{_e(last.verdict)}" class="badge {_e(last.verdict)}">'
               f"{_BADGE.get(last.verdict, last.verdict)}</span> <small>stored with run {last.id}</small>"
               if last.verdict else '<span data-verdict="none" class="badge none">not judged</span>')
    moved = [f"{c.parameter} {_f(c.change, '+.3g')} ± {_f(c.std, '.2g')} {_u(c.unit)} (run {c.from_run} → {c.to_run})"
             for comp in h.comparisons for c in comp.changes if c.significant]
    facts = [("machine", f"id <b>{_e(h.machine_id)}</b> — <code>{_e(last.machine_code)}</code>"),
             ("runs", _e(f"{len(h.runs)}, last measured {last.measured_at}")),
             ("verdict of the last run", verdict),
             ("what changed", _e("; ".join(moved) if moved else "no significant change between consecutive runs "
                                 "(family-wise false-alarm rate 1 % per comparison)"))]
    return f'<div class="answer"><div class="facts">{_kv(facts)}</div></div>'


def _answer_compare(data: ReportData) -> str:
    c = data.comparison
    assert c is not None
    facts = [("machine", f"<code>{_e(c.machine)}</code>"),
             ("verdict", '<span data-verdict="none" class="badge none">not judged</span> <small>give the '
                         "measurement files and --tolerances for a verdict</small>"),
             ("improvement (measured)", f'<span class="basis measured">measured</span> '
                                        f"{_e(f'RMS |d| {c.rms_before_um:.3g} → {c.rms_after_um:.3g} µm ')}"
                                        f"{_e(f'({c.improvement:.0%} less)')}")]
    return f'<div class="answer"><div class="facts">{_kv(facts)}</div></div>'


def _answer_html(data: ReportData) -> str:
    parts = [_answer_one(i, rep, data) for i, rep in enumerate(data.measurements)]
    if not data.measurements and data.history is not None:
        parts.append(_answer_history(data))
    elif not data.measurements and data.comparison is not None:
        parts.append(_answer_compare(data))
    return "\n".join(parts)


def _check_html(rep: MeasurementReport) -> str:
    chk = rep.check
    assert chk is not None
    rows = [[f"<b>{_e(i.name)}</b>", _f(i.value), _f(i.std), _f(i.limit, "g"), _e(_u(i.unit)),
             f'<span class="st {_e(i.status)}">{_e(i.status)}</span>', _e(i.reason)] for i in chk.items]
    parts = [f"<p>Tolerances <code>{_e(chk.tolerances)}</code>; {_e(chk.method)} estimate; rule "
             + (f"<b>guard</b>: pass when |v| + {chk.k:g}u ≤ limit, fail when |v| − {chk.k:g}u &gt; limit, "
                "undecided otherwise (ISO 14253-1)" if chk.rule == "guard" else
                "<b>simple acceptance</b>: the uncertainty is not used")
             + ". A parameter without a value is undecided.</p>",
             _table(["parameter", "value", "std", "limit", "unit", "status", "why"], rows, num_cols=[1, 2, 3])]
    for name, why in chk.not_assessed.items():
        parts.append(f"<p><small>{_e(name)}: not assessed — {_e(why)}.</small></p>")
    return "\n".join(parts)


def _compare_html(data: ReportData, base: Path | None) -> str:
    c = data.comparison
    assert c is not None
    parts = [f"<p>Two <b>measurements</b> of the same program on <code>{_e(c.machine)}</code>: "
             f"<code>{_e(c.before)}</code> (before) and <code>{_e(c.after)}</code> (after); commanded angles agree "
             f"within {_f(c.max_angle_difference_deg, '.4f')}°. No model enters these numbers.</p>",
             _table(["", "RMS |d| [µm]", "max |d| [µm]"],
                    [["before", _f(c.rms_before_um), _f(c.max_before_um)],
                     ["after", _f(c.rms_after_um), _f(c.max_after_um)],
                     ["improvement", _f(c.improvement * 100, ".1f") + " %", "—"]], num_cols=[1, 2])]
    for when, dec in (("before", c.before_parts), ("after", c.after_parts)):
        if dec is None:
            continue
        rows = [[_e(p.name), _f(p.rms_um), _f(p.max_um)] for p in dec.parts]
        expl = "—" if dec.explained is None else f"{dec.explained:.0%}"
        parts.append(f"<h4>What the {when} deviation is made of</h4>"
                     + _table(["part", "RMS [µm]", "max [µm]"], rows, num_cols=[1, 2])
                     + f"<p><small>The model explains {_e(expl)} of the mean square; noise σ "
                       f"{_f(dec.sigma_um)} µm per component. {_e(' '.join(dec.notes))}</small></p>")
    parts.append("".join(_img(f, base) for f in data.figures if f.key == "measured-compare"))
    poses = [[_e(i), *(_f(a, ".2f") for a in ang), _f(b), _f(x)]
             for i, (ang, b, x) in enumerate(zip(c.angles_deg, c.before_um, c.after_um, strict=True))]
    parts.append("<details><summary>|d| per pose</summary>"
                 + _table(["pose", *(f"{a} [deg]" for a in c.rotary_axes), "before [µm]", "after [µm]"], poses,
                          num_cols=range(0, 3 + len(c.rotary_axes))) + "</details>")
    return "\n".join(parts)


def _history_html(data: ReportData, base: Path | None) -> str:
    h = data.history
    assert h is not None
    runs = [[_e(r.id), _e(r.measured_at), f'<code class="path">{_e(Path(r.file_name).name)}</code>', _e(r.method),
             _e(", ".join(str(f.get("effect")) for f in r.effects) or "none"), _e(r.verdict or "—"), _f(r.rms_um)]
            for r in h.runs]
    parts = [f"<p>Machine <b>{_e(h.machine_id)}</b> in <code>{_e(h.database)}</code>.</p>",
             _table(["run", "measured (UTC)", "file", "estimate", "effects", "verdict", "residual RMS [µm]"], runs,
                    num_cols=[0, 6]),
             "".join(_img(f, base) for f in data.figures if f.key == "trend")]
    for comp in h.comparisons:
        sig = [c for c in comp.changes if c.significant]
        head = (f"run {comp.from_run} → {comp.to_run}: " + ("<b>changed</b>" if comp.significant else
                                                           "no significant change")
                + f" (joint p = {_f(comp.p_value, '.3g')})")
        rows = [[_e(c.parameter), _f(c.change, "+.3f"), _f(c.std), _e(_u(c.unit)), _f(c.z, "+.2f"),
                 "yes" if c.significant else ("not tested" if c.significant is None else "no")]
                for c in comp.changes]
        notes = "".join(f'<p class="note">{_e(n)}</p>' for n in comp.notes)
        parts.append(f"<h4>{head}</h4>" + notes
                     + ("<p>" + _e(", ".join(c.parameter for c in sig)) + "</p>" if sig else "")
                     + "<details><summary>every parameter</summary>"
                     + _table(["parameter", "change", "std", "unit", "z", "significant"], rows, num_cols=[1, 2, 4])
                     + "</details>")
    if h.comparisons:
        parts.append(f"<p><small>Test: {_e(h.comparisons[0].test)}, α = {_e(h.comparisons[0].alpha)}.</small></p>")
    return "\n".join(parts)


def _measurement_html(i: int, rep: MeasurementReport, base: Path | None) -> str:
    sid = f"m{i + 1}"
    parts = [f'<section class="measurement" id="{sid}" data-file="{_e(rep.path)}">',
             f"<h2>{i + 1}. {_e(rep.path.name)} — <code>{_e(rep.machine)}</code></h2>"]
    for note in rep.notes:
        parts.append(f'<p class="note">{_e(note)}</p>')
    if rep.check is not None:
        parts += [f'<section data-section="conformance" id="{sid}-conformance"><h3>Conformance</h3>',
                  _check_html(rep), "</section>"]
    parts += [f'<section data-section="summary" id="{sid}-summary"><h3>Machine and test</h3>',
              _summary_html(rep), "</section>",
              f'<section data-section="deviations" id="{sid}-deviations"><h3>Measured deviations</h3>',
              _figs(rep, "deviation", base), _figs(rep, "polar", base), "</section>",
              f'<section data-section="identification" id="{sid}-identification"><h3>Identified PIGEs</h3>',
              _figs(rep, "identification", base), _identification_html(rep), "</section>",
              f'<section data-section="diagnosis" id="{sid}-diagnosis"><h3>Diagnosis</h3>',
              _diagnosis_html(rep, base), "</section>",
              f'<section data-section="compensation" id="{sid}-compensation"><h3>Compensation before/after</h3>',
              _compensation_html(rep, base), "</section>"]
    if rep.projection is not None:
        parts += [f'<section data-section="projection-study" id="{sid}-projection"><h3>Projection study</h3>',
                  _projection_html(rep), "</section>"]
    if rep.sobol is not None:
        parts += [f'<section data-section="sobol" id="{sid}-sobol"><h3>Sobol indices</h3>',
                  _sobol_html(rep, base), "</section>"]
    parts.append("</section>")
    return "\n".join(parts)


def _overview_html(data: ReportData) -> str:
    head = ["#", "file", "machine", "points", "rank", "residual RMS [µm]", "diagnosis", "RMSE before → after [µm]",
            "basis"]
    rows = []
    for i, rep in enumerate(data.measurements):
        gn = rep.identification["gauss-newton"]
        findings = findings_text(rep)
        imp = improvement(rep, data)
        arrow = "→ ≈" if imp.basis == "model" else "→"
        rank = _e(f"{gn.rank}/{len(gn.parameters)}")
        if gn.rank < len(gn.parameters):
            rank = f'<span class="unid">{rank}</span>'
        rows.append([f'<a href="#m{i + 1}">{i + 1}</a>', f'<code class="path">{_e(rep.path.name)}</code>',
                     f"<code>{_e(rep.machine)}</code>", _e(rep.measurement.n_rows), rank, _f(gn.rms_um, ".4f"),
                     _e(findings), f"{_f(imp.before_um)} {arrow} {_f(imp.after_um, '.3g')}", _e(imp.label)])
    return _table(head, rows, num_cols=[3, 5])


def render_html(data: ReportData, *, base: Path | None = None) -> str:
    """The report page: one self-contained HTML document (inline CSS, PNGs as data URIs, no script).

    Parameters
    ----------
    data : ReportData
        With figures drawn (:func:`draw_figures`).
    base : Path, optional
        Figure paths are shown relative to it.
    """
    nav = " ".join([f'<a href="#m{i + 1}">{_e(r.path.name)}</a>' for i, r in enumerate(data.measurements)]
                   + (['<a href="#compare">measured before/after</a>'] if data.comparison is not None else [])
                   + (['<a href="#history">history</a>'] if data.history is not None else [])
                   + (['<a href="#plan">test plan</a>'] if data.plan_html or data.plan is not None else []))
    settings = "; ".join(f"{k}: {v}" for k, v in data.settings.items())
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>pige_sym calibration report</title>",
        f"<style>{CSS}</style></head><body>",
        "<header><h1>Five-axis calibration report (R-test)</h1>",
        f'<p class="meta">pige_sym {_e(__version__)} — {_e(data.created)}</p></header><main>',
        '<section data-section="answer" id="answer">', _answer_html(data), "</section>",
        (f'<p class="meta">{_e(settings)}'
         + (f" — NC program <code>{_e(data.program)}</code>" if data.program is not None else "") + "</p>"
         if data.measurements else ""),
        f"<nav>{nav}</nav>",
    ]
    if data.measurements:
        parts += ['<section data-section="overview" id="overview"><h2>Overview</h2>', _overview_html(data),
                  "</section>"]
    if data.comparison is not None:
        parts += ['<section data-section="measured-compare" id="compare"><h2>Measured before/after</h2>',
                  _compare_html(data, base), "</section>"]
    if data.history is not None:
        parts += ['<section data-section="history" id="history"><h2>Machine history</h2>',
                  _history_html(data, base), "</section>"]
    parts += [_measurement_html(i, rep, base) for i, rep in enumerate(data.measurements)]
    if data.plan_html:
        parts.append(data.plan_html)
    parts += [
        "</main><footer><p>PIGEs: position-independent geometric errors of the rotary axes (ISO 230-7), position "
        "errors in µm, orientation errors in µrad, definitions in CONVENTIONS.md. Standard errors from "
        "σ²(AᵀA)⁺ with σ² = RSS/(N − rank); 95 % intervals from Student's t. A parameter with weight in a "
        "near-null direction of the scaled design is not identifiable and gets no value.</p></footer>",
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"
