"""What to do when the prediction says the correction may not help, and which values cannot be entered (and why);
why each value is entered as it is: :mod:`~pige_sym.compensation.entry_words`.

**Advice on the prediction** (:func:`advice`): when the 95 % bound of the error after the correction is above the
error expected without it (the estimates are too uncertain over the judged poses to be sure the correction helps),
and when entering more values gives a wider 95 % bound than entering fewer (every estimate against the weighed
values, or a controller's fuller way of entering against a smaller one).

**Values without a number** (:func:`undetermined_values`): a PIGE the parameter file gives no value (set to 0 by
``--allow-missing``) and the grid angles of a map without a value are not entered, so not corrected; each is named
with why and what would determine it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from pige_sym.compensation.result import Undetermined

if TYPE_CHECKING:
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.compensation.result import EntryChoice
    from pige_sym.compensation.weighing import Weighing

def advice(weighing: Weighing, choices: Sequence[EntryChoice] = ()) -> list[str]:
    """Advice in plain words on the predicted errors (module docstring); empty when there is nothing to say."""
    p = weighing.predicted
    none, after, every = p.get("none"), p.get("entered"), p.get("all_estimates")
    out = []
    if none is not None and after is not None and after.p95_um > none.expected_um:
        out.append(f"the 95 % bound of the error after this correction ({after.p95_um:.2f} um) is above the error "
                   f"expected without it ({none.expected_um:.2f} um) over {weighing.judged_on}: the estimates are "
                   "too uncertain there to be sure the correction helps; measure again with more poses or setups "
                   "over that range (or enter it and measure to confirm before relying on it)")
    if every is not None and after is not None and every.p95_um > after.p95_um * 1.01 and _differs(weighing):
        out.append(f"entering every estimate as it is (--enter all) would give a wider 95 % bound ({every.p95_um:.2f} "
                   f"um) than the weighed values ({after.p95_um:.2f} um): entering more is not better here; keep "
                   "the weighed values")
    ranked = [c for c in choices if c.predicted is not None]
    for small in ranked:
        for big in ranked:
            if (big is not small and set(small.values) < set(big.values)
                    and big.predicted.p95_um > small.predicted.p95_um * 1.01):  # type: ignore[union-attr]
                out.append(f"entering {big.label} gives a wider 95 % bound ({big.predicted.p95_um:.2f} um) than "  # type: ignore[union-attr]
                           f"{small.label} alone ({small.predicted.p95_um:.2f} um): the values it adds are too "  # type: ignore[union-attr]
                           f"uncertain to help over {weighing.judged_on}; enter {small.label}")
    return out


def _differs(weighing: Weighing) -> bool:
    """Some value is entered other than as estimated."""
    return any(v is not None and v != weighing.estimate.get(n) for n, v in weighing.entered.items())


def undetermined_values(params: CompensationParameters) -> list[Undetermined]:
    """The values the parameter file gives no number: not entered, so not corrected (module docstring)."""
    out = [Undetermined(n, "the parameter file gives it no value: the measurements do not determine it (pige "
                           "identify says which combination and why)",
                        "it is not corrected (set to 0 by --allow-missing); to correct it, measure so that it is "
                        "determined (the identification's remedy) and compensate again") for n in params.set_to_zero]
    maps = params.error_maps
    if maps is None:
        return out
    for axis, m in maps.axes.items():
        for motion, values in m.values.items():
            empty = [f"{a:g}" for a, v in zip(m.grid.angles_deg, np.asarray(values, dtype=float), strict=True)
                     if not np.isfinite(v)]
            if empty:
                out.append(Undetermined(f"{axis}:{motion}", f"no value at {axis} {', '.join(empty)}°: the "
                                        "measurements do not determine it there (the parameter file's "
                                        "map_undetermined says why)",
                                        "nothing is corrected there (a map without a value adds nothing); measure "
                                        "what map_undetermined names and compensate again"))
    return out

