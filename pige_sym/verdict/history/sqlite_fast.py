"""What ``pige checkup`` reads and writes of an SQLite history, with the standard library's ``sqlite3``.

SQLAlchemy's import alone takes 0.6 s on the benchmark machine, more than half of the second ``pige checkup`` has
(issue 42).  A check-up of an SQLite history at the current schema version therefore reads it here, with the same
checks and the same SQL as the SQLAlchemy path (:mod:`~pige_sym.verdict.history.connection` and
:mod:`~pige_sym.verdict.history.store`):

- :func:`open_history` opens the file read-only (``mode=ro``: the file is never written while it is read) and runs
  every check of :mod:`~pige_sym.verdict.history.integrity` — SQLite's page check, the schema version, the tables
  and columns, every stored run of every machine read strictly — so a damaged file or an absurd stored estimate is
  refused in the same one line as ``pige history show`` refuses it, and left as it was;
- the runs of the machine are the records those checks decoded (light: check-ups as chart points), put in
  measurement order (time, then id);
- the check-up's row is checked (:func:`~pige_sym.verdict.history.decode.check_new_run`) before one ``INSERT``
  into ``runs`` in a transaction, on a connection that may write but not create (``mode=rw``).

Anything else goes through SQLAlchemy (:class:`~pige_sym.verdict.history.store.EngineHistory`): PostgreSQL, a file
that does not exist or holds no history, a file of an older schema version (read as it is, migrated when the
check-up stores its run), a machine not in the history (the message lists the known ones).
``tests/test_checkup.py`` checks that both paths read the same records and store the same row.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import quote

from pige_sym.errors import InputError, SchemaRefusal
from pige_sym.verdict.history.decode import check_new_run, decode_run, not_stored
from pige_sym.verdict.history.integrity import SCHEMA_VERSION, Checked, check_database, damaged
from pige_sym.verdict.history.records import RunRecord, checkup_values, file_sha256, fleet_of, normalise_url

__all__ = ["SCHEMA_VERSION", "SqliteHistory", "open_history"]


def _uri(path: Path, mode: str) -> str:
    return f"file:{quote(str(path.resolve()))}?mode={mode}"


def _dict_rows(cursor: sqlite3.Cursor, row: tuple[Any, ...]) -> dict[str, Any]:
    return {d[0]: v for d, v in zip(cursor.description, row, strict=True)}


class _Reader:
    """:class:`~pige_sym.verdict.history.integrity.Reader` on a ``sqlite3`` connection."""

    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn

    def quick_check(self) -> list[str] | None:
        return [str(next(iter(r.values()))) for r in self.conn.execute("PRAGMA quick_check").fetchall()]

    def versions(self) -> list[Any] | None:
        if "schema_version" not in self.tables():
            return None
        return [r["version"] for r in self.conn.execute("SELECT version FROM schema_version").fetchall()]

    def tables(self) -> set[str]:
        return {r["name"] for r in self.conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}

    def columns(self, table: str) -> set[str]:
        return {r["name"] for r in self.conn.execute(f"PRAGMA table_info({_quoted(table)})")}

    def has_run(self) -> bool:
        return "runs" in self.tables() and self.conn.execute("SELECT id FROM runs LIMIT 1").fetchone() is not None

    def runs(self, columns: tuple[str, ...]) -> Iterable[Mapping[Any, Any]]:
        return self.conn.execute(f"SELECT {', '.join(columns)} FROM runs ORDER BY id")


def _quoted(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


class SqliteHistory:
    """A check-up's reads and its insert on an SQLite history at :data:`SCHEMA_VERSION`, checked (module
    docstring)."""

    def __init__(self, path: Path, checked: Checked | None = None) -> None:
        self.path = path
        self.checked = checked if checked is not None else _check(path)
        if self.checked.state != "ready" or self.checked.version != SCHEMA_VERSION:
            raise InputError(f"history database {path} is not a history at schema version {SCHEMA_VERSION}")

    def list_runs(self, machine_id: str, *, light: bool = False) -> list[RunRecord]:
        """The machine's runs in measurement order, check-ups as chart points (``light``, what a check-up reads)."""
        runs = sorted((r for r in self.checked.records if r.machine_id == machine_id),
                      key=lambda r: (r.measured_at, r.id))
        if not light or not runs:
            return _engine(self.path).list_runs(machine_id, light=light)  # its refusal names the known machines
        return runs

    def fleet(self, machine_code: str, machine_id: str) -> list[list[RunRecord]]:
        """The runs of every other machine of the structure ``machine_code`` (each in measurement order, light)."""
        return fleet_of(self.checked.records, machine_code, machine_id)

    def existing(self, path: Path) -> None:
        """Refuse a file already in the history (a run is added once)."""
        sha = file_sha256(path)
        dup = next((r for r in self.checked.records if r.file_sha256 == sha), None)
        if dup is not None:
            raise InputError(f"{path}: this file is already in the history (run {dup.id} of machine {dup.machine_id}, "
                             f"added as {dup.file_name}): a run is added once")

    def add_checkup(self, path: Path, machine_id: str, code: str, measured: tuple[str, str], fit: Any,
                    setup: dict[str, Any], verdict: str, checkup: dict[str, Any], chart: dict[str, Any]) -> RunRecord:
        """Store a check-up of a machine the history knows (its full calibration added it), checked first.

        Raises
        ------
        InputError
            The file is already stored, or the machine id is another machine's.
        HistoryError
            The check-up's estimate is not one pige stores.
        """
        values = checkup_values(path, machine_id, code, measured, fit, setup, verdict, checkup, chart)
        try:
            check_new_run(values)
        except SchemaRefusal as exc:
            raise not_stored(path, exc) from None
        names = list(values)
        conn = sqlite3.connect(_uri(self.path, "rw"), uri=True, timeout=30)
        conn.row_factory = _dict_rows
        try:
            conn.execute("PRAGMA foreign_keys=ON")
            with conn:
                known = conn.execute("SELECT machine_code FROM machines WHERE machine_id = ?", (machine_id,)).fetchone()
                if known is None or known["machine_code"] != code:
                    raise InputError(f"machine id {machine_id!r} is not a {code} in the history: use the right "
                                     "--machine-id")
                cur = conn.execute(f"INSERT INTO runs ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})",
                                   [values[n] for n in names])
                row = conn.execute("SELECT * FROM runs WHERE id = ?", (cur.lastrowid,)).fetchone()
        except sqlite3.IntegrityError:
            raise InputError(f"{path}: this file is already in the history: a run is added once") from None
        except sqlite3.Error as exc:
            raise InputError(f"history database {self.path}: {exc}") from None
        finally:
            conn.close()
        return decode_run(row)


def _check(path: Path) -> Checked:
    """:func:`~pige_sym.verdict.history.integrity.check_database` on the file, opened read-only; the runs kept.

    Raises
    ------
    HistoryError
        Damaged (the file is left as it was).
    """
    try:
        conn = sqlite3.connect(_uri(path, "ro"), uri=True, timeout=30)
    except sqlite3.Error as exc:
        raise InputError(f"history database {path}: {exc}") from None
    conn.row_factory = _dict_rows
    try:
        return check_database(_Reader(conn), str(path), True, keep=True)
    except sqlite3.Error as exc:
        raise damaged(str(path), (str(exc).strip().splitlines() or [type(exc).__name__])[0], True) from None
    finally:
        conn.close()


def _engine(path: Path) -> Any:
    from pige_sym.verdict.history.store import EngineHistory, connect

    return EngineHistory(connect(str(path), create=False))


def open_history(url: str | None) -> Any:
    """The history a check-up reads and writes: :class:`SqliteHistory` for an SQLite file at :data:`SCHEMA_VERSION`
    (checked), else SQLAlchemy's (:class:`~pige_sym.verdict.history.store.EngineHistory`: read-only until the
    check-up stores its run; it refuses, reads an older schema as it is, or connects to PostgreSQL).

    Raises
    ------
    HistoryError
        The file is damaged (module docstring).
    """
    full = normalise_url(url)
    path = Path(full.removeprefix("sqlite:///")) if full.startswith("sqlite:///") else None
    if path is not None and str(path) not in ("", ":memory:") and path.is_file():
        checked = _check(path)
        if checked.state == "ready" and checked.version == SCHEMA_VERSION:
            return SqliteHistory(path, checked)
        return _engine(path)
    from pige_sym.verdict.history.store import EngineHistory, connect

    return EngineHistory(connect(url, create=False))
