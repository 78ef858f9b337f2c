"""``pige checkup``: identify a check-up file, compare it with the machine's history, give a verdict, store the run.

1. The file (R-test or probe, the program ``pige program --checkup`` wrote) is fitted for the check-up's PIGEs with
   the others held (:mod:`~pige_sym.identification.subset`; the PIGEs are the program header's, else ``--pige``,
   else those of the machine's last check-up, else the axis lines' positions).
2. Each PIGE is judged against its control limits (:mod:`~pige_sym.verdict.checkup.limits`, learned from the
   check-ups of the machine with the same poses), against its tolerance (ISO 14253-1 decision rule,
   :func:`~pige_sym.verdict.check.decide`), and its trend is fitted and forecast
   (:mod:`~pige_sym.verdict.checkup.trend`).
3. **Verdict**: ``out`` when a PIGE is not shown within its tolerance (``fail`` or, under the guard rule,
   ``undecided``), else ``drifted`` when one is outside its control limits, else ``ok``.  Exit status 0 for ``ok``,
   1 for ``drifted`` and ``out``, 2 for bad input.
4. **Changes to enter** (:mod:`~pige_sym.verdict.checkup.to_enter`): the check-up's PIGEs weighed by their uncertainty,
   within ``--max-change``; with ``--controller`` as ``pige compensate --controller`` prints them.
5. The run is stored with ``kind = checkup`` and what was found (``runs.checkup_json``).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.verdict.checkup.limits import ALPHA, ALPHA_RANGE, METHOD, MIN_DOF, Limit, control_limit, pooled_scatter
from pige_sym.verdict.checkup.reference import FORMAT, ChartState, chart_state, hours
from pige_sym.verdict.checkup.trend import Trend, trend

VERDICTS = ("ok", "drifted", "out")


@dataclass
class CheckupOptions:
    """The options of ``pige checkup`` (its ``--help``)."""

    tolerances: str | os.PathLike[str] | None = None
    rule: str = "guard"
    k: float = 2.0
    alpha: float = ALPHA
    pige: str | None = None
    corrected: bool = False
    date: str | None = None
    controller: str | None = None
    current: Any = None
    carrier: int = 1
    heidenhain_trans: str | None = None
    max_change: tuple[float, float] = (0.2, 0.1)


@dataclass
class Item:
    """One PIGE of a check-up: value, limits, tolerance, trend."""

    name: str
    unit: str
    value: float
    std: float
    limit: Limit | None
    tolerance: float | None
    status: str
    reason: str
    trend: Trend | None = None

    def to_dict(self, origin: str) -> dict[str, Any]:
        t = None if self.trend is None else self.trend.to_dict() | {
            k: when(origin, self.trend_hours(k)) for k in ("leaves_at", "leaves_low", "leaves_high")}
        return {"name": self.name, "unit": self.unit, "value": self.value, "std": self.std,
                "limit": None if self.limit is None else self.limit.to_dict(), "tolerance": self.tolerance,
                "status": self.status, "reason": self.reason, "trend": t}

    def trend_hours(self, key: str) -> float | None:
        return None if self.trend is None else getattr(self.trend, key)


#: A forecast time past the calendar's end (year 9999) in words: no crossing within it.
BEYOND_CALENDAR = "not before 9999-12-31"


def when(origin: str, h: float | None) -> str | None:
    """The ISO time ``h`` hours after ``origin``; None for None and for a time past the year 9999 (a near-zero drift
    crosses its tolerance centuries away: no date to give, :data:`BEYOND_CALENDAR` in words)."""
    if h is None or not math.isfinite(h):
        return None
    try:
        return (datetime.fromisoformat(origin) + timedelta(hours=h)).isoformat(timespec="minutes")
    except OverflowError:
        return None


def when_text(origin: str, h: float | None) -> str | None:
    """:func:`when` in words: :data:`BEYOND_CALENDAR` for a time past the year 9999."""
    at = when(origin, h)
    return BEYOND_CALENDAR if at is None and h is not None and not math.isnan(h) else at


@dataclass
class CheckupResult:
    """What ``pige checkup`` found (module docstring)."""

    machine_id: str
    machine: str
    file: str
    measured_at: str
    verdict: str
    items: list[Item]
    held: dict[str, float]
    provisional: bool
    origin: str
    alpha: float
    signature: str
    segment: int
    corrected: bool
    correction: dict[str, float]
    changes: Any = None
    run_id: int | None = None
    fit: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def exit_status(self) -> int:
        """0 for ``ok``, 1 when action is needed (``drifted``, ``out``)."""
        return 0 if self.verdict == "ok" else 1

    def outside(self) -> dict[str, bool]:
        """Per PIGE: outside its control limits (learned or provisional)."""
        return {i.name: bool(i.limit is not None and i.limit.outside) for i in self.items}

    def flagged(self) -> dict[str, bool]:
        """Per PIGE: outside its learned limits."""
        return {i.name: bool(i.limit is not None and i.limit.outside and not i.limit.provisional) for i in self.items}

    def in_control(self) -> dict[str, bool]:
        """Per PIGE: stays in the chart (:mod:`~pige_sym.verdict.checkup.limits`, ``TRUST_DOF``)."""
        from pige_sym.verdict.checkup.limits import TRUST_DOF

        return {i.name: not (self.flagged()[i.name] and i.limit is not None and i.limit.dof >= TRUST_DOF)
                for i in self.items}

    def chart(self) -> dict[str, Any]:
        """What later check-ups read of this one (:mod:`~pige_sym.verdict.checkup.reference`)."""
        from pige_sym.files import json_ready

        full = self.to_dict()
        return json_ready({k: full[k] for k in ("signature", "after_correction", "in_control", "outside", "flagged",
                                                "to_enter", "tolerance")})

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        return json_ready({
            "format": FORMAT, "machine_id": self.machine_id, "machine": self.machine, "file": self.file,
            "measured_at": self.measured_at, "run": self.run_id, "verdict": self.verdict,
            "exit_status": self.exit_status,
            "free": [i.name for i in self.items], "held": self.held, "provisional": self.provisional,
            "method": METHOD, "alpha": self.alpha, "min_dof": MIN_DOF, "signature": self.signature,
            "segment": self.segment, "after_correction": self.corrected, "correction": self.correction,
            "in_control": self.in_control(), "outside": self.outside(), "flagged": self.flagged(),
            "items": [i.to_dict(self.origin) for i in self.items],
            "tolerance": {i.name: i.tolerance for i in self.items if i.tolerance is not None},
            "to_enter": None if self.changes is None else self.changes.entered,
            "changes": None if self.changes is None else self.changes.to_dict(), "fit": self.fit,
            "notes": self.notes})


def run_checkup(history: Any, path: str | os.PathLike[str], machine_id: str, opts: CheckupOptions) -> CheckupResult:
    """The check-up of one file (module docstring); stored in the history.

    ``history``: :func:`~pige_sym.verdict.history.sqlite_fast.open_history` of the database, or an SQLAlchemy engine.

    Raises
    ------
    InputError, FileFormatError
        Bad input: the file already stored or of another machine, no full calibration, no tolerances, …
    """
    from pige_sym.identification.instruments import instrument
    from pige_sym.identification.subset import identify_subset
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.rtest import read_measurement
    from pige_sym.verdict.checkup.to_enter import checkup_changes
    from pige_sym.verdict.history.records import measurement_time

    if not ALPHA_RANGE[0] <= opts.alpha <= ALPHA_RANGE[1]:
        raise InputError(f"--alpha {opts.alpha:g}: give a false-alarm rate per check-up from {ALPHA_RANGE[0]:g} to "
                         f"{ALPHA_RANGE[1]:g} (default {ALPHA:g}; docs/checkup.md)")
    if hasattr(history, "dialect"):  # an SQLAlchemy engine
        from pige_sym.verdict.history.store import EngineHistory

        history = EngineHistory(history)
    history.existing(Path(path))
    m = read_measurement(path)
    kern = load_kernels(m.machine)
    runs = history.list_runs(machine_id, light=True)
    _same_machine(m, machine_id, runs, kern.MACHINE_CODE, str(path))
    measured, source = measurement_time(Path(path), m.metadata, opts.date)
    if measured <= runs[-1].measured_at:
        raise InputError(f"{path} was measured {measured}, not after the machine's last run (run {runs[-1].id}, "
                         f"{runs[-1].measured_at}): a check-up follows the runs it is compared with (--date)")
    free = _free(m, opts.pige, runs, kern)
    signature = _signature(m, free)
    state = chart_state(runs, free, signature, corrected=opts.corrected, location=list(kern.LOCATION_PARAMETERS))
    if state.setup.instrument != instrument(m):
        raise InputError(f"{path} is an {instrument(m)} file, the last full calibration (run {state.full.id}) an "
                         f"{state.setup.instrument} run: a check-up repeats its instrument and set-up")
    fit = identify_subset(m, free, state.held, **_rtest_noise(state.full) if instrument(m) == "rtest" else {})
    _storable(fit, path)
    tol = _tolerances(opts, runs, kern.MACHINE_CODE, free)
    items, verdict = judge(fit, state, tol, opts, hours(measured, state.origin))
    changes = checkup_changes(fit, m, opts)
    result = CheckupResult(machine_id, kern.MACHINE_CODE, str(Path(path).resolve()), measured, verdict, items,
                           state.held, any(i.limit is None or i.limit.provisional for i in items), state.origin,
                           opts.alpha, signature, state.segment, opts.corrected, state.correction, changes,
                           fit=fit.to_dict(), notes=list(fit.notes) + _notes(items))
    from pige_sym.measurements.run_setup import setup_of

    record = history.add_checkup(Path(path), machine_id, kern.MACHINE_CODE, (measured, source), fit,
                                 setup_of(m).to_dict(), verdict, result.to_dict(), result.chart())
    result.run_id = record.id
    return result


def _storable(fit: Any, path: str | os.PathLike[str]) -> None:
    """A fit the history would refuse to store is refused before it is judged (no limits, trend or changes made of
    an absurd estimate); the history checks the whole row again before it stores it."""
    from pige_sym.errors import SchemaRefusal
    from pige_sym.verdict.history.decode import check_estimate, not_stored

    try:
        check_estimate(list(fit.parameters), fit.units, fit.values, fit.std)
    except SchemaRefusal as exc:
        raise not_stored(path, exc) from None


def _rtest_noise(full: Any) -> dict[str, Any]:
    """The full calibration's noise per component ``σ = RMS·√(N/ν)`` (``N = ν + P``) and ν, for an R-test check-up."""
    if full.rms_um is None or not math.isfinite(full.rms_um) or full.dof <= 0:
        return {}
    n = full.dof + len(full.parameters)
    return {"noise_um": float(full.rms_um) * math.sqrt(n / full.dof), "noise_dof": int(full.dof)}


def _same_machine(m: Any, machine_id: str, runs: list[Any], code: str, path: str) -> None:
    named = m.metadata.get("program_machine_id")
    if named is not None and named != machine_id:
        raise InputError(f"{path} was probed by the check-up program of machine {named!r}, not {machine_id!r}: use "
                         "the right --machine-id")
    if runs[-1].machine_code != code:
        raise InputError(f"machine id {machine_id!r} is a {runs[-1].machine_code} in the history, {path} measures a "
                         f"{code}: use the right --machine-id")


def _free(m: Any, pige: str | None, runs: list[Any], kern: Any) -> list[str]:
    """The check-up's PIGEs: the program header's, else ``--pige``, else the last check-up's, else the default."""
    from pige_sym.measurements.run_setup import parse_free

    stated = m.metadata.get("program_checkup")
    if stated:
        named = parse_free(stated, kern.MACHINE_CODE)
        if pige is not None and parse_free(pige, kern.MACHINE_CODE) != named:
            raise InputError(f"--pige {pige}: the check-up program re-measures {stated}; leave --pige out")
        return named
    if pige is not None:
        return parse_free(pige, kern.MACHINE_CODE)
    last = [r for r in runs if r.kind == "checkup"]
    return list(last[-1].parameters) if last else parse_free(None, kern.MACHINE_CODE)


def _signature(m: Any, free: list[str]) -> str:
    """The PIGEs and the poses (to 0.1°): check-ups with the same signature share their chart."""
    rows = ";".join(",".join(f"{v:.1f}" for v in row) for row in m.angles_deg)
    return f"{','.join(free)}|{rows}"


def _tolerances(opts: CheckupOptions, runs: list[Any], machine: str, free: list[str]) -> dict[str, float]:
    """Limits of the check-up's PIGEs: ``--tolerances``, else the last check-up's, else the last stored check's."""
    if opts.tolerances is not None:
        from pige_sym.verdict.check import read_tolerances

        limits = read_tolerances(opts.tolerances).resolve(machine)
        return {n: limits[n] for n in free if n in limits}
    for run in reversed(runs):
        if run.kind == "checkup" and (run.checkup or {}).get("tolerance"):
            return {n: float(v) for n, v in run.checkup["tolerance"].items() if n in free}
        if run.check:
            stored = {str(i["name"]): float(i["limit"]) for i in run.check.get("items", [])}
            return {n: stored[n] for n in free if n in stored}
    raise InputError(f"no tolerances are stored for machine {runs[0].machine_id}: give --tolerances TOL.json (it is "
                     "kept for the next check-ups)")


def start_std(full: Any, fit: Any) -> dict[str, float]:
    """Standard error of a full calibration's value as a check-up's starting level [µm, µrad].

    The check-up holds the other PIGEs at the calibration's values, so their errors ``δ_H`` move its fit by
    ``−K δ_H`` (:attr:`~pige_sym.identification.subset.SubsetFit.sensitivity`); the difference to the calibration's
    own value ``x_F + δ_F`` carries ``−(δ_F + K δ_H)``, of covariance ``[I K] Σ [I K]ᵀ`` with Σ the calibration's
    covariance of (F, H).
    """
    names = list(fit.parameters) + list(fit.held)
    if fit.sensitivity is None or any(n not in full.parameters for n in names):
        return {}
    idx = [full.parameters.index(n) for n in names]
    cov = np.asarray(full.covariance, dtype=float)[np.ix_(idx, idx)]
    lift = np.hstack([np.eye(len(fit.parameters)), np.asarray(fit.sensitivity)])
    var = np.diag(lift @ cov @ lift.T)
    if not np.isfinite(var).all():
        return {}
    return {n: float(np.sqrt(max(v, 0.0))) for n, v in zip(fit.parameters, var, strict=True)}


def _starts(state: ChartState, fit: Any) -> dict[str, Any]:
    """The segment's starting levels, a full calibration's with its standard error as the fit sees it."""
    from pige_sym.verdict.checkup.limits import Start

    if not any(s.source == "full" for s in state.start.values()):
        return dict(state.start)
    std = start_std(state.full, fit)
    return {n: Start(s.value, std.get(n, s.std), "full") if s.source == "full" else s for n, s in state.start.items()}


def judge(fit: Any, state: ChartState, tol: dict[str, float], opts: CheckupOptions,
          t_now: float) -> tuple[list[Item], str]:
    """Every PIGE of a check-up fit against its limits, its tolerance and its trend; and the verdict."""
    items = _items(fit, state, tol, opts, t_now)
    return items, _verdict(items)


def _items(fit: Any, state: ChartState, tol: dict[str, float], opts: CheckupOptions, t_now: float) -> list[Item]:
    from pige_sym.verdict.check import decide

    items = []
    starts = _starts(state, fit)
    for i, name in enumerate(fit.parameters):
        value, std = float(fit.values[i]), float(fit.std[i])
        limit = control_limit(state.points[name], state.segment, starts.get(name), value=value, run_std=std,
                              run_dof=fit.dof, m=len(fit.parameters), alpha=opts.alpha)
        if name in tol:
            status, reason = decide(value, std, tol[name], rule=opts.rule, k=opts.k)
        else:
            status, reason = "no limit", "no tolerance given for it"
        quiet = pooled_scatter([p for p in state.points[name] if p.in_control and not p.flagged])
        tr = _trend(state.trend[name], (t_now, value), limit, quiet, (std, fit.dof), tol.get(name))
        items.append(Item(name, fit.units[name], value, std, limit, tol.get(name), status, reason, tr))
    return items


def _trend(points: list[tuple[float, float, bool]], new: tuple[float, float], limit: Limit | None,
           quiet: tuple[float | None, int], own: tuple[float, int], tolerance: float | None) -> Trend | None:
    """The trend of the drift episode (the new value outside its limits: the flagged check-ups before it) or of the
    segment (:mod:`~pige_sym.verdict.checkup.trend`), with the chart's scatter of the unflagged check-ups (``quiet``,
    once learned; before: the run's own standard error, ``own``)."""
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
    if not episode and len(window) < 3:  # two quiet check-ups differ by noise in one pair out of ten at 90 %
        return None
    learned = limit is not None and not limit.provisional and quiet[0] is not None and quiet[1] >= MIN_DOF
    scale, nu = (float(quiet[0] or 0.0), quiet[1]) if learned else own
    return trend(np.array([p[0] for p in window]), np.array([p[1] for p in window]), new[0], tolerance,
                 scale=scale, dof=nu, episode=episode)


def _verdict(items: list[Item]) -> str:
    if any(i.status in ("fail", "undecided") for i in items):
        return "out"
    if any(i.limit is not None and i.limit.outside for i in items):
        return "drifted"
    return "ok"


def _notes(items: list[Item]) -> list[str]:
    notes = []
    if any(i.limit is None for i in items):
        notes.append("the first check-up of this segment has no centre to compare with: judged on its tolerance only")
    elif any(i.limit is not None and i.limit.provisional for i in items):
        notes.append(f"provisional limits from the runs' own standard errors: the run-to-run scatter is learned from "
                     f"{MIN_DOF + 1} in-control check-ups with the same poses on (docs/checkup.md)")
    return notes
