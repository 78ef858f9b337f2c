"""The probing program's own checks, run on real LinuxCNC (tests/linuxcnc/test_linuxcnc_safety.py): three
controller states the program was not written for, each a short run of the AC machine's identity program."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from lcnc_harness import RunResult, Sim, compile_component, make_sim, run_sim
from loop_setup import MACHINES, write_program
from true_table import COMPONENT_NAME, component_source

#: case: (MDI before the program, sphere moved by [mm], what pige's message says)
CASES = {
    "wrong tool": (["T1 M6"], (0.0, 0.0, 0.0), "this program probes with the stylus tool 9"),
    "work offset": (["T9 M6", "G10 L2 P1 X5"], (0.0, 0.0, 0.0), "G54 is X5"),
    "sphere moved": (["T9 M6"], (0.0, 0.6, 0.0), "the sphere"),
}


def safety_run(case: str, root: Path) -> tuple[Sim, RunResult]:
    """The AC identity program after ``CASES[case]``'s MDI, on a true table with the sphere moved."""
    m = MACHINES["AC"]
    setup, moved, _ = CASES[case]
    table = m.true_table()
    table = dataclasses.replace(table, sphere_mm=table.sphere_mm + np.array(moved))
    sim = make_sim(root, m.kind, table.hal_lines())
    compile_component(sim, component_source(m.code), COMPONENT_NAME)
    program = write_program(m, sim.cfg, "identity")
    steps = [{"op": "mdi", "lines": setup}, {"op": "program", "file": str(program), "timeout": 600}]
    return sim, run_sim(sim, steps, timeout_s=900)
