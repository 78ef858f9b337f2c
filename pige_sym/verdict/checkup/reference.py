"""What a new check-up is compared with: the machine's runs read as a control chart.

From a machine's runs in measurement order (:func:`~pige_sym.verdict.history.list_runs`):

- **the last full calibration** with its set-up (``runs.setup_json``; for a run stored before schema version 2,
  read again from its file when that is still there): the poses and the sphere of a check-up are planned from it,
  and the PIGEs a check-up does not re-measure are *held* at its values (less a correction entered right after it,
  when the check-ups measure what the controller leaves of the errors);
- **segments**: a run stored after a correction was entered (``--corrected``: ``pige checkup`` and ``pige history
  add``) starts one; a full calibration alone does not (consecutive calibrations of an unchanged machine show its
  run-to-run scatter);
- **the scatter's data** (:func:`series_of`, :mod:`~pige_sym.verdict.checkup.scatter`): per location PIGE every run
  that measured it, full calibrations and check-ups, in control, with its segment; the newest :data:`LAG` check-ups
  marked recent;
- **the current segment's runs** per re-measured PIGE, the limits' centre (:mod:`~pige_sym.verdict.checkup.limits`),
  started, after a correction, by the previous run (less the correction when the check-ups measure what the
  controller leaves);
- **the values in force** (:attr:`ChartState.in_force`) and the level a check-up reads when nothing changed.

What a check-up measures (:func:`measures_machine`): probing in identity kinematics (RTCP off) measures the machine's
own errors, whatever the controller's kinematics hold, so a correction entered does not move what it reads; an
R-test or probing in TCP kinematics measures what the controller's kinematics leave of them, which a correction
entered moves by what was entered.

A correction is what pige printed to enter: a check-up's ``to_enter`` (the changes of its PIGEs, weighed), or for a
full calibration every PIGE weighed by its uncertainty (:func:`~pige_sym.compensation.weighing.entered_values`, what
``pige compensate --controller`` enters).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.measurements.run_setup import RunSetup
from pige_sym.verdict.checkup.scatter import Series

FORMAT = "pige-checkup 1"
#: The machine's newest check-ups the scatter is not learned from (they are judged, and weigh in the centre and the
#: EWMA): a drift of one standard deviation per run is flagged within five runs, before its points could widen the
#: limits that judge it (docs/checkup.md: with them in, 81.5 % of such drifts were flagged in time, without 92.5 %).
LAG = 5


def hours(iso: str, origin: str) -> float:
    """Hours from ``origin`` to ``iso`` (ISO 8601 times)."""
    return (datetime.fromisoformat(iso) - datetime.fromisoformat(origin)).total_seconds() / 3600.0


def values_of(run: Any) -> dict[str, float]:
    """A run's determined values by name [µm, µrad]."""
    return {p: float(v) for p, v in zip(run.parameters, run.values, strict=True) if math.isfinite(float(v))}


def std_of(run: Any) -> dict[str, float]:
    return {p: float(v) for p, v in zip(run.parameters, run.std, strict=True) if math.isfinite(float(v))}


def correction_of(run: Any) -> dict[str, float]:
    """What pige printed to enter after ``run`` (module docstring) [µm, µrad]; 0 where nothing."""
    if run.kind == "checkup":
        return {n: float(v) for n, v in ((run.checkup or {}).get("to_enter") or {}).items() if v is not None}
    names = [p for p, v in zip(run.parameters, run.values, strict=True) if math.isfinite(float(v))]
    idx = [run.parameters.index(n) for n in names]
    cov = np.asarray(run.covariance, dtype=float)[np.ix_(idx, idx)]
    if not names or not np.isfinite(cov).all() or (np.diag(cov) <= 0).any():
        return {}
    x = np.ascontiguousarray(np.asarray(run.values, dtype=float)[idx])
    return dict(_weighed(tuple(names), x.tobytes(), np.ascontiguousarray(cov).tobytes()))


@lru_cache(maxsize=64)
def _weighed(names: tuple[str, ...], values: bytes, covariance: bytes) -> tuple[tuple[str, float], ...]:
    """:func:`~pige_sym.compensation.weighing.entered_values` of one full calibration (its values and covariance as
    bytes), once: every check-up after it asks for the same correction (a command's chart and segment starts, a
    history's check-ups one after another)."""
    from pige_sym.compensation.weighing import entered_values

    x = np.frombuffer(values, dtype=float)
    entered = entered_values(x, np.frombuffer(covariance, dtype=float).reshape(x.size, x.size))
    return tuple((n, float(v)) for n, v in zip(names, entered, strict=True))


@dataclass
class ChartState:
    """The machine's history read for a new check-up (module docstring).

    Attributes
    ----------
    full : RunRecord
        The last full calibration.
    setup : RunSetup
    held : dict of str to float
        Values of the PIGEs the check-up holds [µm, µrad].
    held_covariance : ndarray, shape=(H, H)
        Their covariance (the last full calibration's, in ``held``'s order): their error moves the check-up's fit.
    segment : int
        The new check-up's segment.
    runs : dict of str to (ndarray, ndarray)
        Per free PIGE the current segment's runs in control, in time order, its start first when a correction
        started it: values and own variances (:mod:`~pige_sym.verdict.checkup.limits`).
    series : dict of str to Series
        Per location PIGE the machine's runs that measured it, in control, by segment (the scatter's data,
        :mod:`~pige_sym.verdict.checkup.scatter`).
    trend : dict of str to list of (float, float, bool)
        (hours from ``origin``, value, outside its limits when judged) of the current segment's check-ups.
    origin : str
        The time the hours count from (the machine's first run).
    absolute : bool
        The check-ups measure the machine's own errors (:func:`measures_machine`), not what the controller leaves.
    in_force : dict of str to float
        Every location PIGE's value in force: what the controller holds as pige printed it to be entered (the last
        full calibration's correction, when it was entered or the check-ups measure the machine itself, plus the
        check-ups' corrections entered since) [µm, µrad].
    level : dict of str to float
        Per free PIGE the value a check-up reads when nothing changed since the values in force: the values in force
        (``absolute``), else 0 (what the controller leaves).
    correction : dict of str to float
        With ``corrected``: what was entered before the new check-up.
    """

    full: Any
    setup: RunSetup
    held: dict[str, float]
    held_covariance: np.ndarray
    segment: int
    runs: dict[str, tuple[np.ndarray, np.ndarray]]
    series: dict[str, Series]
    trend: dict[str, list[tuple[float, float, bool]]]
    origin: str
    previous: Any
    absolute: bool = True
    in_force: dict[str, float] = field(default_factory=dict)
    level: dict[str, float] = field(default_factory=dict)
    correction: dict[str, float] = field(default_factory=dict)


def run_setup(run: Any) -> RunSetup:
    """The set-up of a full calibration: stored, or read from its file (runs stored before schema version 2)."""
    where = f"run {run.id} of machine {run.machine_id}"
    if run.setup is not None:
        return RunSetup.from_dict(run.setup, where)
    path = Path(run.file_name)
    if ";" in run.file_name or not path.is_file():
        raise InputError(f"{where} ({run.file_name}) has no stored set-up and its file is not there: a check-up is "
                         "planned from an R-test or probe calibration stored by this version (pige history add)")
    from pige_sym.measurements.rtest import read_measurement
    from pige_sym.measurements.run_setup import setup_of

    return setup_of(read_measurement(path))


def last_full(runs: list[Any]) -> Any:
    """The last full calibration of a machine (refused when it has none)."""
    full = [r for r in runs if r.kind == "full"]
    if not full:
        raise InputError(f"machine {runs[0].machine_id} has no full calibration in the history: add one with "
                         "pige history add FILE --machine-id ID before its first check-up")
    return full[-1]


def _held(full: Any, free: list[str], names: list[str], entered: dict[str, float]) -> tuple[dict[str, float],
                                                                                          np.ndarray]:
    values = values_of(full)
    missing = [n for n in names if n not in free and n not in values]
    if missing:
        raise InputError(f"the last full calibration (run {full.id}) does not determine {', '.join(missing)}: a "
                         "check-up cannot hold it; calibrate fully with a test that determines every PIGE")
    held = {n: values[n] - entered.get(n, 0.0) for n in names if n not in free}
    idx = [full.parameters.index(n) for n in held]
    return held, np.asarray(full.covariance, dtype=float)[np.ix_(idx, idx)]


def after_correction(run: Any) -> bool:
    """The run was measured after a correction was entered (``--corrected``): it starts a segment."""
    if run.kind == "checkup":
        return bool((run.checkup or {}).get("after_correction"))
    return bool(getattr(run, "after_correction", False))


def segments_of(runs: list[Any]) -> list[int]:
    """The segment of each run (in measurement order): an entered correction starts a new one (module docstring)."""
    out, segment = [], 0
    for run in runs:
        segment += after_correction(run)
        out.append(segment)
    return out


@dataclass
class _Table:
    """A machine's runs as arrays per PIGE (one pass over the runs): value, own variance (NaN where the run did not
    measure it), in control, flagged by learned limits, outside its limits; per run its segment and kind."""

    segments: np.ndarray
    checkup: np.ndarray
    values: dict[str, np.ndarray]
    variances: dict[str, np.ndarray]
    in_control: dict[str, np.ndarray]
    flagged: dict[str, np.ndarray]
    outside: dict[str, np.ndarray]

    @classmethod
    def of(cls, runs: list[Any], names: list[str]) -> _Table:
        n = len(runs)
        values = {k: np.full(n, np.nan) for k in names}
        variances = {k: np.full(n, np.nan) for k in names}
        flags = {key: {k: np.zeros(n, dtype=bool) for k in names} for key in ("in_control", "flagged", "outside")}
        for i, run in enumerate(runs):
            info = run.checkup or {} if run.kind == "checkup" else {}
            for name, x, u in zip(run.parameters, run.values.tolist(), run.std.tolist(), strict=True):
                if name in values:
                    values[name][i], variances[name][i] = x, max(u * u, 1e-18)
                    flags["in_control"][name][i] = bool((info.get("in_control") or {}).get(name, True))
                    flags["flagged"][name][i] = bool((info.get("flagged") or {}).get(name, False))
                    flags["outside"][name][i] = bool((info.get("outside") or {}).get(name, False))
        for name in names:
            bad = ~(np.isfinite(values[name]) & np.isfinite(variances[name]))
            values[name][bad], variances[name][bad] = np.nan, np.nan
        return cls(np.array(segments_of(runs), dtype=int), np.array([r.kind == "checkup" for r in runs]), values,
                   variances, flags["in_control"], flags["flagged"], flags["outside"])

    def measured(self, name: str) -> np.ndarray:
        return np.isfinite(self.values[name]) & self.in_control[name]


def series_of(runs: list[Any], names: list[str], current: int | None = None, lag: int = 0,
              table: _Table | None = None) -> dict[str, Series]:
    """Per PIGE of ``names`` the runs that measured it, in control, with their segments (the scatter's data).

    A check-up the learned limits flagged in a segment before ``current`` (default: the last run's), which a
    correction closed, leaves: its cause was found and corrected.  The last ``lag`` check-ups are marked
    :attr:`~.scatter.Series.recent` (a drift in the making must not widen the limits it is judged by: :data:`LAG`).
    """
    t = table if table is not None else _Table.of(runs, names)
    last = (int(t.segments[-1]) if t.segments.size else 0) if current is None else current
    recent = np.zeros(len(runs), dtype=bool)
    if lag:
        recent[np.flatnonzero(t.checkup)[-lag:]] = True
    kinds = np.array([r.kind for r in runs])
    out = {}
    for name in names:
        keep = t.measured(name) & ~((t.segments < last) & t.checkup & t.flagged[name])
        out[name] = Series(runs[0].machine_id if runs else "", name, t.values[name][keep], t.variances[name][keep],
                           t.segments[keep], kinds[keep].tolist(), recent[keep])
    return out


def measures_machine(setup: RunSetup) -> bool:
    """A check-up of this set-up measures the machine's own errors, whatever the controller holds: probing in
    identity kinematics (RTCP off: the joints are the axes, the controller's kinematics unused).  An R-test, or
    probing in TCP kinematics, measures what the controller's kinematics leave of them (module docstring)."""
    return setup.instrument == "sphere-probe" and (setup.probe or {}).get("kinematics", "identity") == "identity"


def _entered_since(runs: list[Any], full_at: int, corrected: bool) -> tuple[bool, dict[str, float]]:
    """(the full calibration's correction was entered, the sum of the check-ups' corrections entered since it): a
    correction is entered when the run after it says so (``--corrected``; ``corrected``: the new check-up)."""
    marks = [after_correction(r) for r in runs[full_at + 1:]] + [corrected]
    total: dict[str, float] = {}
    for run, entered in zip(runs[full_at + 1:], marks[1:], strict=True):
        if entered and run.kind == "checkup":
            for n, v in correction_of(run).items():
                total[n] = total.get(n, 0.0) + v
    return marks[0], total


def chart_state(runs: list[Any], free: list[str], signature: str, *, corrected: bool,
                location: list[str]) -> ChartState:
    """Read the machine's runs as a chart for a new check-up of ``free`` (module docstring); ``signature`` is kept
    for the record (every run that measured a PIGE counts)."""
    full = last_full(runs)
    setup = run_setup(full)
    absolute = measures_machine(setup)
    segs = segments_of(runs)
    segment = (segs[-1] if segs else 0) + int(corrected)
    origin = runs[0].measured_at
    full_entered, since = _entered_since(runs, runs.index(full), corrected)
    by_full = correction_of(full) if absolute or full_entered else {}
    in_force = {n: by_full.get(n, 0.0) + since.get(n, 0.0) for n in location}
    names = [n for n in location if any(n in r.parameters for r in runs)]
    table = _Table.of(runs, list(dict.fromkeys([*names, *free])))
    series = series_of(runs, names, segment, LAG, table)
    current = [k for k, s in enumerate(segs) if s == segment]
    seg_runs = {n: _segment_runs(runs, table, current, n, absolute) for n in free}
    trend = {n: [(hours(runs[k].measured_at, origin), float(table.values[n][k]), bool(table.outside[n][k]))
                 for k in current if table.checkup[k] and math.isfinite(table.values[n][k])] for n in free}
    correction = correction_of(runs[-1]) if corrected else {}
    held, held_cov = _held(full, free, list(location), {} if absolute else by_full)
    level = {n: in_force[n] if absolute else 0.0 for n in free}
    return ChartState(full, setup, held, held_cov, segment, seg_runs, series, trend, origin, runs[-1], absolute,
                      in_force, level, correction)


def _value(run: Any, name: str) -> tuple[float, float] | None:
    """(value, own variance) of a PIGE a run measured, else None."""
    if name not in run.parameters:
        return None
    i = run.parameters.index(name)
    x, u = float(run.values[i]), float(run.std[i])
    return (x, max(u * u, 1e-18)) if math.isfinite(x) and math.isfinite(u) else None


def _start(runs: list[Any], current: list[int], name: str, absolute: bool) -> tuple[float, float] | None:
    """The start of a segment a correction started: the last run before it that measured ``name``, less what was
    entered after the run before the segment (``correction_of``; nothing when the check-ups measure the machine
    itself, ``absolute``); None when no correction started it."""
    first = current[0] if current else len(runs)
    if first == 0 or first < len(runs) and not after_correction(runs[first]):
        return None
    fix = 0.0 if absolute else correction_of(runs[first - 1]).get(name, 0.0)
    before = next((p for k in range(first - 1, -1, -1) if (p := _value(runs[k], name)) is not None), None)
    return None if before is None else (before[0] - fix, before[1])


def _segment_runs(runs: list[Any], table: _Table, current: list[int], name: str,
                  absolute: bool) -> tuple[np.ndarray, np.ndarray]:
    """The current segment's runs of ``name`` in control (values, own variances), its start first."""
    idx = np.array(current, dtype=int)
    idx = idx[table.measured(name)[idx]] if idx.size else idx
    values, variances = table.values[name][idx], table.variances[name][idx]
    start = _start(runs, current, name, absolute)
    if start is not None:
        values, variances = np.r_[start[0], values], np.r_[start[1], variances]
    return values, variances
