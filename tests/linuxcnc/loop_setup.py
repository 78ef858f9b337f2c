"""The two machines of the LinuxCNC loop and the pige commands run on their files (tests/linuxcnc).

Each machine is LinuxCNC's shipped trt simulation (``xyzac-trt``, ``xyzbc-trt``) with a true table
(:mod:`true_table`) whose PIGEs are chosen here, tilts included.  pige is run as a user runs it: its command
line, in a subprocess, on the files LinuxCNC wrote.
"""

from __future__ import annotations

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from lcnc_harness import RunResult, Sim, compile_component, make_sim, run_sim
from true_table import COMPONENT, COMPONENT_NAME, TrueTable

SPHERE_RADIUS_MM = 6.35
STYLUS_RADIUS_MM = 1.5
SPHERE_MM = np.array([20.0, 10.0, 15.0])  # table coordinates = machine coordinates at the reference pose
PROBE_FEED_MM_MIN = 100.0  # with the 1 ms servo period: contacts exact to 1.67 um along the move
CLEARANCE_MM = 1.0
POSES = 12  # cone points: 13 poses with the reference


@dataclass
class Machine:
    """One shipped trt configuration with its true table."""

    kind: str  # xyzac / xyzbc
    code: str  # ISO 10791 code
    outer: str
    pige: dict[str, float]
    pivot_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def true_table(self, sense: dict[str, int] | None = None, tool_length_mm: float = 0.0) -> TrueTable:
        return TrueTable(self.outer, {self.outer: self.pivot_mm, "C": self.pivot_mm}, self.pige,
                         sense or {self.outer: 1, "C": 1}, tool_length_mm, SPHERE_MM,
                         SPHERE_RADIUS_MM + STYLUS_RADIUS_MM)


MACHINES = {
    "AC": Machine("xyzac", "wC'A'bXYZ(C1)t", "A",
                  {"EY0A": 15.0, "EZ0A": -10.0, "EB0A": 60.0, "EC0A": -45.0,
                   "EX0C": 12.0, "EY0C": -8.0, "EA0C": 40.0, "EB0C": -30.0}),
    "BC": Machine("xyzbc", "wC'B'bXYZ(C1)t", "B",
                  {"EX0B": -14.0, "EZ0B": 9.0, "EA0B": -50.0, "EC0B": 35.0,
                   "EX0C": 10.0, "EY0C": 11.0, "EA0C": -35.0, "EB0C": 45.0}),
}


def pige(*args: str, cwd: Path) -> str:
    """Run ``pige ARGS`` (``python -m pige_sym``) and return its standard output; fail with its messages."""
    proc = subprocess.run([sys.executable, "-m", "pige_sym", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)
    if proc.returncode != 0:
        raise AssertionError(f"pige {' '.join(args)} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}")
    return proc.stdout


def sphere_options() -> list[str]:
    return ["--sphere-radius", f"{SPHERE_RADIUS_MM:g}", "--stylus-radius", f"{STYLUS_RADIUS_MM:g}"]


def write_program(m: Machine, cfg: Path, name: str = "probe.ngc") -> Path:
    """``pige program --instrument sphere-probe --dialect linuxcnc`` into the configuration folder."""
    pivot = ",".join(f"{v:g}" for v in m.pivot_mm)
    pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", m.code,
         "--sphere", ",".join(f"{v:g}" for v in SPHERE_MM), *sphere_options(), "--pivot", pivot,
         "--points", str(POSES), "--clearance", f"{CLEARANCE_MM:g}", "--probe-feed", f"{PROBE_FEED_MM_MIN:g}",
         "--out", name, cwd=cfg)
    return cfg / name


def import_and_identify(m: Machine, log: Path, out: Path) -> dict[str, Any]:
    """``pige import-probe`` then ``pige identify --json``: the identification's JSON."""
    pivot = ",".join(f"{v:g}" for v in m.pivot_mm)
    pige("import-probe", str(log), "--format", "linuxcnc", "--machine", m.code, "--pivot", pivot,
         *sphere_options(), "--out", str(out), cwd=out.parent)
    return json.loads(pige("identify", str(out), "--json", cwd=out.parent))


@dataclass
class ProbeRun:
    """A probing run on one machine: the folder, the true table, LinuxCNC's result."""

    machine: Machine
    sim: Sim
    table: TrueTable
    run: RunResult

    @property
    def log(self) -> Path:
        return self.sim.cfg / "pige_probe.txt"

    @property
    def program_step(self) -> dict[str, Any]:
        return next(s for s in self.run.result["steps"] if s["op"] == "program")


def probing_run(m: Machine, root: Path, table: TrueTable) -> ProbeRun:
    """Copy the shipped configuration, build the true machine, write the program, let LinuxCNC run it."""
    sim = make_sim(root, m.kind, table.hal_lines())
    compile_component(sim, COMPONENT, COMPONENT_NAME)
    program = write_program(m, sim.cfg)
    steps = [{"op": "program", "file": str(program), "timeout": 1800, "clock": "ptt.clock"},
             {"op": "read", "pins": ["ptt.trips", "ptt.clock"]}]
    return ProbeRun(m, sim, table, run_sim(sim, steps))


def run_all(jobs: dict[str, Any]) -> dict[str, Any]:
    """Run several simulations at once (each in its own namespaces), ``{key: callable}`` -> ``{key: result}``."""
    with ThreadPoolExecutor(max_workers=len(jobs)) as pool:
        futures = {k: pool.submit(f) for k, f in jobs.items()}
        return {k: f.result() for k, f in futures.items()}
