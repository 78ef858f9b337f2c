"""The ``setp`` lines that enter the error maps into pige's LinuxCNC kinematics component.

The component (``pige gen --target linuxcnc``, :mod:`pige_sym.codegen.targets.linuxcnc`) holds per rotary axis a
uniform grid in the CONVENTIONS angle θ (``map-<axis>-start``, ``-step``, ``-nodes``, ``-full-turn``) and per node
seven slots: the six motions of CONVENTIONS §10 and the reversal φ⁺ − φ⁻ (pin names:
:mod:`pige_sym.codegen.targets.linuxcnc_pins`).  A map per direction (``ECC+``, ``ECC-``) enters as its mean and
its reversal; the direction of approach comes from the joint's velocity command, netted to ``vel-<axis>``.

Every slot of every node used gets a line: a motion the file has no map of, or a grid angle without a value, is
set to 0 with a comment (nothing corrected there, as the NC rewrite does), so no value set before stays in force.
The grid is set to 0 nodes first and to its size last, so a running machine never sees half a map.  A grid that is
not uniform, or larger than the component's ``MAP_NODES``, is refused with the reason, before any value is weighed
(:func:`check_format`); every value is held to ``--max-change`` in its unit (µm, µrad) before a line is printed
(:mod:`..entry_checks`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.codegen.targets import linuxcnc_pins as pins
from pige_sym.compensation.controllers.entry_checks import check_entries
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.model.error_motions import AxisMaps, axis_motions

#: Decimals of a map value [µm, µrad].
VALUE_DECIMALS = 4


def slot_values(axis_maps: AxisMaps) -> tuple[list[np.ndarray], list[str]]:
    """The seven slots' values at the grid angles (NaN: no value) and, per slot, what the file gives for it."""
    axis = axis_maps.grid.axis
    motions = axis_motions(axis, per_direction=True)
    n = axis_maps.grid.n
    by_kind = {m.kind: v for m, v in axis_maps.motion_values()}
    stored = {m.name: np.asarray(v, dtype=float) for m, v in axis_maps.motion_values()}
    out, said = [], []
    for m in motions:
        v = by_kind.get(m.kind) if m.kind in ("positioning", "reversal") else stored.get(m.name)
        out.append(np.full(n, np.nan) if v is None else np.asarray(v, dtype=float))
        said.append("not in the file: 0" if v is None else "from the file")
    return out, said


@dataclass(frozen=True)
class ComponentMap:
    """One axis' maps as the component's pins hold them (:func:`slot_values`), built once per run.

    Attributes
    ----------
    axis : str
    axis_maps : AxisMaps
    slots : tuple of (n,) arrays [µm, µrad]
        The seven slots' values at the grid angles (NaN: no value), in the component's slot order.
    said : tuple of str
        Per slot, what the file gives for it.
    """

    axis: str
    axis_maps: AxisMaps
    slots: tuple[np.ndarray, ...]
    said: tuple[str, ...]


def component_maps(params: CompensationParameters) -> list[ComponentMap]:
    """Every axis' maps as the component's pins hold them (module docstring)."""
    out = []
    for axis, axis_maps in (params.error_maps.axes.items() if params.error_maps is not None else ()):
        slots, said = slot_values(axis_maps)
        out.append(ComponentMap(axis, axis_maps, tuple(slots), tuple(said)))
    return out


def check_format(params: CompensationParameters) -> None:
    """Every axis' grid against what the component holds (module docstring), before any value is weighed."""
    for axis_maps in (params.error_maps.axes.values() if params.error_maps is not None else ()):
        grid_step(axis_maps)


def grid_step(axis_maps: AxisMaps) -> float:
    """The step [deg] of one axis' grid as the component's ``map-<axis>-step`` pin takes it.

    Raises
    ------
    InputError
        More grid angles than ``MAP_NODES``, or a grid that is not uniform.
    """
    g = axis_maps.grid
    axis = g.axis
    angles = np.asarray(g.angles_deg, dtype=float)
    if g.n > pins.MAP_NODES:
        raise InputError(f"{axis}: {g.n} grid angles; pige's LinuxCNC component holds at most {pins.MAP_NODES} per "
                         "axis (identify with a larger --map-step)")
    steps = np.diff(np.append(angles, angles[0] + 360.0) if g.full_turn else angles)
    if g.n > 1 and not np.allclose(steps, steps[0], rtol=0.0, atol=1e-9):
        raise InputError(f"{axis}: grid angles {', '.join(f'{x:g}' for x in angles)} are not equidistant"
                         + (" around the turn" if g.full_turn else "") + "; pige's LinuxCNC component takes a uniform "
                         "grid (start, step, nodes)")
    return float(steps[0]) if g.n > 1 else 1.0


def _grid_lines(name: str, axis_maps: AxisMaps) -> tuple[list[str], list[str]]:
    """(lines before the values, lines after them) that set one axis' grid."""
    g = axis_maps.grid
    a = g.axis.lower()
    angles = np.asarray(g.angles_deg, dtype=float)
    step = grid_step(axis_maps)
    before = [f"setp {name}.map-{a}-nodes 0", f"setp {name}.map-{a}-start {angles[0]:.10g}",
              f"setp {name}.map-{a}-step {step:.10g}", f"setp {name}.map-{a}-full-turn {int(bool(g.full_turn))}"]
    return before, [f"setp {name}.map-{a}-nodes {g.n}"]


def map_setp_lines(params: CompensationParameters, name: str, limits: Any = None,
                   maps: list[ComponentMap] | None = None) -> list[str]:
    """The comments and ``setp``/``net`` lines that enter every map of ``params`` into component ``name``; every
    value held to ``limits`` (:class:`~pige_sym.compensation.controllers.entry_checks.ChangeLimits`).  ``maps``: the
    slots as built (:func:`component_maps`; None: built here).

    Raises
    ------
    InputError
        A grid the component cannot hold (module docstring), or a value beyond ``limits``.
    """
    if params.error_maps is None:
        return []
    out = ["# error maps (CONVENTIONS §10) as pins of pige's kinematics component: it corrects the tool point for "
           "every motion (do not enter the COMP_FILEs as well: phi would be corrected twice)"]
    for cm in (maps if maps is not None else component_maps(params)):
        axis, axis_maps, values, said = cm.axis, cm.axis_maps, cm.slots, cm.said
        g = axis_maps.grid
        before, after = _grid_lines(name, axis_maps)
        stems = pins.map_slot_names(axis)
        out.append(f"# {axis}: {g.n} grid angles theta {g.angles_deg[0]:g}..{g.angles_deg[-1]:g} deg"
                   + (" (full turn, wraps)" if g.full_turn else " (end values hold outside)") + "; "
                   + ", ".join(f"{stem} {s}" for stem, s in zip(stems, said, strict=True)))
        out += before
        units = [m.unit for m in axis_motions(axis, per_direction=True)]
        for stem, v, unit in zip(stems, values, units, strict=True):
            check_entries(f"pige's LinuxCNC component {name}", f"{stem} pins", np.nan_to_num(v), unit, limits,
                          g.angles_deg, axis)
            empty = [f"{a:g}" for a, x in zip(g.angles_deg, v, strict=True) if not np.isfinite(x)]
            if empty and len(empty) < g.n:
                out.append(f"# {stem}: no value at theta = {', '.join(empty)} deg: set to 0 (nothing corrected there)")
            out += [f"setp {pins.map_pin(name, stem, k)} {x + 0.0:.{VALUE_DECIMALS}f}"
                    for k, x in enumerate(np.nan_to_num(v))]
        out += after
    return out


def entered_map_values(maps: list[ComponentMap]) -> dict[str, float]:
    """What the ``setp`` lines of the maps ``maps`` (:func:`component_maps`, the ones printed) enter, as printed
    (:data:`VALUE_DECIMALS`), in the weighing's names: a map per direction as its printed mean ± half its printed
    reversal."""
    out: dict[str, float] = {}
    for cm in maps:
        axis, axis_maps, values = cm.axis, cm.axis_maps, cm.slots
        printed = {m.name: np.round(np.nan_to_num(v), VALUE_DECIMALS)
                   for m, v in zip(axis_motions(axis, per_direction=True), values, strict=True)}
        angles = axis_maps.grid.angles_deg
        for name in axis_maps.values:
            phi = name[:-1]
            if name.endswith(("+", "-")) and phi in printed:
                sign = 0.5 if name.endswith("+") else -0.5
                vals = printed[phi] + sign * printed[phi + ":reversal"]
            elif name in printed:
                vals = printed[name]
            else:
                continue
            out |= {f"{axis}:{name}@{g:g}": float(v) for g, v in zip(angles, vals, strict=True)}
    return out
