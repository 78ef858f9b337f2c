"""Diagnosis at scale: 10^4, 10^5 and 10^6 rows of an on-the-fly (continuous) R-test run.

The measurement is simulated in memory (a dense cone-frustum with a squareness and a
thermal drift hidden in it; reading the file is not part of the measurement).  For each
size: the wall time of ``diagnose``, the process' peak resident memory so far (``ru_maxrss``), the
effects named, and the effects named on the same file decimated to 3000 rows.  The
floor is one pass that evaluates the super design (the PIGE and every candidate column)
of every row, chunked, without accumulating anything: any method that tests every
candidate on every row must do at least that.  Targets (issue 14): 10^5 rows ≤ 5 s,
10^6 rows ≤ 60 s, same findings as the decimated file.

BLAS threads: on a small shared machine OpenBLAS's worker threads can spin against other
processes and slow the Gram products by 10× or more; ``OPENBLAS_NUM_THREADS=1`` gives
stable numbers (the table header says which setting was in effect).

Run: ``python benchmarks/bench_diagnosis.py [--quick]``; prints a markdown section.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pige_sym.diagnosis.diagnose import diagnose  # noqa: E402
from pige_sym.measurements.measurement import Measurement  # noqa: E402
from pige_sym.model.effects import parse_effect  # noqa: E402
from pige_sym.model.trajectories import Trajectory, cone_frustum, dwell_times  # noqa: E402
from pige_sym.simulation.simulator import random_pige, simulate  # noqa: E402

AC = "wC'A'bXYZ(C1)t"


def dense_measurement(n: int) -> Measurement:
    """A continuous cone run of n rows with two hidden effects (in memory)."""
    base = cone_frustum(AC, points=n - 1, turns=1.0)
    t = dwell_times(base.angles_deg, move_s=0.0, dwell_s=1200.0 / n)
    tr = Trajectory("dense", base.rotary_axes, base.angles_deg, t, f"continuous cone, {n} rows")
    effs = [parse_effect("squareness_XY:gamma_urad=25", ("A", "C")),
            parse_effect("thermal_drift:vx_um=4,vy_um=-3,vz_um=2,tau_s=300", ("A", "C"))]
    return simulate(AC, tr, pige=random_pige(AC, 1), effects=effs, noise_um=0.25, seed=1).measurement


def decimate(m: Measurement, rows: int) -> Measurement:
    keep = np.unique(np.linspace(0, m.n_rows - 1, rows).astype(int))
    lin = None if m.linear_mm is None else m.linear_mm[keep]
    return Measurement(**{**m.__dict__, "t_s": m.t_s[keep], "angles_deg": m.angles_deg[keep],
                          "deviation_um": m.deviation_um[keep], "linear_mm": lin})


def floor_pass(m: Measurement) -> float:
    """Seconds to evaluate the super design of every row once (module docstring)."""
    from pige_sym.diagnosis.diagnose import _setup
    from pige_sym.identification.normal_sums import CHUNK_ROWS

    setup = _setup(m, None)
    design = setup.design()
    t0 = time.perf_counter()
    for s in range(1, m.n_rows, CHUNK_ROWS):
        design(np.arange(s, min(s + CHUNK_ROWS, m.n_rows)))
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="10^4 and 10^5 rows only")
    args = ap.parse_args(argv)
    sizes = [10_000, 100_000] if args.quick else [10_000, 100_000, 1_000_000]
    targets = {100_000: 5.0, 1_000_000: 60.0}
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    lines = ["## Diagnosis at scale", "", f"OpenBLAS threads: {threads}.", "",
             "| rows | diagnose [s] | floor: one design pass [s] | ratio | peak RSS MB | target | findings | "
             "decimated (3000 rows) | same |",
             "|---:|---:|---:|---:|---:|:---|:---|:---|:---|"]
    for n in sizes:
        m = dense_measurement(n)
        floor = floor_pass(m)
        t0 = time.perf_counter()
        d = diagnose(m)
        dt = time.perf_counter() - t0
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        found = [f.effect for f in d.findings]
        dec = [f.effect for f in diagnose(decimate(m, 3000)).findings]
        target = targets.get(n)
        verdict = "-" if target is None else f"≤ {target:g} s: {'met' if dt <= target else 'MISSED'}"
        same = "yes" if set(found) == set(dec) else "NO"
        lines.append(f"| {n:,} | {dt:.2f} | {floor:.2f} | {dt / floor:.1f}x | {peak:.0f} | {verdict} | "
                     f"{', '.join(found) or '-'} | {', '.join(dec) or '-'} | {same} |")
    lines += ["", "Peak RSS is the whole process so far, including the simulated measurement itself (n × 3 "
              "deviations, angles, linear commands).  Findings are compared as sets (their order follows ΔBIC, "
              "which grows with n)."]
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
