"""The map test of the cycle on LinuxCNC (tests/linuxcnc/test_linuxcnc_cycle_maps.py): one simulation and its steps.

The machine is the shipped ``xyzac-trt`` simulation with pige's kinematics component (its PIGE pins at 0, no map:
:func:`cycle_setup.component_lines`) and the true machine of the map loop (:mod:`true_map_table`: the PIGEs of
:data:`loop_setup.MACHINES`, tilts included, hidden error maps on both axes) on the cycle's own grid, 45°: C every
45° over the turn (8 angles), A at 0, 45, 90°.  On a grid of three angles §10 leaves A only its positioning map
(the other motions' representatives are 0 there), which the test's setups determine; C's six motions are all
determined by the three setups.  No reversal (the cycle's settings map no axis per direction).  The axes are the
map loop's faster ones (:data:`map_loop.FAST`), the probing moves start 0.8 mm off the sphere
(:data:`map_loop.MAP_CLEARANCE_MM`), 4 contacts per pose.

The operator is the driver: the stylus loaded, then for each setup k the true sphere moved to setup k's place
(the true component's ``sphere-x|y|z`` pins, table coordinates: :data:`map_loop.SETUPS`, which the install states
as ``--sphere`` and ``--map-sphere``) and ``M451 P3 Q<k>``; the true tool point at work points between the grid
angles (TCP MDI moves, the map loop's held-out moves); ``M451 P2``; the pins; the held-out moves again.  Then
LinuxCNC started again and the pins read.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from corrections import kinematics_changes
from cycle_setup import component_lines
from lcnc_harness import RunResult, Sim, compile_component, make_sim, run_sim
from loop_setup import MACHINES, SPHERE_RADIUS_MM, STYLUS_RADIUS_MM, pige
from map_loop import FAST, MAP_CLEARANCE_MM, SETUPS, TARGET_OFFSETS_MM, TRUE_PINS
from true_map_table import COMPONENT_NAME, TrueMapTable, hidden_map

STEP_DEG = 45.0
C_GRID = np.arange(0.0, 360.0, STEP_DEG)
TILT_GRID = np.arange(0.0, 90.0 + 1e-9, STEP_DEG)
CONTACTS = 4
#: held-out (tilt, C) [deg, CONVENTIONS angles]: between the 45° grid angles of both maps (C at odd multiples of
#: 22.5°, A at 22.5 and 67.5°, two at 30 and 60°)
HELD_OUT = ((22.5, 22.5), (67.5, 112.5), (22.5, 202.5), (67.5, 292.5), (30.0, 157.5), (60.0, 337.5))
#: grid angles, after the held-out ones: where the map test measured (printed beside the held-out errors)
ON_GRID = ((45.0, 90.0), (90.0, 225.0), (0.0, 315.0))
CYCLE_TIMEOUT_S = 1800.0
MODULE = "pige_xyzac_trt"


@dataclass
class CycleMapSim:
    """The simulation with the cycle installed for a map test: the folder, the true machine, the component's
    name."""

    sim: Sim
    table: TrueMapTable
    name: str

    @property
    def values_file(self) -> Path:
        return self.sim.cfg / "pige_cycle" / "values.hal"

    def runs(self) -> list[Path]:
        return sorted((self.sim.cfg / "pige_cycle" / "runs").iterdir())


def true_table() -> TrueMapTable:
    """The AC machine's true table with hidden maps on the 45° grid (module docstring)."""
    m = MACHINES["AC"]
    maps = {"A": hidden_map("A", TILT_GRID, False, 11, tau=2.0, rho=20.0, phi=40.0, reversal=0.0),
            "C": hidden_map("C", C_GRID, True, 12, tau=2.5, rho=25.0, phi=40.0, reversal=0.0)}
    return TrueMapTable(m.code, m.outer, {a: np.array(v) for a, v in m.pivots_mm.items()}, dict(m.pige),
                        {"A": -1, "C": -1}, maps, m.stylus[1], np.asarray(SETUPS[0], dtype=float),
                        SPHERE_RADIUS_MM + STYLUS_RADIUS_MM)


def install_options() -> list[str]:
    m = MACHINES["AC"]
    spheres = [w for s in SETUPS[1:] for w in ("--map-sphere", ",".join(f"{v:g}" for v in s))]
    return ["--sphere", ",".join(f"{v:g}" for v in SETUPS[0]), "--sphere-radius", f"{SPHERE_RADIUS_MM:g}",
            "--stylus-radius", f"{STYLUS_RADIUS_MM:g}", "--stylus-tool", str(m.stylus[0]),
            "--stylus-length", f"{m.stylus[1]:g}", "--kinematics", "pige", "--machine-id", "LCNC-AC-maps",
            "--contacts", str(CONTACTS), "--clearance", f"{MAP_CLEARANCE_MM:g}",
            "--map", "C,A", "--map-step", f"{STEP_DEG:g}", *spheres]


def cycle_map_sim(root: Path) -> CycleMapSim:
    """The simulation of the module docstring with ``pige cycle install --force`` done."""
    from pige_sym.codegen.targets.linuxcnc_pins import default_name

    m = MACHINES["AC"]
    name = default_name(m.code)
    pige("gen", "--target", "linuxcnc", m.code, "--out", str(root / "kins"), "--force", cwd=root)
    table = true_table()
    changes = [*kinematics_changes(m.kind, name, component_lines(m, name)), *FAST]
    sim = make_sim(root, m.kind, table.hal_lines(), changes)
    compile_component(sim, table.component_source(), COMPONENT_NAME)
    compile_component(sim, (root / "kins" / f"{name}.comp").read_text(), name)
    pige("cycle", "install", str(sim.ini), *install_options(), "--force", cwd=sim.cfg)
    return CycleMapSim(sim, table, name)


def cycle_step(line: str) -> dict[str, Any]:
    return {"op": "mdi", "lines": [line], "timeout": CYCLE_TIMEOUT_S, "clock": "ptm.clock", "label": line}


def sphere_step(k: int) -> dict[str, Any]:
    """The operator clamps the sphere of setup ``k`` (1-based) where the cycle said."""
    return {"op": "hal", "commands": [f"setp ptm.sphere-{c} {float(v)!r}" for c, v in zip("xyz", SETUPS[k - 1],
                                                                                          strict=True)]}


def map_pins(cs: CycleMapSim) -> list[str]:
    n = cs.name
    pins = [f"{n}.{p.lower()}" for p in MACHINES["AC"].pige]
    pins += [f"{n}.map-{a}-{k}" for a in ("c", "a") for k in ("start", "step", "nodes", "full-turn")]
    return pins + [f"{n}.{stem}-{k:02d}" for stem in ("exc", "eyc", "ecc") for k in range(len(C_GRID))] + \
        [f"{n}.eaa-{k:02d}" for k in range(len(TILT_GRID))]


def held_out_steps(cs: CycleMapSim, label: str) -> list[dict[str, Any]]:
    """The map loop's held-out TCP moves (work points 6 mm around the first sphere at angles between the grid
    angles), the true probe off, from the reference angles at joint Z 80 in identity kinematics; then back to
    identity kinematics and the rotary axes at 0 above the sphere, the probe on again."""
    t = MACHINES["AC"].stylus[0]
    trip = cs.table.trip_radius_mm
    start = ["M429", "G49", "G53 G0 Z80", "G0 A0 C0", "M428", f"G43 H{t}"]
    moves = [f"G0 X{p[0]:.4f} Y{p[1]:.4f} Z{p[2]:.4f} A{-a:g} C{-c:g}"  # sigma -1
             for p, (a, c) in targets() + targets(ON_GRID)]
    return [{"op": "hal", "commands": ["setp ptm.trip-radius -1"]},
            {"op": "mdi", "lines": [*start, *moves], "read": TRUE_PINS[:3],
             "timeout": 900, "label": label},
            {"op": "mdi", "lines": ["M429", "G49", "G53 G0 Z115", "G0 A0 C0"], "timeout": 300},
            {"op": "hal", "commands": [f"setp ptm.trip-radius {trip!r}"]}]


def loop_steps(cs: CycleMapSim) -> list[dict[str, Any]]:
    """The operator's map test (module docstring)."""
    t = MACHINES["AC"].stylus[0]
    steps: list[dict[str, Any]] = [{"op": "mdi", "lines": [f"T{t} M6", "G53 G0 Z115", "G0 A-2 C-2", "G0 A0 C0"]},
                                   {"op": "read", "pins": map_pins(cs)}]
    for k in range(1, len(SETUPS) + 1):
        steps += [sphere_step(k), cycle_step(f"M451 P3 Q{k}")]
    steps += held_out_steps(cs, "before")
    steps += [cycle_step("M451 P2"), {"op": "read", "pins": map_pins(cs)}]
    return steps + held_out_steps(cs, "after")


def run_map_cycle(cs: CycleMapSim) -> tuple[RunResult, RunResult]:
    """The map test, then LinuxCNC started again and the pins read."""
    run = run_sim(cs.sim, loop_steps(cs), timeout_s=4 * CYCLE_TIMEOUT_S, attempts=1)
    shutil.copyfile(cs.sim.root / "result.json", cs.sim.root / "map_run.json")  # the restart writes result.json again
    restart = run_sim(cs.sim, [{"op": "read", "pins": map_pins(cs)}], attempts=1)
    return run, restart


def targets(angles: tuple[tuple[float, float], ...] = HELD_OUT) -> list[tuple[np.ndarray, tuple[float, float]]]:
    """Work points 6 mm around the first sphere at ``angles``: (point [mm], (tilt, C) [deg])."""
    return [(np.asarray(SETUPS[0], dtype=float) + np.array(off, dtype=float), th) for th in angles
            for off in TARGET_OFFSETS_MM]


def held_out_errors(step: dict[str, Any], angles: tuple[tuple[float, float], ...] = HELD_OUT) -> np.ndarray:
    """|true tool point − work point| at each move to ``angles`` [µm] (the readings after the 6 lines that
    start: the held-out moves, then those on the grid)."""
    goal = np.array([p for p, _ in targets(angles)])
    first = 6 + (0 if angles == HELD_OUT else len(targets()))
    tips = np.array([[r[p] for p in TRUE_PINS[:3]] for r in step["readings"][first:first + len(goal)]])
    return np.asarray(np.linalg.norm(tips - goal, axis=1) * 1e3)
