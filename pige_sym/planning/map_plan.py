"""``pige plan --map AXES``: the setups and poses that determine every map value, their predicted standard errors,
the machine time, and what fewer setups cannot determine.

Sphere probe and R-test (:func:`plan_map_test`): the candidate setups of :mod:`~pige_sym.planning.map_setups`
(three measured points per inner axis, not on one line) at the poses of the map grid; the plan takes the fewest
of them, in order, whose predicted fit determines every value (``--map-setups N`` fixes the number).  Ballbar
(:func:`plan_ballbar_maps`): one reading per pose, so a map needs many setups; candidates are the radial,
tangential and axial setups of :func:`~pige_sym.simulation.ballbar.ballbar_setup` — the table axis swept with the
tilt axis at 0 and at the middle of its range, the tilt axis swept to each end of its range, each with the table
ball at ``--map-point`` and 100 mm higher — added one at a time, each time the one that determines the most values
(then the smallest worst standard error), up to :data:`MAX_BALLBAR_SETUPS`.

The predictions are :func:`~pige_sym.identification.map_design.predict_maps`: the design of ``identify --map``
on the planned files, each file's rows weighed by its instrument's noise.  With fewer setups the same per-angle
test ``identify --map`` runs names the combinations that are not seen (:meth:`MapPlan.summary`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.map_design import MapPrediction, design_sigma, predict_maps
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import SETUPS
from pige_sym.planning.map_setups import (
    MapSetup,
    MapTestRequest,
    axis_nodes,
    map_poses,
    propose_points,
    setup_file,
)

MAX_BALLBAR_SETUPS = 12


@dataclass
class MapPlan:
    """A planned map test.

    Attributes
    ----------
    request : MapTestRequest
    setups : list of MapSetup
        The setups chosen, in order.
    prediction : MapPrediction
        Of the setups chosen.
    fewer : list of (int, MapPrediction)
        Of the first k setups, for every smaller k.
    planning_s : float [s]
    """

    request: MapTestRequest
    setups: list[MapSetup]
    prediction: MapPrediction
    fewer: list[tuple[int, MapPrediction]] = field(default_factory=list)
    planning_s: float = 0.0

    @property
    def seconds(self) -> float:
        return float(sum(s.seconds for s in self.setups))

    def summary(self, pred: MapPrediction) -> list[str]:
        """Per mapped axis: how many values ``pred`` determines, and for the rest the first reason given."""
        out = []
        for ax, m in pred.maps.items():
            stds = np.concatenate([m.std[mo.name] for mo in m.motions])
            left = int((~np.isfinite(stds)).sum())
            names = {mo.name for mo in m.motions} | {f"{ax} maps"}
            why = next((u for u in pred.undetermined if u.motion in names), None)
            text = f"{ax}: {stds.size - left} of {stds.size} values determined"
            if left and why is not None:
                at = "" if why.angle_deg is None else f" (e.g. {why.motion} at {ax} {why.angle_deg:g}°)"
                text += f"; {left} undetermined{at}: {why.why}; remedy: {why.remedy}"
            elif left:
                text += f"; {left} undetermined"
            out.append(text)
        return out

    def to_dict(self) -> dict[str, Any]:
        r = self.request
        return {
            "machine": r.machine, "instrument": r.instrument, "map": list(r.spec.axes), "map_step_deg": r.spec.step_deg,
            "map_per_direction": list(r.spec.per_direction), "noise_um": r.noise_um,
            "ranges_deg": {a: list(v) for a, v in r.ranges.items()},
            "setups": [_setup_dict(s) for s in self.setups], "seconds": self.seconds,
            "complete": self.prediction.complete, "prediction": self.prediction.to_dict(),
            "fewer_setups": [{"setups": k, "determined": p.counts()[0], "values": p.counts()[1],
                              "summary": self.summary(p), "undetermined": [u.to_dict() for u in p.undetermined]}
                             for k, p in self.fewer],
            "planning_s": self.planning_s,
        }


def _setup_dict(s: MapSetup) -> dict[str, Any]:
    out: dict[str, Any] = {"label": s.label, "point_mm": [float(x) for x in s.point_mm],
                           "tool_mm": None if s.tool_mm is None else [float(x) for x in s.tool_mm],
                           "poses": int(s.angles_deg.shape[0]), "seconds": s.seconds, "sigma_um": s.sigma_um}
    if s.contacts:
        out["contacts"] = s.contacts
    if s.ballbar is not None:
        out["ballbar"] = {"kind": s.ballbar.kind, "axis": s.ballbar.axis,
                          "offset_mm": [float(x) for x in s.ballbar.offset_mm],
                          "held_deg": {a: float(v) for a, v in zip(s.ballbar.rotary_axes, s.ballbar.angles_deg[0],
                                                                   strict=True) if a != s.ballbar.axis}}
    return out


def _predict(setups: list[MapSetup], request: MapTestRequest) -> MapPrediction:
    return predict_maps([(s.label, s.item) for s in setups], [s.sigma_um for s in setups], request.spec)


def plan_map_test(request: MapTestRequest) -> MapPlan:
    """The setups, their poses and predictions (module docstring)."""
    start = time.perf_counter()
    if request.instrument == "ballbar":
        return plan_ballbar_maps(request)
    angles = map_poses(request.machine, request.spec, request.ranges)
    pairs = propose_points(request)
    if request.setups is not None and not 1 <= request.setups <= len(pairs):
        raise InputError(f"--map-setups {request.setups}: give 1 to {len(pairs)} (the setups proposed or given)")
    setups: list[MapSetup] = []
    preds: list[MapPrediction] = []
    for i, (point, tool) in enumerate(pairs):
        setups.append(setup_file(request, f"map setup {i + 1}", point, tool, angles))
        preds.append(_predict(setups, request))
        if len(setups) == request.setups or (request.setups is None and preds[-1].complete):
            break
    k = len(setups)
    for s in setups:
        s.label = f"map setup {setups.index(s) + 1} of {k}"
    return MapPlan(request, setups, preds[-1], list(enumerate(preds[:-1], start=1)), time.perf_counter() - start)


def ballbar_candidates(request: MapTestRequest) -> list[MapSetup]:
    """The candidate ballbar setups of a map test (module docstring), each with its planned file."""
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
    balls = [np.asarray(request.point_mm, dtype=float), np.asarray(request.point_mm, dtype=float) + [0.0, 0.0, 100.0]]
    candidates = []
    for ball in balls:
        b = (float(ball[0]), float(ball[1]), float(ball[2]))
        for kind in SETUPS:
            candidates += [ballbar_setup(kern.MACHINE_CODE, kind, table, table_ball_mm=b, tilt_deg=t) for t in
                           (0.0, middle)]
            candidates += [ballbar_setup(kern.MACHINE_CODE, kind, tilt, table_ball_mm=b, tilt_range_deg=end)
                           for end in (lo, hi) if end != 0.0]
    out = []
    for s in candidates:
        run = simulate_ballbar(kern.MACHINE_CODE, s, pige={}, noise_um=0.0)
        n = run.n_rows
        out.append(MapSetup(f"{setup_label(s)}, table ball {', '.join(f'{x:g}' for x in s.table_ball_mm)}",
                            s.table_ball_mm, None, s.angles_deg, n * request.pose_s, run,
                            design_sigma(run, request.noise_um), ballbar=s))
    return out


def plan_ballbar_maps(request: MapTestRequest) -> MapPlan:
    """Ballbar setups added one at a time (module docstring)."""
    start = time.perf_counter()
    candidates = ballbar_candidates(request)
    limit = request.setups or MAX_BALLBAR_SETUPS
    chosen: list[MapSetup] = []
    preds: list[MapPrediction] = []
    while len(chosen) < min(limit, len(candidates)):
        best: tuple[Any, ...] | None = None
        for c in candidates:
            if c in chosen:
                continue
            pred = _predict(chosen + [c], request)
            done, _ = pred.counts()
            worst = max((v for v in (np.nanmax(m.std[mo.name]) if np.isfinite(m.std[mo.name]).any() else np.nan
                                     for m in pred.maps.values() for mo in m.motions) if np.isfinite(v)),
                        default=np.inf)
            key = (-done, worst)
            if best is None or key < best[0]:
                best = (key, c, pred)
        assert best is not None
        chosen.append(best[1])
        preds.append(best[2])
        if request.setups is None and best[2].complete and _covers(best[2], request):
            break
    return MapPlan(request, chosen, preds[-1], list(enumerate(preds[:-1], start=1)), time.perf_counter() - start)


def _covers(pred: MapPrediction, request: MapTestRequest) -> bool:
    """Whether every grid of the prediction spans the planned range of its axis."""
    return all(m.grid.full_turn or m.grid.n >= axis_nodes(ax, request.spec.step_deg, request.ranges).size
               for ax, m in pred.maps.items())


def format_map_plan(plan: MapPlan) -> str:
    """The plan as text: setups, time, predicted standard errors per motion, what fewer setups cannot see."""
    r = plan.request
    pred = plan.prediction
    what = {"sphere-probe": f"sphere probe, contact scatter {r.noise_um:g} um", "rtest": f"R-test, noise "
            f"{r.noise_um:g} um per component", "ballbar": f"ballbar, noise {r.noise_um:g} um per reading"}
    grids = ", ".join(f"{ax} {m.grid.angles_deg[0]:g}..{m.grid.angles_deg[-1]:g}" for ax, m in pred.maps.items())
    lines = [f"map test for {r.machine}: {what[r.instrument]}; maps of {', '.join(r.spec.axes)} every "
             f"{r.spec.step_deg:g} deg ({grids})" + (f"; per direction: {', '.join(r.spec.per_direction)}"
                                                       if r.spec.per_direction else ""),
             f"{len(plan.setups)} setup(s), {plan.seconds / 3600:.2f} h of machine time in all (planned in "
             f"{plan.planning_s:.1f} s)", "",
             f"{'setup':<44}{'point [mm]':>22}{'tool [mm]':>20}{'poses':>7}{'time':>9}"]
    for s in plan.setups:
        tool = "-" if s.tool_mm is None else ", ".join(f"{x:g}" for x in s.tool_mm)
        lines.append(f"{s.label[:43]:<44}{', '.join(f'{x:.4g}' for x in s.point_mm):>22}{tool:>20}"
                     f"{s.angles_deg.shape[0]:>7}{s.seconds / 60:>7.0f} min")
    lines += ["", "predicted standard errors over the grid (every value's in --json):",
              f"{'axis':<6}{'motion':<16}{'unit':<6}{'median':>9}{'worst':>9}   undetermined"]
    for ax, m in pred.maps.items():
        for mo in m.motions:
            std = m.std[mo.name]
            ok = std[np.isfinite(std)]
            med = f"{np.median(ok):.3g}" if ok.size else "-"
            worst = f"{ok.max():.3g}" if ok.size else "-"
            lines.append(f"{ax:<6}{mo.name:<16}{mo.unit:<6}{med:>9}{worst:>9}   {std.size - ok.size} of {std.size}")
    pige = ", ".join(f"{n} {'undetermined' if v is None else f'{v:.3g}'}" for n, v in pred.pige_std.items())
    lines += ["", f"PIGEs and zero-position errors: {pige}"]
    if not pred.complete:
        lines += ["", "not every value is determined by these setups:", *("  " + t for t in plan.summary(pred))]
    for k, p in plan.fewer:
        lines += ["", f"with {'setup 1 alone' if k == 1 else f'the first {k} setups'}:",
                  *("  " + t for t in plan.summary(p))]
    return "\n".join(lines)
