"""The head runs of the LinuxCNC tests (:mod:`test_linuxcnc_head`): a table C + head B on the shipped
``xyzbc-trt`` simulation and a fork head C + A on ``xyzac-trt``, their true machines (:mod:`true_head`),
pige's program for each, and the simulation that runs it (both at once, :mod:`test_linuxcnc_head`).

The programs probe in identity kinematics (M429, back with M428 at the end), where the joints are the axes,
so the shipped trt kinematics never turn anything: joints 3 and 4 are driven as the head's axes (and the
mixed machine's table C).  The stylus is a tool of the shipped tool table.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lcnc_harness import RunResult, Sim, compile_component, make_sim, run_sim
from loop_setup import CLEARANCE_MM, KINEMATICS_CODES, POSES, PROBE_FEED_MM_MIN, pige
from true_head import COMPONENT_NAME, READ_PINS, SOURCE, TrueHead

PIVOT_MM = np.zeros(3)
TOOL_MM = np.array([0.0, 0.0, -60.0])  # stylus-tip centre 60 mm below the head's pivot
SPHERE_MM = np.array([20.0, 10.0, 15.0])
SPHERE_RADIUS_MM, STYLUS_RADIUS_MM = 6.35, 1.5
STEP_MM = PROBE_FEED_MM_MIN / 60.0 * 1e-3  # one 1 ms servo period of probing feed


@dataclass(frozen=True)
class HeadMachine:
    """A head or mixed machine on one shipped simulation."""

    kind: str  # the shipped sim: xyzac / xyzbc
    code: str  # ISO 10791 code
    roles: dict[str, str]  # the axis of joint 3, then of joint 4: its role (true_head.ROLES)
    pige: dict[str, float]
    sense: dict[str, int]
    stylus: tuple[int, float]  # tool number and length [mm] in the shipped tool table

    def true_machine(self) -> TrueHead:
        return TrueHead(self.roles, PIVOT_MM, TOOL_MM, self.pige, self.sense, self.stylus[1], SPHERE_MM,
                        SPHERE_RADIUS_MM + STYLUS_RADIUS_MM)


HEADS = {
    "mixed": HeadMachine("xyzbc", "wC'bXYZB(C1)t", {"B": "head inner", "C": "table outer"},
                         {"EX0B": 12.0, "EZ0B": -9.0, "EA0B": 45.0, "EC0B": -35.0,
                          "EX0C": 10.0, "EY0C": -12.0, "EA0C": 30.0, "EB0C": -40.0},
                         {"B": 1, "C": -1}, (2, 10.0)),
    "fork": HeadMachine("xyzac", "wbXYZCA(C1)t", {"A": "head inner", "C": "head outer"},
                        {"EY0A": -11.0, "EZ0A": 8.0, "EB0A": 50.0, "EC0A": -40.0,
                         "EX0C": 9.0, "EY0C": 13.0, "EA0C": -35.0, "EB0C": 25.0},
                        {"A": -1, "C": 1}, (9, 30.0)),
}


def write_program(m: HeadMachine, cfg: Path) -> Path:
    """``pige program --instrument sphere-probe`` for the head, as a user writes it."""
    vec = ",".join
    pige("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", m.code,
         "--axis-sense", ",".join(f"{a}={s}" for a, s in m.sense.items()),
         "--pivot", vec(f"{v:g}" for v in PIVOT_MM), "--tool", vec(f"{v:g}" for v in TOOL_MM),
         "--rtcp-off", KINEMATICS_CODES[0], "--rtcp-on", KINEMATICS_CODES[1],
         "--sphere", vec(f"{v:g}" for v in SPHERE_MM), "--sphere-radius", f"{SPHERE_RADIUS_MM:g}",
         "--stylus-radius", f"{STYLUS_RADIUS_MM:g}", "--stylus-tool", str(m.stylus[0]),
         "--stylus-length", f"{m.stylus[1]:g}", "--points", str(POSES), "--clearance", f"{CLEARANCE_MM:g}",
         "--probe-feed", f"{PROBE_FEED_MM_MIN:g}", "--out", "probe.ngc", cwd=cfg)
    return cfg / "probe.ngc"


@dataclass
class HeadRun:
    """A head's simulation: the machine, its true machine, the folders, pige's program, LinuxCNC's result."""

    head: HeadMachine
    machine: TrueHead
    sim: Sim
    program: Path
    run: RunResult


def head_probing_run(m: HeadMachine, root: Path) -> HeadRun:
    """Copy the shipped configuration with the true machine, write the program, let LinuxCNC load the stylus
    (``T<n> M6``: the program checks it and applies G43 itself) and run the program."""
    machine = m.true_machine()
    sim = make_sim(root, m.kind, machine.hal_lines())
    compile_component(sim, SOURCE, COMPONENT_NAME)
    program = write_program(m, sim.cfg)
    steps = [{"op": "mdi", "lines": [f"T{m.stylus[0]} M6"]},
             {"op": "program", "file": str(program), "timeout": 1800, "clock": "pth.clock"},
             {"op": "read", "pins": READ_PINS}]
    return HeadRun(m, machine, sim, program, run_sim(sim, steps))
