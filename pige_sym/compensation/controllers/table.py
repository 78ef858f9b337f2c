"""``table``: the corrected kinematic chain itself, controller-neutral (CONVENTIONS §2–3).

Per rotary axis, in the machine frame at the reference pose: side, corrected pivot [mm], corrected unit
direction and zero offset [deg], as :func:`~.axis_lines.controller_corrections` computes them.  Every
identified parameter is carried.
"""

from __future__ import annotations

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import controller_corrections, origin_pivots_note
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.kernels import load_kernels

TITLE = "corrected axis lines in the machine frame (no controller)"
#: The options of ``pige compensate`` this controller reads (:func:`~pige_sym.compensation.controllers.check_options`).
OPTIONS: tuple[str, ...] = ()


def representable(params: CompensationParameters) -> list[str]:
    """Every location and zero-position parameter."""
    kern = load_kernels(params.machine)
    position = [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]
    return position + [n for n in kern.PARAMETERS if n in kern.ZERO_PARAMETERS] + list(kern.LOCATION_PARAMETERS)


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """One line per rotary axis: side, pivot x, y, z [mm], direction, zero [deg]."""
    lines = [f"corrected kinematic chain of {params.machine} (machine frame, reference pose)",
             f"{'axis':<5}{'side':<11}{'pivot x,y,z [mm]':<36}{'direction':<40}zero [deg]"]
    for r in controller_corrections(params):
        piv = ", ".join(f"{x:.6f}" for x in r["pivot_mm"])
        dirs = ", ".join(f"{x:.9f}" for x in r["direction"])
        lines.append(f"{r['axis']:<5}{r['side']:<11}{piv:<36}{dirs:<40}{r['zero_offset_deg']:.7f}")
    note = origin_pivots_note(params)
    return "\n".join(lines + ([f"note: {note}"] if note else []))
