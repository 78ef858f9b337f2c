"""``fanuc``: FANUC 30i/31i tool centre point control for 5-axis machining, rotation-axis parameters.

FANUC Series 30i-MODEL A, *Tool center point control for 5-axis machining*, Additional Manual A-79348E
(sheets cited as n/88), and the Connection Manual (Function) B-63943EN-1/02, p. 1099:

- No. 19680 (sheet 72/88): 2 = tool rotation type (two tool axes, the first the master carrying the
  second), 12 = table rotation type (likewise on the table), 21 = mixed (the first rotation axis is the
  tool's, the second the table's).  No. 19684 (sheet 75/88): 0 = a positive command turns clockwise seen from
  the negative towards the positive axis direction (right-handed), 1 = counterclockwise; "normally, 0 is
  set for a tool rotation axis, and 1 is set for a table rotation axis" (CONVENTIONS' senses, σ = +1).
- Table rotation type (sheet 59/88, 82/88): with both axes at 0°, the *rotary table position* is the vector
  from the machine origin to a point A on the first rotation axis, Nos. 19703–19705 the vector from A to a
  point B on the second.  So a table point x stands at ``A + R1 (AB + R2 (x − A − AB))``: the rotary table
  position changes by δ1, Nos. 19703–19705 by δ2 − δ1.  The parameter numbers of the rotary table position
  are not printed: the pages read do not show them.
- Tool rotation type (sheets 83/88, 84/88): point D on the tool axis lies at tool length + tool holder offset
  (No. 19666) from the tool tip; Nos. 19709–19711 are the vector from D to a point E on the second (slave)
  tool axis, Nos. 19712–19714 the vector from E to a point F on the first (master) axis, all with the tool
  axes at 0°.  The chain ends at F, the controlled point that the linear axes position; so the tool tip
  stands at ``F − R1 (EF + R2 (DE + (L + H) k))``: Nos. 19709–19711 change by δ2, Nos. 19712–19714 by −δ2.
  The master axis' own position errors would move the controlled point off its axis: no tool centre point
  parameter holds them (they belong to the machine's reference position): NOT representable.

Refused: the mixed type (No. 19680 = 21): its tool axis passes through the controlled point (only Nos.
19709–19711 on the tool side, sheet 83/88), so its position errors are not parameters, and the pages read
do not define the table axis' position for that type.  Zero-position errors: a rotary axis' reference
position is not a tool centre point parameter and its sign is not settled by these pages: not printed.
Axis tilts: the axis directions are discrete choices (No. 19682): not representable.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import MM_DECIMALS, Structure, axis_sense, signed, structure
from pige_sym.compensation.controllers.scope import scope_lines
from pige_sym.compensation.controllers.tables.refused import fanuc_lines
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

TITLE = "FANUC 30i/31i tool centre point control for 5-axis machining (No. 19680 = 12 or 2)"
#: The options of ``pige compensate`` this controller reads (:func:`~pige_sym.compensation.controllers.check_options`).
OPTIONS: tuple[str, ...] = ()


def _positions(params: CompensationParameters, axis: str) -> list[str]:
    kern = load_kernels(params.machine)
    return [n for n in kern.LOCATION_PARAMETERS if n.endswith("0" + axis) and kern.UNITS[n] == "um"]


def fanuc_structure(params: CompensationParameters) -> Structure:
    """The machine as FANUC's No. 19680 = 12 or 2 (the mixed type 21 refused: module docstring)."""
    st = structure(params, "FANUC tool centre point")
    if st.kind == "mixed":
        raise InputError(f"{params.machine}: FANUC mixed type (No. 19680 = 21): the tool axis passes through the "
                         "controlled point and the pages read (A-79348E) do not define the table axis' position for "
                         "this type: no parameters printed")
    return st


def representable(params: CompensationParameters) -> list[str]:
    """Table type: the four axis-line positions; tool type: the second (slave) axis' two positions."""
    st = fanuc_structure(params)
    rows = st.table if st.kind == "table" else st.head[1:]
    return [n for r in rows for n in _positions(params, r["axis"])]


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """The parameter changes as text (mm)."""
    st = fanuc_structure(params)
    first, second = (st.table if st.kind == "table" else st.head)
    side = st.kind
    rotation = {r["axis"]: (0 if r["side"] == "tool" else 1) if axis_sense(params, r["axis"]) == 1 else
                (1 if r["side"] == "tool" else 0) for r in (first, second)}
    head = [f"FANUC tool centre point for 5-axis machining of {params.machine}: DELTAS to add (mm); parameters "
            f"from {params.source}",
            f"No. 19680 = {12 if side == 'table' else 2} ({'table' if side == 'table' else 'tool'} rotation type): "
            "first (master) rotation axis "
            f"{first['axis']}, second (slave) {second['axis']}; rotation direction No. 19684 = "
            f"{rotation[first['axis']]}, No. 19689 = {rotation[second['axis']]} (the senses pige assumes; ordinary "
            "rotation axes, No. 19696 IA1 = IA2 = 0)",
            *scope_lines(params, "fanuc", "", options)]
    body = _table_type(first, second) if side == "table" else _tool_type(first, second)
    body.append("chain rebuilt from A-79348E in pige's tests (tests/test_controller_fanuc.py), not run on a FANUC "
                "control: measure again after entering")
    return "\n".join(head + body + fanuc_lines(params))


def map_motions(params: CompensationParameters) -> list[str]:
    """No error map: the pitch error compensation is refused (:mod:`.tables.refused`)."""
    return []


def _xyz(v: np.ndarray) -> list[str]:
    return [signed(x, MM_DECIMALS) for x in v]


def _table_type(first: dict[str, Any], second: dict[str, Any]) -> list[str]:
    d1 = np.array(first["pivot_delta_mm"])
    d12 = np.array(second["pivot_delta_mm"]) - d1
    x, y, z = _xyz(d1)
    a, b, c = _xyz(d12)
    return [f"  rotary table position (machine origin -> point A on {first['axis']}, A-79348E sheet 59/88): "
            f"X {x}  Y {y}  Z {z}",
            f"  No. 19703 {a}   No. 19704 {b}   No. 19705 {c}   (intersection offset vector {first['axis']} -> "
            f"{second['axis']}, sheet 82/88)"]


def _tool_type(first: dict[str, Any], second: dict[str, Any]) -> list[str]:
    d2 = np.array(second["pivot_delta_mm"])
    a, b, c = _xyz(d2)
    na, nb, nc = _xyz(-d2)
    return [f"  No. 19709 {a}   No. 19710 {b}   No. 19711 {c}   (D on the tool axis -> E on {second['axis']}, "
            "sheet 83/88; D stays where the tool length and the tool holder offset No. 19666 put it)",
            f"  No. 19712 {na}   No. 19713 {nb}   No. 19714 {nc}   (E on {second['axis']} -> F on "
            f"{first['axis']}, the controlled point, sheet 84/88)"]
