"""The sections of one measurement in the report: summary, identification, stages, diagnosis,
compensation, excitation projection and sensitivity (Sobol).

Each function takes the gathered data (:mod:`pige_sym.report.gather`) and returns HTML text.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.identification.result import IdentificationResult
from pige_sym.kernels import load_kernels
from pige_sym.report.data import SOBOL_EFFECT_UM, MeasurementReport
from pige_sym.report.html_blocks import badge, esc, figs, kvs, num, path_html, table, units
from pige_sym.report.words import PROBE, Vocabulary, count, per_pose, value_std, vocabulary


def summary_html(rep: MeasurementReport) -> str:
    m = rep.measurement
    words = vocabulary(m)
    kern = load_kernels(m.machine)
    dev = m.deviation_machine_um()
    norms = np.linalg.norm(dev, axis=1)
    side = {a: ("workpiece side" if a in kern.WORKPIECE_ROTARY else "tool side") for a in kern.ROTARY_AXES}
    cmd = m.commanded_deg
    axes = ", ".join(f"{a} ({side[a]}, {num(cmd[:, k].min(), '.1f')} … {num(cmd[:, k].max(), '.1f')}° commanded"
                     + (", sense -1" if m.axis_sense.get(a, 1) == -1 else "") + ")"
                     for k, a in enumerate(m.rotary_axes))
    items = [
        ("file", f'<code class="path">{path_html(rep.path)}</code>'),
        ("machine", f"<code>{esc(rep.machine)}</code>" + (f" (written as <code>{esc(m.machine)}</code>)"
                                                         if m.machine != rep.machine else "")),
        ("rotary axes", esc(axes)),
        (words.reference_point, esc(", ".join(num(x, "g") for x in m.ball_mm) + " mm")),
    ]
    if m.tool_mm is not None:
        items.append((f"tool ({words.tool_point} from the last tool-side pivot)",
                      esc(", ".join(num(x, "g") for x in m.tool_mm) + " mm")))
    for ax, pv in m.pivots_mm.items():
        items.append((f"nominal pivot of {ax}", esc(", ".join(num(x, "g") for x in pv) + " mm")))
    items += [
        ("trajectory", esc(m.trajectory or "not stated in the file")),
        (words.rows, esc(_rows_text(m, words))),
        ("frame of the deviations", esc(m.frame)),
        ("largest deviation", esc(f"|d| max {num(norms.max())} µm; per component max |dx| "
                                  f"{num(np.abs(dev[:, 0]).max())}"
                                  f", |dy| {num(np.abs(dev[:, 1]).max())}, |dz| {num(np.abs(dev[:, 2]).max())} µm")),
        (f"RMS of |d| over the {words.rows}",
         esc(f"{num(math.sqrt(float((norms[1:] ** 2).mean())) if m.n_rows > 1 else 0.0)} µm")),
    ]
    if "source" in m.metadata:
        items.append(("source", esc(m.metadata["source"])))
    extra = [c for c in m.optional] + list(m.extra_columns)
    if extra:
        items.append(("other columns", esc(", ".join(extra))))
    items.append(("known true errors", f"yes, a simulation: {esc(rep.truth.path)}" if rep.truth is not None
                  else "none (a real measurement, or the truth is unknown)"))
    return kvs(items)


def _rows_text(m: Any, words: Vocabulary) -> str:
    """How many rows, and over what: seconds for an R-test, contacts for a probe import (its log has no clock)."""
    if words is PROBE:
        contacts = m.optional.get("n_samples")
        touched = f", {int(contacts.sum())} contacts ({per_pose(int(contacts.min()), int(contacts.max()))})" \
            if contacts is not None else ""
        return f"{count(m.n_rows, 'pose')}: the reference pose and {count(m.n_rows - 1, 'more pose')}{touched}"
    return (f"{count(m.n_rows, 'row')}: the reference pose and {count(m.n_rows - 1, 'measured point')} over "
            f"{num(m.t_s[-1] - m.t_s[0], '.0f')} s")


def _gn_rows(rep: MeasurementReport) -> tuple[list[str], list[list[str]], list[str]]:
    gn = rep.identification["gauss-newton"]
    truth = rep.truth
    ci = gn.ci95()
    head = ["parameter", "unit", "value", "std", "95 % interval", "VIF", "status"]
    if truth is not None:
        head += ["truth", "error", "|error| / std"]
    rows, classes = [], []
    for j, name in enumerate(gn.parameters):
        st, bad = badge(gn, j)
        vif = gn.vif[j] if gn.vif is not None else float("nan")
        cells = (["not identifiable", "—", "—"] if bad else
                 [num(gn.values[j]), num(gn.std[j]), f"[{num(ci[j, 0])}, {num(ci[j, 1])}]"])
        row = [f"<b>{esc(name)}</b>", esc(units(gn.units.get(name, ""))), *cells, num(vif, ".3g"), st]
        if truth is not None:
            t = truth.values.get(name, 0.0)
            if bad:
                row += [num(t), "—", "—"]
            else:
                err = gn.values[j] - t
                ratio = abs(err) / gn.std[j] if gn.std[j] > 0 else float("inf")
                row += [num(t), num(err, "+.3f"), num(ratio, ".2f")]
        rows.append(row)
        classes.append("unid" if bad else "")
    return head, rows, classes


def _dd_table(dd: IdentificationResult) -> str:
    ci = dd.ci95()
    fixed_at = {p: s.index for s in dd.stages for p in s.fixed}
    rows, classes = [], []
    for j, name in enumerate(dd.parameters):
        st, bad = badge(dd, j)
        cells = (["no value", "—", "—"] if bad else
                 [num(dd.values[j]), num(dd.std[j]), f"[{num(ci[j, 0])}, {num(ci[j, 1])}]"])
        rows.append([f"<b>{esc(name)}</b>", esc(units(dd.units.get(name, ""))), *cells, esc(fixed_at.get(name, "—")),
                     st])
        classes.append("unid" if bad else "")
    return table(["parameter", "unit", "value", "std", "95 % interval", "fixed at stage", "status"], rows,
                  row_classes=classes, num_cols=[2, 3, 4])


def identification_html(rep: MeasurementReport) -> str:
    gn = rep.identification["gauss-newton"]
    dd = rep.identification["double-differential"]
    head, rows, classes = _gn_rows(rep)
    num_cols = [2, 3, 4, 5] + ([7, 8, 9] if rep.truth is not None else [])
    parts = ["<h4>Gauss–Newton (all PIGEs at once)</h4>", table(head, rows, row_classes=classes, num_cols=num_cols),
             "<h4>Double-differential scheme</h4>", _dd_table(dd)]
    n_bad = int((~gn.identifiable).sum())
    if n_bad:
        are = "is" if n_bad == 1 else "are"
        parts.append(f'<p class="note"><span class="unid">{count(n_bad, "parameter")} {are} not identifiable from '
                     "these data</span>: no value is reported for them and they are compensated as 0.</p>")
    obs = ", ".join(f"{k} = {num(v, '.3g')}" for k, v in gn.observability.items())
    facts = [
        ("projection / loss", esc(f"{gn.projection} / {gn.loss}")),
        ("rank", esc(f"{gn.rank} of {len(gn.parameters)}") + ("" if gn.rank == len(gn.parameters)
                                                            else ' <span class="unid">(rank-deficient)</span>')),
        ("condition number (scaled)", esc(num(gn.condition, ".4g"))),
        ("residual RMS / σ", esc(f"{num(gn.rms_um, '.4f')} µm / {num(gn.sigma_um, '.4f')} µm "
                                f"({gn.n_obs} observations, {gn.dof} degrees of freedom)")),
        ("observability indices", esc(obs) + " <small>(O1 Borm–Menq, O2 Driels–Pathre, O3 Nahvi, O4 noise "
                                            "amplification, O5 Sun–Hollerbach; scaled columns)</small>"),
        ("singular values (scaled)", esc(", ".join(num(s, ".3g") for s in gn.singular_values))),
    ]
    if gn.outlier_rows:
        facts.append(("outlier rows", esc(gn.outlier_rows)))
    parts.append(kvs(facts))
    parts.append("<h4>Unidentifiable combinations</h4>")
    if gn.unidentifiable:
        parts.append('<ul class="combos">' + "".join(f'<li><span class="unid">{esc(c)}</span></li>'
                                                       for c in gn.unidentifiable) + "</ul>")
    else:
        parts.append("<p>None: every parameter combination is determined by the data.</p>")
    parts.append("<h4>Stages of the double-differential scheme</h4>")
    parts.append(stages_html(dd))
    return "\n".join(parts)


def stages_html(dd: IdentificationResult) -> str:
    if not dd.stages:
        return "<p>No stage.</p>"
    head = ["stage", "solved", "rank", "condition", "fixed at this stage", "values ± std (VIF)"]
    rows = []
    for s in dd.stages:
        vals = []
        for p in s.solved:
            u = units(dd.units.get(p, ""))
            std = s.std.get(p)
            if std is None or not math.isfinite(s.vif.get(p, float("inf"))):
                vals.append(f'{esc(p)}: <span class="unid">not identifiable at this stage</span>')
            else:
                mark = "<b>" if p in s.fixed else ""
                end = "</b>" if p in s.fixed else ""
                vals.append(f"{mark}{esc(p)} = {num(s.values[p])} ± {num(std)} {esc(u)} (VIF {num(s.vif[p], '.3g')})"
                            f"{end}")
        rows.append([esc(s.index), esc(len(s.solved)), esc(f"{s.rank}/{len(s.solved)}"), esc(num(s.condition, ".4g")),
                     esc(", ".join(s.fixed) or "none"), "<br>".join(vals)])
    return table(head, rows, num_cols=[0, 1, 3]) + (
        "<p><small>A parameter is fixed when it is individually identifiable and its variance inflation factor is "
        "at most 10; fixed parameters (bold) are substituted and the rest re-solved.</small></p>")


def final_html(res: IdentificationResult) -> str:
    head = ["parameter", "value", "std", "unit", "status"]
    rows, classes = [], []
    for j, name in enumerate(res.parameters):
        st, bad = badge(res, j)
        rows.append([esc(name), "not identifiable" if bad else num(res.values[j]), "—" if bad else num(res.std[j]),
                     esc(units(res.units.get(name, ""))), st])
        classes.append("unid" if bad else "")
    return table(head, rows, row_classes=classes, num_cols=[1, 2])


def diagnosis_html(rep: MeasurementReport, base: Path | None) -> str:
    d = rep.diagnosis
    if d is None:
        return (f'<p class="note"><span class="bad">The diagnosis failed on these data: {esc(rep.diagnosis_error)}'
                "</span>. The identification above does not depend on it.</p>")
    words = vocabulary(rep.measurement)
    parts = [kvs([
        ("baseline PIGE fit", esc(f"residual RMS {num(d.baseline_rms_um, '.3g')} µm, held-out RMS "
                                 f"{num(d.baseline_heldout_rms_um, '.3g')} µm, BIC {num(d.baseline_bic, '.1f')}")),
        (f"outlier {words.rows}", esc(", ".join(map(str, d.outlier_rows)) or "none")),
    ])]
    if words is PROBE:
        gn = rep.identification["gauss-newton"]
        parts.append(f'<p class="note">Why two residuals: the identification (Overview, {num(gn.rms_um, ".3g")} µm) '
                     "weighs the poses with the reference pose's correlation (generalised least squares) and "
                     "reports the plain residual; the diagnosis searches with every pose brought to one precision "
                     "and the reference centre's error fitted with its known uncertainty (baseline "
                     f"{num(d.baseline_rms_um, '.3g')} µm, at the median pose's precision). Its final estimate is "
                     "solved again with the correlation.</p>")
    parts += [f'<p class="note">{esc(n)}</p>' for n in d.clusters]
    parts.append("<h4>What the diagnosis concludes</h4>")
    if d.findings:
        parts.append('<ul class="verdict">' + "".join(f"<li>{esc(f.sentence())}</li>" for f in d.findings) + "</ul>")
    else:
        parts.append(f"<p>{esc(d.verdict())}</p>")
    parts.append("<h4>Findings</h4>")
    if d.findings:
        head = ["effect", "parameters ± std", "evidence", "moves the PIGEs"]
        rows = []
        for f in d.findings:
            params = "<br>".join(f'<span class="nw">{esc("τ" if k == "tau_s" else k)} = '
                                 f"{esc(value_std(v, f.std.get(k, math.nan)))} "
                                 f"{esc(units(words.time_unit if k == 'tau_s' else f.units.get(k, '')))}</span>"
                                 for k, v in f.params.items())
            shifts = sorted(f.pige_shift.items(), key=lambda kv: -abs(kv[1]))
            shift_txt = "<br>".join(f'<span class="nw">{esc(k)} {num(v, "+.3g")} {esc(units(d.final.units.get(k, "")))}'
                                    "</span>" for k, v in shifts[:4] if abs(v) > 0) or "—"
            held = (f"held-out RMS {num(f.heldout_rms_um_before, '.3g')} → {num(f.heldout_rms_um_after, '.3g')} µm<br>"
                    if math.isfinite(f.heldout_rms_um_before) else "")
            stats = (f"ΔBIC {num(f.delta_bic, '.1f')}, p {num(f.p_value, '.2g')}<br>"
                     f"RMS {num(f.rms_um_before, '.3g')} → {num(f.rms_um_after, '.3g')} µm<br>{held}"
                     + num(f.explained * 100 if math.isfinite(f.explained) else float("nan"), ".0f")
                     + " % of the residual explained")
            opts = {k: v for k, v in f.options.items() if k != "tau_s"}  # τ is among the fitted values
            rows.append([f"<b>{esc(f.effect)}</b> {esc(options_text(opts, words.time_unit))}", params,
                         f'<span class="stack">{stats}</span>', shift_txt])
        parts.append(table(head, rows))
        parts.append("<h4>Final estimates with the accepted extensions</h4>")
        parts.append(final_html(d.final))
        if rep.extensions:
            ids = ", ".join(e.spec.id for e in rep.extensions)
            parts.append(f"<p><small>Compensated with the PIGEs: {esc(ids)} (pose-dependent zero errors).</small></p>")
        for why in rep.extensions_not_compensated:
            parts.append(f"<p><small>Not compensated: {esc(why)}.</small></p>")
        if not rep.extensions and not rep.extensions_not_compensated:
            parts.append("<p><small>Accepted extensions are compensated only when the report's method is "
                         "<code>diagnosis</code>.</small></p>")
    else:
        parts.append("<p>No finding: the PIGE model explains the data down to the noise.</p>")
    parts.append("<h4>Rejected candidates</h4>")
    if d.rejected:
        parts.append('<ul class="rejected">' + "".join(_rejected_item(r, words.time_unit) for r in d.rejected)
                     + "</ul>")
    else:
        parts.append("<p>None.</p>")
    parts.append("<h4>Residual plots</h4>")
    plots = figs(rep, "residual", base)
    parts.append(f'<div class="figrow">{plots}</div>' if plots else "<p>No residual plot (no residuals to plot).</p>")
    return "\n".join(parts)


def compensation_html(rep: MeasurementReport, base: Path | None) -> str:
    parts = []
    if rep.compensation_basis == "truth":
        assert rep.truth is not None
        parts.append(f"<p>Before/after <b>simulated on a known truth</b>: the machine carries the true parameters of "
                     f"<code>{esc(rep.truth.path.name)}</code> and is compensated with the {esc(rep.primary_method)} "
                     "estimate.</p>")
    else:
        parts.append(f'<p class="note">No known true errors (a real measurement): the before/after is '
                     f"<b>model-predicted</b>. The machine is "
                     f"assumed to carry exactly the identified errors ({esc(rep.primary_method)}), so what the "
                     "compensation leaves on that model machine says nothing about the real one and is shown only "
                     "as a check of the algorithm. Expected on the real machine: the identification uncertainty "
                     "propagated to the tool point, combined with what the model leaves unexplained; a measurement "
                     "after compensation (<code>pige compare</code>) proves it.</p>")
    if rep.not_compensated:
        unknown = (" The model-predicted machine carries 0 for them too: their real errors are unknown and not in "
                   "these numbers." if rep.compensation_basis == "model" else "")
        parts.append(f'<p class="note"><span class="unid">Not compensated (no value): '
                     f"{esc(', '.join(rep.not_compensated))}</span> — set to 0.{esc(unknown)}</p>")
    parts.append(_compensation_table(rep))
    parts.append(_weighing_html(rep))
    if rep.compensated_program is not None:
        parts.append(f"<p>Compensated NC program written to <code>{esc(rep.compensated_program)}</code>.</p>")
    parts.append(figs(rep, "compensation", base))
    return "\n".join(parts)


def _weighing_html(rep: MeasurementReport) -> str:
    """What compensation enters of the estimate, weighed by its uncertainty, and what it is predicted to leave."""
    w = rep.weighing
    if w is None:
        return ""
    rows = w.rows() if w.covariance_from != "none" else []
    said = ("Every value is entered as estimated: each lies many standard errors from 0." if not rows else
            "Entered, weighed by its uncertainty (docs/algorithms.md, \"Corrections weighed by their uncertainty\"):")
    items = "".join(f"<li>{esc(r)}</li>" for r in rows)
    pred = w.predicted.get("entered")
    none = w.predicted.get("none")
    predicted = (f" Predicted tool-point RMS error over {esc(w.judged_on)}: {num(none.expected_um, '.2f')} µm "
                 f"uncorrected, {num(pred.expected_um, '.2f')} µm after compensation (95 % ≤ "
                 f"{num(pred.p95_um, '.2f')} µm), from the estimate's covariance.") if pred and none else ""
    return f"<p>{esc(said)}{predicted}</p>" + (f"<ul>{items}</ul>" if items else "")


def _compensation_table(rep: MeasurementReport) -> str:
    from pige_sym.report.lead import unexplained_rms_um

    if rep.compensation_basis == "truth":
        head = ["test", "RMSE before [µm]", "RMSE after [µm]", "reduction", "expected after, from the std [µm]",
                "command change RMS [µm]"]
        rows = [[esc(r.trajectory), num(r.rmse_before_um), num(r.rmse_after_um), num(r.reduction * 100, ".1f") + " %",
                 num(r.predicted_after_um, ".3f", "n/a"), num(r.command_change_rmse_mm * 1e3, ".2f")]
                for r in rep.compensation]
        return table(head, rows, num_cols=[1, 2, 3, 4, 5])
    resid = unexplained_rms_um(rep)
    head = ["test", "RMSE of the identified errors [µm]", "expected after [µm]", "of which: uncertainty [µm]",
            "unexplained residual [µm]", "left by the algorithm on the model [µm]", "command change RMS [µm]"]
    rows = []
    for r in rep.compensation:
        u = r.predicted_after_um
        expected = math.sqrt((u if math.isfinite(u) else 0.0) ** 2 + (resid if math.isfinite(resid) else 0.0) ** 2)
        rows.append([esc(r.trajectory), num(r.rmse_before_um), num(expected, ".2f"), num(u, ".3f", "n/a"),
                     num(resid, ".3f"), num(r.rmse_after_um, ".2g"), num(r.command_change_rmse_mm * 1e3, ".2f")])
    return table(head, rows, num_cols=[1, 2, 3, 4, 5, 6])


def projection_html(rep: MeasurementReport) -> str:
    st = rep.projection
    assert st is not None
    head = ["projection", "rank", "condition", "success rate", "unobserved", "undetermined combinations",
            "determined rate per PIGE"]
    rows, classes = [], []
    for r in st.rows:
        det = ", ".join(f"{k} {v:.0%}" for k, v in r.determined_rate.items())
        und = "<br>".join(f'<span class="unid">{esc(c)}</span>' for c in r.unidentifiable) or "—"
        rows.append([esc(r.projection), esc(f"{r.rank}/{r.n_parameters}"), num(r.condition, ".3g"),
                     num(r.success_rate * 100, ".0f") + " %", esc(", ".join(r.unobserved) or "—"), und, esc(det)])
        classes.append("" if r.rank == r.n_parameters else "unid")
    noise = num(rep.projection_noise_um, ".3g")
    return (f"<p>{esc(st.presets)} random presets simulated on the measured trajectory with {noise} µm noise (the "
            "Gauss–Newton σ) and identified with the double-differential scheme per projection; a preset succeeds "
            "when every PIGE gets a value within 4 standard errors of the preset.</p>"
            + table(head, rows, row_classes=classes, num_cols=[2, 3]) + f"<p>{esc(st.verdict)}</p>")


def sobol_html(rep: MeasurementReport, base: Path | None) -> str:
    st = rep.sobol
    assert st is not None
    words = vocabulary(rep.measurement)
    if rep.sobol_same_as is not None:
        return (f'<p>Same trajectory, {words.table_point} and tool as <a href="#m{rep.sobol_same_as}">measurement '
                f"{rep.sobol_same_as}</a>: the Sobol indices depend on nothing else and are shown there.</p>")
    head = ["parameter"] + [f"{p} {k}" for p in st.projections for k in ("S1", "ST")]
    rows = [[esc(name)] + [num(v, ".3f") for i in range(len(st.projections))
                          for v in (st.first_order[i, j], st.total_order[i, j])]
            for j, name in enumerate(st.parameters)]
    return (f"<p>First-order (S1) and total (ST) indices of the mean-square projected deviation over the measured "
            f"trajectory, {esc(st.method)}. The parameters are scaled like the identification's "
            f"columns: each PIGE is uniform on ±h, h chosen so that its RMS effect on the {words.table_point} is "
            f"{SOBOL_EFFECT_UM:g} µm ({esc(_ranges_text(rep))}), so position and orientation errors compete on "
            "equal terms.</p>"
            + table(head, rows, num_cols=range(1, 1 + 2 * len(st.projections))) + figs(rep, "sobol", base))


def _ranges_text(rep: MeasurementReport) -> str:
    unit_of = load_kernels(rep.machine).UNITS
    return ", ".join(f"{k} ±{v:.3g} {units(unit_of.get(k, ''))}" for k, v in rep.sobol_ranges.items())


_REJECTION_SENTENCES = (
    ("unidentifiable", "{name} cannot be told apart from the PIGEs with this test."),
    ("best candidate", "{name} was the best remaining candidate, but its gain is within the noise."),
    ("not significant", "{name} does not improve the fit beyond the noise."),
    ("not supported", "{name} does not improve the fit enough to be worth its parameters."),
    ("rows ", "{name}: the rows that stand out are better kept than dropped."),
)


def options_text(options: dict[str, float], time_unit: str = "s") -> str:
    """A candidate's settings for a reader: ``harmonic 2``, ``τ 19.1 s`` (probe files: ``τ 19.1 poses``)."""
    return ", ".join(f"τ {v:.3g} {time_unit}" if k == "tau_s" else f"{k} {v:.3g}" for k, v in options.items())


def _rejected_item(r: Any, time_unit: str = "s") -> str:
    """One plain sentence per rejected candidate; the statistics folded in a <details>."""
    opts = options_text(r.options, time_unit)
    name = f"{r.effect}" + (f" ({opts})" if opts else "")
    numbers = r.reason  # the tests' values and thresholds in words (pige_sym.diagnosis.selection.shortfall)
    if r.effect == "outliers":
        return (f"<li>{esc('No row was dropped as an outlier.')} <details><summary>why</summary><small>"
                f"{esc(numbers)}</small></details></li>")
    sentence = next((t.format(name=name) for key, t in _REJECTION_SENTENCES if r.reason.startswith(key)
                     or key in r.reason[:40]), f"{name} was not accepted.")
    return f"<li>{esc(sentence)} <details><summary>why</summary><small>{esc(numbers)}</small></details></li>"
