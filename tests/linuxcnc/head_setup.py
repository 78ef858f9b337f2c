"""The head run of the LinuxCNC tests (:mod:`test_linuxcnc_head`): its true mixed machine, pige's program for it,
and the simulation that runs the program (one of round one's simulations, :mod:`conftest`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lcnc_harness import RunResult, Sim, compile_component, make_sim, run_sim
from loop_setup import CLEARANCE_MM, KINEMATICS_CODES, POSES, PROBE_FEED_MM_MIN, pige
from true_mixed import COMPONENT_NAME, READ_PINS, SOURCE, TrueMixed

CODE = "wC'bXYZB(C1)t"
PIGE = {"EX0B": 12.0, "EZ0B": -9.0, "EA0B": 45.0, "EC0B": -35.0,
        "EX0C": 10.0, "EY0C": -12.0, "EA0C": 30.0, "EB0C": -40.0}
SENSE = {"B": 1, "C": -1}
PIVOT_MM = np.zeros(3)
TOOL_MM = np.array([0.0, 0.0, -60.0])  # stylus-tip centre 60 mm below the head's pivot
STYLUS = (2, 10.0)  # xyzbc-trt.tbl: T2, 10 mm
SPHERE_MM = np.array([20.0, 10.0, 15.0])
SPHERE_RADIUS_MM, STYLUS_RADIUS_MM = 6.35, 1.5
STEP_MM = PROBE_FEED_MM_MIN / 60.0 * 1e-3  # one 1 ms servo period of probing feed


def true_machine() -> TrueMixed:
    return TrueMixed(PIVOT_MM, TOOL_MM, PIGE, SENSE, STYLUS[1], SPHERE_MM, SPHERE_RADIUS_MM + STYLUS_RADIUS_MM)


def write_program(cfg: Path) -> Path:
    """``pige program --instrument sphere-probe`` for the head, as a user writes it."""
    vec = ",".join
    pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", CODE,
         "--axis-sense", ",".join(f"{a}={s}" for a, s in SENSE.items()),
         "--pivot", vec(f"{v:g}" for v in PIVOT_MM), "--tool", vec(f"{v:g}" for v in TOOL_MM),
         "--rtcp-off", KINEMATICS_CODES[0], "--rtcp-on", KINEMATICS_CODES[1],
         "--sphere", vec(f"{v:g}" for v in SPHERE_MM), "--sphere-radius", f"{SPHERE_RADIUS_MM:g}",
         "--stylus-radius", f"{STYLUS_RADIUS_MM:g}", "--stylus-tool", str(STYLUS[0]),
         "--stylus-length", f"{STYLUS[1]:g}", "--points", str(POSES), "--clearance", f"{CLEARANCE_MM:g}",
         "--probe-feed", f"{PROBE_FEED_MM_MIN:g}", "--out", "probe.ngc", cwd=cfg)
    return cfg / "probe.ngc"



@dataclass
class HeadRun:
    """The head's simulation: the true machine, the folders, pige's program, LinuxCNC's result."""

    machine: TrueMixed
    sim: Sim
    program: Path
    run: RunResult


def head_probing_run(root: Path) -> HeadRun:
    """Copy the shipped xyzbc-trt configuration with the true mixed machine, write the program, let LinuxCNC
    load the stylus (``T2 M6``: the program checks it and applies G43 itself) and run the program."""
    machine = true_machine()
    sim = make_sim(root, "xyzbc", machine.hal_lines())
    compile_component(sim, SOURCE, COMPONENT_NAME)
    program = write_program(sim.cfg)
    steps = [{"op": "mdi", "lines": [f"T{STYLUS[0]} M6"]},
             {"op": "program", "file": str(program), "timeout": 1800, "clock": "ptm.clock"},
             {"op": "read", "pins": READ_PINS}]
    return HeadRun(machine, sim, program, run_sim(sim, steps))
