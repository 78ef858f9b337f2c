"""``siemens``: SINUMERIK 840D sl swivel data record ``$TC_CARR…[N]``, written as fine offsets.

Fine offsets ``$TC_CARR41…65`` correct the basic parameters ``$TC_CARR1…25`` one for one (index + 40):
SINUMERIK 828D Basic Functions, Function Manual 09/2011, 6FC5397-0BP40-2BA0, W1 18.6, p. 1503.  Swivel
table chain l2 (machine reference point → pivot of axis 1), l3 (pivot 1 → pivot 2), l4 = −(l2 + l3):
SINUMERIK Operate (IM9) Commissioning Manual 03/2013, 6FC5397-1DP40-3BA1, 22.6 "Swiveling", p. 502.
"""

from __future__ import annotations

import numpy as np

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import bed_first, direction_changes, signed
from pige_sym.compensation.controllers.scope import positions_and_zeros, scope_lines
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError

TITLE = "SINUMERIK 840D sl swivel data record $TC_CARR (fine offsets)"
CAVEAT = ("offset vectors: SINUMERIK swivel-table chain l2, l3, l4 = -(l2 + l3) and fine offsets = basic "
          "parameter + 40 (Siemens manuals cited in docs/controller-corrections.md); the sign of the offset "
          "angles $TC_CARR64/65 is NOT verified on a controller: check it against the machine")


def representable(params: CompensationParameters) -> list[str]:
    """Axis-line positions (offset vectors) and zero-position errors (offset angles)."""
    return positions_and_zeros(params)


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """``$TC_CARR<k>[N]=$TC_CARR<k>[N]±value`` lines after ``;`` comments."""
    carrier = options.carrier
    if not isinstance(carrier, int) or carrier < 1:
        raise InputError("--carrier must be a positive integer")
    first, second = bed_first(params)
    head = [f"corrections for {params.machine} as DELTAS to the current kinematic description "
            f"(axis 1 = {first['axis']}, axis 2 = {second['axis']}); parameters from {params.source}", CAVEAT,
            *(ln.removeprefix("; ") for ln in scope_lines(params, "siemens", "; "))]
    d1, d2 = np.array(first["pivot_delta_mm"]), np.array(second["pivot_delta_mm"])
    vec = {44: d1, 55: d2 - d1, 58: -d2}  # fine offsets of l2 ($TC_CARR4..6), l3 (15..17), l4 (18..20)
    body = []
    for start, v in sorted(vec.items()):
        body += [f"$TC_CARR{start + k}[{carrier}]=$TC_CARR{start + k}[{carrier}]{signed(v[k], 6)}" for k in range(3)]
    body.append(f"$TC_CARR64[{carrier}]=$TC_CARR64[{carrier}]{signed(first['zero_offset_deg'], 7)}")
    body.append(f"$TC_CARR65[{carrier}]=$TC_CARR65[{carrier}]{signed(second['zero_offset_deg'], 7)}")
    orient = direction_changes((first, second))
    if orient:
        body.append("; axis-direction changes (not expressible as offsets; enter only where the controller has an "
                    "axis-direction entry): " + "; ".join(orient))
    return "\n".join(["; " + h for h in head] + body)
