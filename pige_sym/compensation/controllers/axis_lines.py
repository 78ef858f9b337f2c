"""The corrected rotary axis lines that every controller's entries are made from, and shared text.

:func:`controller_corrections` gives per rotary axis the corrected pivot [mm], unit direction and zero
offset [deg] in the machine frame (CONVENTIONS §2–3); :func:`structure` sorts a machine's two rotary axes
into table and head axes (each bed first), which is what every controller's chain is written in;
:func:`signed` writes a signed value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.compensation.parameters import CompensationParameters, kern_axes, kern_axes_names
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

NOT_VERIFIED = "NOT verified on a controller: check every value against the machine's documentation"


def origin_pivots_note(params: CompensationParameters, current: str = "") -> str | None:
    """What is assumed of the axes the parameter file gives no ``pivots_mm`` for (a probe import that used the log's
    coordinates): their lines through the origin of the machine's (joint) coordinates, CONVENTIONS §2; ``current``
    says how the controller checks it; None when the file gives every axis' pivot."""
    missing = [a for a in load_kernels(params.machine).ROTARY_AXES if a not in params.pivots_mm]
    if not missing:
        return None
    lines = "line" if len(missing) == 1 else "lines"
    return (f"{params.source} has no pivots_mm for {', '.join(missing)} (the test was written or imported without "
            f"--pivot): the nominal axis {lines} of {', '.join(missing)} are taken through the joint origin (0, 0, 0 "
            "mm, CONVENTIONS §2), where the PIGEs were identified; if the machine's axis lines are elsewhere in its "
            "joint coordinates, identify from a test written with --pivot AXIS=x,y,z (pige program) before entering "
            "these values" + (f" ({current})" if current else ""))


def controller_corrections(params: CompensationParameters) -> list[dict[str, Any]]:
    """Corrected axis lines: per rotary axis the pivot point [mm] and unit direction, machine frame.

    Each row: ``axis``, ``side`` (``workpiece``/``tool``), ``pivot_mm`` (3,) [mm], ``direction`` (3,),
    ``zero_offset_deg`` [deg], ``pivot_delta_mm`` (3,) [mm] and ``direction_delta`` (3,) (``u' − u``).
    """
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


@dataclass(frozen=True)
class Structure:
    """The two rotary axes of a machine as the controllers' chains see them.

    Attributes
    ----------
    kind : str
        ``table`` (both axes move the workpiece), ``head`` (both move the tool) or ``mixed``.
    table : list of dict
        The workpiece-side rows of :func:`controller_corrections`, the axis nearest the bed first.
    head : list of dict
        The tool-side rows, the axis nearest the bed first (the last one nearest the tool).
    """

    kind: str
    table: list[dict[str, Any]]
    head: list[dict[str, Any]]


def structure(params: CompensationParameters, controller: str) -> Structure:
    """The machine's rotary axes sorted for a controller chain (:class:`Structure`).

    Raises
    ------
    InputError
        Not two rotary axes, or linear axes that move the workpiece or sit between the tool-side rotary
        axes (every chain written here has the linear axes carry the tool, before its rotary axes).
    """
    from pige_sym.codegen.machine_code import parse_machine_code

    st = parse_machine_code(params.machine)
    rotary = [a for a in st.workpiece_axes + st.tool_axes if a.kind == "rotary"]
    tool_kinds = [a.kind for a in st.tool_axes]
    if len(rotary) != 2:
        raise InputError(f"{params.machine}: {controller} entries are written for machines with two rotary axes, "
                         f"this one has {len(rotary)}")
    if any(a.kind == "linear" for a in st.workpiece_axes) or "rotary" in tool_kinds and (
            "linear" in tool_kinds[tool_kinds.index("rotary"):]):
        raise InputError(f"{params.machine}: {controller} entries assume that the linear axes carry the tool ahead "
                         "of its rotary axes; this machine moves a rotary axis with a linear axis")
    by = {r["axis"]: r for r in controller_corrections(params)}
    table = [by[a.name] for a in reversed(st.workpiece_axes) if a.kind == "rotary"]
    head = [by[a.name] for a in st.tool_axes if a.kind == "rotary"]
    kind = "table" if not head else "head" if not table else "mixed"
    return Structure(kind, table, head)


def axis_sense(params: CompensationParameters, axis: str) -> int:
    """σ of a rotary axis (CONVENTIONS §9): +1 unless the parameters state the controller's reverse sense."""
    return -1 if params.axis_sense.get(axis, 1) == -1 else 1


def bed_first(params: CompensationParameters) -> tuple[dict[str, Any], dict[str, Any]]:
    """The two rotary axes' rows, the one nearest the bed first (workpiece side outward, then tool side)."""
    by = {r["axis"]: r for r in controller_corrections(params)}
    chain = [a.name for a in reversed(kern_axes(params.machine, "workpiece"))] + kern_axes_names(params.machine)
    return by[chain[0]], by[chain[1]]


def direction_changes(rows: tuple[dict[str, Any], ...]) -> list[str]:
    """``C: direction change (+…, …)`` for each row whose direction changed."""
    return [f"{r['axis']}: direction change ({', '.join(f'{x:+.9f}' for x in r['direction_delta'])})"
            for r in rows if np.abs(r["direction_delta"]).max() > 0]


#: Decimals printed: 0.1 nm, 1e-8 deg (1.7e-10 rad) and 1e-10 of a direction vector, so that rounding the
#: printed entries moves a tool point 500 mm from a pivot by less than 1e-4 µm per entry.
MM_DECIMALS, DEG_DECIMALS, DIRECTION_DECIMALS = 7, 8, 10


def signed(value: float, decimals: int) -> str:
    """``+0.012000`` / ``-0.009000`` (no ``-0.000000``)."""
    return f"{round(float(value), decimals) + 0.0:+.{decimals}f}"
