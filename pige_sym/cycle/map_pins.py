"""The error-map pins of pige's kinematics component as values the cycle holds, reads back and enters.

With a map test in the settings (``map``, :class:`~pige_sym.cycle.settings.MapTest`) the cycle's values are the 8
PIGE pins and, per mapped axis, the component's grid pins and the map values on that grid
(:mod:`pige_sym.codegen.targets.linuxcnc_pins`): ``map-<a>-start`` [deg], ``-step`` [deg], ``-full-turn`` (0/1), the
seven slots' values at each grid angle (``<name>.exc-00`` … [µm, µrad]) and ``map-<a>-nodes`` (0: no map), in that
order.  The grid is the map test's (:func:`~pige_sym.cycle.settings.map_grids`: every ``step_deg`` over the full
turn of C, over ``ranges`` of an axis that does not turn fully, as ``pige program --map`` visits it).  They are
:class:`~pige_sym.cycle.kinematics.ValuePin` like the PIGE pins: where the configuration sets them (moved into
``values.hal`` by the install), else 0; read from the running HAL; in the fingerprint.

**The safe order** (docs/linuxcnc-kinematics.md#error-maps): a running machine never sees half a map.  An axis
whose map changes gets its ``nodes`` set to 0 first, then the grid and the values, then ``nodes`` last
(:func:`safe_order`); ``values.hal`` writes the same (:func:`nodes_first`: a ``setp … nodes 0`` line before the
axis' values, the node count at the end).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from pige_sym.cycle.hal_scan import HalScan
from pige_sym.cycle.kinematics import KinematicsSetup, ValuePin, value_pin
from pige_sym.cycle.settings import AxisGrid, CycleSettings, map_grids
from pige_sym.errors import InputError

#: ``holds`` of a map pin starts with this (the messages list the PIGE pins only)
MAP_HOLDS = "map "
GRID_UNITS = ("deg", "n")


def grid_targets(module: str, g: AxisGrid) -> dict[str, float]:
    """The grid pins of ``g`` and their values (``nodes`` last)."""
    a = g.axis.lower()
    return {f"{module}.map-{a}-start": g.start_deg, f"{module}.map-{a}-step": g.step_deg,
            f"{module}.map-{a}-full-turn": float(g.full_turn), f"{module}.map-{a}-nodes": float(g.nodes)}


def _axis_pins(setup: KinematicsSetup, scan: HalScan, g: AxisGrid) -> list[ValuePin]:
    from pige_sym.codegen.targets.linuxcnc_pins import map_pin, map_slot_names
    from pige_sym.model.error_motions import axis_motions

    module, a = setup.module, g.axis.lower()
    grid = [value_pin(scan, f"{module}.map-{a}-{k}", u, f"{MAP_HOLDS}{g.axis} {k}", via_signal=False, new_pin=True)
            for k, u in (("start", "deg"), ("step", "deg"), ("full-turn", "n"))]
    units = [m.unit for m in axis_motions(g.axis, per_direction=True)]
    values = [value_pin(scan, map_pin(module, stem, k), unit, f"{MAP_HOLDS}{g.axis} {stem} node {k}",
                        via_signal=False, new_pin=True)
              for stem, unit in zip(map_slot_names(g.axis), units, strict=True) for k in range(g.nodes)]
    nodes = value_pin(scan, f"{module}.map-{a}-nodes", "n", f"{MAP_HOLDS}{g.axis} nodes", via_signal=False,
                      new_pin=True)
    return [*grid, *values, nodes]


def with_map_pins(setup: KinematicsSetup, settings: CycleSettings, scan: HalScan) -> KinematicsSetup:
    """``setup`` with the map pins of the settings' map test after its PIGE pins (module docstring); as it is
    without a map test."""
    if settings.map is None or setup.kinematics != "pige":
        return setup
    pins = [p for g in map_grids(setup.machine, settings.map) for p in _axis_pins(setup, scan, g)]
    return replace(setup, pins=setup.pins + tuple(pins))


def is_map_pin(p: Any) -> bool:
    """Whether ``p`` (a :class:`~pige_sym.cycle.kinematics.ValuePin` or a proposed value: its ``holds``) is a map
    pin."""
    return str(p.holds).startswith(MAP_HOLDS)


def is_nodes_pin(p: Any) -> bool:
    return is_map_pin(p) and str(p.pin).endswith("-nodes")


def axis_of(p: Any) -> str:
    """The axis of a map pin."""
    return str(p.holds)[len(MAP_HOLDS):].split()[0]


def safe_order(setup: KinematicsSetup, in_force: dict[str, float],
               changes: list[tuple[ValuePin, float, float]]) -> list[tuple[ValuePin, float, float]]:
    """``(pin, old, new)`` in the safe order (module docstring): for each axis whose map pins change, its ``nodes``
    → 0 first (when not 0), the other values, then its ``nodes`` to the value it ends with (when not 0).  Undone in
    reverse order (:func:`~pige_sym.cycle.hal_live.set_live`), every pin is back where it was."""
    nodes = {axis_of(p): p for p in setup.pins if is_nodes_pin(p)}
    touched = [a for a in nodes if any(is_map_pin(p) and axis_of(p) == a for p, _, _ in changes)]
    final = {a: in_force[nodes[a].pin] for a in touched}
    final |= {axis_of(p): new for p, _, new in changes if is_nodes_pin(p)}
    first = [(nodes[a], in_force[nodes[a].pin], 0.0) for a in touched if in_force[nodes[a].pin] != 0.0]
    middle = [c for c in changes if not is_nodes_pin(c[0])]
    last = [(nodes[a], 0.0, final[a]) for a in touched if final[a] != 0.0]
    return first + middle + last


def nodes_first(setup: KinematicsSetup) -> list[str]:
    """The ``setp … nodes 0`` lines the values file starts the maps with (module docstring)."""
    return [p.command(0.0) + "    # no map while its values are set; the node count at the end" for p in setup.pins
            if is_nodes_pin(p)]


def check_grid(grids: list[AxisGrid], axis: str, angles_deg: np.ndarray, full_turn: bool) -> AxisGrid:
    """The map test's grid of ``axis``; refused when the identified grid (``angles_deg``) is not that one.

    Raises
    ------
    InputError
    """
    g = next((g for g in grids if g.axis == axis), None)
    want = None if g is None else g.start_deg + g.step_deg * np.arange(g.nodes)
    angles = np.asarray(angles_deg, dtype=float)
    if g is None or want is None or want.shape != angles.shape or not np.allclose(want, angles, atol=1e-9) or \
            bool(full_turn) != g.full_turn:
        raise InputError(f"the identified grid of {axis} ({', '.join(f'{x:g}' for x in angles)} deg) is not the map "
                         "test's pins' (settings.json map): the setups were measured with other map settings; "
                         "measure every setup again (M451 P3 Q1 ...)")
    return g
