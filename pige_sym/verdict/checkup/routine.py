"""``pige checkup``: identify a check-up file, compare it with the machine's history, give a verdict, store the run.

1. The file (R-test or probe, the program ``pige program --checkup`` wrote) is fitted for the check-up's PIGEs with
   the others held (:mod:`~pige_sym.identification.subset`; the PIGEs are the program header's, else ``--pige``,
   else those of the machine's last check-up, else the axis lines' positions).
   Its standard errors include the held values' error (the last full calibration's covariance).
2. Each PIGE is judged (:mod:`~pige_sym.verdict.checkup.judging`) against its control limits
   (:mod:`~pige_sym.verdict.checkup.limits`, the run-to-run scatter learned from every run of the machine and its
   fleet, :mod:`~pige_sym.verdict.checkup.scatter`), against its tolerance (ISO 14253-1 decision rule,
   :func:`~pige_sym.verdict.check.decide`), and its trend is fitted and, where the drift is shown, forecast
   (:mod:`~pige_sym.verdict.checkup.trend`).
3. **Verdict**: ``out`` when a PIGE is not shown within its tolerance (``fail`` or, under the guard rule,
   ``undecided``), else ``drifted`` when one is outside its control limits, else ``ok``.  Exit status 0 for ``ok``,
   1 for ``drifted`` and ``out``, 2 for bad input.
4. **Changes to enter** (:mod:`~pige_sym.verdict.checkup.to_enter`): the change of each re-measured PIGE since the
   values in force, weighed by its uncertainty, within ``--max-change``; the held PIGEs stay at the values in force;
   with ``--controller`` as ``pige compensate --controller`` prints them.
5. The run is stored with ``kind = checkup`` and what was found (``runs.checkup_json``).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from pige_sym.errors import InputError
from pige_sym.verdict.checkup.judging import Item, flags, fleet_series, judge
from pige_sym.verdict.checkup.limits import ALPHA, ALPHA_RANGE, METHOD, MIN_DOF
from pige_sym.verdict.checkup.reference import FORMAT, chart_state, hours

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
    db: str | None = None


def item_dict(item: Item, origin: str) -> dict[str, Any]:
    """One judged PIGE as JSON (times of the forecast as ISO times)."""
    t = None if item.trend is None else item.trend.to_dict() | {
        k: when(origin, getattr(item.trend, k)) for k in ("leaves_at", "leaves_low", "leaves_high")}
    return {"name": item.name, "unit": item.unit, "value": item.value, "std": item.std, "left": item.left,
            "limit": None if item.limit is None else item.limit.to_dict(), "tolerance": item.tolerance,
            "status": item.status, "reason": item.reason, "trend": t}


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
    run_number: int = 0
    fit: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    db: str | None = None
    dialect: str | None = None
    program_options: str = ""

    @property
    def exit_status(self) -> int:
        """0 for ``ok``, 1 when action is needed (``drifted``, ``out``)."""
        return 0 if self.verdict == "ok" else 1

    def outside(self) -> dict[str, bool]:
        """Per PIGE: outside its control limits (learned or provisional)."""
        return flags(self.items)["outside"]

    def flagged(self) -> dict[str, bool]:
        """Per PIGE: outside its learned limits."""
        return flags(self.items)["flagged"]

    def in_control(self) -> dict[str, bool]:
        """Per PIGE: stays in the chart (:func:`~pige_sym.verdict.checkup.judging.flags`)."""
        return flags(self.items)["in_control"]

    def limits_source(self) -> str:
        """Where the limits came from (one sentence)."""
        return limits_source(self.items)

    def next_step(self) -> tuple[str, str]:
        """What to do now and the command: :func:`next_step` (the CLI and the report print it)."""
        return next_step(self.verdict, self.notes, None if self.changes is None else self.changes.entered,
                         self.machine_id, NextRun(self.db, self.dialect, self.run_number, self.program_options))

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
            "measured_at": self.measured_at, "run": self.run_id, "run_number": self.run_number,
            "verdict": self.verdict, "next_step": list(self.next_step()),
            "exit_status": self.exit_status,
            "free": [i.name for i in self.items], "held": self.held, "provisional": self.provisional,
            "method": METHOD, "alpha": self.alpha, "min_dof": MIN_DOF, "signature": self.signature,
            "segment": self.segment, "after_correction": self.corrected, "correction": self.correction,
            "in_control": self.in_control(), "outside": self.outside(), "flagged": self.flagged(),
            "limits_source": self.limits_source(), "items": [item_dict(i, self.origin) for i in self.items],
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
    from pige_sym.measurements.run_setup import setup_of

    fit = identify_subset(m, free, state.held, held_covariance=state.held_covariance,
                          **_rtest_noise(state.full) if instrument(m) == "rtest" else {})
    _storable(fit, path)
    tol = _tolerances(opts, runs, kern.MACHINE_CODE, free)
    fleet = fleet_series(history.fleet(kern.MACHINE_CODE, machine_id), list(kern.LOCATION_PARAMETERS))
    items, verdict = judge(fit, state, tol, opts, hours(measured, state.origin), fleet)
    changes = checkup_changes(fit, m, opts, state)
    result = CheckupResult(machine_id, kern.MACHINE_CODE, str(Path(path).resolve()), measured, verdict, items,
                           state.held, any(i.limit is None or i.limit.provisional for i in items), state.origin,
                           opts.alpha, signature, state.segment, opts.corrected, state.correction, changes,
                           run_number=len(runs) + 1, fit=fit.to_dict(), notes=list(fit.notes) + _notes(items),
                           db=opts.db, dialect=_dialect(m, state.setup),
                           program_options=controller_options(setup_of(m).probe, state.setup.probe))

    record = history.add_checkup(Path(path), machine_id, kern.MACHINE_CODE, (measured, source), fit,
                                 setup_of(m).to_dict(), verdict, result.to_dict(), result.chart())
    result.run_id = record.id
    return result


def _dialect(m: Any, setup: Any) -> str | None:
    """The dialect of the check-up's program: its header's (the probe file imported with ``--program``), else the
    full calibration's program's; None for an R-test (not stated in its file)."""
    stated = m.metadata.get("program_dialect") or ((setup.probe or {}).get("program") or {}).get("dialect")
    return str(stated) if stated else None


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


#: The program file name's extension per dialect (as ``pige plan`` names them).
PROGRAM_SUFFIX = {"siemens": ".mpf", "fanuc": ".nc", "linuxcnc": ".ngc", "heidenhain": ".h"}


@dataclass(frozen=True)
class NextRun:
    """Where the next check-up's program comes from: the history the check-up used (``--db`` as given, None for
    the default), the dialect of the check-up's program (None: not known, an R-test; ``pige program``'s default
    applies), the check-up's run number (the program is named for the next) and the controller options its program
    was written with where the history does not hold them (:func:`controller_options`)."""

    db: str | None = None
    dialect: str | None = None
    run_number: int = 0
    options: str = ""


def controller_options(checkup_probe: dict[str, Any] | None, full_probe: dict[str, Any] | None) -> str:
    """The controller options ``pige program --checkup`` needs to write the check-up's program again (`` --kinematics
    … --window …``): none when the check-up's program stated the full calibration's controller state (the command
    reads that from the history) or stated none; else the state the check-up's program stated.

    ``checkup_probe``, ``full_probe``: the ``probe`` items of the check-up's and the full calibration's set-up
    (:class:`~pige_sym.measurements.run_setup.RunSetup`)."""
    import shlex

    mine, full = _controller(checkup_probe), _controller(full_probe)
    if mine is None or mine == full:
        return ""
    words = [f"--kinematics {mine.kinematics}"]
    words += [f"--{name} {shlex.quote(code)}" for name, code in (("rtcp-off", mine.rtcp_off),
                                                                 ("rtcp-on", mine.rtcp_on)) if code]
    offset = ",".join(f"{x:.12g}" for x in mine.work_offset_mm)
    words += [f"--stylus-tool {mine.stylus_tool}", f"--stylus-length {mine.stylus_length_mm:.12g}",
              f"--work-offset {mine.work_offset}={offset}", f"--window {mine.window_mm:.12g}"]
    return " " + " ".join(words)


def _controller(probe: dict[str, Any] | None) -> Any:
    """The controller state a stored probing set-up states (None: none stated)."""
    from pige_sym.nc.probe_safety import controller_from_header

    if not probe or not probe.get("program"):
        return None
    try:
        return controller_from_header(dict(probe["program"]) | {"kinematics": str(probe.get("kinematics", "identity"))},
                                      "the set-up")
    except InputError:
        return None


def db_option(db: str | None) -> str:
    """`` --db URL`` for a command (empty for the default database); a password in the URL is left out (the
    printed command is stored and shown in the report: PostgreSQL then reads it from ~/.pgpass or $PGPASSWORD)."""
    import shlex

    if db is None:
        return ""
    if "://" in db:
        from sqlalchemy.engine import make_url
        from sqlalchemy.exc import ArgumentError

        try:
            url = make_url(db)
        except ArgumentError:
            url = None
        if url is not None and url.password is not None:
            db = url.render_as_string(hide_password=True).replace(":***@", "@", 1)
    return f" --db {shlex.quote(db)}"


def checkup_program_command(machine_id: str, run: NextRun) -> str:
    """``pige program --checkup`` writing the next check-up's program from the history, as printed after a check-up:
    the machine id and database the check-up used, its program's dialect, a new file named for the next run (an
    existing file is never replaced: no ``--force``)."""
    import re
    import shlex

    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", machine_id).strip("._-") or "machine"
    dialect = f" --dialect {run.dialect}" if run.dialect in PROGRAM_SUFFIX else ""
    out = f"checkup_{stem}_run{run.run_number + 1}{PROGRAM_SUFFIX.get(run.dialect or 'siemens', '.mpf')}"
    return (f"pige program --checkup --machine-id {shlex.quote(machine_id)}{db_option(run.db)}{dialect}"
            f"{run.options} --out {shlex.quote(out)}")


def next_step(verdict: str, notes: list[str], entered: dict[str, float | None] | None,
              machine_id: str, run: NextRun | None = None) -> tuple[str, str]:
    """What to do after a check-up, and the command (one sentence each; ``pige checkup`` and the report of the
    machine's history print the same).  The command runs as printed now: the next check-up's program written from
    the history (:func:`checkup_program_command`); what follows it (run it, ``pige checkup`` on its measurement) is
    said in words.  "Calibrate fully" has no command (empty): the history keeps the full calibration's set-up but
    not its poses nor its program's options, so pige cannot write its program again; the words say what to do."""
    import shlex

    run = NextRun() if run is None else run
    again = f"--machine-id {shlex.quote(machine_id)}{db_option(run.db)}"
    if any("calibrate the machine fully" in n for n in notes):
        return ("calibrate the machine fully: the check-up's poses disagree with the PIGEs it held beyond their "
                "uncertainty; run the full calibration's program again (the history keeps its set-up, not its poses "
                "nor its program: none is printed), and add its measurement to this history (pige history add, "
                f"{again})", "")
    command = checkup_program_command(machine_id, run)

    def then(corrected: bool) -> str:
        written = "" if run.dialect else " (for a Siemens control: add --dialect fanuc or linuxcnc for another)"
        return (f"; the command below writes its program{written}: run it on the machine, then pige checkup its "
                f"measurement (the log imported with pige import-probe, or pige acquire's file) with {again}"
                + (" --corrected" if corrected else ""))

    if verdict == "ok":
        return f"nothing to correct: the next check-up as usual (pige history fleet says when){then(False)}", command
    if not any(v for v in (entered or {}).values()):
        return (f"{'out of tolerance' if verdict == 'out' else 'drifted'}, but no change is shown beyond its "
                f"uncertainty: run the next check-up now to confirm (calibrate fully if it says so again){then(False)}",
                command)
    tail = "; if it is still out, calibrate fully" if verdict == "out" else ""
    return f"enter the changes, then the next check-up{then(True)}{tail}", command


def _notes(items: list[Item]) -> list[str]:
    notes = []
    if any(i.limit is None for i in items):
        notes.append("the first run of this segment has nothing to compare with: judged on its tolerance only")
    elif any(i.limit is not None and i.limit.provisional for i in items):
        notes.append("provisional limits from the runs' own standard errors: the run-to-run scatter is learned once "
                     "the machine (or a machine of its structure in this history) has two runs of a PIGE between "
                     "corrections (docs/checkup.md)")
    return notes


def limits_source(items: list[Item]) -> str:
    """Where the limits of a check-up came from, in one sentence (the first learned PIGE's posterior speaks for
    the population; each PIGE's own figures are in its limit)."""
    lims = [i.limit for i in items if i.limit is not None]
    if not lims:
        return "no limits: the first run of this segment"
    if all(lim.provisional for lim in lims):
        return "provisional: from the runs' own standard errors (the run-to-run scatter is not known yet)"
    learned = next(lim for lim in lims if not lim.provisional)
    return f"learned from {learned.source}"
