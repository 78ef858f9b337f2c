"""The map loop on real LinuxCNC (issue 40): measure the error maps, correct them two ways, measure again.

The machines are the shipped trt simulations of :mod:`loop_setup` (``xyzac-trt``, ``xyzbc-trt``: σ = −1 for both
axes, the stock lines, the stylus a tool of the shipped table), with a true machine that has the PIGEs of
:data:`loop_setup.MACHINES`, hidden error maps on both axes and a reversal error on C (:mod:`true_map_table`).

**Measure.** Three sphere setups (:data:`SETUPS`, three points of the table not on one line, CONVENTIONS §10), one
pige probing program each, each run in its own simulation of the machine (the three at once: a shop would run them
one after the other, each right after start-up, as docs/linuxcnc.md §8 advises) in identity kinematics.  Until
``pige program --map`` exists, the poses are an angle file written here on the 30° grid of the maps: C up
through a turn at the tilt 30° and back down at 60° (each C grid angle approached from both sides: the
reversal), then the tilt 90° at C 0 and 180 and the tilt 0 at C 180 (:func:`angle_rows`).  No pose repeats with
the same approach: the probe would trip at the same servo periods and LinuxCNC log the same contacts, which
pige's import refuses as duplicated lines.  LinuxCNC writes each program's log (``PROBEOPEN``), one per
simulation.  pige imports the logs and identifies the PIGEs and the maps jointly (``--map C,<tilt>
--map-step 30 --map-per-direction C``), and the PIGEs alone.

pige takes the reference pose of each file as reached from neither side (φ the mean of φ⁺ and φ⁻, the identify
of issue 39); so before each measurement program the true machine's directions of approach are reset, as a
fresh start leaves them.

**Correct**, each setup again in its own fresh copy of the shipped configuration:

- (a) the stock kinematics with the ``[JOINT_n]COMP_FILE`` that ``pige compensate --controller linuxcnc
  --comp-dir`` writes (the INI lines it prints added under ``[JOINT_3]``/``[JOINT_4]``), probed again in identity
  kinematics (the files act on the joints in either mode).  The joints move once before the first program
  (LinuxCNC applies a trim only once the joint has moved, ``control.c``);
- (b) pige's kinematics component with every ``setp``/``net`` line ``pige compensate --controller linuxcnc``
  prints (PIGEs and maps), probed again in its TCP kinematics; then, in one more simulation with the same
  configuration, TCP MDI moves to work points around the first sphere at angles between the grid angles, first
  with the maps, then with the PIGEs of the PIGE-only identification and no map (the map pins' node counts set
  to 0).

The rotary axes run at 90°/s instead of the shipped 30°/s, the linear axes at 200 mm/s with 3000 mm/s² (more INI
changes, :data:`FAST`), and the programs probe from 0.8 mm off the sphere (:data:`MAP_CLEARANCE_MM`): a setup takes
about 230 s of machine time instead of 310 s.  The probing feed (F50) is the PIGE loop's: it sets the contacts'
resolution.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from corrections import kinematics_changes
from lcnc_harness import (
    ACCELERATION,
    RAPID_MM_S,
    IniChange,
    RunResult,
    Sim,
    compile_component,
    make_sim,
    run_sim,
)
from loop_setup import (
    KINEMATICS_CODES,
    MACHINES,
    PROBE_FEED_MM_MIN,
    SPHERE_RADIUS_MM,
    STYLUS_RADIUS_MM,
    Machine,
    pige,
    run_all,
)
from true_map_table import COMPONENT_NAME, TrueMapTable, hidden_map

STEP_DEG = 30.0
C_GRID = np.arange(0.0, 360.0, STEP_DEG)
TILT_GRID = np.arange(0.0, 90.0 + 1e-9, STEP_DEG)
SWEEP_TILT_DEG = (30.0, 60.0)  # the tilt of C's sweep up, and of its sweep down
#: sphere centres in table coordinates [mm], one per setup: three points not on one line
SETUPS = (np.array([20.0, 10.0, 15.0]), np.array([-25.0, 10.0, 10.0]), np.array([-15.0, -15.0, 10.0]))
#: held-out (tilt, C) [deg, CONVENTIONS angles]: between the grid angles of both maps
HELD_OUT = ((15.0, 45.0), (45.0, 105.0), (75.0, 195.0), (45.0, 285.0), (15.0, 345.0), (75.0, 135.0))
TARGET_OFFSETS_MM = ((0, 0, 0), (6, 0, 0), (0, 6, 0), (-6, 0, 0), (0, -6, 0), (0, 0, 6))
TRUE_PINS = ["ptm.tip-x", "ptm.tip-y", "ptm.tip-z", "ptm.approach1", "ptm.approach2"]
MOTOR_PINS = [f"joint.{k}.motor-pos-fb" for k in range(5)]
TRIM_PINS = ["joint.3.backlash-filt", "joint.4.backlash-filt"]
ROTARY_FAST = IniChange("rotary axes and joints at 90 deg/s", r"^(\s*MAX_VELOCITY =)\s*30\s*$", r"\1 90", count=4)
#: the map programs' moves, faster than the PIGE loop's (a machine's 12 m/min and 3 m/s²): most of them are short,
#: so the acceleration sets their time
FAST = (ROTARY_FAST,
        IniChange("linear axes and joints at 200 mm/s", rf"^(\s*MAX_VELOCITY =)\s*{RAPID_MM_S}\s*$", r"\1 200",
                  count=6),
        IniChange("the trajectory planner's limit too", rf"^(\s*MAX_LINEAR_VELOCITY =)\s*{RAPID_MM_S}\s*$", r"\1 200"),
        IniChange("accelerations 3000 mm/s^2 (deg/s^2)", rf"^(\s*MAX_(?:LINEAR_)?ACCELERATION =)\s*{ACCELERATION}\s*$",
                  r"\1 3000", count=11))
#: the probing moves start 0.8 mm off the sphere (the PIGE loop's 1 mm): 0.96 s per contact at F50 instead of 1.2 s,
#: and pige's read-back still finds every rapid move at least 0.54 mm from the sphere
MAP_CLEARANCE_MM = 0.8


@dataclass(frozen=True)
class MapMachine:
    """One shipped trt configuration with its true machine's hidden maps."""

    base: Machine
    seeds: tuple[int, int]  # the tilt axis' and C's hidden maps

    @property
    def outer(self) -> str:
        return self.base.outer

    @cached_property
    def maps(self) -> dict[str, Any]:
        return {self.outer: hidden_map(self.outer, TILT_GRID, False, self.seeds[0], tau=2.0, rho=20.0, phi=40.0,
                                       reversal=0.0),
                "C": hidden_map("C", C_GRID, True, self.seeds[1], tau=2.5, rho=25.0, phi=40.0, reversal=40.0)}

    def true_table(self, sphere: np.ndarray = SETUPS[0]) -> TrueMapTable:
        m = self.base
        return TrueMapTable(m.code, m.outer, {a: np.array(v) for a, v in m.pivots_mm.items()}, dict(m.pige),
                            {m.outer: -1, "C": -1}, self.maps, m.stylus[1], np.asarray(sphere, dtype=float),
                            SPHERE_RADIUS_MM + STYLUS_RADIUS_MM)

    @property
    def map_options(self) -> list[str]:
        return ["--map", f"C,{self.outer}", "--map-step", f"{STEP_DEG:g}", "--map-per-direction", "C"]


MAP_MACHINES = {"AC": MapMachine(MACHINES["AC"], (11, 12)), "BC": MapMachine(MACHINES["BC"], (13, 14))}


def angle_rows() -> np.ndarray:
    """The poses [deg, CONVENTIONS angles] (tilt, C): the reference, C up a turn at one tilt and down at another,
    then the last tilt at two C angles and the reference tilt at C 180 (module docstring)."""
    up = [(SWEEP_TILT_DEG[0], c) for c in np.arange(0.0, 360.0 + 1e-9, STEP_DEG)]
    down = [(SWEEP_TILT_DEG[1], c) for c in np.arange(360.0 - STEP_DEG, -1e-9, -STEP_DEG)]
    return np.array([(0.0, 0.0), *up, *down, (TILT_GRID[-1], 0.0), (TILT_GRID[-1], 180.0), (0.0, 180.0)])


def write_program(mm: MapMachine, cfg: Path, kinematics: str, index: int) -> Path:
    """The angle file and ``pige program --instrument sphere-probe`` of setup ``index``, into the configuration."""
    angles = cfg / "map_angles.csv"
    angles.write_text(f"{mm.outer}_deg,C_deg\n" + "".join(f"{t:g},{c:g}\n" for t, c in angle_rows()))
    m = mm.base
    mode = (["--rtcp-off", KINEMATICS_CODES[0], "--rtcp-on", KINEMATICS_CODES[1]] if kinematics == "identity"
            else ["--kinematics", "tcp"])
    name = f"setup{index}.ngc"
    pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", m.code,
         "--axis-sense", m.axis_sense, *m.pivot_options(), *mode,
         "--sphere", ",".join(f"{v:g}" for v in SETUPS[index]),
         "--sphere-radius", f"{SPHERE_RADIUS_MM:g}", "--stylus-radius", f"{STYLUS_RADIUS_MM:g}",
         "--stylus-tool", str(m.stylus[0]), "--stylus-length", f"{m.stylus[1]:g}", "--trajectory", angles.name,
         "--clearance", f"{MAP_CLEARANCE_MM:g}", "--probe-feed", f"{PROBE_FEED_MM_MIN:g}", "--out", name, cwd=cfg)
    return cfg / name


def setup_steps(mm: MapMachine, program: Path, index: int, kinematics: str, *, reset: bool) -> list[dict[str, Any]]:
    """Back to the reference pose above everything (identity kinematics), the sphere of setup ``index``, the true
    machine's directions of approach reset if ``reset``, the program, then the pins read."""
    tcp = [KINEMATICS_CODES[1]] if kinematics == "tcp" else []
    steps: list[dict[str, Any]] = [
        {"op": "mdi", "lines": [KINEMATICS_CODES[0], "G49", "G53 G0 Z115", f"G0 {mm.outer}0 C0", *tcp]},
        {"op": "hal", "commands": [f"setp ptm.sphere-{c} {float(v)!r}" for c, v in zip("xyz", SETUPS[index],
                                                                                        strict=True)]}]
    if reset:
        steps.append({"op": "hal", "commands": ["setp ptm.reset-direction 1", "setp ptm.reset-direction 0"]})
    return steps + [{"op": "program", "file": str(program), "timeout": 3600, "clock": "ptm.clock"},
                    {"op": "read", "pins": ["ptm.trips", "ptm.clock", *TRIM_PINS, *MOTOR_PINS, *TRUE_PINS]}]


@dataclass
class SetupRun:
    """One setup's simulation: its folder, pige's program, LinuxCNC's result."""

    sim: Sim
    program: Path
    run: RunResult

    @property
    def log(self) -> Path:
        return self.sim.cfg / "pige_probe.txt"

    def step(self, op: str, index: int = 0) -> dict[str, Any]:
        return [s for s in self.run.result["steps"] if s["op"] == op][index]


@dataclass(frozen=True)
class Configuration:
    """What a correction changes in the shipped configuration: INI edits, files beside the INI, components
    compiled beside the true machine, HAL lines after it."""

    extra: tuple[IniChange, ...] = ()
    files: tuple[Path, ...] = ()
    components: tuple[tuple[str, str], ...] = ()
    nets: tuple[str, ...] = ()


def machine_sim(mm: MapMachine, root: Path, config: Configuration) -> Sim:
    """A fresh copy of the shipped configuration with the true machine (rotary axes at 90°/s) and ``config``."""
    table = mm.true_table()
    sim = make_sim(root, mm.base.kind, table.hal_lines() + list(config.nets), [*FAST, *config.extra])
    for f in config.files:
        (sim.cfg / f.name).write_text(f.read_text())
    compile_component(sim, table.component_source(), COMPONENT_NAME)
    for name, source in config.components:
        compile_component(sim, source, name)
    return sim


def setup_run(mm: MapMachine, root: Path, index: int, kinematics: str, config: Configuration,
              first: list[dict[str, Any]], *, reset: bool) -> SetupRun:
    """Setup ``index`` in its own simulation: ``first`` steps, then the setup's (:func:`setup_steps`)."""
    sim = machine_sim(mm, root, config)
    program = write_program(mm, sim.cfg, kinematics, index)
    steps = [*first, *setup_steps(mm, program, index, kinematics, reset=reset)]
    return SetupRun(sim, program, run_sim(sim, steps, timeout_s=3600))


@dataclass
class MapRun:
    """A measurement of the map loop: the machine, one simulation per setup, the folder of pige's files, and (b)'s
    simulation of the TCP moves."""

    machine: MapMachine
    setups: list[SetupRun]
    root: Path
    label: str
    moves: RunResult | None = None

    @property
    def runs(self) -> list[RunResult]:
        return [s.run for s in self.setups] + ([self.moves] if self.moves is not None else [])

    @property
    def logs(self) -> list[Path]:
        return [s.log for s in self.setups]

    @cached_property
    def measurements(self) -> list[Path]:
        """``pige import-probe`` of each setup's log (its program's header gives the rest)."""
        out = []
        for i, setup in enumerate(self.setups):
            path = self.root / f"setup{i}.csv"
            pige("import-probe", str(setup.log), "--format", "linuxcnc", "--program", str(setup.program), "--out",
                 str(path), "--force", cwd=self.root)
            out.append(path)
        return out

    def _identify(self, name: str, *options: str) -> Path:
        path = self.root / name
        path.write_text(pige("identify", *map(str, self.measurements), *options, "--json", cwd=self.root))
        return path

    @cached_property
    def maps_file(self) -> Path:
        return self._identify("maps.json", *self.machine.map_options)

    @cached_property
    def pige_only_file(self) -> Path:
        return self._identify("pige_only.json")

    @cached_property
    def maps(self) -> dict[str, Any]:
        return dict(json.loads(self.maps_file.read_text()))

    @cached_property
    def pige_only(self) -> dict[str, Any]:
        return dict(json.loads(self.pige_only_file.read_text()))


def start_steps(mm: MapMachine) -> list[dict[str, Any]]:
    m = mm.base
    return [{"op": "mdi", "lines": [f"T{m.stylus[0]} M6", "G49", "G53 G0 Z115", f"G0 {mm.outer}-2 C-2",
                                    f"G0 {mm.outer}0 C0"]}]


def all_setups(mm: MapMachine, root: Path, kinematics: str, config: Configuration, first: list[dict[str, Any]],
               *, reset: bool, label: str, moves: Callable[[], RunResult] | None = None) -> MapRun:
    """Every setup in its own simulation, all at once (and ``moves``, a simulation of its own, beside them)."""
    root.mkdir(parents=True, exist_ok=True)
    jobs: dict[Any, Callable[[], Any]] = {
        i: (lambda i=i: setup_run(mm, root / f"setup{i}", i, kinematics, config, first, reset=reset))
        for i in range(len(SETUPS))}
    if moves is not None:
        jobs["moves"] = moves
    done = run_all(jobs)
    return MapRun(mm, [done[i] for i in range(len(SETUPS))], root, label, done.get("moves"))


def measurement_run(mm: MapMachine, root: Path) -> MapRun:
    """Measure: the stock configuration, identity kinematics, three setups (module docstring)."""
    first = [{"op": "mdi", "lines": [f"T{mm.base.stylus[0]} M6"]}]
    return all_setups(mm, root, "identity", Configuration(), first, reset=True, label="measure")


def comp_file_lines(params: Path, comp_dir: Path) -> tuple[str, list[str]]:
    """What ``pige compensate --controller linuxcnc --comp-dir`` prints, and its INI lines (``[JOINT_n]`` and the
    ``COMP_FILE`` lines under it)."""
    text = pige("compensate", "--params", str(params), "--controller", "linuxcnc", "--comp-dir", str(comp_dir),
                cwd=params.parent)
    lines = [ln for ln in text.splitlines() if re.match(r"^(\[JOINT_\d\]|COMP_FILE(_TYPE)? = )", ln)]
    return text, lines


def comp_ini_changes(lines: list[str]) -> list[IniChange]:
    """Add each ``[JOINT_n]`` group's lines at the top of that section of the shipped INI."""
    out, section = [], None
    groups: dict[str, list[str]] = {}
    for ln in lines:
        if ln.startswith("["):
            section = ln
            groups[section] = []
        elif section is not None:
            groups[section].append(ln)
    for section, body in groups.items():
        out.append(IniChange(f"the COMP_FILE of {section}", rf"^{re.escape(section)}\s*$",
                             section + "\n" + "\n".join(body)))
    return out


def comp_file_run(mm: MapMachine, first: MapRun, root: Path) -> tuple[MapRun, str]:
    """(a): the COMP_FILEs pige writes on the stock kinematics, probed again in identity kinematics."""
    root.mkdir(parents=True, exist_ok=True)
    comp_dir = root / "comp"
    comp_dir.mkdir()
    text, lines = comp_file_lines(first.maps_file, comp_dir)
    config = Configuration(tuple(comp_ini_changes(lines)), tuple(sorted(comp_dir.iterdir())))
    return all_setups(mm, root, "identity", config, start_steps(mm), reset=False, label="comp-file"), text


def pige_lines(params: Path, name: str) -> list[str]:
    """The ``setp``/``net`` lines of pige's component that ``pige compensate --controller linuxcnc`` prints."""
    text = pige("compensate", "--params", str(params), "--controller", "linuxcnc", cwd=params.parent)
    return [ln.strip() for ln in text.splitlines() if ln.startswith((f"setp {name}.", "net pige-vel-"))]


def targets(mm: MapMachine) -> list[tuple[np.ndarray, tuple[float, float]]]:
    """Work points around the first sphere at the held-out angles: (point [mm], (tilt, C) [deg, CONVENTIONS])."""
    return [(SETUPS[0] + np.array(off, dtype=float), th) for th in HELD_OUT for off in TARGET_OFFSETS_MM]


def move_lines(mm: MapMachine) -> list[str]:
    """One TCP move per target (commanded angles: σ = −1)."""
    return [f"G0 X{p[0]:.4f} Y{p[1]:.4f} Z{p[2]:.4f} {mm.outer}{-t:g} C{-c:g}" for p, (t, c) in targets(mm)]


def pige_maps_run(mm: MapMachine, first: MapRun, root: Path) -> MapRun:
    """(b): pige's component with the maps, probed again in TCP; beside it, in one more simulation, the held-out
    TCP moves: with the maps, then with the PIGE-only identification and no map."""
    from pige_sym.codegen.targets.linuxcnc_pins import default_name

    m = mm.base
    root.mkdir(parents=True, exist_ok=True)
    name = default_name(m.code)
    kins = root / "kins"
    pige("gen", "--target", "linuxcnc", m.code, "--out", str(kins), "--force", cwd=root)
    with_maps = pige_lines(first.maps_file, name)
    only = [ln for ln in pige_lines(first.pige_only_file, name) if re.match(rf"^setp {name}\.e[xyzabc]0[abc] ", ln)]
    no_map = [f"setp {name}.map-{a.lower()}-nodes 0" for a in (mm.outer, "C")]
    ini = kinematics_changes(m.kind, name, [ln for ln in with_maps if ln.startswith("setp")])
    config = Configuration(tuple(ini), components=((name, (kins / f"{name}.comp").read_text()),),
                           nets=tuple(ln for ln in with_maps if ln.startswith("net ")))
    read = TRUE_PINS + MOTOR_PINS + [f"{name}.approach-{a.lower()}" for a in (mm.outer, "C")]
    moves = move_lines(mm)
    # each series from the reference angles at joint Z 80 in identity kinematics: the tool length (G43) and the
    # TCP switch then keep every joint inside the sim's limits
    start = [KINEMATICS_CODES[0], "G49", "G53 G0 Z80", f"G0 {mm.outer}0 C0", KINEMATICS_CODES[1], f"G43 H{m.stylus[0]}"]
    first_steps = [{"op": "mdi", "lines": [KINEMATICS_CODES[1], f"T{m.stylus[0]} M6"]}]
    move_steps = [*first_steps, {"op": "hal", "commands": ["setp ptm.trip-radius -1"]},
                  {"op": "mdi", "lines": [*start, *moves], "read": read},
                  {"op": "mdi", "lines": [KINEMATICS_CODES[0]]},
                  {"op": "hal", "commands": only + no_map},
                  {"op": "mdi", "lines": [*start, *moves], "read": read}]

    def move_run() -> RunResult:
        sim = machine_sim(mm, root / "moves", config)
        return run_sim(sim, move_steps, timeout_s=3600)

    return all_setups(mm, root, "tcp", config, first_steps, reset=False, label="pige-maps", moves=move_run)
