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

import numpy as np

from pige_sym import __version__
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text
from pige_sym.identification import IdentificationResult
from pige_sym.kernels import load_kernels
from pige_sym.report.figures import draw_figures
from pige_sym.report.gather import (
    UNIT_TEXT,
    MeasurementReport,
    ReportData,
    ReportFigure,
    findings_text,
    gather_report,
)


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
    html_path = out / "report.html"
    atomic_write_text(html_path, render_html(data, base=out))
    data.html_path = html_path
    return html_path


def build_report(measurement_paths: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str], *,
                 studies: Iterable[str] = (), program: str | os.PathLike[str] | None = None,
                 method: str = "gauss-newton", projection: str = "xyz", with_zero: bool = False,
                 presets: int = 50, sobol_samples: int = 2048, seed: int = 0, progress: bool = False) -> Path:
    """Build the report of measurement files into ``out_dir``; returns the path of ``report.html``.

    Parameters are those of :func:`gather_report`; PNGs are kept in ``out_dir/<label>/``.
    """
    data = gather_report(measurement_paths, studies=studies, program=program, method=method, projection=projection,
                         with_zero=with_zero, presets=presets, sobol_samples=sobol_samples, seed=seed,
                         progress=progress)
    return write_report(data, out_dir)


# ---------------------------------------------------------------------------------------------
# HTML

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:0;color:#1d232a;
background:#f6f7f9;line-height:1.4}
header,main,footer{max-width:1150px;margin:0 auto;padding:0 18px}
header{padding-top:18px}
h1{font-size:1.6em;margin:.2em 0}
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
    return "<table>" + "".join(f"<tr><th>{_e(k)}</th><td>{v}</td></tr>" for k, v in items) + "</table>"


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


def _identification_html(rep: MeasurementReport) -> str:
    gn = rep.identification["gauss-newton"]
    dd = rep.identification["double-differential"]
    truth = rep.truth
    ci = gn.ci95()
    ci_dd = dd.ci95()
    fixed_at = {p: s.index for s in dd.stages for p in s.fixed}
    head = ["parameter", "unit", "Gauss–Newton value", "std", "95 % interval", "VIF", "status (GN)",
            "double-diff. value", "std", "95 % interval", "fixed at stage", "status (DD)"]
    if truth is not None:
        head += ["truth", "error (GN)", "|error| / std"]
    rows, classes = [], []
    for j, name in enumerate(gn.parameters):
        u = _u(gn.units.get(name, ""))
        st_gn, bad_gn = _status(gn, j)
        jd = dd.parameters.index(name)
        st_dd, bad_dd = _status(dd, jd)
        vif = gn.vif[j] if gn.vif is not None else float("nan")
        if bad_gn:
            cells_gn = ["not identifiable", "—", "—", _f(vif, ".3g")]
        else:
            cells_gn = [_f(gn.values[j]), _f(gn.std[j]), f"[{_f(ci[j, 0])}, {_f(ci[j, 1])}]", _f(vif, ".3g")]
        if bad_dd:
            cells_dd = ["no value", "—", "—", _e(fixed_at.get(name, "—"))]
        else:
            cells_dd = [_f(dd.values[jd]), _f(dd.std[jd]), f"[{_f(ci_dd[jd, 0])}, {_f(ci_dd[jd, 1])}]",
                        _e(fixed_at.get(name, "—"))]
        row = [f"<b>{_e(name)}</b>", _e(u), *cells_gn, st_gn, *cells_dd, st_dd]
        if truth is not None:
            t = truth.values.get(name, 0.0)
            if bad_gn:
                row += [_f(t), "—", "—"]
            else:
                err = gn.values[j] - t
                ratio = abs(err) / gn.std[j] if gn.std[j] > 0 else float("inf")
                row += [_f(t), _f(err, "+.3f"), _f(ratio, ".2f")]
        rows.append(row)
        classes.append("unid" if (bad_gn or bad_dd) else "")
    num_cols = [2, 3, 4, 5, 7, 8, 9, 10] + ([12, 13, 14] if truth is not None else [])
    parts = [_table(head, rows, row_classes=classes, num_cols=num_cols)]
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
        rows = [[_e(r.effect), _e(" ".join(f"{k}={v:g}" for k, v in r.options.items()) or "—"), _e(r.reason),
                 _f(r.delta_bic, ".1f"), _f(r.p_value, ".2g")] for r in d.rejected]
        parts.append(_table(["candidate", "options", "why not accepted", "ΔBIC", "p"], rows, num_cols=[3, 4]))
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
        parts.append(f"<p>Before/after <b>simulated</b> on a machine with the true parameters of "
                     f"<code>{_e(rep.truth.path.name)}</code>, compensated with the {_e(rep.primary_method)} "
                     "estimate.</p>")
    else:
        parts.append(f'<p class="note">No truth sidecar: the before/after is <b>model-predicted</b>. The machine is '
                     f"assumed to carry exactly the identified errors ({_e(rep.primary_method)}), so “after” shows "
                     "only what the compensation itself leaves (second-order terms). What to expect on the real "
                     "machine: the column “expected after, from the std” (identification uncertainty alone), plus "
                     f"what the PIGE model does not explain (residual RMS {_f(rep.primary.rms_um, '.3f')} µm).</p>")
    if rep.not_compensated:
        unknown = (" The model-predicted machine carries 0 for them too: their real errors are unknown and not in "
                   "these numbers." if rep.compensation_basis == "model" else "")
        parts.append(f'<p class="note"><span class="unid">Not compensated (no value): '
                     f"{_e(', '.join(rep.not_compensated))}</span> — set to 0.{_e(unknown)}</p>")
    head = ["test", "RMSE before [µm]", "RMSE after [µm]", "reduction", "expected after, from the std [µm]",
            "command change RMS [µm]"]
    rows = [[_e(r.trajectory), _f(r.rmse_before_um), _f(r.rmse_after_um), _f(r.reduction * 100, ".1f") + " %",
             _f(r.predicted_after_um, ".3f", "n/a"), _f(r.command_change_rmse_mm * 1e3, ".2f")]
            for r in rep.compensation]
    parts.append(_table(head, rows, num_cols=[1, 2, 3, 4, 5]))
    if rep.compensated_program is not None:
        parts.append(f"<p>Compensated NC program written to <code>{_e(rep.compensated_program)}</code>.</p>")
    parts.append(_figs(rep, "compensation", base))
    return "\n".join(parts)


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
    head = ["parameter"] + [f"{p} {k}" for p in st.projections for k in ("S1", "ST")]
    rows = [[_e(name)] + [_f(v, ".3f") for i in range(len(st.projections))
                          for v in (st.first_order[i, j], st.total_order[i, j])]
            for j, name in enumerate(st.parameters)]
    return (f"<p>First-order (S1) and total (ST) indices of the mean-square projected deviation over the measured "
            f"trajectory, every PIGE uniform on ±15 µm / µrad, {st.n_samples} base samples.</p>"
            + _table(head, rows, num_cols=range(1, 1 + 2 * len(st.projections))) + _figs(rep, "sobol", base))


def _measurement_html(i: int, rep: MeasurementReport, base: Path | None) -> str:
    sid = f"m{i + 1}"
    parts = [f'<section class="measurement" id="{sid}" data-file="{_e(rep.path)}">',
             f"<h2>{i + 1}. {_e(rep.path.name)} — <code>{_e(rep.machine)}</code></h2>"]
    for note in rep.notes:
        parts.append(f'<p class="note">{_e(note)}</p>')
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
    head = ["#", "file", "machine", "points", "rank", "residual RMS [µm]", "diagnosis", "RMSE before → after [µm]"]
    rows = []
    for i, rep in enumerate(data.measurements):
        gn = rep.identification["gauss-newton"]
        findings = findings_text(rep)
        comp = rep.compensation[0]
        rank = _e(f"{gn.rank}/{len(gn.parameters)}")
        if gn.rank < len(gn.parameters):
            rank = f'<span class="unid">{rank}</span>'
        rows.append([f'<a href="#m{i + 1}">{i + 1}</a>', f"<code>{_e(rep.path.name)}</code>",
                     f"<code>{_e(rep.machine)}</code>", _e(rep.measurement.n_rows), rank, _f(gn.rms_um, ".4f"),
                     _e(findings), f"{_f(comp.rmse_before_um)} → {_f(comp.rmse_after_um)}"
                     + (" (model)" if rep.compensation_basis == "model" else "")])
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
    nav = " ".join(f'<a href="#m{i + 1}">{_e(r.path.name)}</a>' for i, r in enumerate(data.measurements))
    settings = "; ".join(f"{k}: {v}" for k, v in data.settings.items())
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>pige_sym calibration report</title>",
        f"<style>{CSS}</style></head><body>",
        "<header><h1>Five-axis calibration report (R-test)</h1>",
        f"<p>pige_sym {_e(__version__)} — {_e(data.created)} — {_e(settings)}"
        + (f" — NC program <code>{_e(data.program)}</code>" if data.program is not None else "") + "</p>",
        f"<nav>{nav}</nav></header><main>",
        '<section data-section="overview" id="overview"><h2>Overview</h2>', _overview_html(data), "</section>",
    ]
    parts += [_measurement_html(i, rep, base) for i, rep in enumerate(data.measurements)]
    parts += [
        "</main><footer><p>PIGEs: position-independent geometric errors of the rotary axes (ISO 230-7), position "
        "errors in µm, orientation errors in µrad, definitions in CONVENTIONS.md. Standard errors from "
        "σ²(AᵀA)⁺ with σ² = RSS/(N − rank); 95 % intervals from Student's t. A parameter with weight in a "
        "near-null direction of the scaled design is not identifiable and gets no value.</p></footer>",
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"
