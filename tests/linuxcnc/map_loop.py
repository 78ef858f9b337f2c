"""The map loop on real LinuxCNC (issue 40): measure the error maps, correct them two ways, measure again.

The machines are the shipped trt simulations of :mod:`loop_setup` (``xyzac-trt``, ``xyzbc-trt``: σ = −1 for both
axes, the stock lines, the stylus a tool of the shipped table), with a true machine that has the PIGEs of
:data:`loop_setup.MACHINES`, hidden error maps on both axes and a reversal error on C (:mod:`true_map_table`).

**Measure.** Three sphere setups (:data:`SETUPS`, three points of the table not on one line, CONVENTIONS §10), one
pige probing program each, run one after the other in one simulation in identity kinematics.  Until
``pige program --map`` exists, the poses are an angle file written here on the 30° grid of the maps: C up
through a turn at the tilt 30° and back down at 60° (each C grid angle approached from both sides: the
reversal), then the tilt 90° at C 0 and 180 and the tilt 0 at C 180 (:func:`angle_rows`).  No pose repeats with
the same approach: the probe would trip at the same servo periods and LinuxCNC log the same contacts, which
pige's import refuses as duplicated lines.  LinuxCNC writes each program's log (``PROBEOPEN``); it is copied
aside before the next.  pige imports the logs and identifies the PIGEs and the maps jointly (``--map C,<tilt>
--map-step 30 --map-per-direction C``), and the PIGEs alone.

pige takes the reference pose of each file as reached from neither side (φ the mean of φ⁺ and φ⁻, the identify
of issue 39); so before each measurement program the true machine's directions of approach are reset, as a
fresh start leaves them.

**Correct**, each in a fresh copy of the shipped configuration:

- (a) the stock kinematics with the ``[JOINT_n]COMP_FILE`` that ``pige compensate --controller linuxcnc
  --comp-dir`` writes (the INI lines it prints added under ``[JOINT_3]``/``[JOINT_4]``), probed again in identity
  kinematics (the files act on the joints in either mode).  The joints move once before the first program
  (LinuxCNC applies a trim only once the joint has moved, ``control.c``);
- (b) pige's kinematics component with every ``setp``/``net`` line ``pige compensate --controller linuxcnc``
  prints (PIGEs and maps), probed again in its TCP kinematics; then TCP MDI moves to work points around the
  first sphere at angles between the grid angles, first with the maps, then with the PIGEs of the PIGE-only
  identification and no map (the map pins' node counts set to 0).

The rotary axes run at 90°/s instead of the shipped 30°/s (one more INI change; the probing feed is the
program's).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from corrections import kinematics_changes
from lcnc_harness import IniChange, RunResult, Sim, compile_component, make_sim, run_sim
from loop_setup import (
    CLEARANCE_MM,
    KINEMATICS_CODES,
    MACHINES,
    PROBE_FEED_MM_MIN,
    SPHERE_RADIUS_MM,
    STYLUS_RADIUS_MM,
    Machine,
    pige,
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


def write_programs(mm: MapMachine, cfg: Path, kinematics: str) -> list[Path]:
    """The angle file and one ``pige program --instrument sphere-probe`` per setup, into the configuration."""
    angles = cfg / "map_angles.csv"
    angles.write_text(f"{mm.outer}_deg,C_deg\n" + "".join(f"{t:g},{c:g}\n" for t, c in angle_rows()))
    m = mm.base
    mode = (["--rtcp-off", KINEMATICS_CODES[0], "--rtcp-on", KINEMATICS_CODES[1]] if kinematics == "identity"
            else ["--kinematics", "tcp"])
    out = []
    for i, sphere in enumerate(SETUPS):
        name = f"setup{i}.ngc"
        pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", m.code,
             "--axis-sense", m.axis_sense, *m.pivot_options(), *mode, "--sphere", ",".join(f"{v:g}" for v in sphere),
             "--sphere-radius", f"{SPHERE_RADIUS_MM:g}", "--stylus-radius", f"{STYLUS_RADIUS_MM:g}",
             "--stylus-tool", str(m.stylus[0]), "--stylus-length", f"{m.stylus[1]:g}", "--trajectory", angles.name,
             "--clearance", f"{CLEARANCE_MM:g}", "--probe-feed", f"{PROBE_FEED_MM_MIN:g}", "--out", name, cwd=cfg)
        out.append(cfg / name)
    return out


def setup_steps(mm: MapMachine, programs: list[Path], kinematics: str, *, reset: bool) -> list[dict[str, Any]]:
    """Per setup: back to the reference pose above everything (identity kinematics), the sphere moved, the true
    machine's directions of approach reset if ``reset``, the program, its log copied aside."""
    tcp = [KINEMATICS_CODES[1]] if kinematics == "tcp" else []
    steps: list[dict[str, Any]] = []
    for i, (program, sphere) in enumerate(zip(programs, SETUPS, strict=True)):
        steps.append({"op": "mdi", "lines": [KINEMATICS_CODES[0], "G49", "G53 G0 Z115", f"G0 {mm.outer}0 C0", *tcp]})
        steps.append({"op": "hal", "commands": [f"setp ptm.sphere-{c} {float(v)!r}" for c, v in zip("xyz", sphere,
                                                                                             strict=True)]})
        if reset:
            steps.append({"op": "hal", "commands": ["setp ptm.reset-direction 1", "setp ptm.reset-direction 0"]})
        steps += [{"op": "program", "file": str(program), "timeout": 3600, "clock": "ptm.clock"},
                  {"op": "hal", "commands": [f"loadusr -w cp pige_probe.txt probe{i}.txt"]},
                  {"op": "read", "pins": ["ptm.trips", "ptm.clock", *TRIM_PINS, *MOTOR_PINS, *TRUE_PINS]}]
    return steps


@dataclass
class MapRun:
    """One simulation of the map loop: the machine, its folder, the programs, LinuxCNC's result."""

    machine: MapMachine
    sim: Sim
    programs: list[Path]
    run: RunResult
    label: str

    @property
    def logs(self) -> list[Path]:
        return [self.sim.cfg / f"probe{i}.txt" for i in range(len(SETUPS))]

    @cached_property
    def measurements(self) -> list[Path]:
        """``pige import-probe`` of each setup's log (its program's header gives the rest)."""
        out = []
        for i, (log, program) in enumerate(zip(self.logs, self.programs, strict=True)):
            path = self.sim.root / f"setup{i}.csv"
            pige("import-probe", str(log), "--format", "linuxcnc", "--program", str(program), "--out", str(path),
                 "--force", cwd=self.sim.root)
            out.append(path)
        return out

    def _identify(self, name: str, *options: str) -> Path:
        path = self.sim.root / name
        path.write_text(pige("identify", *map(str, self.measurements), *options, "--json", cwd=self.sim.root))
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

    def step(self, op: str, index: int = 0) -> dict[str, Any]:
        return [s for s in self.run.result["steps"] if s["op"] == op][index]


def start_steps(mm: MapMachine) -> list[dict[str, Any]]:
    m = mm.base
    return [{"op": "mdi", "lines": [f"T{m.stylus[0]} M6", "G49", "G53 G0 Z115", f"G0 {mm.outer}-2 C-2",
                                    f"G0 {mm.outer}0 C0"]}]


def measurement_run(mm: MapMachine, root: Path) -> MapRun:
    """Measure: the stock configuration, identity kinematics, three setups (module docstring)."""
    table = mm.true_table()
    sim = make_sim(root, mm.base.kind, table.hal_lines(), [ROTARY_FAST])
    compile_component(sim, table.component_source(), COMPONENT_NAME)
    programs = write_programs(mm, sim.cfg, "identity")
    steps = [{"op": "mdi", "lines": [f"T{mm.base.stylus[0]} M6"]}, *setup_steps(mm, programs, "identity", reset=True)]
    return MapRun(mm, sim, programs, run_sim(sim, steps, timeout_s=7200), "measure")


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
    table = mm.true_table()
    root.mkdir(parents=True, exist_ok=True)
    comp_dir = root / "comp"
    comp_dir.mkdir()
    text, lines = comp_file_lines(first.maps_file, comp_dir)
    sim = make_sim(root, mm.base.kind, table.hal_lines(), [ROTARY_FAST, *comp_ini_changes(lines)])
    for f in comp_dir.iterdir():
        (sim.cfg / f.name).write_text(f.read_text())
    compile_component(sim, table.component_source(), COMPONENT_NAME)
    programs = write_programs(mm, sim.cfg, "identity")
    steps = [*start_steps(mm), *setup_steps(mm, programs, "identity", reset=False)]
    return MapRun(mm, sim, programs, run_sim(sim, steps, timeout_s=7200), "comp-file"), text


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
    """(b): pige's component with the maps, probed again in TCP, then the held-out TCP moves: with the maps, then
    with the PIGE-only identification and no map."""
    from pige_sym.codegen.targets.linuxcnc_pins import default_name

    m = mm.base
    table = mm.true_table()
    root.mkdir(parents=True, exist_ok=True)
    name = default_name(m.code)
    kins = root / "kins"
    pige("gen", "--target", "linuxcnc", m.code, "--out", str(kins), "--force", cwd=root)
    with_maps = pige_lines(first.maps_file, name)
    only = [ln for ln in pige_lines(first.pige_only_file, name) if re.match(rf"^setp {name}\.e[xyzabc]0[abc] ", ln)]
    no_map = [f"setp {name}.map-{a.lower()}-nodes 0" for a in (mm.outer, "C")]
    ini = kinematics_changes(m.kind, name, [ln for ln in with_maps if ln.startswith("setp")])
    nets = [ln for ln in with_maps if ln.startswith("net ")]
    sim = make_sim(root, m.kind, table.hal_lines() + nets, [ROTARY_FAST, *ini])
    compile_component(sim, table.component_source(), COMPONENT_NAME)
    compile_component(sim, (kins / f"{name}.comp").read_text(), name)
    programs = write_programs(mm, sim.cfg, "tcp")
    read = TRUE_PINS + MOTOR_PINS + [f"{name}.approach-{a.lower()}" for a in (mm.outer, "C")]
    moves = move_lines(mm)
    # each series from the reference angles at joint Z 80 in identity kinematics: the tool length (G43) and the
    # TCP switch then keep every joint inside the sim's limits
    start = [KINEMATICS_CODES[0], "G49", "G53 G0 Z80", f"G0 {mm.outer}0 C0", KINEMATICS_CODES[1], f"G43 H{m.stylus[0]}"]
    after = [{"op": "hal", "commands": ["setp ptm.trip-radius -1"]},
             {"op": "mdi", "lines": [*start, *moves], "read": read},
             {"op": "mdi", "lines": [KINEMATICS_CODES[0]]},
             {"op": "hal", "commands": only + no_map},
             {"op": "mdi", "lines": [*start, *moves], "read": read}]
    steps = [{"op": "mdi", "lines": [KINEMATICS_CODES[1], f"T{m.stylus[0]} M6"]},
             *setup_steps(mm, programs, "tcp", reset=False), *after]
    return MapRun(mm, sim, programs, run_sim(sim, steps, timeout_s=7200), "pige-maps")
