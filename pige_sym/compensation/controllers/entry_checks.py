"""Check before writing: what every controller's entries are made from, against physical bounds.

Every controller (:mod:`pige_sym.compensation.controllers`) and the NC rewrite (:mod:`pige_sym.compensation.program`)
make what they write from the parameters: the PIGEs and zero-position errors [µm, µrad], the nominal pivots
[mm] the corrected axis lines start from, and on head machines the tool vector [mm].  Before anything is
rendered they are held to the bounds the parameter file's reader holds them to
(:mod:`~pige_sym.measurements.schema`: ``MAX_PIGE``, ``MAX_POSITION_MM``), whatever built them (a file, a
result in memory, a script), and the pivots must belong to the machine's rotary axes.  Today's configuration
of a controller is checked by the controller that reads one (``check_current``, LinuxCNC's ``--current``).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable

from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels


def check_parameters(params: CompensationParameters) -> None:
    """Refuse a parameter set whose values no controller entry may be made from (module docstring).

    Raises
    ------
    InputError
        Naming the parameter source, the field, its value and the bound.
    """
    from pige_sym.measurements.schema import MAX_PIGE, MAX_POSITION_MM

    kern = load_kernels(params.machine)
    for name, value in params.values.items():
        unit = kern.UNITS.get(name, "")
        _bounded(params.source, f"parameters.{name}", [value], MAX_PIGE, unit)
    for axis, pivot in params.pivots_mm.items():
        if axis not in kern.ROTARY_AXES:
            raise InputError(f"{params.source}: pivots_mm.{axis}: not a rotary axis of {kern.MACHINE_CODE} (axes: "
                             f"{', '.join(kern.ROTARY_AXES)})")
        _bounded(params.source, f"pivots_mm.{axis}", pivot, MAX_POSITION_MM, "mm", length=3)
    if params.tool_mm is not None:
        _bounded(params.source, "tool_mm", params.tool_mm, MAX_POSITION_MM, "mm", length=3)


def _bounded(source: str, field: str, values: Iterable[object], bound: float, unit: str,
             length: int | None = None) -> None:
    items = list(values)
    if length is not None and len(items) != length:
        raise InputError(f"{source}: {field} has {len(items)} values: give {length} ({unit})")
    for v in items:
        number = float(v) if isinstance(v, numbers.Real) and not isinstance(v, bool) else math.nan
        if not abs(number) <= bound:
            raise InputError(f"{source}: {field} = {v!r:.40}: nothing is written for a controller from it (a finite "
                             f"number within ±{bound:g} {unit}); give the parameters of a machine")
