"""The report's error-map section (``pige report FILES --map C,A``): the maps, what they leave, what is missing.

For the files of one machine, the joint fit of PIGEs, zero-position errors and maps
(:func:`pige_sym.identification.maps.identify_maps`) and the maps' held-out gain
(:mod:`pige_sym.diagnosis.map_gain`). The section shows per axis the plot with ±2σ bands and a table per motion
(the largest value and its standard error, how many values are determined); what the map leaves (per file the
joint residual against its noise, and the gain over the PIGEs alone); and every value the setups do not
determine, grouped by motion, with the remedy. The numbers come from the same objects ``pige identify --map``
and ``pige diagnose --map`` print.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

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

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "files": self.files, "error_motions": self.result.to_dict()["error_motions"],
                "map_undetermined": [u.to_dict() for u in self.result.undetermined], "map_gain": self.gain.to_dict()}


def gather_maps(items: Sequence[tuple[str, Any]], spec: MapSpec) -> MapReport:
    """Identify the maps of ``items`` (label, measurement or ballbar run) and their held-out gain."""
    result = identify_maps(items, spec)
    return MapReport(result.result.machine, [lab for lab, _ in items], result, map_gain(items, spec, result))


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
    if not r.undetermined:
        return "<p>Every value of every map is determined by these setups.</p>"
    groups: dict[tuple[str, str, str], list[float]] = {}
    for u in r.undetermined:
        key = (u.motion, u.why.split("; not seen")[0], u.remedy)
        groups.setdefault(key, []).append(math.nan if u.angle_deg is None else u.angle_deg)
    items = []
    for (motion, why, remedy), angles in groups.items():
        where = ", ".join(f"{a:g}°" for a in angles if math.isfinite(a))
        items.append(f"<li><b>{esc(motion)}</b>{(' at ' + esc(where)) if where else ''}: {esc(why)}. "
                     f"To determine it: {esc(remedy)}.</li>")
    return ("<h3>Not determined (no value given)</h3><ul>" + "".join(items) + "</ul>")
