"""Timing a ``pige`` command as a user runs it: a fresh process, its wall and CPU time and its peak memory.

Shared by the scale benchmarks (benchmarks/bench_scale_maps.py, benchmarks/bench_scale_history.py).  ``source`` runs
the command with another checkout's ``pige_sym`` (``git archive main | tar -x -C DIR``): the code before a change,
measured in the same run as the code after it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

STEP = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from pige_sym.cli.main import main
code = main(sys.argv[1:])
dt = time.perf_counter() - t0
use = resource.getrusage(resource.RUSAGE_SELF)
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")][0].split()[1]
print(json.dumps({"s": dt, "cpu_s": use.ru_utime + use.ru_stime, "rss_mb": int(hwm) / 1024, "code": code}),
      file=sys.stderr)
"""


def run_pige(argv: list[str], cwd: Path, *, source: Path = ROOT, timeout: float | None = None,
             codes: tuple[int, ...] = (0,)) -> dict[str, Any] | None:
    """``pige ARGV`` in a fresh process with ``source``'s pige_sym: ``{"s", "cpu_s", "rss_mb", "code", "wall_s",
    "stdout"}`` (``s``: from the start of ``main``'s import to its end; ``wall_s``: the whole process), or None when
    it did not finish within ``timeout`` seconds.

    Raises
    ------
    RuntimeError
        The command exited with a status not in ``codes``.
    """
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(source)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-c", STEP, *argv], capture_output=True, text=True, cwd=cwd, env=env,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    wall = time.perf_counter() - t0
    try:
        stats: dict[str, Any] = json.loads(proc.stderr.strip().splitlines()[-1])
    except (IndexError, ValueError):
        stats = {"code": proc.returncode}
    if proc.returncode != 0 or stats["code"] not in codes:
        raise RuntimeError(f"pige {' '.join(argv[:3])} … exited {stats['code']}: {proc.stderr[-2000:]}")
    stats["wall_s"] = wall
    stats["stdout"] = proc.stdout
    return stats


def cell(stats: dict[str, Any] | None, key: str, fmt: str = ".2f", timeout: float | None = None) -> str:
    """A table cell: the number, or ``not done in T s``."""
    if stats is None:
        return f"not done in {timeout:g} s" if timeout else "—"
    return format(stats[key], fmt)


def run_footer(load_start: tuple[float, ...] | str) -> str:
    """The line that ends a scale section: when and where it ran, and the load at its start and end."""
    import os
    import time

    from run import cpu_model, load_average

    return (f"Run {time.strftime('%Y-%m-%d %H:%M %Z')} on {cpu_model()}, {os.cpu_count()} cores; load average "
            f"(1, 5, 15 min) at its start: {load_start}; at its end: {load_average()}.")
