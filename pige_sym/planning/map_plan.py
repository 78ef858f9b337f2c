"""``pige plan --map AXES``: the setups and poses that determine every map value, their predicted standard errors,
the machine time, and what fewer setups cannot determine.

Sphere probe and R-test (:func:`plan_map_test`): the candidate setups of :mod:`~pige_sym.planning.map_setups`
(three measured points per inner axis, not on one line) at the poses of the map grid; the plan takes the fewest
of them, in order, whose predicted fit determines every value (``--map-setups N`` fixes the number).  The ballbar
has its own search (:mod:`~pige_sym.planning.map_ballbar`).

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
from pige_sym.identification.map_design import MapPrediction, predict_maps
from pige_sym.planning.map_setups import (
    MapSetup,
    MapTestRequest,
    map_poses,
    propose_points,
    setup_file,
)


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
                              "summary": self.summary(p)} for k, p in self.fewer],
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


def predict_setups(setups: list[MapSetup], request: MapTestRequest) -> MapPrediction:
    """The prediction of ``identify --map`` on the setups' planned files."""
    return predict_maps([(s.label, s.item) for s in setups], [s.sigma_um for s in setups], request.spec)


def plan_map_test(request: MapTestRequest, *, fewer: bool = True) -> MapPlan:
    """The setups, their poses and predictions (module docstring).  With ``request.setups`` given and ``fewer``
    False, only the chosen set is predicted (what ``pige program --map`` needs)."""
    start = time.perf_counter()
    if request.instrument == "ballbar":
        raise InputError("ballbar map tests are planned by pige_sym.planning.map_ballbar.plan_ballbar_maps")
    angles = map_poses(request.machine, request.spec, request.ranges)
    pairs = propose_points(request)
    if request.setups is not None and not 1 <= request.setups <= len(pairs):
        raise InputError(f"--map-setups {request.setups}: give 1 to {len(pairs)} (the setups proposed or given)")
    setups: list[MapSetup] = []
    preds: list[MapPrediction] = []
    for i, (point, tool) in enumerate(pairs):
        try:
            setups.append(setup_file(request, f"map setup {i + 1}", point, tool, angles))
        except InputError as exc:
            where = f"point {', '.join(f'{x:.6g}' for x in point)} mm" + (
                "" if tool is None else f", tool {', '.join(f'{x:.6g}' for x in tool)} mm")
            raise InputError(f"map setup {i + 1} ({where}): {exc} (give --map-point / --map-tool, --map-range or "
                             "--map-step)") from None
        if fewer or request.setups is None or len(setups) == request.setups:
            preds.append(predict_setups(setups, request))
        if len(setups) == request.setups or (request.setups is None and preds[-1].complete):
            break
    for s in setups:
        s.label = f"map setup {setups.index(s) + 1} of {len(setups)}"
    return MapPlan(request, setups, preds[-1], list(enumerate(preds[:-1], start=1)), time.perf_counter() - start)


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
    if r.target is not None:
        met = "within" if pred.worst_std() <= r.target else f"NOT within (best found with {len(plan.setups)} setups)"
        lines += ["", f"worst predicted std {pred.worst_std():.3g}: {met} --target {r.target:g}"]
    pige = ", ".join(f"{n} {'undetermined' if v is None else f'{v:.3g}'}" for n, v in pred.pige_std.items())
    lines += ["", f"PIGEs and zero-position errors: {pige}"]
    if not pred.complete:
        lines += ["", "not every value is determined by these setups:", *("  " + t for t in plan.summary(pred))]
    for k, p in plan.fewer:
        lines += ["", f"with {'setup 1 alone' if k == 1 else f'the first {k} setups'}:",
                  *("  " + t for t in plan.summary(p))]
    return "\n".join(lines)
