"""The answer the report leads with: plain sentences and rows computed from the report data.

What the first screen says, per measurement (rendered by :mod:`~pige_sym.report.html`):

- the verdict of ``pige check`` when tolerances were given;
- the PIGEs actually used for compensation: the primary estimate (by default the diagnosis'
  final fit, i.e. the PIGEs estimated jointly with the accepted effects);
- the main finding in one sentence: the effects found beyond the PIGEs (or that there are
  none) and the PIGE that matters most: with tolerances the one closest to its limit, else the
  one with the largest effect at the ball or sphere (value × the RMS sensitivity of that point to it over
  the trajectory, the identification's column scale);
- the improvement, labelled with its basis: *measured* (``--compare``), *simulated on a known
  truth* (truth sidecar) or *model-predicted*.  A model-predicted "after" is never shown as the
  compensation's own near-zero leftover: the expected result is the identification
  uncertainty propagated to the tool point combined with what the model leaves unexplained
  (``√(u² + r²)``), and the page says a measurement after compensation must confirm it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pige_sym.kernels import load_kernels
from pige_sym.report.data import UNIT_TEXT, MeasurementReport, ReportData
from pige_sym.report.gather import sobol_half_ranges
from pige_sym.report.words import vocabulary


@dataclass
class PigeRow:
    """One PIGE used for compensation, with its verdict when tolerances were given."""

    name: str
    value: float | None
    std: float | None
    unit: str
    limit: float | None = None
    status: str | None = None


@dataclass
class Improvement:
    """Before/after RMS [µm] with its basis: ``measured``, ``truth`` or ``model``."""

    basis: str
    label: str
    before_um: float
    after_um: float
    text: str


def pige_rows(rep: MeasurementReport) -> list[PigeRow]:
    """The machine's PIGEs in the primary estimate (the compensated values), with their check items."""
    res = rep.primary
    kern = load_kernels(rep.machine)
    items = {i.name: i for i in rep.check.items} if rep.check is not None else {}
    out = []
    for j, name in enumerate(res.parameters):
        if name not in kern.PARAMETERS:
            continue
        v, s = float(res.values[j]), float(res.std[j])
        item = items.get(name)
        out.append(PigeRow(name, v if math.isfinite(v) else None, s if math.isfinite(s) and math.isfinite(v) else None,
                           UNIT_TEXT.get(res.units.get(name, ""), res.units.get(name, "")),
                           None if item is None else item.limit, None if item is None else item.status))
    return out


#: Effects of the test set-up, not of the machine (named by :func:`pige_sym.diagnosis.results.effect_title`).
SETUP_EFFECTS = ("table_drift", "probe_trigger", "setup_offset", "pose_cluster")


def _effects_clause(rep: MeasurementReport) -> str:
    d = rep.diagnosis
    if d is None:
        return f"The diagnosis failed on these data ({rep.diagnosis_error})"
    found = [f for f in d.findings if f.effect != "outliers"]
    if not found:
        return (f"The PIGE model explains the measurement down to the noise (residual RMS "
                f"{d.final.rms_um:.2g} µm)")
    machine = [f.title() for f in found if f.effect not in SETUP_EFFECTS]
    setup = [f.title() for f in found if f.effect in SETUP_EFFECTS]
    parts = ([f"the machine shows {', '.join(machine)}"] if machine else []) + \
        ([f"the test set-up shows {', '.join(setup)}, fitted and kept out of the PIGEs"] if setup else [])
    return "Beyond the PIGEs " + "; ".join(parts)


def main_finding(rep: MeasurementReport) -> str:
    """One sentence: the effects found (or none) and the largest PIGE."""
    rows = [r for r in pige_rows(rep) if r.value is not None]
    clause = _effects_clause(rep)
    if not rows:
        return clause + "; no PIGE could be identified from these data."
    if any(r.limit for r in rows):
        worst = max((r for r in rows if r.limit), key=lambda r: abs(r.value or 0.0) / (r.limit or 1.0))
        share = abs(worst.value or 0.0) / (worst.limit or 1.0)
        tail = f", {share:.0%} of its {worst.limit:g} {worst.unit} limit"
    else:
        scale = {k: 1.0 / v for k, v in sobol_half_ranges(rep.measurement, 1.0).items()}
        worst = max(rows, key=lambda r: abs(r.value or 0.0) * scale.get(r.name, 1.0))
        tail = (f", about {abs(worst.value or 0.0) * scale.get(worst.name, 1.0):.2g} µm RMS at the "
                f"{vocabulary(rep.measurement).table_point}")
    what = "closest to its limit" if any(r.limit for r in rows) else "with the largest effect"
    return (f"{clause}; the PIGE {what} is {worst.name} = {worst.value:.3g} ± {worst.std or float('nan'):.2g} "
            f"{worst.unit}{tail}.")


def unexplained_rms_um(rep: MeasurementReport) -> float:
    """RMS over the measured points of ``|residual|`` of the primary fit [µm] (NaN without residuals)."""
    res = rep.primary.residuals_um
    if res.ndim != 2 or res.shape[0] < 2:
        return float("nan")
    return float(np.sqrt((res[1:] ** 2).sum(axis=1).mean()))


def improvement(rep: MeasurementReport, data: ReportData) -> Improvement:
    """The before/after the first screen shows, with its basis (module docstring)."""
    comp = data.comparison
    if comp is not None and comp.machine == rep.machine:
        return Improvement("measured", "measured", comp.rms_before_um, comp.rms_after_um,
                           f"RMS |d| {comp.rms_before_um:.3g} → {comp.rms_after_um:.3g} µm "
                           f"({comp.improvement:.0%} less), max {comp.max_before_um:.3g} → {comp.max_after_um:.3g} µm, "
                           "two measurements of the same program")
    row = rep.compensation[0]
    if rep.compensation_basis == "truth":
        return Improvement("truth", "simulated on a known truth", row.rmse_before_um, row.rmse_after_um,
                           f"tool-point RMSE {row.rmse_before_um:.3g} → {row.rmse_after_um:.3g} µm "
                           f"({row.reduction:.0%} less) on the measured trajectory, computed on a simulated machine "
                           "that has the known true errors")
    u = row.predicted_after_um
    r = unexplained_rms_um(rep)
    expected = math.sqrt((u if math.isfinite(u) else 0.0) ** 2 + (r if math.isfinite(r) else 0.0) ** 2)
    return Improvement("model", "model-predicted", row.rmse_before_um, expected,
                       f"tool-point RMSE {row.rmse_before_um:.3g} µm of the identified errors; after compensation "
                       f"about {expected:.2g} µm expected (identification uncertainty {u:.2g} µm ⊕ unexplained "
                       f"residual {r:.2g} µm): confirm with a measurement after compensation (pige compare)")
