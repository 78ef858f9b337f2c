"""One answer per file: the estimate compensation uses, and where it differs from the PIGE-only fit.

``pige identify`` fits the PIGEs alone; ``pige check`` and ``pige compensate --params diagnosis.json`` use the
diagnosis' final fit (the PIGEs estimated jointly with the effects it accepted).  When the PIGE model misses an
effect the two disagree, and the PIGE-only fit is the biased one.  The report says so, per PIGE:

- a PIGE *moved* when ``|used − PIGE-only| > √(u_used² + u_PIGE-only²)``, its combined standard uncertainty
  (the two fits share the data, so the difference's own uncertainty is smaller: a PIGE named here moved by
  at least that much, and none is named for a shift within the noise of either fit);
- the model check of the PIGE-only fit (:mod:`pige_sym.identification.model_check`): a residual well above
  the noise says the PIGE-only fit misses something, and the next step is ``pige diagnose``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pige_sym.kernels import load_kernels
from pige_sym.report.data import UNIT_TEXT, MeasurementReport
from pige_sym.report.html_blocks import esc, num, path_html, table


@dataclass
class Shift:
    """One PIGE in the estimate used for compensation and in the PIGE-only fit [µm or µrad]."""

    name: str
    unit: str
    used: float
    used_std: float
    pige_only: float
    pige_only_std: float

    @property
    def difference(self) -> float:
        return self.used - self.pige_only

    @property
    def combined_std(self) -> float:
        return math.hypot(self.used_std, self.pige_only_std)

    @property
    def moved(self) -> bool:
        """True when the two estimates differ by more than their combined standard uncertainty."""
        return all(map(math.isfinite, (self.used, self.pige_only, self.combined_std))) and \
            abs(self.difference) > self.combined_std


def shifts(rep: MeasurementReport) -> list[Shift]:
    """Every PIGE of the machine in the estimate used and in the Gauss–Newton PIGE-only fit (empty when the
    estimate used is that fit)."""
    used, only = rep.primary, rep.identification["gauss-newton"]
    if used is only:
        return []
    out = []
    for name in load_kernels(rep.machine).PARAMETERS:
        if name not in used.parameters or name not in only.parameters:
            continue
        i, j = used.parameters.index(name), only.parameters.index(name)
        unit = used.units.get(name, "")
        out.append(Shift(name, UNIT_TEXT.get(unit, unit), float(used.values[i]), float(used.std[i]),
                         float(only.values[j]), float(only.std[j])))
    return out


def used_label(rep: MeasurementReport) -> str:
    """What the estimate used for compensation is, in words."""
    if rep.primary_method != "diagnosis" or rep.diagnosis is None:
        return f"the {rep.primary_method} fit of the PIGEs alone"
    found = [f.title() for f in rep.diagnosis.findings if f.effect != "outliers"]
    return ("the diagnosis' final fit: the PIGEs estimated jointly with " + ", ".join(found) if found
            else "the diagnosis' final fit (no effect accepted: the PIGE-only model)")


def differs_sentence(rep: MeasurementReport) -> str:
    """One sentence: where the estimate used differs from the PIGE-only fit ("" when it is that fit)."""
    moved = [s for s in shifts(rep) if s.moved]
    if not shifts(rep):
        return ""
    if not moved:
        return "It agrees with the PIGE-only fit within their combined uncertainty for every PIGE."
    parts = [f"{s.name} by {s.difference:+.3g} {s.unit} ({abs(s.difference) / s.combined_std:.1f}× their combined "
             "uncertainty)" for s in sorted(moved, key=lambda s: -abs(s.difference) / s.combined_std)]
    return ("It differs from the PIGE-only fit (pige identify) by more than their combined uncertainty in "
            + "; ".join(parts) + ": the PIGE-only fit is biased by what it does not model.")


def differs_short_html(rep: MeasurementReport) -> str:
    """The first screen's line, HTML: which PIGEs the estimate used moved from the PIGE-only fit ("" when none); the
    file name may wrap after ``_ - /`` (a long name must not widen the page)."""
    moved = [s.name for s in shifts(rep) if s.moved]
    if not moved:
        return ""
    return (esc(f"Differs from the PIGE-only fit (pige identify) in {', '.join(moved)}, by more than their combined "
                "uncertainty (section ") + path_html(rep.path.name) + ", Identified PIGEs).")


def estimate_used_html(rep: MeasurementReport) -> str:
    """The head of the report's "Identified PIGEs": the estimate used, the model check, the PIGEs that moved."""
    parts = [f"<p><b>Used for compensation and for the verdict:</b> {esc(used_label(rep))}. "
             f"{esc(differs_sentence(rep))}</p>"]
    chk = rep.model_check
    if chk is not None:
        cls = "bad" if chk.flagged else ""
        what = ("the PIGE-only fit leaves a residual well above the noise: the PIGE model misses something"
                if chk.flagged else "the PIGE-only fit explains the data down to the noise")
        p = "< 1e-15" if chk.p_value < 1e-15 else f"= {chk.p_value:.2g}"
        parts.append(f'<p data-model-check="{"flagged" if chk.flagged else "explained"}"><b>Model check:</b> '
                     f'<span class="{cls}">{esc(what)}</span> <small>' + esc(
                         f"(residual σ {chk.sigma_um:.3g} µm = {math.sqrt(chk.ratio):.2g} × the noise "
                         f"{chk.noise_um:.3g} µm, {chk.noise_source}; p {p}, flagged below p = 0.001"
                         + (f"; next step: {chk.next_step}" if chk.flagged else "") + ")") + "</small></p>")
    rows = [[f"<b>{esc(s.name)}</b>", num(s.used), num(s.used_std), num(s.pige_only), num(s.pige_only_std),
             num(s.difference, "+.3f"), num(s.combined_std), esc(s.unit), "moved" if s.moved else "—"]
            for s in shifts(rep)]
    if rows:
        parts.append("<details><summary>the estimate used against the PIGE-only fit, per PIGE</summary>"
                     + table(["PIGE", "used", "std", "PIGE-only", "std", "difference", "combined std", "unit",
                              "moved"], rows, num_cols=[1, 2, 3, 4, 5, 6]) + "</details>")
    return "\n".join(parts)
