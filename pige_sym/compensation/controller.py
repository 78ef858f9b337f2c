"""Controller corrections: the corrected rotary axis lines, and their rendering per controller.

:func:`controller_corrections` gives per rotary axis the corrected pivot [mm], unit direction and zero
offset [deg] in the machine frame; :func:`format_controller` writes them in the words of one controller
style (``CONTROLLER_STYLES``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pige_sym.compensation.parameters import CompensationParameters, kern_axes, kern_axes_names
from pige_sym.constants import CONTROLLER_STYLES as CONTROLLER_STYLES
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels


def controller_corrections(params: CompensationParameters) -> list[dict[str, Any]]:
    """Corrected axis lines: per rotary axis the pivot point [mm] and unit direction, machine frame."""
    kern = load_kernels(params.machine)
    out = []
    pos_idx = {"A": (1, 2), "B": (0, 2), "C": (0, 1)}
    for ax in kern.ROTARY_AXES:
        names = [n for n in kern.LOCATION_PARAMETERS if n.endswith("0" + ax)]
        vals = [params.values.get(n, 0.0) for n in names]
        d = "ABC".index(ax[0])
        u = np.eye(3)[d]
        pivot = np.asarray(params.pivots_mm.get(ax, [0.0, 0.0, 0.0]), dtype=float).copy()
        i1, i2 = pos_idx[ax[0]]
        pivot[i1] += vals[0] * 1e-3
        pivot[i2] += vals[1] * 1e-3
        eps = np.zeros(3)
        eps[i1], eps[i2] = vals[2] * 1e-6, vals[3] * 1e-6
        direction = u + np.cross(eps, u)
        direction /= np.linalg.norm(direction)
        zero = params.values.get(f"E{ax[0]}0{ax}", 0.0)
        side = "workpiece" if ax in kern.WORKPIECE_ROTARY else "tool"
        nominal = np.asarray(params.pivots_mm.get(ax, [0.0, 0.0, 0.0]), dtype=float)
        out.append({"axis": ax, "side": side, "pivot_mm": pivot.tolist(), "direction": direction.tolist(),
                    "zero_offset_deg": float(np.degrees(zero * 1e-6)),
                    "pivot_delta_mm": (pivot - nominal).tolist(), "direction_delta": (direction - u).tolist()})
    return out


NOT_VERIFIED = "NOT verified on a controller: check every value against the machine's documentation"
#: Siemens: the vector chain and the fine offsets are documented (docs/controller-corrections.md), the sign of
#: the offset angles relative to a zero-position error is not.
SIEMENS_CAVEAT = ("offset vectors: SINUMERIK swivel-table chain l2, l3, l4 = -(l2 + l3) and fine offsets = basic "
                  "parameter + 40 (Siemens manuals cited in docs/controller-corrections.md); the sign of the offset "
                  "angles $TC_CARR64/65 is NOT verified on a controller: check it against the machine")


def format_controller(params: CompensationParameters, style: str = "table", *, carrier: int = 1,
                      current: dict[str, float] | None = None) -> str:
    """The corrections as deltas to the machine's current kinematic description.

    Styles (units, signs and mappings in docs/controller-corrections.md): ``table`` (corrected
    axis lines, machine frame), ``siemens`` (``$TC_CARR`` *fine offsets* of swivel data record
    ``carrier``), ``heidenhain`` (kinematics-table deltas), ``fanuc`` (rotation-axis centre and
    direction deltas), ``linuxcnc`` (:func:`format_linuxcnc`: trt kinematics HAL pins, absolute with
    ``current``).  Every style also says what it enters, what it cannot represent and the tool-point
    error each choice leaves (:mod:`~pige_sym.compensation.controller_scope`).
    """
    rows = controller_corrections(params)
    if style == "table":
        lines = [f"corrected kinematic chain of {params.machine} (machine frame, reference pose)",
                 f"{'axis':<5}{'side':<11}{'pivot x,y,z [mm]':<36}{'direction':<40}zero [deg]"]
        for r in rows:
            piv = ", ".join(f"{x:.6f}" for x in r["pivot_mm"])
            dirs = ", ".join(f"{x:.9f}" for x in r["direction"])
            lines.append(f"{r['axis']:<5}{r['side']:<11}{piv:<36}{dirs:<40}{r['zero_offset_deg']:.7f}")
        return "\n".join(lines)
    if style not in CONTROLLER_STYLES:
        raise InputError(f"unknown controller style {style!r}: use {', '.join(CONTROLLER_STYLES)}")
    if not isinstance(carrier, int) or carrier < 1:
        raise InputError("--carrier must be a positive integer")
    if style == "linuxcnc":
        return format_linuxcnc(params, current)
    kern = load_kernels(params.machine)
    chain = [a.name for a in reversed(kern_axes(params.machine, "workpiece"))] + kern_axes_names(params.machine)
    by = {r["axis"]: r for r in rows}
    first, second = by[chain[0]], by[chain[1]]
    head = [f"corrections for {kern.MACHINE_CODE} as DELTAS to the current kinematic description "
            f"(axis 1 = {chain[0]}, axis 2 = {chain[1]}); parameters from {params.source}",
            SIEMENS_CAVEAT if style == "siemens" else NOT_VERIFIED]
    body = {"siemens": _siemens_fine, "heidenhain": _heidenhain, "fanuc": _fanuc}[style](first, second, carrier)
    orient = [f"{r['axis']}: direction change ({', '.join(f'{x:+.9f}' for x in r['direction_delta'])})"
              for r in (first, second) if np.abs(r["direction_delta"]).max() > 0]
    comment = "; " if style == "siemens" else ""
    from pige_sym.compensation.controller_scope import scope_lines

    head += [ln.removeprefix(comment) for ln in scope_lines(params, style, comment)]
    if orient:
        body.append(comment + "axis-direction changes (not expressible as offsets; enter only where the controller "
                    "has an axis-direction entry): " + "; ".join(orient))
    return "\n".join([comment + h for h in head] + body)


def _siemens_fine(first: dict, second: dict, carrier: int) -> list[str]:
    d1, d2 = np.array(first["pivot_delta_mm"]), np.array(second["pivot_delta_mm"])
    vec = {44: d1, 55: d2 - d1, 58: -d2}  # fine offsets of l2 ($TC_CARR4..6), l3 (15..17), l4 (18..20)
    out = []
    for start, v in sorted(vec.items()):
        out += [f"$TC_CARR{start + k}[{carrier}]=$TC_CARR{start + k}[{carrier}]{_signed(v[k], 6)}" for k in range(3)]
    out.append(f"$TC_CARR64[{carrier}]=$TC_CARR64[{carrier}]{_signed(first['zero_offset_deg'], 7)}")
    out.append(f"$TC_CARR65[{carrier}]=$TC_CARR65[{carrier}]{_signed(second['zero_offset_deg'], 7)}")
    return out


def _signed(value: float, decimals: int) -> str:
    """``+0.012000`` / ``-0.009000`` (no ``-0.000000``)."""
    return f"{round(float(value), decimals) + 0.0:+.{decimals}f}"


def _heidenhain(first: dict, second: dict, carrier: int) -> list[str]:
    # the description table's KEY = Trans rows (AXIS X/Y/Z, value in COORD) before each MachAxis row
    # (iTNC 530 HSCI Technical Manual, kinematics description table; docs/controller-corrections.md)
    out = ["kinematics description table: add to COORD of the KEY = Trans rows (AXIS X, Y, Z) that place each "
           "rotary axis before its MachAxis row (mm), and to the axis datum (deg)"]
    for r in (first, second):
        d = r["pivot_delta_mm"]
        out.append(f"  {r['axis']}: X {d[0]:+.6f}  Y {d[1]:+.6f}  Z {d[2]:+.6f} mm   "
                   f"zero (axis datum) {r['zero_offset_deg']:+.7f} deg")
    return out


def _fanuc(first: dict, second: dict, carrier: int) -> list[str]:
    if first["side"] == second["side"] == "workpiece":
        # FANUC Series 30i-A, Tool center point control for 5-axis machining (A-79348E): No. 19680 = 12
        # (table rotation type); the rotary table position is the vector from the machine origin to a point
        # on the first (master) rotation axis, Nos. 19703-19705 the vector from that point to a point on the
        # second rotation axis, machine coordinates, both axes at 0 deg
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
    out = ["tool centre point parameters: add to the rotation-axis centre / offset entries (mm, deg)"]
    for r in (first, second):
        d = r["pivot_delta_mm"]
        out.append(f"  {r['axis']}: centre dX {d[0]:+.6f}  dY {d[1]:+.6f}  dZ {d[2]:+.6f} mm   "
                   f"angle offset {r['zero_offset_deg']:+.7f} deg")
    return out


#: LinuxCNC trt kinematics module of each tilt axis (src/emc/kinematics/xyzac-trt-kins.c, xyzbc-trt-kins.c).
TRT_MODULES = {"A": "xyzac-trt-kins", "B": "xyzbc-trt-kins"}
#: Their HAL input pins (trtfuncs.c, trtKinematicsSetup).
TRT_PINS = ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset", "tool-offset",
            "conventional-directions")


def linuxcnc_trt_deltas(params: CompensationParameters) -> tuple[str, dict[str, float]]:
    """The trt kinematics module and the change of each of its HAL pins [mm] (controller_scope docstring).

    Raises
    ------
    InputError
        The machine is not a tilting rotary table with C on an A or B tilt axis.
    """
    kern = load_kernels(params.machine)
    axes = tuple(kern.ROTARY_AXES)
    tilt = next((a for a in axes if a[0] in "AB"), None)
    if kern.TOOL_ROTARY or tilt is None or "C" not in axes or len(axes) != 2:
        raise InputError(f"{kern.MACHINE_CODE}: LinuxCNC's trt kinematics describe a tilting rotary table (C on an "
                         "A or B tilt axis, xyzac-trt-kins / xyzbc-trt-kins); no mapping for this machine")
    v = {k: params.values.get(k, 0.0) * 1e-3 for k in kern.LOCATION_PARAMETERS}
    deltas = {"x-rot-point": v["EX0C"], "y-rot-point": v["EY0C"], "z-rot-point": 0.0}
    if tilt == "A":
        deltas |= {"y-offset": v["EY0A"] - v["EY0C"], "z-offset": v["EZ0A"]}
    else:
        deltas |= {"x-offset": v["EX0B"] - v["EX0C"], "z-offset": v["EZ0B"]}
    return TRT_MODULES[tilt], deltas


def format_linuxcnc(params: CompensationParameters, current: dict[str, float] | None = None) -> str:
    """LinuxCNC trt kinematics: ``setp`` lines with absolute values when ``current`` gives today's pin values,
    otherwise the change of each pin as a comment (HAL has no "add")."""
    from pige_sym.compensation.controller_scope import scope_lines

    module, deltas = linuxcnc_trt_deltas(params)
    out = [f"# LinuxCNC {module} (src/emc/kinematics/trtfuncs.c): HAL pins [mm], parameters from {params.source}",
           *scope_lines(params, "linuxcnc", "# ")]
    unknown = sorted(set(current or {}) - set(TRT_PINS))
    if unknown:
        raise InputError(f"--current {unknown[0]}: not a pin of {module} ({', '.join(TRT_PINS)})")
    for pin, d in deltas.items():
        if current is not None and pin in current:
            out.append(f"setp {module}.{pin} {current[pin] + d:.6f}")
        else:
            out.append(f"# {module}.{pin}: add {_signed(d, 6)} (give --current {pin}=VALUE,... or your HAL file "
                       "for the setp line)")
    return "\n".join(out)
