"""The sections of the report that answer the engineer's questions: in tolerance (check), what changed
(history), did the compensation work (compare).

Each function takes the gathered data (:mod:`pige_sym.report.gather`) and returns HTML text.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pige_sym.report.data import MeasurementReport, ReportData
from pige_sym.report.estimate_used import differs_short_html
from pige_sym.report.html_blocks import esc, img, kvs, num, table, units
from pige_sym.report.lead import improvement, main_finding, pige_rows
from pige_sym.report.next_step import compare_next, history_next, measurement_next, next_html
from pige_sym.report.words import value_std
from pige_sym.verdict.check import CheckResult

_BADGE = {"pass": "PASS", "fail": "FAIL", "undecided": "UNDECIDED", "ok": "OK", "drifted": "DRIFTED", "out": "OUT"}


def verdict_html(rep: MeasurementReport) -> str:
    chk = rep.check
    if chk is None:
        return ('<span data-verdict="none" class="badge none">not judged</span> <small>no tolerances given '
                "(give pige report your tolerance file with --tolerances)</small>")
    rule = f"|v| ± {chk.k:g}u vs limit (ISO 14253-1)" if chk.rule == "guard" else "simple acceptance"
    odd = [f"{i.name} {i.status}" for i in chk.items if i.status != "pass"]
    tail = f": {', '.join(odd)}" if odd else f": all {len(chk.items)} items pass"
    return (f'<span data-verdict="{esc(chk.verdict)}" class="badge {esc(chk.verdict)}">{_BADGE[chk.verdict]}</span> '
            f"<small>{esc(rule)}{esc(tail)}</small>")


def pige_used_html(rep: MeasurementReport) -> str:
    rows, classes = [], []
    for r in pige_rows(rep):
        val = "not identifiable" if r.value is None else esc(value_std(r.value, r.std if r.std is not None
                                                                       else float("nan")))
        row = [f"<b>{esc(r.name)}</b>", val, esc(r.unit)]
        if rep.check is not None:
            row += [num(r.limit, "g"), f'<span class="st {esc(r.status or "")}">{esc(r.status or "no limit")}</span>']
        rows.append(row)
        classes.append("unid" if r.value is None else "")
    head = ["PIGE", "value ± std", "unit"] + (["limit", "status"] if rep.check is not None else [])
    return table(head, rows, row_classes=classes, num_cols=[1, 3])


def _estimate_label(rep: MeasurementReport) -> str:
    if rep.primary_method == "diagnosis":
        found = rep.diagnosis is not None and any(f.effect != "outliers" for f in rep.diagnosis.findings)
        return ("diagnosis' final fit: PIGEs estimated jointly with the accepted effects" if found
                else "diagnosis' final fit (no effect accepted: the PIGE-only model)")
    return f"{rep.primary_method} fit"


def _answer_one(i: int, rep: MeasurementReport, data: ReportData) -> str:
    imp = improvement(rep, data)
    facts = [
        ("machine", f"<code>{esc(rep.machine)}</code>" + (f" — id <b>{esc(data.history.machine_id)}</b>"
                                                          if data.history is not None else "")),
        ("measured", esc(f"{rep.measured_at} ({rep.time_source})") + f" — <code>{esc(rep.path.name)}</code>"),
        ("verdict", verdict_html(rep)),
        ("main finding", esc(main_finding(rep))),
        (f"improvement ({imp.label})", f'<span class="basis {esc(imp.basis)}">{esc(imp.label)}</span> {esc(imp.text)}'),
        ("next step", next_html(measurement_next(rep, data))),
    ]
    differs = differs_short_html(rep)
    return (f'<div class="answer" id="answer-m{i + 1}"><div class="facts">{kvs(facts)}</div>'
            f'<div class="used"><p class="cap">PIGEs used for compensation ({esc(_estimate_label(rep))})</p>'
            f"{pige_used_html(rep)}" + (f'<p class="cap" data-differs="pige-only">{differs}</p>' if differs
                                        else "") + "</div></div>")


def _answer_history(data: ReportData) -> str:
    h = data.history
    assert h is not None
    last = h.runs[-1]
    if h.check is not None:  # judged now against the report's --tolerances
        odd = [f"{i.name} {i.status}" for i in h.check.items if i.status != "pass"]
        verdict = (f'<span data-verdict="{esc(h.check.verdict)}" class="badge {esc(h.check.verdict)}">'
                   f"{_BADGE[h.check.verdict]}</span> <small>run {len(h.runs)} against {esc(h.check.tolerances)}"
                   f"{esc(': ' + ', '.join(odd) if odd else f': all {len(h.check.items)} items pass')}</small>")
    elif last.verdict:
        what = "its check-up" if last.kind == "checkup" else "stored with it"
        verdict = (f'<span data-verdict="{esc(last.verdict)}" class="badge {esc(last.verdict)}">'
                   f"{_BADGE.get(last.verdict, last.verdict)}</span> <small>run {len(h.runs)}, {what}</small>")
    else:
        verdict = ('<span data-verdict="none" class="badge none">not judged</span> <small>no tolerances stored with '
                   "the run or given (give pige report --history your tolerance file with --tolerances)</small>")
    number = run_numbers(h.runs)
    moved = [f"{c.parameter} {num(c.change, '+.3g')} ± {num(c.std, '.2g')} {units(c.unit)} "
             f"(run {number[c.from_run]} → {number[c.to_run]})"
             for comp in h.comparisons for c in comp.changes if c.significant]
    facts = [("machine", f"id <b>{esc(h.machine_id)}</b> — <code>{esc(last.machine_code)}</code>"),
             ("runs", esc(f"{len(h.runs)}, last measured {last.measured_at}")),
             ("verdict of the last run", verdict),
             ("what changed", esc("; ".join(moved) if moved else "no significant change between consecutive runs "
                                 "(family-wise false-alarm rate 1 % per comparison)")),
             ("next step", next_html(history_next(data)))]
    return f'<div class="answer"><div class="facts">{kvs(facts)}</div></div>'


def _answer_compare(data: ReportData) -> str:
    c = data.comparison
    assert c is not None
    facts = [("machine", f"<code>{esc(c.machine)}</code>"),
             ("verdict", '<span data-verdict="none" class="badge none">not judged</span> <small>give the '
                         "measurement files and --tolerances for a verdict</small>"),
             ("improvement (measured)", f'<span class="basis measured">measured</span> '
                                        f"{esc(f'RMS |d| {c.rms_before_um:.3g} → {c.rms_after_um:.3g} µm ')}"
                                        f"{esc(f'({c.improvement:.0%} less)')}"),
             ("next step", next_html(compare_next(data)))]
    return f'<div class="answer"><div class="facts">{kvs(facts)}</div></div>'


def answer_html(data: ReportData) -> str:
    parts = [_answer_one(i, rep, data) for i, rep in enumerate(data.measurements)]
    if not data.measurements and data.history is not None:
        parts.append(_answer_history(data))
    elif not data.measurements and data.comparison is not None:
        parts.append(_answer_compare(data))
    return "\n".join(parts)


def check_html(rep: MeasurementReport) -> str:
    assert rep.check is not None
    return check_table_html(rep.check)


def check_table_html(chk: CheckResult) -> str:
    """A check's items, its rule and what it could not assess."""
    rows = [[f"<b>{esc(i.name)}</b>", num(i.value), num(i.std), num(i.limit, "g"), esc(units(i.unit)),
             f'<span class="st {esc(i.status)}">{esc(i.status)}</span>', esc(i.reason)] for i in chk.items]
    parts = [f"<p>Tolerances <code>{esc(chk.tolerances)}</code>; {esc(chk.method)} estimate; rule "
             + (f"<b>guard</b>: pass when |v| + {chk.k:g}u ≤ limit, fail when |v| − {chk.k:g}u &gt; limit, "
                "undecided otherwise (ISO 14253-1)" if chk.rule == "guard" else
                "<b>simple acceptance</b>: the uncertainty is not used")
             + ". A parameter without a value is undecided.</p>",
             table(["parameter", "value", "std", "limit", "unit", "status", "why"], rows, num_cols=[1, 2, 3])]
    for name, why in chk.not_assessed.items():
        parts.append(f"<p><small>{esc(name)}: not assessed — {esc(why)}.</small></p>")
    return "\n".join(parts)


def compare_html(data: ReportData, base: Path | None) -> str:
    c = data.comparison
    assert c is not None
    parts = [f"<p>Two <b>measurements</b> of the same program on <code>{esc(c.machine)}</code>: "
             f"<code>{esc(c.before)}</code> (before) and <code>{esc(c.after)}</code> (after); commanded angles agree "
             f"within {num(c.max_angle_difference_deg, '.4f')}°. No model enters these numbers.</p>",
             table(["", "RMS |d| [µm]", "max |d| [µm]"],
                    [["before", num(c.rms_before_um), num(c.max_before_um)],
                     ["after", num(c.rms_after_um), num(c.max_after_um)],
                     ["improvement", num(c.improvement * 100, ".1f") + " %", "—"]], num_cols=[1, 2])]
    for when, dec in (("before", c.before_parts), ("after", c.after_parts)):
        if dec is None:
            continue
        rows = [[esc(p.name), num(p.rms_um), num(p.max_um)] for p in dec.parts]
        expl = "—" if dec.explained is None else f"{dec.explained:.0%}"
        parts.append(f"<h4>What the {when} deviation is made of</h4>"
                     + table(["part", "RMS [µm]", "max [µm]"], rows, num_cols=[1, 2])
                     + f"<p><small>The model explains {esc(expl)} of the mean square; noise σ "
                       f"{num(dec.sigma_um)} µm per component. {esc(' '.join(dec.notes))}</small></p>")
    parts.append("".join(img(f, base) for f in data.figures if f.key == "measured-compare"))
    poses = [[esc(i), *(num(a, ".2f") for a in ang), num(b), num(x)]
             for i, (ang, b, x) in enumerate(zip(c.angles_deg, c.before_um, c.after_um, strict=True))]
    parts.append("<details><summary>|d| per pose</summary>"
                 + table(["pose", *(f"{a} [deg]" for a in c.rotary_axes), "before [µm]", "after [µm]"], poses,
                          num_cols=range(0, 3 + len(c.rotary_axes))) + "</details>")
    return "\n".join(parts)


def run_numbers(runs: list[Any]) -> dict[int, int]:
    """Per run id its number among the machine's runs (:func:`pige_sym.cli.history.run_numbers`)."""
    return {r.id: k for k, r in enumerate(runs, start=1)}


def history_html(data: ReportData, base: Path | None) -> str:
    h = data.history
    assert h is not None
    number = run_numbers(h.runs)
    runs = [[esc(number[r.id]), esc(r.measured_at), f'<code class="path">{esc(Path(r.file_name).name)}</code>',
             esc(r.method), esc(", ".join(str(f.get("effect")) for f in r.effects) or "none"), esc(r.verdict or "—"),
             num(r.rms_um)] for r in h.runs]
    parts = [f"<p>Machine <b>{esc(h.machine_id)}</b> in <code>{esc(h.database)}</code>.</p>",
             table(["run", "measured (UTC)", "file", "estimate", "effects", "verdict", "residual RMS [µm]"], runs,
                    num_cols=[0, 6]),
             "".join(img(f, base) for f in data.figures if f.key == "trend")]
    for comp in h.comparisons:
        sig = [c for c in comp.changes if c.significant]
        said = (f"<b>changed: {esc(', '.join(c.parameter for c in sig))}</b>" if sig else "<b>changed</b> (jointly, "
                "no parameter alone)") if comp.significant else "no significant change"
        head = f"run {number[comp.from_run]} → {number[comp.to_run]}: {said} (joint p = {num(comp.p_value, '.3g')})"
        rows = [[esc(c.parameter), num(c.change, "+.3f"), num(c.std), esc(units(c.unit)), num(c.z, "+.2f"),
                 "yes" if c.significant else ("not tested" if c.significant is None else "no")]
                for c in comp.changes]
        notes = "".join(f'<p class="note">{esc(n)}</p>' for n in comp.notes)
        parts.append(f"<h4>{head}</h4>" + notes
                     + "<details><summary>every parameter</summary>"
                     + table(["parameter", "change", "std", "unit", "z", "significant"], rows, num_cols=[1, 2, 4])
                     + "</details>")
    if h.comparisons:
        parts.append(f"<p><small>Test: {esc(h.comparisons[0].test)}, α = {esc(h.comparisons[0].alpha)}.</small></p>")
    return "\n".join(parts)
