"""Add a run to the history, list a machine's runs, store a check-up: through SQLAlchemy (any database).

The database is opened by :func:`~pige_sym.verdict.history.connection.connect` (checked first; read-only to read,
migrated to write; re-exported here).  A file is identified by the SHA-256 of its bytes and is added once (a second
add is refused).  The stored estimate is the one used for compensation: the diagnosis' final fit (PIGEs jointly
with the accepted effects) by default, with its full covariance, and the set-up the file was measured with (what a
check-up repeats).  Every run is checked before it is stored
(:func:`~pige_sym.verdict.history.decode.check_new_run`: what the history would refuse to read back is never
stored) and read strictly (:func:`~pige_sym.verdict.history.decode.decode_run`); a damaged one is refused in one
line naming the database, the run and the column.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from pige_sym.errors import InputError, SchemaRefusal
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.run_setup import setup_of
from pige_sym.verdict.history import tables as T
from pige_sym.verdict.history.connection import connect, raw_columns, reason, where, writable
from pige_sym.verdict.history.decode import check_new_run, decode_run, not_stored
from pige_sym.verdict.history.integrity import COLUMNS, check_runs, damaged, no_machine
from pige_sym.verdict.history.records import (
    ENV_URL,
    RunRecord,
    checkup_values,
    default_url,
    dumps,
    file_sha256,
    measurement_time,
)

__all__ = ["ENV_URL", "EngineHistory", "RunRecord", "add_checkup_run", "add_run", "connect", "default_url",
           "existing_run", "list_runs", "machine_ids", "measurement_time", "run_by_id"]


@dataclass
class _Read:
    """What was read: the machine and each file's contents."""

    machine: str
    items: list[Any]


def _estimate_set(paths: list[Path], method: str, identified: tuple[Measurement, Any] | None = None
                  ) -> tuple[_Read, Any, list[dict[str, Any]], str]:
    """(what was read, result with parameters/values/covariance/dof, accepted findings, stored method);
    ``identified``: the single file's measurement and its Gauss-Newton result, made already (not made again)."""
    from pige_sym.measurements.ballbar import is_ballbar_file

    if identified is not None:
        if len(paths) != 1 or method != "gauss-newton":
            raise InputError("an identification made already is stored only for one file, method gauss-newton")
        return _Read(identified[0].machine, [identified[0]]), identified[1], [], method
    if len(paths) == 1 and not is_ballbar_file(paths[0]):
        m, result, effects = _estimate(paths[0], method)
        return _Read(m.machine, [m]), result, effects, method
    from pige_sym.measurements.sets import read_files

    items = read_files(paths)
    read = _Read(items[0][1].machine, [x for _, x in items])
    if method == "diagnosis":
        from pige_sym.diagnosis.joint import diagnose_joint

        diag = diagnose_joint(items)
        effects = [f.to_dict() | {"file": fd.label} for fd in diag.files for f in fd.findings]
        effects += [f.to_dict() | {"file": "jointly"} for f in diag.effects]
        return read, diag, effects, "joint-diagnosis"
    from pige_sym.identification.joint import identify_joint

    return read, identify_joint(items).result, [], "joint"


def _estimate(path: Path, method: str) -> tuple[Any, Any, list[dict[str, Any]]]:
    """(measurement, result with parameters/values/covariance/dof, accepted findings) of a file."""
    from pige_sym.measurements.rtest import read_measurement

    m = read_measurement(path)
    if method == "diagnosis":
        from pige_sym.diagnosis.diagnose import diagnose

        diag = diagnose(m)
        return m, diag, [f.to_dict() for f in diag.findings]
    from pige_sym.identification.least_squares import identify

    return m, identify(m, method=method), []


def _existing(conn: sa.Connection, sha: str) -> Any:
    return conn.execute(sa.select(T.runs.c.id, T.runs.c.machine_id, T.runs.c.file_name)
                        .where(T.runs.c.file_sha256 == sha)).first()


def add_run(engine: sa.Engine, path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], machine_id: str, *,
            method: str = "diagnosis", tolerances: str | os.PathLike[str] | None = None, rule: str = "guard",
            k: float = 2.0, date: str | None = None, corrected: bool = False,
            identified: tuple[Measurement, Any] | None = None) -> RunRecord:
    """Identify/diagnose a measurement file (or a set of files of one machine) and store the run.

    A set (several files, or a ``pige-ballbar 1`` file) is stored as one run of method ``joint``
    (``joint-diagnosis`` with ``method="diagnosis"``): the joint PIGE estimate, each file's findings,
    the file names joined by ``; ``, the SHA-256 of the sorted files' SHA-256s (the same set is added
    once, in any order) and the latest of the files' times.

    ``corrected``: the run was measured after a correction was entered (it starts a segment of the check-ups'
    chart, :mod:`pige_sym.verdict.checkup`).

    ``identified``: ``(measurement, result)`` of the one file, read from it and identified with ``method``
    ``"gauss-newton"`` by the caller already (the cycle's analysis): stored as it is, not identified again.

    Raises
    ------
    InputError
        The same file or set (same SHA-256) is already stored, the machine id holds another machine
        structure, or the machine id is empty.
    HistoryError
        The estimate is not one pige stores (:func:`~pige_sym.verdict.history.decode.check_new_run`).
    """
    from pige_sym.kernels import load_kernels
    from pige_sym.verdict.check import check, estimates_from_result, read_tolerances

    if not machine_id.strip():
        raise InputError("--machine-id must not be empty")
    engine = writable(engine)
    paths = [Path(path)] if isinstance(path, (str, os.PathLike)) else [Path(x) for x in path]
    if not paths:
        raise InputError("give at least one file")
    shas = [file_sha256(x) for x in paths]
    sha = shas[0] if len(paths) == 1 else hashlib.sha256("\n".join(sorted(shas)).encode()).hexdigest()
    p = paths[0] if len(paths) == 1 else Path("; ".join(str(x) for x in paths))
    what = "file" if len(paths) == 1 else "set of files"
    with engine.connect() as conn:
        dup = _existing(conn, sha)
    if dup is not None:
        raise InputError(f"{p}: this {what} is already in the history (run {dup.id} of machine {dup.machine_id}, "
                         f"added as {dup.file_name}): a run is added once")
    tol = read_tolerances(tolerances) if tolerances is not None else None
    m, result, effects, method = _estimate_set(paths, method, identified)
    final = getattr(result, "final", result)
    code = load_kernels(m.machine).MACHINE_CODE
    times = [measurement_time(x, getattr(item, "metadata", {}), date) for x, item in zip(paths, m.items, strict=True)]
    measured, source = max(times)
    chk = check(estimates_from_result(result, str(p)), tol, rule=rule, k=k) if tol is not None else None
    now = datetime.now(timezone.utc).isoformat(timespec="seconds")
    values = {
        "machine_id": machine_id, "file_sha256": sha,
        "file_name": "; ".join(str(x.resolve()) for x in paths), "measured_at": measured,
        "time_source": source, "added_at": now, "machine_code": code, "method": method,
        "parameters": dumps(final.parameters), "units": dumps(final.units), "values_json": dumps(final.values),
        "std_json": dumps(final.std), "covariance_json": dumps(final.covariance), "dof": int(final.dof),
        "rms_um": float(final.rms_um) if math.isfinite(final.rms_um) else None, "effects_json": dumps(effects),
        "verdict": None if chk is None else chk.verdict, "check_json": None if chk is None else dumps(chk.to_dict()),
        "kind": "full", "setup_json": dumps(setup_of(m.items[0]).to_dict())
        if len(m.items) == 1 and isinstance(m.items[0], Measurement) else None,
        "after_correction": int(corrected),
    }
    _check_new(values, p)
    for attempt in range(3):
        try:
            row = _insert_run(engine, machine_id, code, now, values, p)
            break
        except sa.exc.IntegrityError:
            with engine.connect() as conn:
                if _existing(conn, sha) is not None or attempt == 2:  # another user added the same file meanwhile
                    raise InputError(f"{p}: this file is already in the history: a run is added once") from None
            # else: another process created the machine at the same moment; its row is there now
    return decode_run(row)


def _check_new(values: dict[str, Any], p: Path) -> None:
    """Refuse to store what the history would refuse to read back (a check-up's estimate too)."""
    try:
        check_new_run(values)
    except SchemaRefusal as exc:
        raise not_stored(p, exc) from None


def _insert_run(engine: sa.Engine, machine_id: str, code: str, now: str, values: dict[str, Any], p: Path) -> Any:
    """Insert the machine (when new) and the run in one transaction; the stored row (as stored: no conversion)."""
    with engine.begin() as conn:
        known = conn.execute(sa.select(T.machines.c.machine_code).where(T.machines.c.machine_id == machine_id)).scalar()
        if known is None:
            conn.execute(sa.insert(T.machines).values(machine_id=machine_id, machine_code=code, created_at=now))
        elif known != code:
            raise InputError(f"machine id {machine_id!r} is a {known} in the history, {p} measures a {code}: "
                             "use the right --machine-id")
        run_id = conn.execute(sa.insert(T.runs).values(**values)).inserted_primary_key[0]  # type: ignore[index]
        return conn.execute(sa.select(*raw_columns(c.name for c in T.runs.columns)).select_from(T.runs)
                            .where(T.runs.c.id == run_id)).one()


def machine_ids(engine: sa.Engine) -> list[str]:
    """Every machine id in the history, sorted.

    Raises
    ------
    HistoryError
        The database cannot be read (damaged).
    """
    try:
        with engine.connect() as conn:
            ids: list[Any] = list(conn.execute(sa.select(sa.literal_column("machines.machine_id"))
                                               .select_from(T.machines)).scalars())
    except sa.exc.SQLAlchemyError as exc:
        w = where(engine)
        raise damaged(w.shown, reason(exc), w.sqlite) from None
    return sorted(str(x) for x in ids)


def _rows(engine: sa.Engine, select: Any, light: bool) -> list[RunRecord]:
    """The runs of a query, each read strictly; the database's errors as damage."""
    w = where(engine)
    names = [c for c in COLUMNS[w.version]["runs"] if not light or c != "checkup_json"]
    try:
        with engine.connect() as conn:
            rows = conn.execute(select.with_only_columns(*raw_columns(names)).select_from(T.runs)).all()
    except sa.exc.SQLAlchemyError as exc:
        raise damaged(w.shown, reason(exc), w.sqlite) from None
    return check_runs((r._mapping for r in rows), w.shown, w.sqlite, light=light)


def list_runs(engine: sa.Engine, machine_id: str, *, light: bool = False) -> list[RunRecord]:
    """Runs of a machine in measurement order (time, then insertion), each read strictly
    (:func:`~pige_sym.verdict.history.decode.decode_run`; ``light``: check-ups as chart points, what ``pige
    checkup`` reads of a long history).  A file of schema version 1 is read as it is (no check-up columns).

    Raises
    ------
    InputError
        No such machine id (the message lists the known ones).
    HistoryError
        A run or the database is damaged (the message names the run and the column).
    """
    runs = _rows(engine, sa.select(T.runs.c.id).where(T.runs.c.machine_id == machine_id)
                 .order_by(T.runs.c.measured_at, T.runs.c.id), light)
    if not runs:
        raise no_machine(machine_id, where(engine).shown, machine_ids(engine))
    return runs


def all_runs(engine: sa.Engine, *, light: bool = True) -> list[RunRecord]:
    """Every run of every machine, by machine id, then in measurement order (``history fleet``)."""
    return _rows(engine, sa.select(T.runs.c.id).order_by(T.runs.c.machine_id, T.runs.c.measured_at, T.runs.c.id),
                 light)


def run_by_id(engine: sa.Engine, run_id: int) -> RunRecord:
    """One run, all of it (a check-up's findings too), read strictly."""
    found = _rows(engine, sa.select(T.runs.c.id).where(T.runs.c.id == run_id), False)
    if not found:
        raise InputError(f"no run {run_id} in the history {where(engine).shown}")
    return found[0]


def existing_run(engine: sa.Engine, path: Path) -> None:
    """Refuse a file that is already in the history (a run is added once).

    Raises
    ------
    InputError
    """
    with engine.connect() as conn:
        dup = _existing(conn, file_sha256(path))
    if dup is not None:
        raise InputError(f"{path}: this file is already in the history (run {dup.id} of machine {dup.machine_id}, "
                         f"added as {dup.file_name}): a run is added once")


def add_checkup_run(engine: sa.Engine, path: Path, machine_id: str, code: str, measured: tuple[str, str], fit: Any,
                    setup: dict[str, Any], verdict: str, checkup: dict[str, Any], chart: dict[str, Any]) -> RunRecord:
    """Store a check-up (``kind = checkup``): the row of :func:`~.records.checkup_values`, checked first; the
    database migrated to the current schema first when it is older (writing migrates, reading never does).

    Raises
    ------
    InputError
        The file is already stored (also when another user stored it meanwhile).
    HistoryError
        The check-up's estimate is not one pige stores.
    """
    values = checkup_values(path, machine_id, code, measured, fit, setup, verdict, checkup, chart)
    _check_new(values, path)
    try:
        return decode_run(_insert_run(writable(engine), machine_id, code, values["added_at"], values, path))
    except sa.exc.IntegrityError:
        raise InputError(f"{path}: this file is already in the history: a run is added once") from None


class EngineHistory:
    """What a check-up reads and writes of a history, through SQLAlchemy (any database, any schema version)."""

    def __init__(self, engine: sa.Engine) -> None:
        self.engine = engine

    def list_runs(self, machine_id: str, *, light: bool = False) -> list[RunRecord]:
        return list_runs(self.engine, machine_id, light=light)

    def fleet(self, machine_code: str, machine_id: str) -> list[list[RunRecord]]:
        """The runs of every other machine of the structure ``machine_code`` (each in measurement order, light)."""
        from pige_sym.verdict.history.records import fleet_of

        return fleet_of(all_runs(self.engine, light=True), machine_code, machine_id)

    def existing(self, path: Path) -> None:
        existing_run(self.engine, path)

    def add_checkup(self, *args: Any) -> RunRecord:
        return add_checkup_run(self.engine, *args)
