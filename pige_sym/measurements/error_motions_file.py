"""The ``error_motions`` of a parameter file: error maps of rotary axes (CONVENTIONS §10), validated.

Format (what ``pige identify --map --json`` writes, and what a truth sidecar holds)::

    "error_motions": {
      "C": {"angle_deg": [0, 15, …], "full_turn": true,
            "EXC": {"value": [… or null], "std": [… or null], "unit": "um", "kind": "radial"}, …},
      "A": {…}}

- an axis is a rotary axis of the file's machine; ``angle_deg`` is strictly increasing and finite
  (|θ| ≤ 720); a ``full_turn`` grid (default: the C axes) lies within one turn;
- a motion is one of CONVENTIONS §10's names of that axis (``EXC EYC EZC EAC EBC ECC`` for C, ``EXA EYA EZA EBA
  ECA EAA`` for A, a number suffix kept: ``EXC2``), the reversal map ``ECC:reversal``, or φ per approach
  direction ``ECC+`` and ``ECC-`` (both or neither);
- ``value`` has one number or ``null`` (no value) per angle; ``std`` the same, not negative; both in ``unit``:
  CONVENTIONS' µm for a translation (``EXC``) and µrad for a rotation (``EAC``, ``ECC``, ``ECC+``, ``ECC:reversal``)
  when it is left out; a translation may be given in ``"mm"``, a rotation in ``"mrad"``, ``"rad"``, ``"deg"`` or
  ``"arcsec"`` and is converted (:data:`UNITS`); a length for a rotation, an angle for a translation or any other
  unit is refused, never taken as µm or µrad.  Converted, |v| ≤ MAX_PIGE;
- ``kind`` is informational.

The names are checked here by the rule of §10's table (translations E<X|Y|Z><axis>, rotations E<A|B|C><axis>);
:mod:`pige_sym.model.error_motions` holds the same table for the model.  The result is plain data, turned into
maps by :mod:`pige_sym.compensation.parameters`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pige_sym.constants import MAX_PIGE
from pige_sym.errors import FileFormatError

#: The units a map's values may be given in → (what they measure, factor to CONVENTIONS' µm or µrad).
UNITS: dict[str, tuple[str, float]] = {
    "um": ("length", 1.0), "µm": ("length", 1.0), "mm": ("length", 1000.0),
    "urad": ("angle", 1.0), "µrad": ("angle", 1.0), "mrad": ("angle", 1000.0), "rad": ("angle", 1e6),
    "deg": ("angle", math.pi / 180.0 * 1e6), "arcsec": ("angle", math.pi / 180.0 / 3600.0 * 1e6)}


def motion_names(axis: str) -> tuple[set[str], str]:
    """The names a map of ``axis`` may hold (§10 table, reversal, per direction) and φ's name."""
    letter, suffix = axis[0].upper(), axis[1:]
    names = {f"E{c}{letter}{suffix}" for c in "XYZABC"}
    phi = f"E{letter}{letter}{suffix}"
    return names | {phi + ":reversal", phi + "+", phi + "-"}, phi


def read_error_motions(data: dict[str, Any], path: str, kern: Any) -> dict[str, Any]:
    """Validate ``error_motions`` (module docstring); returns axis → ``{"angle_deg": (n,), "full_turn": bool,
    "value": {name: (n,)}, "std": {name: (n,)}}`` with NaN where a value or std is null."""
    out: dict[str, Any] = {}
    for axis, body in data.items():
        where = f"error_motions.{axis}"
        if axis not in kern.ROTARY_AXES:
            raise FileFormatError(path, None, f"{where}: not a rotary axis of {kern.MACHINE_CODE} "
                                  f"(axes: {', '.join(kern.ROTARY_AXES)})")
        if not isinstance(body, dict) or not isinstance(body.get("angle_deg"), list) or not body["angle_deg"]:
            raise FileFormatError(path, None, f"{where}: give angle_deg (a list of angles) and the motions' values")
        angles = np.array([_number(path, f"{where}.angle_deg[{i}]", a, 720.0) for i, a in enumerate(body["angle_deg"])])
        full = body.get("full_turn", axis[0].upper() == "C")
        if not isinstance(full, bool):
            raise FileFormatError(path, None, f"{where}.full_turn: expected true or false")
        if np.any(np.diff(angles) <= 0) or (full and angles[-1] - angles[0] >= 360.0):
            raise FileFormatError(path, None, f"{where}.angle_deg: the angles must increase"
                                  + (" and lie within one turn" if full else ""))
        known, phi = motion_names(axis)
        values: dict[str, np.ndarray] = {}
        stds: dict[str, np.ndarray] = {}
        for name, motion in body.items():
            if name in ("angle_deg", "full_turn"):
                continue
            if name not in known:
                raise FileFormatError(path, None, f"{where}.{name}: not an error motion of {axis} (CONVENTIONS §10: "
                                      f"{', '.join(sorted(known))})")
            values[name], stds[name] = _motion(path, f"{where}.{name}", motion, angles.size)
        if (phi + "+" in values) != (phi + "-" in values):
            raise FileFormatError(path, None, f"{where}: give both {phi}+ and {phi}- (or neither)")
        out[axis] = {"angle_deg": angles, "full_turn": full, "value": values, "std": stds}
    return out


def _number(path: str, where: str, value: Any, limit: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FileFormatError(path, None, f"{where}: expected a number")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v) or abs(v) > limit:
        within = f" within ±{limit:g}" if math.isfinite(limit) else ""
        raise FileFormatError(path, None, f"{where}: expected a finite number{within}")
    return v


def unit_factor(path: str, where: str, name: str, unit: Any) -> float:
    """The factor that turns a motion's values in ``unit`` into CONVENTIONS' µm or µrad (module docstring)."""
    measures = "length" if name[1] in "XYZ" else "angle"
    default = "um" if measures == "length" else "urad"
    if unit is None:
        return 1.0
    known = [u for u, (m, _) in UNITS.items() if m == measures and u[0] != "µ"]
    if not isinstance(unit, str) or UNITS.get(unit.strip(), ("", 0.0))[0] != measures:
        kind = "a translation" if measures == "length" else "a rotation"
        raise FileFormatError(path, None, f"{where}.unit: {unit!r:.40} is not the unit of {kind} ({name}, "
                              f"CONVENTIONS §10: {default}); give one of {', '.join(known)}, or leave it out for "
                              f"{default}")
    return UNITS[unit.strip()][1]


def _converted(path: str, where: str, value: Any, factor: float) -> float:
    """One value in CONVENTIONS' unit, within ±MAX_PIGE (the bound said in the file's unit too)."""
    v = _number(path, where, value, math.inf) * factor
    if not abs(v) <= MAX_PIGE:
        said = "" if factor == 1.0 else f" ({value!r:.20} x {factor:.6g})"
        raise FileFormatError(path, None, f"{where}: {v:.6g}{said} is beyond ±{MAX_PIGE:g} um or urad: no machine errs "
                              "that much; check the value and its unit")
    return v


def _motion(path: str, where: str, motion: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(motion, dict) or not isinstance(motion.get("value"), list):
        raise FileFormatError(path, None, f"{where}: expected an object with a value list")
    factor = unit_factor(path, where, where.rsplit(".", 1)[-1], motion.get("unit"))
    out = {}
    for key in ("value", "std"):
        seq = motion.get(key)
        if seq is None:
            out[key] = np.full(n, np.nan)
            continue
        if not isinstance(seq, list) or len(seq) != n:
            raise FileFormatError(path, None, f"{where}.{key}: expected {n} entries, one per angle (null: no value)")
        out[key] = np.array([np.nan if v is None else _converted(path, f"{where}.{key}[{i}]", v, factor)
                             for i, v in enumerate(seq)])
    if np.any(out["std"] < 0):
        raise FileFormatError(path, None, f"{where}.std: a standard error cannot be negative")
    return out["value"], out["std"]
