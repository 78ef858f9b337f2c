"""The machines of the cycle's LinuxCNC tests (tests/linuxcnc/test_linuxcnc_cycle.py) and the driver steps they take.

Each simulation is a copy of a shipped trt configuration (:mod:`lcnc_harness`) with a hidden true machine
(:mod:`true_table`: the PIGEs of :mod:`loop_setup`, tilts included), into which ``pige cycle install --force`` puts
the cycle as a user would; with ``kinematics="pige"`` the configuration loads pige's kinematics component instead of
the stock trt kinematics (``pige gen --target linuxcnc``; its pivots and senses those of the stock lines, its PIGE
pins at 0), as :mod:`corrections` loads it.  The operator is the driver (:mod:`lcnc_driver`): it loads the stylus,
calls ``M451``/``M452`` from MDI (or a program), reads pins and the configuration's files between the calls, and
moves the stylus centre onto the sphere centre at the probed poses in TCP kinematics (the true machine's probe off)
to read where the true tool point lands.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from corrections import TRT_MODULE, kinematics_changes
from lcnc_harness import RunResult, Sim, compile_component, make_sim, run_sim
from loop_setup import MACHINES, SPHERE_MM, SPHERE_RADIUS_MM, STYLUS_RADIUS_MM, Machine, pige
from true_table import COMPONENT_NAME, TrueTable, component_source

#: the cycle's record: runs, proposal, journal, history (everything else is the configuration)
RECORD = ["pige_cycle/run/", "pige_cycle/runs/", "pige_cycle/proposal.json", "pige_cycle/journal.jsonl",
          "pige_cycle/history.db", "pige_cycle/values.hal.previous"]
CYCLE_TIMEOUT_S = 1800.0
TIP = ["ptt.tip-x", "ptt.tip-y", "ptt.tip-z"]


@dataclass
class CycleSim:
    """A configuration with the cycle installed: the simulation, its machine, the true table, the kinematics."""

    sim: Sim
    machine: Machine
    table: TrueTable
    kinematics: str
    poses: int
    value_pins: list[str] = field(default_factory=list)

    @property
    def runs(self) -> list[Path]:
        """The run folders in the order they were made."""
        return sorted((self.sim.cfg / "pige_cycle" / "runs").iterdir())  # named by their start time

    def run_of(self, index: int) -> dict[str, Any]:
        """The run's files: request, result, messages (what exists)."""
        run = self.runs[index]
        out: dict[str, Any] = {"path": run}
        for name in ("request", "result", "messages", "prepared"):
            f = run / f"{name}.json"
            if f.is_file():
                out[name] = json.loads(f.read_text())
        return out


def component_lines(m: Machine, name: str) -> list[str]:
    """pige's component with the stock lines as its nominal pivots, σ = −1, its PIGE pins at 0 (the lines ``pige
    compensate --controller linuxcnc`` prints for a machine without errors)."""
    tilt = m.outer.lower()
    lines = [f"setp {name}.sense-{tilt} -1", f"setp {name}.sense-c -1"]
    for axis, xyz in m.pivots_mm.items():
        lines += [f"setp {name}.pivot-{axis.lower()}-{c} {v:g}" for c, v in zip("xyz", xyz, strict=True)]
    return lines + [f"setp {name}.{n.lower()} 0" for n in m.pige]


def install_options(m: Machine, poses: int) -> list[str]:
    return ["--sphere", ",".join(f"{v:g}" for v in SPHERE_MM), "--sphere-radius", f"{SPHERE_RADIUS_MM:g}",
            "--stylus-radius", f"{STYLUS_RADIUS_MM:g}", "--stylus-tool", str(m.stylus[0]),
            "--stylus-length", f"{m.stylus[1]:g}", "--poses", str(poses), "--machine-id", f"LCNC-{m.kind}"]


def cycle_sim(root: Path, key: str, *, kinematics: str = "stock", poses: int = 8,
              table: TrueTable | None = None, extra: list[str] | None = None) -> CycleSim:
    """A simulation of machine ``key`` with the cycle installed (module docstring)."""
    from pige_sym.codegen.targets.linuxcnc_pins import default_name

    m = MACHINES[key]
    table = table or m.true_table()
    changes, components = [], {}
    if kinematics == "pige":
        name = default_name(m.code)
        pige("gen", "--target", "linuxcnc", m.code, "--out", str(root / "kins"), "--force", cwd=root)
        components[name] = (root / "kins" / f"{name}.comp").read_text()
        changes = kinematics_changes(m.kind, name, component_lines(m, name))
    sim = make_sim(root, m.kind, table.hal_lines(), changes)
    compile_component(sim, component_source(m.code), COMPONENT_NAME)
    for name, source in components.items():
        compile_component(sim, source, name)
    pige("cycle", "install", str(sim.ini), *install_options(m, poses), *(extra or []), "--force", cwd=sim.cfg)
    module = default_name(m.code) if kinematics == "pige" else TRT_MODULE[m.kind]
    if kinematics == "pige":
        pins = [f"{module}.{n.lower()}" for n in m.pige]
    else:
        offsets = ("y-offset", "z-offset") if m.outer == "A" else ("x-offset", "z-offset")
        pins = [f"{module}.{p}" for p in ("x-rot-point", "y-rot-point", "z-rot-point", *offsets)]
    return CycleSim(sim, m, table, kinematics, poses, pins)


def files_step(cs: CycleSim) -> dict[str, Any]:
    """SHA-256 of the configuration's files (the cycle's record left out)."""
    return {"op": "files", "root": str(cs.sim.cfg), "exclude": RECORD}


def pins_step(cs: CycleSim) -> dict[str, Any]:
    return {"op": "read", "pins": [*cs.value_pins, "motion.switchkins-type"]}


def cycle_step(line: str, *, allow_error: bool = False) -> dict[str, Any]:
    step: dict[str, Any] = {"op": "mdi", "lines": [line], "timeout": CYCLE_TIMEOUT_S, "clock": "ptt.clock"}
    if allow_error:
        step["allow_error"] = True
    return step


def probed_angles(cs: CycleSim) -> np.ndarray:
    """The commanded angles (tilt, C) [deg] of the poses the cycle probes (its cone, σ = −1): (n, 2)."""
    from pige_sym.model.trajectories import make_trajectory

    return -make_trajectory(cs.machine.code, "cone-frustum", points=cs.poses).angles_deg


def tcp_error_steps(cs: CycleSim) -> list[dict[str, Any]]:
    """The stylus centre commanded onto the sphere centre at every probed pose in TCP kinematics, the true tool
    point read at each (the true machine's probe off meanwhile), then back to identity and the rotary axes at 0."""
    outer = cs.machine.outer
    trip = cs.table.trip_radius_mm
    x, y, z = SPHERE_MM
    moves = [f"G0 X{x:g} Y{y:g} Z{z:g} {outer}{t:.4f} C{c:.4f}" for t, c in probed_angles(cs)]
    return [{"op": "hal", "commands": ["setp ptt.trip-radius -1"]},
            {"op": "mdi", "lines": [f"T{cs.machine.stylus[0]} M6", "M428", f"G43 H{cs.machine.stylus[0]}",
                                    "G0 Z60", *moves], "read": TIP, "timeout": 600},
            {"op": "mdi", "lines": ["G0 Z60", "M429", f"G0 Z60 {outer}0 C0"], "timeout": 600},
            {"op": "hal", "commands": [f"setp ptt.trip-radius {trip!r}"]}]


def tcp_errors(step: dict[str, Any]) -> np.ndarray:
    """|true tool point − sphere centre| at each probed pose [µm], from a :func:`tcp_error_steps` MDI step."""
    tips = np.array([[r[p] for p in TIP] for r in step["readings"][4:]])
    return np.linalg.norm(tips - SPHERE_MM, axis=1) * 1e3


def run_cycle(cs: CycleSim, steps: list[dict[str, Any]]) -> RunResult:
    """LinuxCNC on the configuration: the stylus loaded, then ``steps``."""
    first = [{"op": "mdi", "lines": [f"T{cs.machine.stylus[0]} M6", "G0 Z60"]}]
    return run_sim(cs.sim, first + steps, timeout_s=4 * CYCLE_TIMEOUT_S, attempts=1)


def steps_of(run: RunResult, op: str) -> list[dict[str, Any]]:
    return [s for s in run.result.get("steps", []) if s["op"] == op]


def true_pige_table(cs: CycleSim, change: dict[str, float]) -> dict[str, float]:
    """The true table's pins with its PIGEs changed by ``change`` [µm, µrad] (a warm-up, a moved offset)."""
    pige_values = {k: v + change.get(k, 0.0) for k, v in cs.machine.pige.items()}
    return cs.machine.true_table(pige_values).pin_values()


def table_commands(values: dict[str, float]) -> list[str]:
    return [f"setp ptt.{pin} {v!r}" for pin, v in values.items() if pin.startswith(("err-", "r1-", "r2-"))]

