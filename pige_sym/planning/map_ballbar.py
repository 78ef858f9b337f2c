"""Ballbar setups for a map test (``pige plan --instrument ballbar --map AXES``).

A ballbar reads one length per pose, so at one angle a setup gives one number where the motions have six:
a map needs many setups, whose bars lie along different directions at different places of the table.
Candidates (:func:`ballbar_candidates`): the radial, tangential and axial setups of
:func:`~pige_sym.simulation.ballbar.ballbar_setup` with the table ball at ``--map-point`` (default
100, 0, 50 mm), 100 mm higher, and twice as far from the table axis — the table axis swept with the tilt axis
at 0 and near the middle of its range, the tilt axis swept to each end of its range.

The search (:func:`plan_ballbar_maps`) adds one candidate at a time: the one after which the per-angle test of
``identify --map`` (:func:`~pige_sym.identification.map_check.local_check`) sees the most map columns, ties
broken by the largest sum over the grid angles of the smallest scaled singular value of their columns (the
combination seen worst).  Once every column is seen, the full prediction
(:func:`~pige_sym.identification.map_design.predict_maps`) decides; the search stops when it determines every
value on the whole planned grid (and, with ``--target``, the worst predicted standard error is within it), or
after :data:`MAX_BALLBAR_SETUPS` setups — then the plan says what is left.
The per-angle scores use the blocks of ``identify --map`` built once for every candidate on the common grid.
"""

from __future__ import annotations

import time

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.joint import Block
from pige_sym.identification.map_check import MapLayout, local_check
from pige_sym.identification.map_design import MapPrediction, design_sigma
from pige_sym.identification.maps import map_blocks
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import SETUPS
from pige_sym.planning.map_plan import MapPlan, predict_setups
from pige_sym.planning.map_setups import MapSetup, MapTestRequest, axis_nodes

MAX_BALLBAR_SETUPS = 12


def ballbar_candidates(request: MapTestRequest) -> list[MapSetup]:
    """The candidate setups (module docstring), each with its planned file (no data)."""
    from pige_sym.planning.ballbar import setup_label
    from pige_sym.simulation.ballbar import ballbar_setup, simulate_ballbar

    kern = load_kernels(request.machine)
    table = next((a for a in kern.ROTARY_AXES if a[0] == "C"), None)
    tilt = next((a for a in kern.ROTARY_AXES if a != table), None)
    if table is None or tilt is None or kern.TOOL_ROTARY:
        raise InputError(f"{kern.MACHINE_CODE}: ballbar setups are planned for a C table on a tilt axis")
    lo, hi = request.ranges[tilt]
    nodes = axis_nodes(tilt, request.spec.step_deg, request.ranges)
    middle = float(nodes[np.argmin(np.abs(nodes - (lo + hi) / 2))]) or float(nodes[-1])
    p = np.asarray(request.point_mm, dtype=float)
    balls = [p, p + [0.0, 0.0, 100.0], p * [2.0, 2.0, 1.0]]
    setups = []
    for ball in balls:
        b = (float(ball[0]), float(ball[1]), float(ball[2]))
        for kind in SETUPS:
            setups += [ballbar_setup(kern.MACHINE_CODE, kind, table, table_ball_mm=b, tilt_deg=t) for t in
                       (0.0, middle)]
            setups += [ballbar_setup(kern.MACHINE_CODE, kind, tilt, table_ball_mm=b, tilt_range_deg=end)
                       for end in (lo, hi) if end != 0.0]
    out = []
    for s in setups:
        run = simulate_ballbar(kern.MACHINE_CODE, s, pige={}, noise_um=0.0)
        out.append(MapSetup(f"{setup_label(s)}, table ball {', '.join(f'{x:g}' for x in s.table_ball_mm)}",
                            s.table_ball_mm, None, s.angles_deg, run.n_rows * request.pose_s, run,
                            design_sigma(run, request.noise_um), ballbar=s))
    return out


def _scores(blocks: list[Block], sigmas: list[float], p: int, layout: MapLayout) -> tuple[int, float]:
    """(columns the per-angle test sees, sum over the grid angles of the smallest scaled singular value)."""
    _, kept = local_check(blocks, sigmas, p, layout)
    a = np.vstack([b.design[:, p:] / s for b, s in zip(blocks, sigmas, strict=True)])
    total = 0.0
    for ax, grid in layout.grids.items():
        for g in range(grid.n):
            idx = [j for j, (m, gg) in enumerate(layout.columns) if m.axis == ax and gg == g]
            cols = a[:, idx]
            norms = np.linalg.norm(cols, axis=0)
            if np.all(norms > 0):
                total += float(np.linalg.svd(cols / norms, compute_uv=False)[-1])
    return int(kept.sum()), total


def plan_ballbar_maps(request: MapTestRequest) -> MapPlan:
    """The ballbar setups of a map test, added one at a time (module docstring)."""
    start = time.perf_counter()
    candidates = ballbar_candidates(request)
    _, names, layout, blocks = map_blocks([(c.label, c.item) for c in candidates], request.spec)
    p = len(names)
    limit = min(request.setups or MAX_BALLBAR_SETUPS, len(candidates))
    chosen: list[int] = []
    preds: list[MapPrediction] = []
    while len(chosen) < limit:
        rest = [i for i in range(len(candidates)) if i not in chosen]
        scored = [(_scores([blocks[j] for j in chosen + [i]], [candidates[j].sigma_um for j in chosen + [i]], p,
                           layout), i) for i in rest]
        chosen.append(max(scored, key=lambda t: t[0])[1])
        if request.setups is None and max(scored)[0][0] == len(layout.columns):
            pred = predict_setups([candidates[i] for i in chosen], request)
            within = request.target is None or pred.worst_std() <= request.target
            if pred.complete and _covers(pred, request) and within:
                break
    setups = [candidates[i] for i in chosen]
    preds = [predict_setups(setups[:k], request) for k in range(1, len(setups) + 1)]
    return MapPlan(request, setups, preds[-1], list(enumerate(preds[:-1], start=1)), time.perf_counter() - start)


def _covers(pred: MapPrediction, request: MapTestRequest) -> bool:
    """Whether every grid of the prediction spans the planned range of its axis."""
    return all(m.grid.full_turn or m.grid.n >= axis_nodes(ax, request.spec.step_deg, request.ranges).size
               for ax, m in pred.maps.items())
