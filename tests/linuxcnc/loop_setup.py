"""The two machines of the LinuxCNC loop and the pige commands run on their files (tests/linuxcnc).

Each machine is LinuxCNC's shipped trt simulation (``xyzac-trt``, ``xyzbc-trt``) as shipped: its trt
kinematics with their pins (the A line at y-offset 20, z-offset 10 from the C line; the B line at x-offset
-20, z-offset -15), which turn the table the other way from CONVENTIONS (σ = −1 for both axes, §9), and its
tool table: the stylus is one of its tools (T9, 30 mm long, in xyzac-trt.tbl; T2, 10 mm, in xyzbc-trt.tbl).
The true table (:mod:`true_table`) has those nominal lines moved by the PIGEs chosen here, tilts included,
and turns the way the kinematics assume.  pige is run as a user runs it: its command line, in a subprocess,
on the files LinuxCNC wrote.
"""

from __future__ import annotations

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from lcnc_harness import IniChange, RunResult, Sim, compile_component, make_sim, run_sim
from true_table import COMPONENT_NAME, TrueTable, component_source

SPHERE_RADIUS_MM = 6.35
STYLUS_RADIUS_MM = 1.5
SPHERE_MM = np.array([20.0, 10.0, 15.0])  # table coordinates = machine coordinates at the reference pose
PROBE_FEED_MM_MIN = 50.0  # with the 1 ms servo period: contacts exact to 0.83 um along the move
CLEARANCE_MM = 1.0
POSES = 12  # cone points: 13 poses with the reference
KINEMATICS_CODES = ("M429", "M428")  # the shipped sims' remaps: identity, TCP (sparm=identityfirst)


@dataclass
class Machine:
    """One shipped trt configuration with its true table."""

    kind: str  # xyzac / xyzbc
    code: str  # ISO 10791 code
    outer: str
    pige: dict[str, float]
    pivots_mm: dict[str, tuple[float, float, float]]  # the stock kinematics' lines (trtfuncs.c, the INI's pins)
    stylus: tuple[int, float]  # tool number and length [mm] in the shipped tool table

    @property
    def axis_sense(self) -> str:
        return f"{self.outer}=-1,C=-1"

    def true_table(self, pige: dict[str, float] | None = None) -> TrueTable:
        return TrueTable(self.code, self.outer, {a: np.array(v) for a, v in self.pivots_mm.items()},
                         self.pige if pige is None else pige, {self.outer: -1, "C": -1}, self.stylus[1],
                         SPHERE_MM, SPHERE_RADIUS_MM + STYLUS_RADIUS_MM)

    def pivot_options(self, pivots: dict[str, tuple[float, float, float]] | None = None) -> list[str]:
        out = []
        for axis, v in (pivots or self.pivots_mm).items():
            out += ["--pivot", f"{axis}=" + ",".join(f"{x:.9g}" for x in v)]
        return out


MACHINES = {
    "AC": Machine("xyzac", "wC'A'bXYZ(C1)t", "A",
                  {"EY0A": 15.0, "EZ0A": -10.0, "EB0A": 60.0, "EC0A": -45.0,
                   "EX0C": 12.0, "EY0C": -8.0, "EA0C": 40.0, "EB0C": -30.0},
                  {"A": (0.0, 20.0, 10.0), "C": (0.0, 0.0, 0.0)}, (9, 30.0)),
    "BC": Machine("xyzbc", "wC'B'bXYZ(C1)t", "B",
                  {"EX0B": -14.0, "EZ0B": 9.0, "EA0B": -50.0, "EC0B": 35.0,
                   "EX0C": 10.0, "EY0C": 11.0, "EA0C": -35.0, "EB0C": 45.0},
                  {"B": (-20.0, 0.0, -15.0), "C": (0.0, 0.0, 0.0)}, (2, 10.0)),
}
MODES = ("identity", "tcp")


def pige(*args: str, cwd: Path) -> str:
    """Run ``pige ARGS`` (``python -m pige_sym``) and return its standard output; fail with its messages."""
    proc = subprocess.run([sys.executable, "-m", "pige_sym", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)
    if proc.returncode != 0:
        raise AssertionError(f"pige {' '.join(args)} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}")
    return proc.stdout


def write_program(m: Machine, cfg: Path, kinematics: str, pivots: dict | None = None,
                  name: str = "probe.ngc") -> Path:
    """``pige program --instrument sphere-probe --dialect linuxcnc`` into the configuration folder."""
    mode = (["--rtcp-off", KINEMATICS_CODES[0], "--rtcp-on", KINEMATICS_CODES[1]] if kinematics == "identity"
            else ["--kinematics", "tcp"])
    pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", m.code,
         "--axis-sense", m.axis_sense, *m.pivot_options(pivots), *mode,
         "--sphere", ",".join(f"{v:g}" for v in SPHERE_MM), "--sphere-radius", f"{SPHERE_RADIUS_MM:g}",
         "--stylus-radius", f"{STYLUS_RADIUS_MM:g}", "--stylus-tool", str(m.stylus[0]),
         "--stylus-length", f"{m.stylus[1]:g}", "--points", str(POSES), "--clearance", f"{CLEARANCE_MM:g}",
         "--probe-feed", f"{PROBE_FEED_MM_MIN:g}", "--out", name, cwd=cfg)
    return cfg / name


def import_and_identify(program: Path, log: Path, out: Path) -> Path:
    """``pige import-probe --program`` (its header gives machine, sense, pivots, kinematics) then
    ``pige identify --json`` into ``<out>.json``: that file."""
    pige("import-probe", str(log), "--format", "linuxcnc", "--program", str(program), "--out", str(out),
         cwd=out.parent)
    result = out.with_suffix(".json")
    result.write_text(pige("identify", str(out), "--json", cwd=out.parent))
    return result


@dataclass
class ProbeRun:
    """A probing run on one machine: the folder, the true table, the kinematics mode, LinuxCNC's result."""

    machine: Machine
    sim: Sim
    table: TrueTable
    kinematics: str
    run: RunResult

    @property
    def log(self) -> Path:
        return self.sim.cfg / "pige_probe.txt"

    @property
    def program(self) -> Path:
        return self.sim.cfg / "probe.ngc"

    def step(self, op: str) -> dict[str, Any]:
        return next(s for s in self.run.result["steps"] if s["op"] == op)

    @property
    def readings(self) -> dict[str, Any]:
        return self.step("read")["readings"][0]

    @cached_property
    def identification_file(self) -> Path:
        return import_and_identify(self.program, self.log, self.sim.root / "probe.csv")

    @cached_property
    def identification(self) -> dict[str, Any]:
        return json.loads(self.identification_file.read_text())


READ_PINS = ["ptt.trips", "ptt.clock", "ptt.twin-diff", "ptt.model-failures"]


def probing_run(m: Machine, root: Path, kinematics: str, *, table: TrueTable | None = None,
                extra: list[IniChange] | None = None, components: dict[str, str] | None = None,
                pivots: dict[str, tuple[float, float, float]] | None = None,
                after: list[dict[str, Any]] | None = None) -> ProbeRun:
    """Copy the shipped configuration (with ``extra`` INI changes and ``components`` compiled beside the true
    machine), write the program (for ``pivots``, default the stock lines), let LinuxCNC run it: TCP kinematics
    selected first if the program probes in them (the sims start in identity), then the stylus loaded
    (``T<n> M6``: the program checks the tool and its length, and applies G43 itself); ``after`` steps follow."""
    table = table or m.true_table()
    sim = make_sim(root, m.kind, table.hal_lines(), extra or [])
    compile_component(sim, component_source(m.code), COMPONENT_NAME)
    for name, source in (components or {}).items():
        compile_component(sim, source, name)
    program = write_program(m, sim.cfg, kinematics, pivots)
    setup = ([KINEMATICS_CODES[1]] if kinematics == "tcp" else []) + [f"T{m.stylus[0]} M6"]
    steps = [{"op": "mdi", "lines": setup},
             {"op": "program", "file": str(program), "timeout": 1800, "clock": "ptt.clock"},
             {"op": "read", "pins": READ_PINS}, *(after or [])]
    return ProbeRun(m, sim, table, kinematics, run_sim(sim, steps))


def run_all(jobs: dict[Any, Any]) -> dict[Any, Any]:
    """Run several simulations at once (each in its own namespaces), ``{key: callable}`` -> ``{key: result}``."""
    with ThreadPoolExecutor(max_workers=len(jobs)) as pool:
        futures = {k: pool.submit(f) for k, f in jobs.items()}
        return {k: f.result() for k, f in futures.items()}
