"""Benchmark of the touch-probe import and identification on a head and on a table, measured in one run.

A 37-pose, 185-contact LinuxCNC log of pige's virtual probing machine (a cone frustum of 36 poses after the
reference, 5 contacts each) on a fork head ``wbXYZCA(C1)t`` (stylus 160 mm below the pivot) and on the AC table
``wC'A'bXYZ(C1)t``:

- *in process*: :func:`~pige_sym.measurements.probe_import.import_probe_log` and
  :func:`~pige_sym.identification.least_squares.identify` (median of repeats, kernels loaded);
- *as commands*: ``pige import-probe`` and ``pige identify`` in fresh processes (wall clock and CPU time,
  interpreter start included), against ``python -c "import numpy, scipy.linalg"`` in the same run.

Target from the issue on heads: a 37-pose, 185-contact head log imports and identifies in under 1 s.
``main()`` prints a markdown section.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pige_sym.identification.least_squares import identify  # noqa: E402
from pige_sym.measurements.probe_import import ProbeImport, import_probe_log  # noqa: E402
from pige_sym.model.trajectories import make_trajectory  # noqa: E402
from pige_sym.nc.probe_program import ProbeSetup, plan_probing  # noqa: E402
from pige_sym.nc.probe_render import render_probe_program  # noqa: E402
from pige_sym.nc.probe_safety import ProbeController  # noqa: E402
from pige_sym.simulation.probe_machine import ProbeMachine, run_probe_program  # noqa: E402
from pige_sym.simulation.simulator import random_pige  # noqa: E402

MACHINES = {"fork head": ("wbXYZCA(C1)t", (0.0, 0.0, -160.0)), "AC table": ("wC'A'bXYZ(C1)t", None)}
CONTROLLER = ProbeController(rtcp_off="M429", rtcp_on="M428", stylus_tool=99, stylus_length_mm=120.0)


def _log(folder: Path, machine: str, tool: tuple[float, float, float] | None) -> Path:
    setup = ProbeSetup(machine, np.array([100.0, 20.0, 60.0]), np.zeros(3), 12.7, 1.5, controller=CONTROLLER,
                       tool_mm=None if tool is None else np.array(tool))
    traj = make_trajectory(machine, "cone-frustum", points=36)
    text = render_probe_program(plan_probing(setup, traj.angles_deg, traj.description), "linuxcnc")
    path = folder / f"{machine[:3]}.txt"
    path.write_text(run_probe_program(text, "linuxcnc", ProbeMachine(setup, random_pige(machine, 1), seed=1)))
    return path


def _in_process(path: Path, machine: str, tool: tuple[float, float, float] | None, repeats: int) -> tuple[float, float]:
    spec = ProbeImport(machine, (0.0, 0.0, 0.0), 12.7, 1.5, tool_mm=tool)
    m = import_probe_log(path, "linuxcnc", spec)
    identify(m)  # warm: kernels loaded, caches filled
    imp, ide = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        m = import_probe_log(path, "linuxcnc", spec)
        t1 = time.perf_counter()
        identify(m)
        ide.append(time.perf_counter() - t1)
        imp.append(t1 - t0)
    return statistics.median(imp), statistics.median(ide)


def _command(args: list[str], repeats: int) -> tuple[float, float]:
    """Median wall clock and CPU time [s] of a fresh process."""
    wall, cpu = [], []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(args, check=True, capture_output=True, env=os.environ | {"PYTHONPATH": str(ROOT)})
        wall.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(wall), statistics.median(cpu)


def main(argv: list[str] | None = None) -> None:
    repeats = 5
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        floor = _command([sys.executable, "-c", "import numpy, scipy.linalg"], repeats)
        for label, (machine, tool) in MACHINES.items():
            log = _log(folder, machine, tool)
            imp, ide = _in_process(log, machine, tool, repeats)
            csv = folder / f"{machine[:3]}.csv"
            cmd = [sys.executable, "-m", "pige_sym", "import-probe", str(log), "--format", "linuxcnc", "--machine",
                   machine, "--sphere-radius", "12.7", "--stylus-radius", "1.5", "--out", str(csv), "--force",
                   *(["--tool", ",".join(f"{v:g}" for v in tool)] if tool else [])]
            c_imp = _command(cmd, repeats)
            c_ide = _command([sys.executable, "-m", "pige_sym", "identify", str(csv)], repeats)
            rows.append((label, imp, ide, c_imp, c_ide))
    print("## Touch probe: import and identification of a head log (benchmarks/bench_probe.py)\n")
    print("37 poses, 185 contacts (LinuxCNC log of the virtual machine). Target on a head: import + identify < 1 s.\n")
    print("| machine | import (in process) | identify (in process) | `pige import-probe` wall / CPU | "
          "`pige identify` wall / CPU | target |\n|---|---:|---:|---:|---:|---|")
    for label, imp, ide, c_imp, c_ide in rows:
        met = "met" if imp + ide < 1.0 else "MISSED"
        print(f"| {label} | {imp * 1e3:.1f} ms | {ide * 1e3:.1f} ms | {c_imp[0]:.2f} / {c_imp[1]:.2f} s | "
              f"{c_ide[0]:.2f} / {c_ide[1]:.2f} s | in process {met}; commands {c_imp[1] + c_ide[1]:.2f} s CPU |")
    print(f"\nFloor of a command: `python -c \"import numpy, scipy.linalg\"` {floor[0]:.2f} s wall / {floor[1]:.2f} s "
          f"CPU in this run (medians of {repeats}); the commands' wall clock depends on the machine's load.")


if __name__ == "__main__":
    main(sys.argv[1:])
