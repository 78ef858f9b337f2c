"""The changes a check-up says to enter: its PIGEs weighed by their uncertainty, within ``--max-change``.

The check-up's estimates ``x̂`` (its PIGEs only: the held ones are the full calibration's and are not re-entered)
are weighed as ``pige compensate`` weighs them (:func:`~pige_sym.compensation.weighing.entered_values`: what the
data do not show beyond their uncertainty is not entered, a well-determined value is entered as estimated).  A
change beyond ``--max-change`` (position errors in mm, orientation errors in degrees, as ``pige compensate
--max-change``) is not entered: a change that large is no drift to correct between calibrations, calibrate fully.
With ``--controller`` the entries are printed as ``pige compensate --controller`` prints them
(:func:`~pige_sym.compensation.controllers.format_controller`), the held PIGEs at 0 (not entered).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

UM_PER_MM = 1000.0
URAD_PER_DEG = math.pi / 180.0 * 1e6


@dataclass
class Changes:
    """What to enter [µm, µrad]: per PIGE the value (None: not entered), why, and the controller's text."""

    entered: dict[str, float | None]
    why: dict[str, str]
    controller: str | None = None
    controller_text: str = ""
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"entered": dict(self.entered), "why": dict(self.why), "controller": self.controller,
                "controller_text": self.controller_text or None, "notes": list(self.notes)}


def checkup_changes(fit: Any, m: Any, opts: Any) -> Changes:
    """The changes of a check-up fit (module docstring); ``opts`` a :class:`~.routine.CheckupOptions`."""
    from pige_sym.compensation.weighing import entered_values

    values = np.asarray(fit.values, dtype=float)
    weighed = entered_values(values, np.asarray(fit.covariance, dtype=float))
    max_mm, max_deg = opts.max_change
    entered: dict[str, float | None] = {}
    why: dict[str, str] = {}
    for name, x, c in zip(fit.parameters, values, weighed, strict=True):
        bound = max_mm * UM_PER_MM if fit.units[name] == "um" else max_deg * URAD_PER_DEG
        if abs(c) > bound:
            entered[name] = None
            why[name] = (f"not entered: {c:+.4g} {fit.units[name]} is beyond --max-change ({bound:.4g}): no drift to "
                         "correct between calibrations; calibrate fully")
        else:
            entered[name] = float(c)
            share = c / x if x else 0.0
            why[name] = ("not entered: within its uncertainty" if c == 0.0 else "entered as estimated"
                         if abs(share - 1.0) < 0.05 else f"entered in part ({share:.0%}): weakly determined")
    out = Changes(entered, why, opts.controller)
    if opts.controller:
        out.controller_text = _controller_text(fit, m, entered, opts)
    return out


def _controller_text(fit: Any, m: Any, entered: dict[str, float | None], opts: Any) -> str:
    """The entries as ``pige compensate --controller`` prints them, the held PIGEs not entered."""
    from pige_sym.compensation.controllers import format_controller
    from pige_sym.compensation.controllers.entry_checks import ChangeLimits
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.kernels import load_kernels

    kern = load_kernels(fit.machine)
    refused = [n for n, v in entered.items() if v is None]
    names = [n for n in fit.parameters if n not in refused]
    idx = [fit.parameters.index(n) for n in names]
    values = {n: float(fit.values[fit.parameters.index(n)]) if n in names else 0.0 for n in kern.LOCATION_PARAMETERS}
    params = CompensationParameters(
        kern.MACHINE_CODE, values, {n: kern.UNITS[n] for n in values},
        None if m.tool_mm is None else [float(x) for x in m.tool_mm],
        {a: [float(x) for x in v] for a, v in m.pivots_mm.items()}, m.path or "the check-up", [],
        axis_sense=dict(m.axis_sense), std={n: float(fit.std[fit.parameters.index(n)]) for n in names},
        covariance=(tuple(names), np.asarray(fit.covariance)[np.ix_(idx, idx)]),
        set_to_zero=[n for n in values if n not in names], ball_mm=[float(x) for x in m.ball_mm])
    return format_controller(params, opts.controller, carrier=opts.carrier, current=opts.current,
                             heidenhain_trans=opts.heidenhain_trans, limits=ChangeLimits(*opts.max_change))
