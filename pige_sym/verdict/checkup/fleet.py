"""``pige history fleet``: every machine of the history, its last calibration and check-up, when the next is due.

**Next due** (UTC): right after the last check-up when it said ``drifted`` or ``out`` (or after the last
calibration when it failed its check: overdue since then); otherwise the last run plus the machine's usual
interval — the median gap between its check-ups, or :data:`DEFAULT_INTERVAL_DAYS` days before it has two — brought
forward to the earliest time the last check-up's forecast gives for a PIGE to leave its tolerance (the low end of
the interval, :mod:`~pige_sym.verdict.checkup.trend`; only a shown drift is forecast).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import numpy as np

#: The check-up interval before a machine has two check-ups [days].
DEFAULT_INTERVAL_DAYS = 7.0


@dataclass
class FleetRow:
    """One machine of the fleet (times ISO 8601 UTC)."""

    machine_id: str
    machine: str
    runs: int
    last_full: str | None
    last_full_verdict: str | None
    last_checkup: str | None
    verdict: str | None
    next_due: str
    why: str

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _interval(checkups: list[Any]) -> tuple[timedelta, str]:
    times = [datetime.fromisoformat(r.measured_at) for r in checkups]
    gaps = [(b - a).total_seconds() for a, b in zip(times, times[1:], strict=False)]
    if not gaps:
        return timedelta(days=DEFAULT_INTERVAL_DAYS), f"the default interval ({_days(DEFAULT_INTERVAL_DAYS)})"
    days = float(np.median(gaps)) / 86400.0
    return timedelta(days=days), f"its usual interval ({_days(days)}, median of {len(gaps)} gap{'s' * (len(gaps) > 1)})"


def _minutes(iso: str) -> str:
    return datetime.fromisoformat(iso).isoformat(timespec="minutes")


def _days(days: float) -> str:
    """``1 day``, ``7 days``, ``0.25 days``."""
    text = f"{days:.3g}"
    return f"{text} day" if text == "1" else f"{text} days"


def _forecast(run: Any) -> tuple[str, str] | None:
    """(earliest time a PIGE leaves its tolerance, which) from a check-up's stored trends."""
    soonest = None
    for item in (run.checkup or {}).get("items", []):
        when = (item.get("trend") or {}).get("leaves_low")
        if when is not None and (soonest is None or when < soonest[0]):
            soonest = (when, item["name"])
    return soonest


def fleet_row(runs: list[Any], now: datetime) -> FleetRow:
    """The fleet line of one machine's runs (in measurement order) (module docstring)."""
    full = [r for r in runs if r.kind == "full"]
    checks = [r for r in runs if r.kind == "checkup"]
    last = runs[-1]
    f, c = (full[-1] if full else None), (checks[-1] if checks else None)
    row = FleetRow(last.machine_id, last.machine_code, len(runs), f and f.measured_at, f and f.verdict,
                   c and c.measured_at, c and c.verdict, "", "")
    if last.kind == "checkup" and last.verdict in ("drifted", "out"):
        row.next_due, row.why = _minutes(last.measured_at), f"the last check-up said {last.verdict}"
        return row
    if last.kind == "full" and last.verdict == "fail":
        row.next_due, row.why = _minutes(last.measured_at), "the last calibration failed its check"
        return row
    gap, said = _interval([r for r in checks if f is None or r.measured_at > f.measured_at] or checks)
    due = datetime.fromisoformat(last.measured_at) + gap
    row.next_due, row.why = due.isoformat(timespec="minutes"), f"the last run plus {said}"
    soon = _forecast(c) if c is not None and c is last else None
    if soon is not None and datetime.fromisoformat(soon[0]).astimezone(due.tzinfo) < due:
        row.next_due, row.why = soon[0], f"{soon[1]} may leave its tolerance then (the forecast's earliest time)"
    return row


def fleet(engine: Any, now: datetime) -> list[FleetRow]:
    """Every machine of the history, sorted by id (one query, and one per machine for its last check-up's forecast);
    every run read strictly (:func:`~pige_sym.verdict.history.decode.decode_run`)."""
    from pige_sym.verdict.history.store import all_runs, run_by_id

    by_machine: dict[str, list[Any]] = {}
    for run in all_runs(engine, light=True):
        by_machine.setdefault(run.machine_id, []).append(run)
    for runs in by_machine.values():  # the last check-up's forecast: its whole record
        last = [k for k, r in enumerate(runs) if r.kind == "checkup"]
        if last:
            runs[last[-1]] = run_by_id(engine, runs[last[-1]].id)
    return [fleet_row(runs, now) for _, runs in sorted(by_machine.items())]
