"""``fanuc``: FANUC 30i/31i tool centre point for 5-axis machining, rotation-axis parameters.

Table rotation type (No. 19680 = 12): the rotary table position (machine origin → a point on the first,
master rotation axis) and the intersection offset vector Nos. 19703–19705 (that point → a point on the
second axis), machine coordinates with every rotary axis at 0° (FANUC Series 30i-MODEL A, Tool center
point control for 5-axis machining, Additional Manual A-79348E, sheets 59/88 and 82/88).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import NOT_VERIFIED, bed_first, direction_changes
from pige_sym.compensation.controllers.scope import positions_and_zeros, scope_lines
from pige_sym.compensation.parameters import CompensationParameters

TITLE = "FANUC 30i/31i tool centre point control, rotation-axis parameters"


def representable(params: CompensationParameters) -> list[str]:
    """Axis-line positions and zero-position errors."""
    return positions_and_zeros(params)


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """The parameter changes as text (mm, deg)."""
    first, second = bed_first(params)
    head = [f"corrections for {params.machine} as DELTAS to the current kinematic description "
            f"(axis 1 = {first['axis']}, axis 2 = {second['axis']}); parameters from {params.source}", NOT_VERIFIED,
            *scope_lines(params, "fanuc", "")]
    body = _table_type(first, second) if first["side"] == second["side"] == "workpiece" else _generic(first, second)
    orient = direction_changes((first, second))
    if orient:
        body.append("axis-direction changes (not expressible as offsets; enter only where the controller has an "
                    "axis-direction entry): " + "; ".join(orient))
    return "\n".join(head + body)


def _table_type(first: dict[str, Any], second: dict[str, Any]) -> list[str]:
    d1 = np.array(first["pivot_delta_mm"])
    d12 = np.array(second["pivot_delta_mm"]) - d1
    return [f"tool centre point, table rotation type (No. 19680 = 12): first (master) rotation axis "
            f"{first['axis']}, second {second['axis']}; add (mm):",
            f"  rotary table position (point on the {first['axis']} axis): X {d1[0]:+.6f}  Y {d1[1]:+.6f}  "
            f"Z {d1[2]:+.6f}",
            f"  No. 19703 {d12[0]:+.6f}   No. 19704 {d12[1]:+.6f}   No. 19705 {d12[2]:+.6f}   "
            f"(intersection offset vector {first['axis']} -> {second['axis']})",
            f"  zero offsets (axis reference positions, not tool centre point parameters): "
            f"{first['axis']} {first['zero_offset_deg']:+.7f} deg, {second['axis']} "
            f"{second['zero_offset_deg']:+.7f} deg"]


def _generic(first: dict[str, Any], second: dict[str, Any]) -> list[str]:
    out = ["tool centre point parameters: add to the rotation-axis centre / offset entries (mm, deg)"]
    for r in (first, second):
        d = r["pivot_delta_mm"]
        out.append(f"  {r['axis']}: centre dX {d[0]:+.6f}  dY {d[1]:+.6f}  dZ {d[2]:+.6f} mm   "
                   f"angle offset {r['zero_offset_deg']:+.7f} deg")
    return out
