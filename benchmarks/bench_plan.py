"""Benchmark of ``pige plan``: planned vs default cone, the prediction against simulated runs, planning time.

For each shipped machine, in one run: the default cone frustum (``pige program --trajectory
cone-frustum --points 30``) and the planned test with the same 30 poses, the same noise
(0.25 µm), the same ball (120, 0, 80 mm; head machines with the ball 250 mm below the last
pivot) and the same limits (rotary axis endless; tilt axis -90..90°, which contains the
default cone, and again 0..40°, the default cone's own tilt range).  Columns: worst
predicted standard error of each (µm or µrad), their ratio (target ≤ 0.5), the planning
time (target ≤ 10 s), and the range over the eight PIGEs of the empirical standard
deviation over 30 simulated runs of the plan (random PIGEs, simulate + identify) divided
by the predicted one (target within [0.65, 1.5]).

Run ``python benchmarks/bench_plan.py``; prints a markdown section.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pige_sym.constants import SHIPPED_MACHINES  # noqa: E402
from pige_sym.identification.least_squares import identify  # noqa: E402
from pige_sym.kernels import load_kernels  # noqa: E402
from pige_sym.model.trajectories import Trajectory  # noqa: E402
from pige_sym.planning import PlanRequest, Setup, parse_limits, plan_test  # noqa: E402
from pige_sym.planning.plan import schedule_times  # noqa: E402
from pige_sym.simulation.simulator import random_pige, simulate  # noqa: E402

POINTS = 30
NOISE = 0.25
BALL = (120.0, 0.0, 80.0)
TOOL = (0.0, 0.0, -250.0)
RUNS = 30


def empirical_ratio(code: str, plan, tool) -> np.ndarray:
    """Empirical std of (estimate − truth) over RUNS simulated runs / predicted std, per PIGE."""
    axes = load_kernels(code).ROTARY_AXES
    tr = Trajectory("plan", axes, plan.angles_deg, schedule_times(plan.angles_deg.shape[0], 5, 7), "plan")
    errs = []
    for seed in range(RUNS):
        truth = random_pige(code, 500 + seed)
        sim = simulate(code, tr, pige=truth, ball_mm=plan.setup.ball_mm, tool_mm=tool, noise_um=NOISE, seed=seed)
        res = identify(sim.measurement)
        errs.append([res.value(p) - truth[p] for p in res.parameters])
    return np.sqrt((np.array(errs) ** 2).mean(axis=0)) / plan.prediction.std


def _worst_name(pred) -> str:
    return pred.names[int(np.nanargmax(pred.std))]


def main() -> str:
    lines = ["## Test planning (`pige plan`)", "",
             f"{POINTS} poses, noise {NOISE} um, ball {BALL} mm (head machines: tool {TOOL} mm), rotary axis endless. "
             "Tilt axis limited to -90..90 deg (contains the default cone) or to 0..40 deg (the default cone's own "
             f"tilt range). Empirical/predicted std over {RUNS} simulated runs of the plan (-90..90 only).", "",
             "| machine | tilt limits | default cone worst std | planned worst std | ratio (<= 0.5) | family "
             "| planning s (<= 10) | empirical/predicted min..max ([0.65, 1.5]) |",
             "|---|---|---|---|---|---|---|---|"]
    for code in SHIPPED_MACHINES:
        kern = load_kernels(code)
        tool = TOOL if kern.TOOL_ROTARY else None
        tilt = "A" if "A" in kern.ROTARY_AXES else "B"
        for limits in ("-90:90", "0:40"):
            req = PlanRequest(Setup(code, BALL, tool, noise_um=NOISE), POINTS,
                              parse_limits([f"{tilt}={limits}"], kern))
            t0 = time.perf_counter()
            plan = plan_test(req)
            elapsed = time.perf_counter() - t0
            assert plan.baseline is not None
            check = "—"
            if limits == "-90:90":
                ratio = empirical_ratio(code, plan, tool)
                check = f"{ratio.min():.2f}..{ratio.max():.2f}"
            base = f"{plan.baseline.worst:.3f} ({_worst_name(plan.baseline)})"
            planned = f"{plan.prediction.worst:.3f} ({_worst_name(plan.prediction)})"
            ratio_text = f"{plan.prediction.worst / plan.baseline.worst:.3f}"
            lines.append(f"| `{code}` | {tilt} {limits} | {base} | {planned} | {ratio_text} | {plan.family} | "
                         f"{elapsed:.2f} | {check} |")
    text = "\n".join(lines) + "\n"
    print(text)
    return text


if __name__ == "__main__":
    main()
