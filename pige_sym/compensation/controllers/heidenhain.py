"""``heidenhain``: TNC kinematics description table, deltas to the ``Trans`` rows before each ``MachAxis`` row.

In the description table each row has a ``KEY``; ``Trans`` rows translate along the axis named in ``AXIS``
by ``COORD``, and a ``MachAxis`` row is where a machine axis becomes effective in the chain (HEIDENHAIN
Technical Manual iTNC 530 HSCI, "description table" format, p. 722).
"""

from __future__ import annotations

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import NOT_VERIFIED, bed_first, direction_changes
from pige_sym.compensation.controllers.scope import positions_and_zeros, scope_lines
from pige_sym.compensation.parameters import CompensationParameters

TITLE = "HEIDENHAIN TNC kinematics description table"


def representable(params: CompensationParameters) -> list[str]:
    """Axis-line positions (Trans rows) and zero-position errors (axis datum)."""
    return positions_and_zeros(params)


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """Per rotary axis the X, Y, Z shift [mm] and the datum shift [deg]."""
    first, second = bed_first(params)
    head = [f"corrections for {params.machine} as DELTAS to the current kinematic description "
            f"(axis 1 = {first['axis']}, axis 2 = {second['axis']}); parameters from {params.source}", NOT_VERIFIED,
            *scope_lines(params, "heidenhain", "")]
    body = ["kinematics description table: add to COORD of the KEY = Trans rows (AXIS X, Y, Z) that place each "
            "rotary axis before its MachAxis row (mm), and to the axis datum (deg)"]
    for r in (first, second):
        d = r["pivot_delta_mm"]
        body.append(f"  {r['axis']}: X {d[0]:+.6f}  Y {d[1]:+.6f}  Z {d[2]:+.6f} mm   "
                    f"zero (axis datum) {r['zero_offset_deg']:+.7f} deg")
    orient = direction_changes((first, second))
    if orient:
        body.append("axis-direction changes (not expressible as offsets; enter only where the controller has an "
                    "axis-direction entry): " + "; ".join(orient))
    return "\n".join(head + body)
