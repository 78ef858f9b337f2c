"""The report's error-map section (``pige report FILES --map C,A``): the maps, what they leave, what is missing.

For the files of one machine, the joint fit of PIGEs, zero-position errors and maps
(:func:`pige_sym.identification.maps.identify_maps`) and the maps' held-out gain
(:mod:`pige_sym.diagnosis.map_gain`). The section shows per axis the plot with ±2σ bands and a table per motion
(the largest value and its standard error, how many values are determined); what the map leaves (per file the
joint residual against its noise, and the gain over the PIGEs alone); and every value the setups do not
determine, grouped by reason, with the remedy. The numbers come from the same objects ``pige identify --map``
and ``pige diagnose --map`` print.

The page leads with the maps' answer (:func:`map_answer_html`): what they explain, what to enter and what it is
predicted to leave (the compensation stage's result on the maps' parameter file, judged over the axes' travel:
:func:`pige_sym.compensation.stage.compensate`), and what is not determined and why.  Motions and effects are named
in words first, their symbols after.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.compensation.result import Compensation
from pige_sym.diagnosis.map_gain import MapGain, map_gain
from pige_sym.identification.maps import MapResult, MapSpec, identify_maps
from pige_sym.report.html_blocks import esc, num, table


@dataclass
class MapReport:
    """The maps of a report's files."""

    machine: str
    files: list[str]
    result: MapResult
    gain: MapGain
    compensation: Compensation | None = None
    next_commands: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "files": self.files, "error_motions": self.result.to_dict()["error_motions"],
                "map_undetermined": [u.to_dict() for u in self.result.undetermined], "map_gain": self.gain.to_dict(),
                "compensation": None if self.compensation is None else self.compensation.to_dict()}


def gather_maps(items: Sequence[tuple[str, Any]], spec: MapSpec) -> MapReport:
    """Identify the maps of ``items`` (label, measurement or ballbar run), their held-out gain, and what the
    compensation stage enters of them over the axes' travel."""
    from pige_sym.compensation.parameters import parameters_from_result
    from pige_sym.compensation.stage import compensate

    result = identify_maps(items, spec)
    compensation = compensate(parameters_from_result(result, allow_missing=True))
    gain = map_gain(items, spec, result)
    return MapReport(result.result.machine, [lab for lab, _ in items], result, gain, compensation,
                     next_commands(items, spec, gain.explains()))


def next_commands(items: Sequence[tuple[str, Any]], spec: MapSpec, explains: bool) -> list[str]:
    """What to run next, as commands that run as printed in order: the maps' parameter file (or the PIGEs', when the
    maps do not explain the residual), then the entries of the controller the probing programs were written for
    (else the controller-neutral axis lines)."""
    import shlex

    files = " ".join(shlex.quote(lab) for lab, _ in items)
    dialects = {str(x.metadata.get("program_dialect")) for _, x in items if getattr(x, "metadata", None)}
    controller = next(iter(dialects)) if len(dialects) == 1 and dialects <= {"linuxcnc", "siemens"} else "table"
    options = f"--map {','.join(spec.axes)} --map-step {spec.step_deg:g}" + (
        f" --map-per-direction {','.join(spec.per_direction)}" if spec.per_direction else "")
    name = "maps.json" if explains else "pige.json"
    fit = f"pige identify {files} {options} --json > {name}" if explains else f"pige identify {files} --json > {name}"
    return [fit, f"pige compensate --params {name} --controller {controller}"]


def maps_html(rep: MapReport, figures: str) -> str:
    """The section (module docstring); ``figures`` holds the plots' HTML."""
    r = rep.result
    parts = ['<section data-section="maps" id="maps"><h2>Error maps of the rotary axes</h2>',
             f"<p>{esc(len(rep.files))} files of {esc(rep.machine)} fitted jointly: the PIGEs, the zero-position "
             "errors and the error motions of "
             f"{esc(', '.join(r.maps))} on a {esc(f'{r.spec.step_deg:g}')}° grid (conventions §10; each map "
             "without the functions the PIGEs and the set-up describe). Values ± standard error; bands ±2σ.</p>",
             figures]
    for axis, m in r.maps.items():
        rows = []
        for mo in m.motions:
            v, s = m.value[mo.name], m.std[mo.name]
            ok = np.isfinite(v)
            big = int(np.argmax(np.where(ok, np.abs(v), -1.0))) if ok.any() else None
            rows.append([esc(mo.name), esc(mo.kind), f"{int(ok.sum())} of {v.size}",
                         num(float(np.sqrt(np.mean(v[ok] ** 2))) if ok.any() else math.nan, ".3g", "—"),
                         (f"{num(v[big], '.3g')} ± {num(s[big], '.2g')} at {m.grid.angles_deg[big]:g}°"
                          if big is not None else "—"), esc(mo.unit)])
        parts.append(f"<h3>{esc(axis)}</h3>")
        parts.append(table(["motion", "kind", "determined", "RMS of the map", "largest value", "unit"], rows,
                           num_cols=[3]))
    parts.append(_left_html(rep))
    parts.append(_undetermined_html(r))
    parts.append("</section>")
    return "\n".join(parts)


def _left_html(rep: MapReport) -> str:
    files = rep.result.joint.files
    rows = [[esc(f.label), esc(f.instrument), num(f.rms_um, ".3g"), num(f.sigma_um, ".3g")] for f in files]
    gain = "".join(f"<li>{esc(s)}</li>" for s in rep.gain.sentences())
    return ("<h3>What the maps leave</h3>" + table(["file", "instrument", "joint residual RMS", "its noise σ"], rows,
                                                   num_cols=[2, 3])
            + f"<ul>{gain}</ul>")


def _undetermined_html(r: MapResult) -> str:
    from pige_sym.identification.map_output import group_undetermined

    head = "" if r.undetermined else "<p>Every value of every map is determined by these setups.</p>"
    if not r.undetermined and not r.not_identifiable:
        return head
    items = [f"<li><b>{esc(g.axis)}: {esc(', '.join(g.motions))}</b>{esc(g.where())}: {esc(g.why)}. "
             f"To determine {'it' if g.count == 1 else 'them'}: {esc(g.remedy)}.</li>" for g in group_undetermined(r)]
    items += [f"<li><b>{esc(', '.join(n.parameters))}</b>: {esc(n.why)}. To determine "
              f"{'it' if len(n.parameters) == 1 else 'them'}: {esc(n.remedy)}.</li>" for n in r.not_identifiable]
    return (head + "<h3>Not determined (no value given, nothing corrected there)</h3><ul>" + "".join(items)
            + "</ul>")


def map_answer_html(rep: MapReport) -> str:
    """The maps' answer, first on the page: what they explain, what to enter and what it leaves, what is not
    determined and why (module docstring)."""
    r, g = rep.result, rep.gain
    axes = ", ".join(r.maps)
    explains = (f"The error maps of {axes} explain what the PIGEs alone miss: held-out RMS {g.heldout_pige:.2f} σ "
                f"with the PIGEs alone, {g.heldout_map:.2f} σ with the maps ({g.gain:.0%} less)."
                if g.explains() else
                f"The error maps of {axes} do not explain enough of what the PIGEs miss to be worth entering: held-out "
                f"RMS {g.heldout_pige:.2f} σ with the PIGEs alone, {g.heldout_map:.2f} σ with the maps.")
    shapes = [h.sentence() for h in g.harmonics if h.significant] if g.explains() else []
    parts = ['<div class="answer" data-answer="maps">', f"<h2>Error maps: the answer ({esc(rep.machine)}, "
             f"{esc(len(rep.files))} files)</h2>", f"<p><b>What they explain.</b> {esc(explains)}</p>"]
    if shapes:
        parts.append("<ul>" + "".join(f"<li>{esc(s)}</li>" for s in shapes) + "</ul>")
    parts.append(_enter_html(rep.compensation))
    if rep.next_commands:
        parts.append("<p><b>Next.</b> Write the parameter file and the controller's entries (an NC program is "
                     "corrected by the second command too, given the program and --out):"
                     + "".join(f'<br><code class="cmd">{esc(c)}</code>' for c in rep.next_commands) + "</p>")
    parts.append("<p><b>Not determined.</b></p>" + _undetermined_html(r))
    parts.append("</div>")
    return "\n".join(parts)


def _enter_html(c: Compensation | None) -> str:
    """What the compensation stage enters of the maps and what it is predicted to leave."""
    if c is None:
        return ""
    w = c.weighing
    values = [n for n, v in w.entered.items() if v is not None]
    maps = [n for n in values if "@" in n]
    pige = [n for n in values if "@" not in n]
    part = sum(1 for n in values if w.why[n].startswith("entered in part"))
    none = sum(1 for n, v in w.entered.items() if v == 0.0)
    text = (f"Every determined value, weighed by its uncertainty: the PIGEs {', '.join(pige) or 'none'} and "
            f"{len(maps)} map values ({part} entered in part, {none} not entered: within their uncertainty); in the "
            "NC rewrite of a program, or a controller's own tables (docs/maps.md, sections 7 and 9).")
    p = w.predicted
    if "none" in p and "entered" in p:
        text += (f" Predicted tool-point RMS error over {w.judged_on}: {p['none'].expected_um:.2f} µm uncorrected, "
                 f"{p['entered'].expected_um:.2f} µm after (95 % ≤ {p['entered'].p95_um:.2f} µm).")
    advice = "".join(f"<li>{esc(a)}</li>" for a in c.advice)
    return f"<p><b>What to enter.</b> {esc(text)}</p>" + (f"<ul>{advice}</ul>" if advice else "")
