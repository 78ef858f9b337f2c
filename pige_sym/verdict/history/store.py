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

A database that exists is checked before anything is read or written: SQLite's page check
(``PRAGMA quick_check``), pige's tables and their columns, the schema version; every stored run is read
strictly (:mod:`~pige_sym.verdict.history.records`).  A damaged one is refused in one line naming it, what is
damaged (the run and column when known) and how to recover (restore it from a backup).  Reading
(``history show``, ``report --history``) opens the database read-only (SQLite ``mode=ro``, PostgreSQL
read-only transactions) and migrates nothing, so a refused database is left exactly as it was.  A new SQLite
file is created with the mode every pige output gets (``0666`` less the umask: ``0664`` under ``002``, so a
shop's group can add runs), not SQLite's fixed ``0644``.
"""

from __future__ import annotations

import hashlib
import math
import os
import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from pige_sym.errors import FileFormatError, HistoryError, InputError, SchemaRefusal
from pige_sym.verdict.history import tables as T
from pige_sym.verdict.history.migrations import MIGRATIONS, migrate
from pige_sym.verdict.history.records import RunRecord, check_new_run, decode_run

ENV_URL = "PIGE_HISTORY_DB"


def default_url() -> str:
    """``$PIGE_HISTORY_DB``, else the SQLite file in the user data directory."""
    env = os.environ.get(ENV_URL)
    if env:
        return env
    import platformdirs

    return f"sqlite:///{Path(platformdirs.user_data_dir('pige_sym')) / 'history.sqlite'}"


def normalise_url(text: str | None) -> str:
    """A SQLAlchemy URL from ``--db`` (module docstring)."""
    text = text or default_url()
    if "://" not in text:
        return f"sqlite:///{Path(text).expanduser().resolve()}"
    scheme, _, rest = text.partition("://")
    if scheme in ("postgresql", "postgres", "postgresql+psycopg"):
        try:
            import psycopg  # noqa: F401
        except ImportError:
            raise InputError("--db postgresql://…: the PostgreSQL driver is not installed: "
                             "pip install 'pige_sym[postgres]' (psycopg 3)") from None
        return f"postgresql+psycopg://{rest}"
    if scheme == "sqlite":
        return text
    raise InputError(f"--db {text}: use a file path, sqlite:///PATH or postgresql://user@host/dbname")


def connect(url: str | None = None, *, create: bool = True) -> sa.Engine:
    """Engine of the history database, schema migrated (module docstring).

    ``create=False`` (reading: ``history show``, ``report --history``) opens it read-only and migrates nothing; an
    SQLite file that does not exist is refused instead of created there.

    Raises
    ------
    InputError
        The database cannot be opened or reached (message with the URL, password hidden), or (``create=False``)
        the SQLite file does not exist or holds no history.
    HistoryError
        The database is damaged (nothing in it is changed).
    """
    full = normalise_url(url)
    path = _sqlite_file(full)
    if path is not None:
        if not create and not path.is_file():
            raise InputError(f"no history database at {path} (pige history add creates one; --db or "
                             f"$PIGE_HISTORY_DB name another)")
        if create and not path.exists():
            _new_sqlite_file(path)
    engine = _engine(full, path, read_only=not create)
    shown = str(path) if path is not None else engine.url.render_as_string(hide_password=True)
    _WHERE[engine] = (shown, path is not None)
    state = _checked(engine, shown, path is not None)
    if not create:
        if state != "ready":
            raise InputError(f"history database {shown} holds no history yet (pige history add creates it)")
        return engine
    try:
        migrate(engine)
    except sa.exc.SQLAlchemyError as exc:
        raise InputError(f"history database {shown}: {_reason(exc)}") from None
    return engine


#: Every column of ``runs`` as the database holds it (no type conversion: the reader checks each value).
_RAW_RUNS: list[sa.Label[Any]] = [sa.literal_column(f"runs.{c.name}").label(c.name) for c in T.runs.columns]


def _sqlite_file(full: str) -> Path | None:
    """The file of an SQLite URL (None: another database, or SQLite in memory)."""
    if not full.startswith("sqlite:///"):
        return None
    path = Path(full.removeprefix("sqlite:///"))
    return None if str(path) in ("", ":memory:") else path


def _new_sqlite_file(path: Path) -> None:
    """Create an empty SQLite file (SQLite fills it) with the mode ``0666`` less the umask, its folder first."""
    from pige_sym.files import make_folder

    make_folder(path.parent, what="--db")
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except FileExistsError:  # another process made it meanwhile
        pass
    except OSError as exc:
        raise InputError(f"--db {path}: cannot create it ({exc.strerror or exc})") from None


def _engine(full: str, path: Path | None, *, read_only: bool) -> sa.Engine:
    """The engine; read-only: SQLite ``mode=ro`` (the file is never written), PostgreSQL read-only transactions."""
    if path is not None and read_only:
        import sqlite3
        from urllib.parse import quote

        uri = f"file:{quote(str(path.resolve()))}?mode=ro"
        engine = sa.create_engine("sqlite://", creator=lambda: sqlite3.connect(uri, uri=True,
                                                                              check_same_thread=False))
    elif read_only and full.startswith("postgresql"):
        engine = sa.create_engine(full, connect_args={"options": "-c default_transaction_read_only=on"})
    else:
        engine = sa.create_engine(full)
    if engine.dialect.name == "sqlite":
        @sa.event.listens_for(engine, "connect")
        def _fk(dbapi_conn: Any, _record: Any) -> None:
            dbapi_conn.execute("PRAGMA foreign_keys=ON")
    return engine


def _reason(exc: BaseException) -> str:
    """The database's own words for an error, one line."""
    orig = getattr(exc, "orig", None) or exc
    return (str(orig).strip().splitlines() or [type(orig).__name__])[0]


def damaged(shown: str, what: str, sqlite: bool) -> HistoryError:
    """The one-line refusal of a damaged database (module docstring)."""
    backup = "restore the file from a backup" if sqlite else "restore the database from a backup"
    return HistoryError(f"history database {shown} is damaged ({what}): {backup}; pige has changed nothing in it")


def _checked(engine: sa.Engine, shown: str, sqlite: bool) -> str:
    """``"empty"`` (none of pige's tables: a new database) or ``"ready"``; a damaged database is refused.

    Raises
    ------
    InputError
        The database cannot be reached, or is newer than this pige.
    HistoryError
        Damaged: SQLite's page check fails, a table or column is missing, the schema version is unreadable, a
        stored run is not what pige writes (:func:`~pige_sym.verdict.history.records.decode_run`).
    """
    import time

    from pige_sym.verdict.history.migrations import MIGRATION_ATTEMPTS

    try:
        conn = engine.connect()
    except sa.exc.SQLAlchemyError as exc:
        raise InputError(f"history database {shown}: {_reason(exc)}") from None
    with conn:
        for attempt in range(MIGRATION_ATTEMPTS):
            try:
                return _check_schema(conn, shown, sqlite)
            except sa.exc.OperationalError as exc:  # another process holds the file a moment: wait, as migrate does
                if "locked" not in str(exc) or attempt == MIGRATION_ATTEMPTS - 1:
                    raise damaged(shown, _reason(exc), sqlite) from None
                conn.rollback()
                time.sleep(0.05 * (attempt + 1))
            except sa.exc.SQLAlchemyError as exc:
                raise damaged(shown, _reason(exc), sqlite) from None
    raise AssertionError("unreachable")  # pragma: no cover


def _check_schema(conn: sa.Connection, shown: str, sqlite: bool) -> str:
    """:func:`_checked`'s checks.  The schema version is read first: it is recorded last, once a migration's tables
    all exist, so a database another process is creating this moment is never taken for a damaged one.  A database
    with no version recorded and no run (a creation under way, or interrupted) is new: migrating completes it."""
    if sqlite:
        found = [str(r[0]) for r in conn.exec_driver_sql("PRAGMA quick_check").all()]
        if found != ["ok"]:
            raise damaged(shown, f"SQLite's page check: {found[0] if found else 'no answer'}", sqlite)
    versions: list[Any] = []
    if sa.inspect(conn).has_table("schema_version"):
        versions = list(conn.execute(sa.select(sa.literal_column("version")).select_from(T.schema_version)).scalars())
    inspector = sa.inspect(conn)  # a fresh one: the tables as they are now, after the version
    names = set(inspector.get_table_names())
    if not versions:
        stored = "runs" in names and conn.execute(sa.select(sa.literal_column("id")).select_from(T.runs).limit(1))\
            .first() is not None
        if not stored:
            return "empty"
        why = "the table schema_version is missing" if "schema_version" not in names else "no schema version recorded"
        raise damaged(shown, f"{why}, but runs are stored", sqlite)
    for table in T.metadata.sorted_tables:
        if table.name not in names:
            raise damaged(shown, f"the table {table.name} is missing", sqlite)
        have = {c["name"] for c in inspector.get_columns(table.name)}
        missing = [c.name for c in table.columns if c.name not in have]
        if missing:
            raise damaged(shown, f"the table {table.name} has no column {missing[0]}", sqlite)
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in versions):
        raise damaged(shown, f"schema_version holds {versions[:3]}, not pige's version numbers", sqlite)
    newest = max(m.version for m in MIGRATIONS)
    if max(versions) > newest:
        raise InputError(f"history database {shown} has schema version {max(versions)}, newer than this pige_sym "
                         f"knows ({newest}): upgrade pige_sym")
    for row in conn.execute(sa.select(*_RAW_RUNS).select_from(T.runs).order_by(T.runs.c.id)):  # every run, any machine
        try:
            decode_run(row)
        except SchemaRefusal as exc:
            raise damaged(shown, f"run {row.id}, {exc}", sqlite) from None
    return "ready"


def _dumps(x: Any) -> str:
    from pige_sym.files import to_json

    return to_json(x, indent=None)


def measurement_time(path: Path, metadata: dict[str, str], given: str | None) -> tuple[str, str]:
    """(ISO 8601 UTC time, where it comes from): ``--date``, the file's ``date`` metadata, else its mtime.

    Raises
    ------
    InputError, FileFormatError
        A date that is not ISO 8601.
    """
    def parse(text: str) -> datetime:
        t = datetime.fromisoformat(text.strip())
        return t.replace(tzinfo=timezone.utc) if t.tzinfo is None else t.astimezone(timezone.utc)

    if given is not None:
        try:
            return parse(given).isoformat(timespec="seconds"), "--date"
        except ValueError:
            raise InputError(f"--date {given!r}: expected ISO 8601, e.g. 2026-11-23T14:05") from None
    if "date" in metadata:
        try:
            return parse(metadata["date"]).isoformat(timespec="seconds"), "file metadata date"
        except ValueError:
            raise FileFormatError(str(path), None, f"metadata date {metadata['date']!r} is not ISO 8601 "
                                                   "(e.g. 2026-11-23T14:05): fix it or pass --date") from None
    mtime = datetime.fromtimestamp(path.stat().st_mtime, timezone.utc)
    return mtime.isoformat(timespec="seconds"), "file modification time"


@dataclass
class _Read:
    """What was read: the machine and each file's contents."""

    machine: str
    items: list[Any]


def _sha256(path: Path) -> str:
    from pige_sym.files import read_input_bytes

    return hashlib.sha256(read_input_bytes(path)).hexdigest()


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
    }
    try:
        check_new_run(values)  # what the history would refuse to read back is never stored
    except SchemaRefusal as exc:
        raise HistoryError(f"{p}: not added to the history: its estimate ({exc}) is not one pige stores") from None
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


#: Where each engine :func:`connect` made points (for messages): its file or URL, and whether it is SQLite.
_WHERE: weakref.WeakKeyDictionary[sa.Engine, tuple[str, bool]] = weakref.WeakKeyDictionary()


def _where(engine: sa.Engine) -> tuple[str, bool]:
    return _WHERE.get(engine) or (engine.url.render_as_string(hide_password=True), engine.dialect.name == "sqlite")


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
        shown, sqlite = _where(engine)
        raise damaged(shown, _reason(exc), sqlite) from None
    return sorted(str(x) for x in ids)


def list_runs(engine: sa.Engine, machine_id: str) -> list[RunRecord]:
    """Runs of a machine in measurement order (time, then insertion), each read strictly
    (:func:`~pige_sym.verdict.history.records.decode_run`).

    Raises
    ------
    InputError
        No such machine id (the message lists the known ones).
    HistoryError
        A run or the database is damaged (the message names the run and the column).
    """
    shown, sqlite = _where(engine)
    try:
        with engine.connect() as conn:
            rows = conn.execute(sa.select(*_RAW_RUNS).select_from(T.runs).where(T.runs.c.machine_id == machine_id)
                                .order_by(T.runs.c.measured_at, T.runs.c.id)).all()
    except sa.exc.SQLAlchemyError as exc:
        raise damaged(shown, _reason(exc), sqlite) from None
    if not rows:
        known = machine_ids(engine)
        raise InputError(f"no machine {machine_id!r} in the history {shown}"
                         f"; known: {', '.join(known) or 'none (add a run with pige history add)'}")
    out = []
    for r in rows:
        try:
            out.append(decode_run(r))
        except SchemaRefusal as exc:
            raise damaged(shown, f"run {r.id}, {exc}", sqlite) from None
    return out
