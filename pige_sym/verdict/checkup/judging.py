"""A check-up's PIGEs judged: the scatter learned (the machine and its fleet), the limits, the tolerance, the trend.

1. **The scatter** (:mod:`~pige_sym.verdict.checkup.scatter`): per unit [µm or µrad], the population is every
   location PIGE series of the machine (:attr:`~.reference.ChartState.series`) and of the machines of its structure
   in the same history (the *fleet*, :func:`fleet_series`); the posterior of each judged PIGE's ``τ²``.  While the
   population has fewer than :data:`~.limits.MIN_DOF` degrees of freedom the limits are provisional.
2. **The limits** (:mod:`~pige_sym.verdict.checkup.limits`) of each PIGE against the current segment's runs.
3. **The tolerance**: ISO 14253-1 decision rule (:func:`~pige_sym.verdict.check.decide`) on the error the values in
   force leave, ``x − level`` (:attr:`~.reference.ChartState.level`: a check-up that measures the machine itself
   reads the values in force as its level; one that measures what the controller leaves reads 0).
4. **The trend** (:mod:`~pige_sym.verdict.checkup.trend`) of that error, with the run-to-run scatter as its scale;
   a forecast only where the drift is shown.

**Verdict**: ``out`` when a PIGE is not shown within its tolerance (``fail`` or, under the guard rule, ``undecided``),
else ``drifted`` when one is outside its control limits, else ``ok``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.verdict.checkup.limits import MIN_DOF, TRUST_DOF, Limit, control_limit
from pige_sym.verdict.checkup.reference import ChartState, series_of
from pige_sym.verdict.checkup.scatter import Posterior, Series, posteriors
from pige_sym.verdict.checkup.trend import Trend, trend


@dataclass
class Item:
    """One PIGE of a check-up: value, limits, tolerance, trend; ``left`` the error the values in force leave
    (``value − level``, what the tolerance and the trend judge)."""

    name: str
    unit: str
    value: float
    std: float
    limit: Limit | None
    tolerance: float | None
    status: str
    reason: str
    trend: Trend | None = None
    left: float = 0.0


def fleet_series(fleet: list[list[Any]], names: list[str]) -> list[Series]:
    """The location PIGE series (``names``) of each other machine of the structure (runs in measurement order)."""
    return [s for runs in fleet if runs for s in series_of(runs, names).values() if s.values.size]


def scatter_posteriors(state: ChartState, fleet: list[Series], free: list[str],
                       units: dict[str, str]) -> dict[str, Posterior | None]:
    """Per judged PIGE its scatter's posterior, None while its unit's population is not worth :data:`MIN_DOF`.

    The machine's newest check-ups (:attr:`~.scatter.Series.recent`) are left out while the population is worth
    :data:`MIN_DOF` without them."""
    out: dict[str, Posterior | None] = {}
    for unit in sorted({units[n] for n in free}):
        fleet_group = [s for s in fleet if units.get(s.name) == unit]
        own = {n: s for n, s in state.series.items() if units.get(n) == unit and s.values.size}
        settled = {n: s.settled() for n, s in own.items()}
        if sum(s.dof for s in [*settled.values(), *fleet_group]) >= MIN_DOF:
            own = settled
        group = [*own.values(), *fleet_group]
        judged = [own[n] for n in free if units[n] == unit and n in own]
        found = posteriors(judged, group) if sum(s.dof for s in group) >= MIN_DOF else {}
        out |= {n: found.get(n) for n in free if units[n] == unit}
    return out


def judge(fit: Any, state: ChartState, tol: dict[str, float], opts: Any, t_now: float,
          fleet: list[Series] | None = None) -> tuple[list[Item], str]:
    """Every PIGE of a check-up fit against its limits, its tolerance and its trend; and the verdict (module
    docstring).  ``opts``: :class:`~.routine.CheckupOptions` (``alpha``, ``rule``, ``k``)."""
    from pige_sym.verdict.check import decide

    posts = scatter_posteriors(state, fleet or [], list(fit.parameters), dict(fit.units))
    items = []
    for i, name in enumerate(fit.parameters):
        value, std = float(fit.values[i]), float(fit.std[i])
        values, variances = state.runs.get(name, (np.zeros(0), np.zeros(0)))
        limit = control_limit(values, variances, posts.get(name), value=value, variance=std * std,
                              run_dof=int(fit.dof), m=len(fit.parameters), alpha=opts.alpha)
        level = state.level.get(name, 0.0)
        if name in tol:
            status, reason = decide(value - level, std, tol[name], rule=opts.rule, k=opts.k)
        else:
            status, reason = "no limit", "no tolerance given for it"
        points = [(t, x - level, out) for t, x, out in state.trend.get(name, [])]
        tr = _trend(points, (t_now, value - level), limit, posts.get(name), std, tol.get(name),
                    opts.alpha / len(fit.parameters))
        items.append(Item(name, fit.units[name], value, std, limit, tol.get(name), status, reason, tr, value - level))
    return items, verdict_of(items)


def _trend(points: list[tuple[float, float, bool]], new: tuple[float, float], limit: Limit | None,
           post: Posterior | None, std: float, tolerance: float | None, shown_alpha: float) -> Trend | None:
    """The trend of the drift episode (the new value outside its limits: the run of flagged check-ups it ends) or of
    the segment's check-ups (:mod:`~pige_sym.verdict.checkup.trend`), scaled by the run-to-run scatter (the
    posterior median of ``τ`` with the run's own standard error; provisional: the run's own alone)."""
    from pige_sym.verdict.checkup.trend import WINDOW

    episode = bool(limit is not None and limit.outside)
    if episode:
        k = len(points)
        while k > 0 and points[k - 1][2]:
            k -= 1
        window = [p[:2] for p in points[k:]]
    else:
        window = [p[:2] for p in points[-(WINDOW - 1):]]
    window.append(new)
    if not episode and len(window) < 3:
        return None
    if post is None:
        scale, dof = std, 1.0
    else:
        scale, dof = math.sqrt(post.median**2 + std * std), max(post.effective_dof(std * std), 1.0)
    return trend(np.array([p[0] for p in window]), np.array([p[1] for p in window]), new[0], tolerance,
                 scale=scale, dof=dof, episode=episode, shown_alpha=shown_alpha)


def verdict_of(items: list[Item]) -> str:
    """``out``, ``drifted`` or ``ok`` (module docstring)."""
    if any(i.status in ("fail", "undecided") for i in items):
        return "out"
    if any(i.limit is not None and i.limit.outside for i in items):
        return "drifted"
    return "ok"


def flags(items: list[Item]) -> dict[str, dict[str, bool]]:
    """Per PIGE: ``outside`` its limits, ``flagged`` by learned ones, and whether it stays ``in_control`` (a value
    the learned limits flag with :data:`TRUST_DOF` behind them leaves the centre and the scatter)."""
    outside = {i.name: bool(i.limit is not None and i.limit.outside) for i in items}
    flagged = {i.name: bool(outside[i.name] and i.limit is not None and not i.limit.provisional) for i in items}
    in_control = {i.name: not (flagged[i.name] and i.limit is not None and i.limit.dof >= TRUST_DOF) for i in items}
    return {"outside": outside, "flagged": flagged, "in_control": in_control}
