"""Scale of the probe path: ``pige import-probe`` and ``pige identify`` from 10^3 to 2·10^5 poses.

A LinuxCNC probe log of N poses (five contacts each: the top, then four horizontal contacts of the 15° and 50°
rings, as ``pige program --instrument sphere-probe`` probes; 5·N lines, so 2·10^5 poses are 10^6 lines, the size
of the issue's 1,000,060-line log) is written from the virtual machine's true sphere centres
(:func:`pige_sym.simulation.probe_machine.true_centres`, random PIGEs, 0.5 µm
trigger scatter along each probing move, LinuxCNC's ``%f``).  Then, each in a fresh Python process so that the
peak resident memory (``VmHWM``) belongs to that step alone:

* **import**: ``pige import-probe LOG --format linuxcnc ... --out probe.csv`` (read, group, fit every centre and
  the shared radius, screen faulty contacts, check the result, write the file and read it back);
* **identify**: ``pige identify probe.csv`` (read the file, the generalised least squares with the reference-pose
  coupling in O(n): :mod:`pige_sym.identification.instruments`).

Times are wall clock of the whole command (``main()`` in the process, interpreter start excluded; the start of
``pige`` is in RESULTS.md's start-up section).  The growth is stated as the exponent ``b`` of a least-squares fit
``t = a·N^b`` over the sizes (1 = linear).  The identified PIGEs are compared with the truth (largest
``|error| / std``) so a fast wrong answer cannot pass.

Targets (issue 33): import and identify linear; 2·10^5 poses import in ≤ 15 s and identify in ≤ 5 s; peak memory
≤ 500 MB.  ``main()`` prints a markdown section; ``python benchmarks/bench_scale.py [N ...]``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from commands import STEP  # noqa: E402

from pige_sym.kernels import load_kernels  # noqa: E402
from pige_sym.model.trajectories import cone_frustum  # noqa: E402
from pige_sym.nc.probe_program import ProbeSetup  # noqa: E402
from pige_sym.simulation.probe_machine import ProbeMachine, true_centres  # noqa: E402
from pige_sym.simulation.simulator import random_pige  # noqa: E402

AC = "wC'A'bXYZ(C1)t"
SPHERE = np.array([100.0, 20.0, 60.0])
R, STYLUS = 12.7, 1.5
SIZES = (1_000, 10_000, 100_000, 200_000)
SPHERE_ARGS = ["--sphere-radius", str(R), "--stylus-radius", str(STYLUS)]



def contact_normals() -> tuple[np.ndarray, np.ndarray]:
    """The five contact normals of pige's default pattern (top; +X, −X at 15°; +Y, −Y at 50°) and their moves."""
    out, moves = [np.array([0.0, 0.0, 1.0])], [np.array([0.0, 0.0, -1.0])]
    for elev, az in ((15.0, 0.0), (15.0, 180.0), (50.0, 90.0), (50.0, 270.0)):
        e, a = math.radians(elev), math.radians(az)
        out.append(np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]))
        moves.append(-np.array([math.cos(a), math.sin(a), 0.0]))  # horizontal, towards the centre
    return np.array(out), np.array(moves)


def write_log(path: Path, poses: int, seed: int = 1) -> dict[str, float]:
    """A LinuxCNC log of ``poses`` poses (module docstring); returns the true PIGEs."""
    kern = load_kernels(AC)
    turns = max(1.0, poses / 400.0)  # a cone of about 400 poses per turn
    angles = cone_frustum(AC, points=max(poses - 1, 1), turns=turns).angles_deg[:poses]
    truth = random_pige(AC, seed)
    setup = ProbeSetup(AC, SPHERE, np.zeros(3), R, STYLUS)
    machine = ProbeMachine(setup, truth)
    centres = true_centres(machine, angles)  # (n, 3)
    normals, moves = contact_normals()
    rng = np.random.default_rng(seed)
    # a contact lies on the trigger sphere R + r around the true centre, moved by scatter along its probing move
    # (its radial share cos(move, normal) on the sphere, the rest of the error moves it along the surface)
    points = centres[:, None, :] + (R + STYLUS) * normals[None, :, :]
    points += rng.normal(0.0, 0.5e-3, (poses, len(normals), 1)) * moves[None, :, :]
    rows = np.zeros((poses * len(normals), 9))
    rows[:, :3] = points.reshape(-1, 3)
    for axis, column in (("A", 3), ("C", 5)):
        rows[:, column] = np.repeat(angles[:, kern.ROTARY_AXES.index(axis)], len(normals))
    with open(path, "w", encoding="ascii") as fh:
        for start in range(0, len(rows), 100_000):
            block = rows[start:start + 100_000]
            fh.write("\n".join(" ".join(f"{v:f}" for v in r) for r in block.tolist()) + "\n")
    return truth


def run_step(argv: list[str], cwd: Path) -> dict[str, float]:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", STEP, *argv], capture_output=True, text=True, cwd=cwd,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{argv[0]} failed: {proc.stderr[-2000:]}")
    stats = json.loads(proc.stderr.strip().splitlines()[-1])
    stats["wall_s"] = wall
    stats["stdout"] = proc.stdout
    return stats


def worst_z(identify_json: str, truth: dict[str, float]) -> float:
    res = json.loads(identify_json)
    return max(abs(res["pige"][k] - truth[k]) / res["std"][k] for k in res["pige"])


def exponent(sizes: list[int], seconds: list[float]) -> float:
    """``b`` of the least-squares fit of ``log t = log a + b log N``."""
    return float(np.polyfit(np.log(sizes), np.log(seconds), 1)[0])


def measure(sizes: tuple[int, ...] = SIZES) -> list[dict[str, float]]:
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for n in sizes:
            log = d / f"probe_{n}.txt"
            truth = write_log(log, n)
            lines = sum(1 for _ in open(log, "rb"))
            imp = run_step(["import-probe", str(log), "--format", "linuxcnc", "--machine", AC, *SPHERE_ARGS,
                            "--out", str(d / f"probe_{n}.csv")], d)
            ident = run_step(["identify", str(d / f"probe_{n}.csv"), "--json"], d)
            out.append({"poses": n, "lines": lines, "import_s": imp["s"], "import_cpu": imp["cpu_s"],
                        "import_mb": imp["rss_mb"], "identify_s": ident["s"], "identify_cpu": ident["cpu_s"],
                        "identify_mb": ident["rss_mb"], "worst_z": worst_z(ident["stdout"], truth)})
            log.unlink()
    return out


def main(sizes: tuple[int, ...] = SIZES) -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    rows = measure(sizes)
    ns = [r["poses"] for r in rows]
    b = {k: exponent(ns, [r[k] for r in rows]) for k in ("import_s", "import_cpu", "identify_s", "identify_cpu")}
    big = [r for r in rows if r["poses"] >= 10_000]  # past the fixed cost of start-up and imports
    tail = {k: exponent([r["poses"] for r in big], [r[k] for r in big])
            for k in ("import_s", "import_cpu", "identify_s", "identify_cpu")} if len(big) > 1 else {}
    lines = ["## Probe import and identification at scale (benchmarks/bench_scale.py)", "",
             "LinuxCNC logs of N poses × 5 contacts from the virtual machine (random PIGEs, 0.5 µm scatter); each "
             "command in a fresh process: wall time of `main()`, the process's CPU time (user + system) and its peak "
             f"resident memory (VmHWM). Load average when the run started: {load:.1f} on {os.cpu_count()} cores (the "
             "machine is shared: wall times follow the load, CPU times much less).", "",
             "| poses | log lines | import wall [s] | import CPU [s] | import peak [MB] | identify wall [s] | "
             "identify CPU [s] | identify peak [MB] | worst PIGE error / std |", "|" + "---|" * 9]
    for r in rows:
        lines.append(f"| {r['poses']:,} | {r['lines']:,} | {r['import_s']:.2f} | {r['import_cpu']:.2f} | "
                     f"{r['import_mb']:.0f} | {r['identify_s']:.2f} | {r['identify_cpu']:.2f} | {r['identify_mb']:.0f} "
                     f"| {r['worst_z']:.2f} |")
    lines += ["", f"Growth exponent b (t ∝ N^b, least squares over all sizes): import b = {b['import_s']:.2f} wall, "
              f"{b['import_cpu']:.2f} CPU; identify b = {b['identify_s']:.2f} wall, {b['identify_cpu']:.2f} CPU"
              + (f"; over 10^4 poses and more: import {tail['import_s']:.2f} wall, {tail['import_cpu']:.2f} CPU, "
                 f"identify {tail['identify_s']:.2f} wall, {tail['identify_cpu']:.2f} CPU" if tail else "")
              + " (below 1 over all sizes: start-up and imports are a fixed cost that dominates at 10^3). "
              "Targets: linear; 2·10^5 poses import ≤ 15 s and identify ≤ 5 s; peak ≤ 500 MB."]
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main(tuple(int(x) for x in sys.argv[1:]) or SIZES)
