"""``heidenhain``: TNC kinematics description table, deltas to the ``Trans`` rows around each ``MachAxis`` row.

The description table (HEIDENHAIN Technical Manual iTNC 530 HSCI, p. 722): each row has a ``KEY``;
``MachAxis`` "defines the point at which a machine axis becomes effective in the kinematics sequence.
From this entry onward, movements by the indicated axis ... change the positions of previously defined
axes or objects relative to subsequent axes or objects.  The start of the sequence is always the tool
reference point"; ``Trans`` performs "a transformation of the indicated axis (AXIS column) in the current
kinematics sequence by the value entered in the COORD column ... a linear translation as well as a rotation
about an axis".  So the rows act in sequence: tool reference point → head rows → linear axes → machine base
→ table rows → workpiece (the example of p. 670: ``Trans X, Trans Z, MachAxis B, MachAxis Y, MachAxis X,
MachBase, MachAxis Z, Trans X, Trans Y, MachAxis C``).

What the manual does not settle is the sign of a ``Trans`` row: whether COORD holds where the next element
lies relative to the previous one along the sequence (``position``, e.g. ``Trans Z +250`` for a pivot 250 mm
above the tool reference point, as the example on p. 670 reads for a swivel head) or the displacement of
the previous objects relative to the next (``shift``, every value negated).  The user states it
(``--heidenhain-trans``), from the rows of the own table that place a known pivot; without it pige refuses.

Layouts, both printed (closed at the reference pose: each side's rows out and back sum to zero; no rotation
row before these rows, so X, Y, Z are the machine's): *chained*, the rows between consecutive ``MachAxis``
rows hold the vector from one pivot to the next (δ_next − δ_previous), the rows after the last one lead back
(−δ); *per axis*, each rotary ``MachAxis`` row sits between its own rows out (δ) and back (−δ).  A
zero-position error E is a rotation row ``Trans <axis>`` directly before the ``MachAxis`` row (after the rows
that place it): −E in the ``position`` sense.  Axis tilts would need rotation rows around the axis: not
printed (not representable here).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import DEG_DECIMALS, MM_DECIMALS, axis_sense, signed, structure
from pige_sym.compensation.controllers.scope import positions_and_zeros, scope_lines
from pige_sym.compensation.controllers.tables.refused import heidenhain_lines
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError

TITLE = "HEIDENHAIN TNC kinematics description table (Trans rows around MachAxis rows)"
#: The options of ``pige compensate`` this controller reads (:func:`~pige_sym.compensation.controllers.check_options`).
OPTIONS = ("--heidenhain-trans",)
TRANS_SENSES = ("position", "shift")


def representable(params: CompensationParameters) -> list[str]:
    """Axis-line positions (Trans rows) and zero-position errors (rotation rows)."""
    return positions_and_zeros(params)


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """The Trans-row deltas in both layouts and the rotation rows (module docstring)."""
    if options.heidenhain_trans not in TRANS_SENSES:
        raise InputError("--controller heidenhain needs --heidenhain-trans position|shift: the iTNC 530 Technical "
                         "Manual (p. 722) does not settle the sign of a Trans row; look at the rows that place a pivot "
                         "you know (position: COORD = where it lies relative to the previous element)")
    st = structure(params, "HEIDENHAIN kinematics description")
    reversed_axes = [r["axis"] for r in st.table + st.head if axis_sense(params, r["axis"]) != 1]
    if reversed_axes:
        raise InputError(f"--controller heidenhain: axis {reversed_axes[0]} is commanded in the reverse sense; how a "
                         "description table reverses an axis is not settled by the manual: no entries printed")
    sign = 1.0 if options.heidenhain_trans == "position" else -1.0
    head_side = list(reversed(st.head))  # the sequence meets the head axes from the tool first
    out = [f"HEIDENHAIN kinematics description table of {params.machine}: DELTAS to add to COORD (Trans X/Y/Z rows "
           f"in mm, rotation rows in deg); parameters from {params.source}",
           "sequence (Technical Manual iTNC 530 HSCI, p. 722): tool reference point -> "
           + "".join(f"MachAxis {r['axis']} -> " for r in head_side)
           + "linear MachAxis rows, MachBase -> " + "".join(f"MachAxis {r['axis']} -> " for r in st.table)
           + "workpiece; closed at the reference pose, no rotation row ahead of these rows",
           f"--heidenhain-trans {options.heidenhain_trans}: a Trans row holds "
           + ("where the next element lies relative to the previous one" if sign > 0 else
              "the shift of the previous elements relative to the next one (the negative of their position)"),
           *scope_lines(params, "heidenhain", "", options)]
    for label, rows, start in (("head", head_side, "tool reference point"), ("table", st.table, "machine base")):
        if rows:
            out += _side(label, rows, start, sign)
    rotations = [f"Trans {r['axis']} {signed(-sign * r['zero_offset_deg'], DEG_DECIMALS)} deg"
                 for r in head_side + st.table]
    out.append("zero-position errors: a rotation row Trans <axis> directly before its MachAxis row (after the "
               "rows that place it): " + ", ".join(rotations))
    out.append("chain rebuilt from the manual in pige's tests (tests/test_controller_heidenhain.py), not run on a "
               "TNC: check the layout against your table and measure again (cycle 451)")
    return "\n".join(out + heidenhain_lines(params))


def map_motions(params: CompensationParameters) -> list[str]:
    """No error map: the nonlinear axis error compensation is refused (:mod:`.tables.refused`)."""
    return []


def _side(label: str, rows: list[dict[str, Any]], start: str, sign: float) -> list[str]:
    """Both layouts of one side's rows (head: from the tool; table: from the machine base)."""
    deltas = [np.array(r["pivot_delta_mm"]) for r in rows]
    names = [r["axis"] for r in rows]
    end = "tool reference point" if label == "head" else "workpiece"
    chained = [f"  Trans rows before MachAxis {names[0]} ({start} -> {names[0]}): {_xyz(sign * deltas[0])}"]
    for k in range(1, len(rows)):
        chained.append(f"  Trans rows between MachAxis {names[k - 1]} and MachAxis {names[k]} ({names[k - 1]} -> "
                       f"{names[k]}): {_xyz(sign * (deltas[k] - deltas[k - 1]))}")
    chained.append(f"  Trans rows after MachAxis {names[-1]} (back, {names[-1]} -> {end}): "
                   f"{_xyz(-sign * deltas[-1])}")
    if len(rows) == 1:
        return [f"{label} side:", *chained]
    per_axis = []
    for name, d in zip(names, deltas, strict=True):
        per_axis += [f"  Trans rows before MachAxis {name} (out): {_xyz(sign * d)}",
                     f"  Trans rows after MachAxis {name} (back): {_xyz(-sign * d)}"]
    return [f"{label} side, layout chained (Trans rows between consecutive MachAxis rows):", *chained,
            f"{label} side, layout per axis (each MachAxis row between its own Trans rows out and back):", *per_axis]


def _xyz(v: np.ndarray) -> str:
    return "  ".join(f"{a} {signed(x, MM_DECIMALS)}" for a, x in zip("XYZ", v, strict=True))
