"""Connect to the history database, add a run, list a machine's runs.

Database URLs (``--db``):

- default: an SQLite file ``history.sqlite`` in the user data directory (platformdirs;
  ``$PIGE_HISTORY_DB`` overrides), embedded, nothing to start;
- a plain path or ``sqlite:///PATH``: that SQLite file;
- ``postgresql://user@host:port/dbname``: a PostgreSQL server (shops with many machines and
  users; needs ``pip install 'pige_sym[postgres]'``, i.e. psycopg 3).

The schema is created and migrated on connect (:mod:`~pige_sym.verdict.history.migrations`).  A file
is identified by the SHA-256 of its bytes and is added once (a second add is refused).  The
stored estimate is the one used for compensation: the diagnosis' final fit (PIGEs jointly with
the accepted effects) by default, with its full covariance.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from pige_sym.errors import InputError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.run_setup import setup_of
from pige_sym.verdict.history import tables as T
from pige_sym.verdict.history.migrations import migrate
from pige_sym.verdict.history.records import (  # noqa: F401 - re-exported: the store's names as before
    ENV_URL,
    RunRecord,
    _dumps,
    _float_rows,
    _sha256,
    checkup_values,
    default_url,
    measurement_time,
    normalise_url,
    run_record,
)


def connect(url: str | None = None, *, create: bool = True) -> sa.Engine:
    """Engine of the history database, schema migrated.

    ``create=False`` (reading: ``history show``, ``report --history``) refuses an SQLite file that does not
    exist instead of creating an empty database there.

    Raises
    ------
    InputError
        The database cannot be opened or reached (message with the URL, password hidden), or (``create=False``)
        the SQLite file does not exist.
    """
    full = normalise_url(url)
    if full.startswith("sqlite:///"):
        path = Path(full.removeprefix("sqlite:///"))
        if not create and str(path) not in ("", ":memory:") and not path.is_file():
            raise InputError(f"no history database at {path} (pige history add creates one; --db or "
                             f"$PIGE_HISTORY_DB name another)")
        if str(path) not in ("", ":memory:"):
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise InputError(f"--db {path}: cannot create {path.parent} ({exc.strerror or exc})") from None
    engine = sa.create_engine(full)
    if engine.dialect.name == "sqlite":
        @sa.event.listens_for(engine, "connect")
        def _fk(dbapi_conn: Any, _record: Any) -> None:
            dbapi_conn.execute("PRAGMA foreign_keys=ON")
    try:
        migrate(engine)
    except sa.exc.SQLAlchemyError as exc:
        shown = engine.url.render_as_string(hide_password=True)
        raise InputError(f"history database {shown}: {str(exc.orig if hasattr(exc, 'orig') else exc).strip()}"
                         .splitlines()[0]) from None
    return engine


@dataclass
class _Read:
    """What was read: the machine and each file's contents."""

    machine: str
    items: list[Any]


def _estimate_set(paths: list[Path], method: str) -> tuple[_Read, Any, list[dict[str, Any]], str]:
    """(what was read, result with parameters/values/covariance/dof, accepted findings, stored method)."""
    from pige_sym.measurements.ballbar import is_ballbar_file

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
            k: float = 2.0, date: str | None = None) -> RunRecord:
    """Identify/diagnose a measurement file (or a set of files of one machine) and store the run.

    A set (several files, or a ``pige-ballbar 1`` file) is stored as one run of method ``joint``
    (``joint-diagnosis`` with ``method="diagnosis"``): the joint PIGE estimate, each file's findings,
    the file names joined by ``; ``, the SHA-256 of the sorted files' SHA-256s (the same set is added
    once, in any order) and the latest of the files' times.

    Raises
    ------
    InputError
        The same file or set (same SHA-256) is already stored, the machine id holds another machine
        structure, or the machine id is empty.
    """
    from pige_sym.kernels import load_kernels
    from pige_sym.verdict.check import check, estimates_from_result, read_tolerances

    if not machine_id.strip():
        raise InputError("--machine-id must not be empty")
    paths = [Path(path)] if isinstance(path, (str, os.PathLike)) else [Path(x) for x in path]
    if not paths:
        raise InputError("give at least one file")
    shas = [_sha256(x) for x in paths]
    sha = shas[0] if len(paths) == 1 else hashlib.sha256("\n".join(sorted(shas)).encode()).hexdigest()
    p = paths[0] if len(paths) == 1 else Path("; ".join(str(x) for x in paths))
    what = "file" if len(paths) == 1 else "set of files"
    with engine.connect() as conn:
        dup = _existing(conn, sha)
    if dup is not None:
        raise InputError(f"{p}: this {what} is already in the history (run {dup.id} of machine {dup.machine_id}, "
                         f"added as {dup.file_name}): a run is added once")
    tol = read_tolerances(tolerances) if tolerances is not None else None
    m, result, effects, method = _estimate_set(paths, method)
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
        "parameters": _dumps(final.parameters), "units": _dumps(final.units), "values_json": _dumps(final.values),
        "std_json": _dumps(final.std), "covariance_json": _dumps(final.covariance), "dof": int(final.dof),
        "rms_um": float(final.rms_um) if math.isfinite(final.rms_um) else None, "effects_json": _dumps(effects),
        "verdict": None if chk is None else chk.verdict, "check_json": None if chk is None else _dumps(chk.to_dict()),
        "kind": "full", "setup_json": _dumps(setup_of(m.items[0]).to_dict())
        if len(m.items) == 1 and isinstance(m.items[0], Measurement) else None,
    }
    for attempt in range(3):
        try:
            row = _insert_run(engine, machine_id, code, now, values, p)
            break
        except sa.exc.IntegrityError:
            with engine.connect() as conn:
                if _existing(conn, sha) is not None or attempt == 2:  # another user added the same file meanwhile
                    raise InputError(f"{p}: this file is already in the history: a run is added once") from None
            # else: another process created the machine at the same moment; its row is there now
    return run_record(row)


def _insert_run(engine: sa.Engine, machine_id: str, code: str, now: str, values: dict[str, Any], p: Path) -> Any:
    """Insert the machine (when new) and the run in one transaction; the stored row."""
    with engine.begin() as conn:
        known = conn.execute(sa.select(T.machines.c.machine_code).where(T.machines.c.machine_id == machine_id)).scalar()
        if known is None:
            conn.execute(sa.insert(T.machines).values(machine_id=machine_id, machine_code=code, created_at=now))
        elif known != code:
            raise InputError(f"machine id {machine_id!r} is a {known} in the history, {p} measures a {code}: "
                             "use the right --machine-id")
        run_id = conn.execute(sa.insert(T.runs).values(**values)).inserted_primary_key[0]  # type: ignore[index]
        return conn.execute(sa.select(T.runs).where(T.runs.c.id == run_id)).one()


def machine_ids(engine: sa.Engine) -> list[str]:
    """Every machine id in the history, sorted."""
    with engine.connect() as conn:
        return sorted(conn.execute(sa.select(T.machines.c.machine_id)).scalars())


def list_runs(engine: sa.Engine, machine_id: str, *, light: bool = False) -> list[RunRecord]:
    """Runs of a machine in measurement order (time, then insertion); ``light``: check-ups as chart points
    (:func:`run_record`), what ``pige checkup`` reads of a long history.

    Raises
    ------
    InputError
        No such machine id (the message lists the known ones).
    """
    columns = [c for c in T.runs.c if not light or c.name != "checkup_json"]
    with engine.connect() as conn:
        rows = conn.execute(sa.select(*columns).where(T.runs.c.machine_id == machine_id)
                            .order_by(T.runs.c.measured_at, T.runs.c.id)).all()
    if not rows:
        known = machine_ids(engine)
        raise InputError(f"no machine {machine_id!r} in the history {engine.url.render_as_string(hide_password=True)}"
                         f"; known: {', '.join(known) or 'none (add a run with pige history add)'}")
    if not light:
        return [run_record(r) for r in rows]
    values = _float_rows([r.values_json for r in rows])  # one parse for the whole history
    std = _float_rows([r.std_json for r in rows])
    charts = json.loads("[" + ",".join(r.chart_json or "null" for r in rows) + "]")
    return [run_record(r, light=True, numbers=(v, e), chart=c) for r, v, e, c in zip(rows, values, std, charts,
                                                                                       strict=True)]


def existing_run(engine: sa.Engine, path: Path) -> None:
    """Refuse a file that is already in the history (a run is added once).

    Raises
    ------
    InputError
    """
    with engine.connect() as conn:
        dup = _existing(conn, _sha256(path))
    if dup is not None:
        raise InputError(f"{path}: this file is already in the history (run {dup.id} of machine {dup.machine_id}, "
                         f"added as {dup.file_name}): a run is added once")


def add_checkup_run(engine: sa.Engine, path: Path, machine_id: str, code: str, measured: tuple[str, str], fit: Any,
                    setup: dict[str, Any], verdict: str, checkup: dict[str, Any], chart: dict[str, Any]) -> RunRecord:
    """Store a check-up (``kind = checkup``): the row of :func:`~.records.checkup_values`.

    Raises
    ------
    InputError
        The file is already stored (also when another user stored it meanwhile).
    """
    values = checkup_values(path, machine_id, code, measured, fit, setup, verdict, checkup, chart)
    try:
        return run_record(_insert_run(engine, machine_id, code, values["added_at"], values, path))
    except sa.exc.IntegrityError:
        raise InputError(f"{path}: this file is already in the history: a run is added once") from None


class EngineHistory:
    """What a check-up reads and writes of a history, through SQLAlchemy (any database)."""

    def __init__(self, engine: sa.Engine) -> None:
        self.engine = engine

    def list_runs(self, machine_id: str, *, light: bool = False) -> list[RunRecord]:
        return list_runs(self.engine, machine_id, light=light)

    def existing(self, path: Path) -> None:
        existing_run(self.engine, path)

    def add_checkup(self, *args: Any) -> RunRecord:
        return add_checkup_run(self.engine, *args)
