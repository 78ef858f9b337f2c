"""Check before writing: every controller entry against the same physical bounds and ``--max-change``.

Every controller (:mod:`pige_sym.compensation.controllers`) and the NC rewrite (:mod:`pige_sym.compensation.program`)
make what they write from the parameters: the PIGEs and zero-position errors [µm, µrad], the error maps [µm, µrad]
(CONVENTIONS §10), the nominal pivots [mm] the corrected axis lines start from, and on head machines the tool
vector [mm].  Before anything is rendered they are held to the bounds the parameter file's reader holds them to
(:mod:`~pige_sym.measurements.schema`: ``MAX_PIGE``, ``MAX_POSITION_MM``), whatever built them (a file, a result in
memory, a script), and the pivots must belong to the machine's rotary axes (:func:`check_parameters`).

A controller entry is a change of the machine's geometry, so each is also held to ``--max-change``
(:class:`ChangeLimits`: position errors against its millimetres, orientation errors and angles against its degrees,
as ``pige compensate`` holds the changes of an NC program): every PIGE and every map value before the work
(:func:`check_parameters`), and every value a table writes after it (:func:`check_entries`: LinuxCNC's
``COMP_FILE`` trims and its component's map pins, SINUMERIK's ``$AA_ENC_COMP``, ISG's ``kw.ssfk``), each in its own
unit.  A table's integer fields are held to the range its format gives them (:func:`check_integer`, the source
cited by the table's module).  Every refusal names where the value comes from, the field, the value and the bound.
Today's configuration of a controller is checked by the controller that reads one (``check_current``, LinuxCNC's
``--current``).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.constants import DEFAULT_MAX_CHANGE_DEG, DEFAULT_MAX_CHANGE_MM
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

#: One millimetre in µm, one degree in µrad.
UM_PER_MM = 1000.0
URAD_PER_DEG = math.pi / 180.0 * 1e6


@dataclass(frozen=True)
class ChangeLimits:
    """``--max-change MM,DEG``: the largest change an entry may make (position errors [mm], angles [deg])."""

    mm: float = DEFAULT_MAX_CHANGE_MM
    deg: float = DEFAULT_MAX_CHANGE_DEG

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mm) and math.isfinite(self.deg) and self.mm > 0 and self.deg > 0):
            raise InputError(f"--max-change {self.mm:g},{self.deg:g}: give two positive finite numbers, MM,DEG")

    def bound(self, unit: str) -> float:
        """The limit in ``unit`` (``mm``, ``um``, ``deg`` or ``urad``)."""
        return {"mm": self.mm, "um": self.mm * UM_PER_MM, "deg": self.deg, "urad": self.deg * URAD_PER_DEG}[unit]

    def text(self) -> str:
        return f"--max-change {self.mm:g},{self.deg:g} ({self.mm:g} mm, {self.deg:g} deg)"


def check_parameters(params: CompensationParameters, limits: ChangeLimits | None = None) -> None:
    """Refuse a parameter set whose values no controller entry may be made from (module docstring); with ``limits``
    every PIGE and every map value is held to ``--max-change`` too.

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
        if limits is not None and unit in ("um", "urad"):
            _within_change(params.source, f"parameters.{name}", [value], unit, limits)
    for axis, pivot in params.pivots_mm.items():
        if axis not in kern.ROTARY_AXES:
            raise InputError(f"{params.source}: pivots_mm.{axis}: not a rotary axis of {kern.MACHINE_CODE} (axes: "
                             f"{', '.join(kern.ROTARY_AXES)})")
        _bounded(params.source, f"pivots_mm.{axis}", pivot, MAX_POSITION_MM, "mm", length=3)
    if params.tool_mm is not None:
        _bounded(params.source, "tool_mm", params.tool_mm, MAX_POSITION_MM, "mm", length=3)
    if params.error_maps is not None:
        _check_maps(params, MAX_PIGE, limits)


def motion_unit(name: str) -> str:
    """The unit of a map motion (CONVENTIONS §10): ``um`` for a translation (``EXC``), ``urad`` for a rotation
    (``EAC``, ``ECC``, ``ECC+``, ``ECC:reversal``)."""
    return "um" if name[1] in "XYZ" else "urad"


def _check_maps(params: CompensationParameters, bound: float, limits: ChangeLimits | None) -> None:
    for axis, maps in params.error_maps.axes.items():
        angles = np.asarray(maps.grid.angles_deg, dtype=float)
        for name, values in maps.values.items():
            unit = motion_unit(name)
            field = f"error_motions.{axis}.{name}"
            v = np.asarray(values, dtype=float)
            over = np.flatnonzero(np.isfinite(v) & ~(np.abs(v) <= bound)) if v.size else np.array([], dtype=int)
            if over.size:
                i = int(over[0])
                raise InputError(f"{params.source}: {field} at {axis} {angles[i]:g} deg = {v[i]:.6g} {unit}: nothing "
                                 f"is written for a controller from it (a finite number within ±{bound:g} {unit}); "
                                 "check the map's unit")
            if limits is not None:
                _within_change(params.source, field, v, unit, limits, angles=angles, axis=axis)


def check_entries(where: str, field: str, values: Iterable[float], unit: str, limits: ChangeLimits | None,
                  angles: Iterable[float] | None = None, axis: str = "") -> None:
    """Refuse a table whose entries (``field``, in ``unit``: ``mm``, ``um``, ``deg`` or ``urad``) are not finite or
    beyond ``limits`` (module docstring); ``angles`` [deg] of ``axis`` name where each entry lies.

    Raises
    ------
    InputError
        Naming ``where`` (the table), the field, the entry, its value and the bound.
    """
    v = np.asarray(list(values), dtype=float)
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise InputError(f"{where}: {field}[{int(bad[0])}] = {v[bad[0]]!r}: not a number; nothing is written")
    if limits is not None:
        _within_change(where, field, v, unit, limits, angles=None if angles is None else np.asarray(list(angles)),
                       axis=axis)


def check_integer(where: str, field: str, values: Iterable[float], low: int, high: int, source: str,
                  fix: str) -> None:
    """Refuse an integer field of a table format (``values``: the numbers it would hold, rounded) outside ``[low,
    high]`` (``source``: the page that gives the range; ``fix``: what to change).

    Raises
    ------
    InputError
    """
    for v in values:
        if not low <= v <= high:
            raise InputError(f"{where}: {field} would be {float(v):.6g}, outside {low}..{high} ({source}): nothing is "
                             f"written; {fix}")


def _within_change(where: str, field: str, values: Iterable[float], unit: str, limits: ChangeLimits,
                   angles: np.ndarray | None = None, axis: str = "") -> None:
    bound = limits.bound(unit)
    v = np.array(list(values), dtype=float)
    over = np.flatnonzero(np.isfinite(v) & (np.abs(v) > bound))
    if not over.size:
        return
    i = int(over[0])
    at = f" at {axis} {angles[i]:g} deg" if angles is not None and i < angles.size else (
        f"[{i}]" if v.size > 1 else "")
    raise InputError(f"{where}: {field}{at} = {v[i]:+.6g} {unit} is beyond {limits.text()}: ±{bound:.6g} {unit}; "
                     "nothing is written for a controller: a change that large points to a wrong set-up or unit, not "
                     "to a drift to correct (check the values; give a larger --max-change only if the machine really "
                     "errs that much)")


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
