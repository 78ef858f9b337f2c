"""``siemens``: SINUMERIK 840D sl swivel data record ``$TC_CARR…[N]`` (TOOLCARRIER), as fine offsets.

The chain, per kinematics type ``$TC_CARR23`` (vectors in the machine frame with both rotary axes at
their initial setting):

- swivel table ``P``: l2 machine reference point → pivot of rotary axis 1, l3 pivot 1 → pivot 2,
  l4 = −(l2 + l3); a table point x stands at ``l2 + R1 (l3 + R2 (l4 + x))``;
- swivel head ``T``: l3 tool adapter → pivot of rotary axis 2, l2 pivot 2 → pivot 1, l1 = −(l2 + l3)
  ("vectors which describe offsets in the rotary head are positive in the direction from the tool tip to
  the reference point"); the tool tip stands at ``P − l1 − R1 (l2 + R2 (l3 + L))`` for the toolholder
  reference point P and the tool vector L (tip → adapter);
- mixed ``M``: l2 tool adapter → pivot of rotary axis 1 (the head), l1 = −l2; l3 machine reference point
  → pivot of rotary axis 2 (the table), l4 = −l3.

Ri turns about vi by the axis position minus its offset angle, right-handed ("counted positively for
clockwise rotation facing the direction of the rotation vector"); vi is the axis direction, reversed for an
axis that moves the workpiece.  So an axis line moved by δ changes the vectors that end or start at its
pivot (:func:`vector_changes`), a tilt changes vi by ±(u' − u), and a zero-position error E (the axis
stands at θ + E when θ is commanded, CONVENTIONS §3) needs the offset angle −σE (§9).  A positioning map's
``$AA_ENC_COMP`` table (:mod:`.tables.siemens_lec`) holds the map without E: both act on the machine axis position,
so E is entered once, by the offset angle, whether the table is entered or not.

Sources: SINUMERIK Operate (IM9) Commissioning Manual 03/2013, 6FC5397-1DP40-3BA1, 22.6 "Swiveling",
p. 502 (the three chains); Function Manual Tool Compensation (W1) 08/2005, 6FC5397-0BP10-0BA0,
pp. 2-88/2-89 (vector directions, the rotary table chain), p. 2-92 (sense of rotation) and p. 2-91 (fine
offsets = basic parameter + 40, added only with SD42974 ``$SC_TOCARR_FINE_CORRECTION`` = 1, limited by
MD20188 ``$MC_TOCARR_FINE_LIM_LIN`` and MD20190 ``$MC_TOCARR_FINE_LIM_ROT``).  "Rotary axis 2 is based on
rotary axis 1.  With mixed kinematics, rotary axis 1 is always the axis for the tool orientation"; "if the
... rotary axis moves the workpiece, the direction of motion of the axis and also the sign of the rotary
axis vector change" (840D sl IM9 Commissioning Manual, 21.7.2 "CYCLE800 checklist for the identification
of the machine kinematics").  Offset angles ``$TC_CARR24/25``: "the initial state of the associated rotary
axis is the position specified by the parameter" (840D sl Function Manual W1, "Rotary axis offset").
TRAORI reads ``$TC_CARR`` only with transformer type 72 (MD24582 ``$MC_TRAFO5_TCARR_NO_1``); types 24/40/56
take the vectors from the machine data of the correspondence table (IM9 Commissioning Manual 12/2017,
6FC5397-1DP40-6BA1, p. 572).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pige_sym.compensation.controllers import ControllerOptions, built_tables
from pige_sym.compensation.controllers.axis_lines import (
    DEG_DECIMALS,
    DIRECTION_DECIMALS,
    MM_DECIMALS,
    Structure,
    axis_sense,
    signed,
    structure,
)
from pige_sym.compensation.controllers.scope import positions_and_zeros, scope_lines
from pige_sym.compensation.controllers.tables.siemens_lec import LecTable, lec_tables
from pige_sym.compensation.controllers.tables.siemens_lec import check_format as lec_format
from pige_sym.compensation.controllers.tables.siemens_lec import entered_values as lec_values
from pige_sym.compensation.controllers.tables.siemens_lec import map_motions as map_motions
from pige_sym.compensation.controllers.tables.siemens_lec import render_lines as lec_lines
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

TITLE = "SINUMERIK 840D sl swivel data record $TC_CARR (fine offsets), kinematics types P, T, M"
#: The options of ``pige compensate`` this controller reads (:func:`~pige_sym.compensation.controllers.check_options`).
OPTIONS = ("--carrier", "--machine-axis")
#: $TC_CARR23 and the transformer type of TRAORI without the swivel data record (IM9 12/2017, p. 572).
KIND = {"table": ("P", 40), "head": ("T", 24), "mixed": ("M", 56)}
#: First basic parameter of each offset vector (its fine offset: + 40).
VECTOR = {"l1": 1, "l2": 4, "l3": 15, "l4": 18}
#: Machine data holding each vector for the transformer types 24/40/56 (IM9 12/2017, p. 572).
MACHINE_DATA = {
    "head": {"l1": "MD24500 $MC_TRAFO5_PART_OFFSET_1", "l2": "MD24560 $MC_TRAFO5_JOINT_OFFSET_1",
             "l3": "MD24550 $MC_TRAFO5_BASE_TOOL_1"},
    "table": {"l2": "MD24550 $MC_TRAFO5_BASE_TOOL_1", "l3": "MD24558 $MC_TRAFO5_JOINT_OFFSET_PART_1",
              "l4": "MD24500 $MC_TRAFO5_PART_OFFSET_1"},
    "mixed": {"l1": "MD24560 $MC_TRAFO5_JOINT_OFFSET_1", "l2": "MD24550 $MC_TRAFO5_BASE_TOOL_1",
              "l3": "MD24558 $MC_TRAFO5_JOINT_OFFSET_PART_1", "l4": "MD24500 $MC_TRAFO5_PART_OFFSET_1"},
}


def check_tables(params: CompensationParameters, options: ControllerOptions) -> None:
    """The ``$AA_ENC_COMP`` tables' machine axis names and grids, before any value is weighed (:mod:`.tables.
    siemens_lec`)."""
    lec_format(params, options.machine_axes)


def tables(params: CompensationParameters, options: ControllerOptions) -> list[LecTable]:
    """The ``$AA_ENC_COMP`` tables, built once (:func:`.tables.siemens_lec.lec_tables`; none without every mapped
    axis' machine name)."""
    return lec_tables(params, options.machine_axes, options.change_limits())


def representable(params: CompensationParameters) -> list[str]:
    """Axis-line positions (offset vectors) and zero-position errors (offset angles) as fine offsets."""
    return positions_and_zeros(params)


def base_data(params: CompensationParameters) -> list[str]:
    """The axis tilts: printed as changes of the direction vectors v1, v2 (base data, no fine offset)."""
    kern = load_kernels(params.machine)
    return [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "urad"]


def siemens_axes(st: Structure) -> tuple[dict[str, Any], dict[str, Any]]:
    """Rotary axis 1 and 2 in Siemens' sense (axis 2 is carried by axis 1; mixed: axis 1 on the head)."""
    if st.kind == "mixed":
        return st.head[0], st.table[0]
    rows = st.table if st.kind == "table" else st.head
    return rows[0], rows[1]


def vector_changes(st: Structure) -> dict[str, np.ndarray]:
    """Change of each offset vector [mm] for the axis-line shifts δ (module docstring)."""
    one, two = siemens_axes(st)
    d1, d2 = np.array(one["pivot_delta_mm"]), np.array(two["pivot_delta_mm"])
    if st.kind == "table":
        return {"l2": d1, "l3": d2 - d1, "l4": -d2}
    if st.kind == "head":
        return {"l1": -d1, "l2": d1 - d2, "l3": d2}
    return {"l1": -d1, "l2": d1, "l3": d2, "l4": -d2}


def entries(params: CompensationParameters, options: ControllerOptions | None) -> list[tuple[str, dict[str, float]]]:
    """The swivel data record's fine offsets (positions and zero offsets) and, when printed, the $AA_ENC_COMP tables
    (one value per angle for both directions)."""
    from pige_sym.compensation.controllers.scope import kinematic_values

    kinematic = kinematic_values(params, "siemens")
    maps = lec_values(params, built_tables(tables, params, options))
    out = [("the swivel data record", kinematic)]
    return out + [("the swivel data record and the $AA_ENC_COMP tables", kinematic | maps)] if maps else out


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """``$TC_CARR<k>[N]=$TC_CARR<k>[N]±value`` lines after ``;`` comments (module docstring)."""
    carrier = options.carrier
    if not isinstance(carrier, int) or carrier < 1:
        raise InputError("--carrier must be a positive integer")
    st = structure(params, "SINUMERIK swivel data record")
    one, two = siemens_axes(st)
    letter, _ = KIND[st.kind]
    vectors = vector_changes(st)
    offsets = {64: -axis_sense(params, one["axis"]) * one["zero_offset_deg"],
               65: -axis_sense(params, two["axis"]) * two["zero_offset_deg"]}
    lines = [f"; SINUMERIK swivel data record {carrier} of {params.machine}, kinematics type $TC_CARR23[{carrier}]="
             f"\"{letter}\": DELTAS as fine offsets; parameters from {params.source}",
             f"; rotary axis 1 = {one['axis']} (v1 $TC_CARR7..9, offset $TC_CARR24/64), rotary axis 2 = "
             f"{two['axis']} (v2 $TC_CARR10..12, offset $TC_CARR25/65); " + _chain_text(st.kind),
             "; offset angle = the axis position of the initial setting: -sigma*E for a zero-position error E; "
             f"commanded senses (CONVENTIONS §9): {_senses_text(params, (one, two))}",
             *_requirements(carrier, vectors, offsets),
             *scope_lines(params, "siemens", "; ", options),
             "; chain rebuilt from the manuals in pige's tests (tests/test_controller_siemens.py), not run on a "
             "SINUMERIK: enter with the fine-offset limits active and measure again"]
    for name, change in vectors.items():
        first = VECTOR[name] + 40
        lines += [f"$TC_CARR{first + k}[{carrier}]=$TC_CARR{first + k}[{carrier}]{signed(change[k], MM_DECIMALS)}"
                  for k in range(3)]
    lines += [f"$TC_CARR{k}[{carrier}]=$TC_CARR{k}[{carrier}]{signed(v, DEG_DECIMALS)}" for k, v in offsets.items()]
    return "\n".join(lines + _base_and_machine_data(params, st, carrier, vectors)
                     + lec_lines(params, options.machine_axes, options.change_limits(),
                                 built_tables(tables, params, options)))


def _senses_text(params: CompensationParameters, rows: tuple[dict[str, Any], ...]) -> str:
    return ", ".join(f"{r['axis']} sigma={axis_sense(params, r['axis']):+d}" for r in rows)


def _chain_text(kind: str) -> str:
    return {"table": "swivel table: l2 machine reference point -> pivot 1, l3 pivot 1 -> pivot 2, l4 = -(l2 + l3)",
            "head": "swivel head: l3 tool adapter -> pivot 2, l2 pivot 2 -> pivot 1, l1 = -(l2 + l3)",
            "mixed": "mixed: l2 tool adapter -> pivot 1 (head), l1 = -l2; l3 machine reference point -> pivot 2 "
                     "(table), l4 = -l3"}[kind] + " (IM9 Commissioning Manual 6FC5397-1DP40-3BA1, p. 502)"


def _requirements(carrier: int, vectors: dict[str, np.ndarray], offsets: dict[int, float]) -> list[str]:
    lin = max(float(np.abs(v).max()) for v in vectors.values())
    rot = max(abs(v) for v in offsets.values())
    return [f"; requires: TRAORI with transformer type 72 (MD24100 $MC_TRAFO_TYPE_1 = 72) reading this record "
            f"(MD24582 $MC_TRAFO5_TCARR_NO_1 = {carrier}); types 24/40/56 ignore $TC_CARR (see the end)",
            f"; requires: SD42974 $SC_TOCARR_FINE_CORRECTION = 1 (else the fine offsets are not added), MD20188 "
            f"$MC_TOCARR_FINE_LIM_LIN >= {lin:.{MM_DECIMALS}f} mm and MD20190 $MC_TOCARR_FINE_LIM_ROT >= "
            f"{rot:.{DEG_DECIMALS}f} deg "
            "(W1 Function Manual 6FC5397-0BP10-0BA0, p. 2-91)"]


def _base_and_machine_data(params: CompensationParameters, st: Structure, carrier: int,
                           vectors: dict[str, np.ndarray]) -> list[str]:
    """The direction vectors (base data) and the machine data of the types 24/40/56, as comments."""
    one, two = siemens_axes(st)
    out = []
    if any(np.abs(r["direction_delta"]).max() > 0 for r in (one, two)):
        out.append("; axis directions: no fine offset exists ($TC_CARR47..54 are not defined); change the base "
                   "vectors only as their owner; Siemens' sign: reversed for an axis that moves the workpiece")
        for first, row in ((7, one), (10, two)):
            s = axis_sense(params, row["axis"]) * (-1 if row["side"] == "workpiece" else 1)
            out += [f"; $TC_CARR{first + k}[{carrier}]=$TC_CARR{first + k}[{carrier}]"
                    f"{signed(s * row['direction_delta'][k], DIRECTION_DECIMALS)}" for k in range(3)]
    _, trafo = KIND[st.kind]
    changes = "; ".join(f"{name} -> {md} ({', '.join(signed(x, MM_DECIMALS) for x in vectors[name])})"
                        for name, md in MACHINE_DATA[st.kind].items())
    out.append(f"; transformer type {trafo} instead of 72 (geometry in machine data, correspondence table of the IM9 "
               f"Commissioning Manual 6FC5397-1DP40-6BA1, p. 572): add {changes}; pige cannot write the offset "
               "angles there")
    return out
