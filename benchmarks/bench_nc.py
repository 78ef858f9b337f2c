"""Benchmark: compensating a 100k-block five-axis NC program (target <= 5 s).

Measured in one run: the whole ``compensate_nc`` (interpret, plan, compensate, rewrite, read back
and verify, change report) against its floors: interpreting the program once (the read-back does
it a second time), the vectorised compensation of its poses, and the change report's physics (the
predicted tool-point and orientation errors of every changed block before and after, two
vectorised model evaluations).  Prints a markdown section.
"""

from __future__ import annotations

import gc
import os
import time
from typing import Any

import numpy as np


def cam_program(n_blocks: int, seed: int = 0) -> str:
    """A CAM-style 840D program: header comments, TRAORI, ``n_blocks`` G1 blocks with F words."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 40 * np.pi, n_blocks)
    x = 60 * np.cos(t) + rng.normal(0, 0.01, n_blocks)
    y = 60 * np.sin(t)
    z = 40 + 10 * np.sin(t / 7)
    a = -30 + 25 * np.sin(t / 3)
    c = np.degrees(t) % 360
    lines = ["%_N_BENCH_MPF", ";$PATH=/_N_MPF_DIR", "; NX post, tool T1 D10 ball", "G90 G71 G17 G64", "TRAORI",
             "G54", "N10 G0 X60 Y0 Z100 A0 C0"]
    for i in range(n_blocks):
        lines.append(f"N{20 + 2 * i} G1 X{x[i]:.4f} Y{y[i]:.4f} Z{z[i]:.4f} A{a[i]:.4f} C{c[i]:.4f} F2000")
    lines += ["TRAFOOF", "M30"]
    return "\n".join(lines) + "\n"


def main(n_blocks: int = 100_000) -> None:
    from pige_sym.compensation.kinematics import compensate_poses, predicted_errors
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.compensation.program import compensate_nc
    from pige_sym.kernels import load_kernels
    from pige_sym.nc.program import parse_program

    code = "wC'A'bXYZ(C1)t"
    kern = load_kernels(code)
    values = {"EY0A": 12.0, "EZ0A": -9.0, "EB0A": 25.0, "EC0A": -18.0, "EX0C": -14.0, "EY0C": 10.0,
              "EA0C": 20.0, "EB0C": -22.0}
    params = CompensationParameters(kern.MACHINE_CODE, values, {}, None, {}, "bench", [])
    text = cam_program(n_blocks)

    def timed(fn: Any) -> tuple[Any, float, float]:
        gc.disable()  # as compensate_nc does: every step is timed without the cyclic collector
        try:
            w0, c0 = time.perf_counter(), time.process_time()
            out = fn()
            return out, time.perf_counter() - w0, time.process_time() - c0
        finally:
            gc.enable()

    def loop() -> None:
        x = 0
        for i in range(1_000_000):
            x += i

    _, w_loop, c_loop = timed(loop)
    prog, w_parse, c_parse = timed(lambda: parse_program(text, dialect="siemens"))
    poses = np.array([b.after for b in prog.blocks if b.is_motion])
    comp, w_model, c_model = timed(lambda: compensate_poses(code, values, poses[:, 3:], poses[:, :3], rtcp=True,
                                                            max_angle_step_deg=0.1, keep_turn=True))
    a, xyz, on = comp.angles_deg, comp.xyz_mm, np.ones(len(poses), dtype=bool)
    zero = np.zeros_like(a)
    new_a, new_xyz = comp.new_angles_deg, comp.new_xyz_mm
    _, w_pred, c_pred = timed(lambda: (predicted_errors(params, a, xyz, on, a, xyz, zero),
                                       predicted_errors(params, a, xyz, on, new_a, new_xyz, zero)))
    res, w_all, c_all = timed(lambda: compensate_nc(text, params, path="bench.mpf", dialect="siemens"))
    print(f"## NC compensation ({n_blocks} blocks, 840D, TRAORI)\n")
    print("| step | wall [s] | CPU [s] | CPU ratio to whole |")
    print("|---|---|---|---|")
    print(f"| interpret once (floor) | {w_parse:.2f} | {c_parse:.2f} | {c_parse / c_all:.2f} |")
    print(f"| compensate poses, vectorised (floor) | {w_model:.2f} | {c_model:.2f} | {c_model / c_all:.2f} |")
    print(f"| change report's predicted errors before + after, vectorised (floor) | {w_pred:.2f} | {c_pred:.2f} | "
          f"{c_pred / c_all:.2f} |")
    print(f"| whole `compensate_nc` (interpret, plan, compensate, rewrite, read back, report) | {w_all:.2f} | "
          f"{c_all:.2f} | 1 |")
    print(f"\n{res.report.compensated} blocks changed; target <= 5 s: {'met' if w_all <= 5 else 'MISSED'} "
          f"(machine speed: a 10^6-step Python loop takes {c_loop:.3f} s CPU here; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")


if __name__ == "__main__":
    main()
