"""Open the history database through SQLAlchemy: checked before anything else, read-only to read, migrated to write.

Database URLs (``--db``, :func:`~pige_sym.verdict.history.records.normalise_url`):

- default: an SQLite file ``history.sqlite`` in the user data directory (platformdirs;
  ``$PIGE_HISTORY_DB`` overrides), embedded, nothing to start;
- a plain path or ``sqlite:///PATH``: that SQLite file;
- ``postgresql://user@host:port/dbname``: a PostgreSQL server (shops with many machines and
  users; needs ``pip install 'pige_sym[postgres]'``, i.e. psycopg 3).

A database that exists is checked before anything is read or written
(:mod:`~pige_sym.verdict.history.integrity`: SQLite's page check, the schema version, pige's tables and their
columns at that version, every stored run read strictly); a damaged one is refused in one line naming it, what is
damaged and how to recover.

**Reading never changes the database.**  Reading (``history show``, ``history fleet``, ``report --history``,
``plan --checkup``, what ``pige checkup`` reads) opens it read-only (SQLite ``mode=ro``, PostgreSQL read-only
transactions) and migrates nothing: a file of an older schema version (1: no check-up columns) is read as it is,
its runs full calibrations with no stored set-up.  **Writing migrates**: ``history add`` and a check-up storing its
run open the database for writing (:func:`connect` with ``write``), which applies the missing migrations
(:mod:`~pige_sym.verdict.history.migrations`) after the checks and before the run is added.  A new SQLite file is
created by writing only, with the mode every pige output gets (``0666`` less the umask: ``0664`` under ``002``, so
a shop's group can add runs), not SQLite's fixed ``0644``.
"""

from __future__ import annotations

import os
import weakref
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from pige_sym.errors import InputError
from pige_sym.verdict.history import tables as T
from pige_sym.verdict.history.integrity import SCHEMA_VERSION, Checked, check_database, damaged
from pige_sym.verdict.history.migrations import migrate
from pige_sym.verdict.history.records import normalise_url


@dataclass(frozen=True)
class Where:
    """What an engine :func:`connect` made points at: its file (or URL, password hidden) for messages, whether it
    is SQLite, the schema version its tables have, the URL to open it again, whether it was opened for writing."""

    shown: str
    sqlite: bool
    version: int
    url: str
    write: bool


_WHERE: weakref.WeakKeyDictionary[sa.Engine, Where] = weakref.WeakKeyDictionary()


def where(engine: sa.Engine) -> Where:
    """:class:`Where` of an engine (one made elsewhere: its URL, the current schema, writable)."""
    found = _WHERE.get(engine)
    if found is not None:
        return found
    url = engine.url.render_as_string(hide_password=False)
    return Where(engine.url.render_as_string(hide_password=True), engine.dialect.name == "sqlite", SCHEMA_VERSION,
                 url, True)


def connect(url: str | None = None, *, create: bool = True, write: bool | None = None) -> sa.Engine:
    """Engine of the history database, checked (module docstring).

    ``create`` (``history add``): an SQLite file that does not exist is created.  ``write`` (default: ``create``):
    the engine writes, and the schema is migrated to the current version first.  ``create=False, write=False``
    (reading) opens it read-only and migrates nothing; ``create=False, write=True`` (a check-up storing its run)
    writes to a history that must exist.

    Raises
    ------
    InputError
        The database cannot be opened or reached (message with the URL, password hidden), or (``create=False``)
        the SQLite file does not exist or holds no history.
    HistoryError
        The database is damaged (nothing in it is changed).
    """
    write = create if write is None else write
    full = normalise_url(url)
    path = sqlite_file(full)
    if path is not None:
        if not create and not path.is_file():
            raise InputError(f"no history database at {path} (pige history add creates one; --db or "
                             f"$PIGE_HISTORY_DB name another)")
        if create and not path.exists():
            _new_sqlite_file(path)
    engine = _engine(full, path, read_only=not write)
    shown = str(path) if path is not None else engine.url.render_as_string(hide_password=True)
    checked = _checked(engine, shown, path is not None)
    if not create and checked.state != "ready":
        raise InputError(f"history database {shown} holds no history yet (pige history add creates it)")
    if write:
        try:
            migrate(engine)
        except sa.exc.SQLAlchemyError as exc:
            raise InputError(f"history database {shown}: {reason(exc)}") from None
    _WHERE[engine] = Where(shown, path is not None, SCHEMA_VERSION if write else checked.version, full, write)
    return engine


def writable(engine: sa.Engine) -> sa.Engine:
    """An engine that writes to the database ``engine`` reads (itself when it writes): migrated first."""
    w = where(engine)
    return engine if w.write else connect(w.url, create=False, write=True)


def sqlite_file(full: str) -> Path | None:
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


def reason(exc: BaseException) -> str:
    """The database's own words for an error, one line."""
    orig = getattr(exc, "orig", None) or exc
    return (str(orig).strip().splitlines() or [type(orig).__name__])[0]


def raw_columns(names: Iterable[str]) -> list[sa.Label[Any]]:
    """Columns of ``runs`` as the database holds them (no type conversion: the reader checks each value)."""
    return [sa.literal_column(f"runs.{c}").label(c) for c in names]


class _Reader:
    """:class:`~pige_sym.verdict.history.integrity.Reader` on an SQLAlchemy connection."""

    def __init__(self, conn: sa.Connection, sqlite: bool) -> None:
        self.conn, self.sqlite = conn, sqlite

    def quick_check(self) -> list[str] | None:
        return [str(r[0]) for r in self.conn.exec_driver_sql("PRAGMA quick_check").all()] if self.sqlite else None

    def versions(self) -> list[Any] | None:
        if not sa.inspect(self.conn).has_table("schema_version"):
            return None
        return list(self.conn.execute(sa.select(sa.literal_column("version")).select_from(T.schema_version))
                    .scalars())

    def tables(self) -> set[str]:
        return set(sa.inspect(self.conn).get_table_names())  # a fresh inspector: the tables as they are now

    def columns(self, table: str) -> set[str]:
        return {c["name"] for c in sa.inspect(self.conn).get_columns(table)}

    def has_run(self) -> bool:
        return "runs" in self.tables() and self.conn.execute(
            sa.select(sa.literal_column("id")).select_from(T.runs).limit(1)).first() is not None

    def runs(self, columns: tuple[str, ...]) -> Iterable[Mapping[Any, Any]]:
        rows = self.conn.execute(sa.select(*raw_columns(columns)).select_from(T.runs).order_by(T.runs.c.id))
        return (r._mapping for r in rows)


def _checked(engine: sa.Engine, shown: str, sqlite: bool) -> Checked:
    """:func:`~pige_sym.verdict.history.integrity.check_database` on an engine, waiting while another process holds
    the file a moment (as :func:`~pige_sym.verdict.history.migrations.migrate` does).

    Raises
    ------
    InputError
        The database cannot be reached, or is newer than this pige.
    HistoryError
        Damaged.
    """
    import time

    from pige_sym.verdict.history.migrations import MIGRATION_ATTEMPTS

    try:
        conn = engine.connect()
    except sa.exc.SQLAlchemyError as exc:
        raise InputError(f"history database {shown}: {reason(exc)}") from None
    with conn:
        for attempt in range(MIGRATION_ATTEMPTS):
            try:
                return check_database(_Reader(conn, sqlite), shown, sqlite)
            except sa.exc.OperationalError as exc:
                if "locked" not in str(exc) or attempt == MIGRATION_ATTEMPTS - 1:
                    raise damaged(shown, reason(exc), sqlite) from None
                conn.rollback()
                time.sleep(0.05 * (attempt + 1))
            except sa.exc.SQLAlchemyError as exc:
                raise damaged(shown, reason(exc), sqlite) from None
    raise AssertionError("unreachable")  # pragma: no cover
