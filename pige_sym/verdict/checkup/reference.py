"""What a new check-up is compared with: the machine's runs read as a control chart.

From a machine's runs in measurement order (:func:`~pige_sym.verdict.history.list_runs`):

- **the last full calibration** with its set-up (``runs.setup_json``; for a run stored before schema version 2,
  read again from its file when that is still there): the poses and the sphere of a check-up are planned from it,
  and the PIGEs a check-up does not re-measure are *held* at its values, less a correction entered right after it;
- **segments** (:mod:`~pige_sym.verdict.checkup.limits`): a full calibration starts one at its values; a check-up
  stored with ``--corrected`` (the changes printed for the previous run were entered before it) starts one at the
  previous run's values less those changes;
- **points**: the check-ups with the same signature (PIGEs and poses), each with its segment and whether the
  learned limits flagged it (those of a segment closed by a correction leave the scatter).

A correction is what pige printed to enter: a check-up's ``to_enter`` (its PIGEs, weighed), or for a full calibration
every PIGE weighed by its uncertainty (:func:`~pige_sym.compensation.weighing.entered_values`, what ``pige compensate
--controller`` enters).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.measurements.run_setup import RunSetup
from pige_sym.verdict.checkup.limits import Point, Start

FORMAT = "pige-checkup 1"


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
    from pige_sym.compensation.weighing import entered_values

    names = [p for p, v in zip(run.parameters, run.values, strict=True) if math.isfinite(float(v))]
    idx = [run.parameters.index(n) for n in names]
    cov = np.asarray(run.covariance, dtype=float)[np.ix_(idx, idx)]
    if not names or not np.isfinite(cov).all() or (np.diag(cov) <= 0).any():
        return {}
    entered = entered_values(np.asarray(run.values, dtype=float)[idx], cov)
    return {n: float(v) for n, v in zip(names, entered, strict=True)}


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
    segment : int
        The new check-up's segment.
    start : dict of str to Start
        The segment's starting level per PIGE (until it has check-ups of its own).
    points : dict of str to list of Point
        Earlier check-ups with the same signature, per PIGE.
    trend : dict of str to list of (float, float, bool)
        (hours from ``origin``, value, outside its limits when judged) of the current segment's check-ups with the
        same signature.
    origin : str
        The time the hours count from (the machine's first run).
    correction : dict of str to float
        With ``corrected``: what was entered before the new check-up.
    """

    full: Any
    setup: RunSetup
    held: dict[str, float]
    segment: int
    start: dict[str, Start]
    points: dict[str, list[Point]]
    trend: dict[str, list[tuple[float, float, bool]]]
    origin: str
    previous: Any
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


def _held(full: Any, free: list[str], names: list[str], entered: dict[str, float]) -> dict[str, float]:
    values = values_of(full)
    missing = [n for n in names if n not in free and n not in values]
    if missing:
        raise InputError(f"the last full calibration (run {full.id}) does not determine {', '.join(missing)}: a "
                         "check-up cannot hold it; calibrate fully with a test that determines every PIGE")
    return {n: values[n] - entered.get(n, 0.0) for n in names if n not in free}


def chart_state(runs: list[Any], free: list[str], signature: str, *, corrected: bool,
                location: list[str]) -> ChartState:
    """Read the machine's runs as a chart for a new check-up of ``free`` with ``signature`` (module docstring)."""
    full = last_full(runs)
    setup = run_setup(full)
    segment, level, start = 0, {}, {}
    points: dict[str, list[Point]] = {n: [] for n in free}
    trend: dict[str, list[tuple[float, float, bool]]] = {n: [] for n in free}
    origin = runs[0].measured_at
    held_entered: dict[str, float] = {}
    prev = None
    for run in [*runs, None]:
        starts = run is None and corrected or run is not None and (
            run.kind == "full" or bool((run.checkup or {}).get("after_correction")))
        if starts:
            _close(points, segment)
            segment += 1
            trend = {n: [] for n in free}
            if run is not None and run.kind == "full":
                level, held_entered = values_of(run), {}
                start = {n: Start(level[n], std_of(run).get(n, 0.0)) for n in free if n in level}
            elif prev is not None:
                fix = correction_of(prev)
                if prev.kind == "full":
                    held_entered = fix
                std, base = std_of(prev), level | values_of(prev)
                kind = "full" if prev.kind == "full" else "corrected"
                start = {n: Start(base[n] - fix.get(n, 0.0), std.get(n, 0.0), kind) for n in free if n in base}
        if run is None:
            break
        if run.kind == "checkup":
            _add_point(run, free, signature, segment, points, trend, origin)
        if run.kind == "full":
            level = values_of(run)
        prev = run
    correction = correction_of(runs[-1]) if corrected else {}
    held = _held(full, free, list(location), held_entered)
    return ChartState(full, setup, held, segment, start, points, trend, origin, runs[-1], correction)


def _close(points: dict[str, list[Point]], segment: int) -> None:
    """A segment closed by a correction: its flagged check-ups leave the scatter (:mod:`~.limits`)."""
    for pts in points.values():
        for p in pts:
            if p.segment == segment and p.flagged:
                p.in_control = False


def _add_point(run: Any, free: list[str], signature: str, segment: int, points: dict[str, list[Point]],
               trend: dict[str, list[tuple[float, float, bool]]], origin: str) -> None:
    info = run.checkup or {}
    if info.get("signature") != signature:
        return
    values = dict(zip(run.parameters, run.values.tolist(), strict=True))
    std = dict(zip(run.parameters, run.std.tolist(), strict=True))
    for n in free:
        if n in values and math.isfinite(values[n]):
            kept = bool((info.get("in_control") or {}).get(n, True))
            learned = bool((info.get("flagged") or {}).get(n, False))
            points[n].append(Point(values[n], std.get(n, 0.0), int(run.dof), segment, kept, learned))
            outside = bool((info.get("outside") or {}).get(n, False))
            trend[n].append((hours(run.measured_at, origin), values[n], outside))
