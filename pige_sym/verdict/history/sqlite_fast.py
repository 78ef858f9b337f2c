"""What ``pige checkup`` reads and writes of an SQLite history, with the standard library's ``sqlite3``.

SQLAlchemy's import alone takes 0.6 s on the benchmark machine, more than half of the second ``pige checkup`` has
(issue 42).  A check-up of an SQLite history at the current schema version therefore reads the machine's runs and
stores its one row here, with the same SQL the SQLAlchemy path runs (:mod:`~pige_sym.verdict.history.store`: the
runs of a machine ordered by time then id; the file's SHA-256 looked up; one ``INSERT`` into ``runs`` in a
transaction) and the same records (:mod:`~pige_sym.verdict.history.records`).  Anything else — PostgreSQL, a file
that does not exist, a schema version other than :data:`SCHEMA_VERSION` (to be migrated), a machine not in the
history (the message lists the known ones) — goes through SQLAlchemy: :func:`open_history` decides.
``tests/test_checkup.py`` checks that both paths read the same records and store the same row.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from pige_sym.errors import InputError
from pige_sym.verdict.history.records import RunRecord, _float_rows, _sha256, checkup_values, normalise_url, run_record

#: The schema version this code writes (the last migration's; a test checks they agree).
SCHEMA_VERSION = 2
LIGHT_COLUMNS = ("id", "machine_id", "file_sha256", "file_name", "measured_at", "time_source", "added_at",
                 "machine_code", "method", "parameters", "units", "values_json", "std_json", "covariance_json", "dof",
                 "rms_um", "effects_json", "verdict", "check_json", "kind", "setup_json", "chart_json")


def _rows(cursor: sqlite3.Cursor, row: tuple[Any, ...]) -> SimpleNamespace:
    return SimpleNamespace(**{d[0]: v for d, v in zip(cursor.description, row, strict=True)})


class SqliteHistory:
    """A check-up's reads and its insert on an SQLite history at :data:`SCHEMA_VERSION` (module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def _connect(self) -> sqlite3.Connection:
        conn = sqlite3.connect(self.path, timeout=30)
        conn.row_factory = _rows
        conn.execute("PRAGMA foreign_keys=ON")
        return conn

    def list_runs(self, machine_id: str, *, light: bool = False) -> list[RunRecord]:
        """The machine's runs in measurement order, check-ups as chart points (``light``, what a check-up reads)."""
        if not light:
            return _engine(self.path).list_runs(machine_id)
        conn = self._connect()
        try:
            rows = conn.execute(f"SELECT {', '.join(LIGHT_COLUMNS)} FROM runs WHERE machine_id = ? "
                                "ORDER BY measured_at, id", (machine_id,)).fetchall()
        finally:
            conn.close()
        if not rows:
            return _engine(self.path).list_runs(machine_id, light=True)  # its refusal names the known machines
        values = _float_rows([r.values_json for r in rows])
        std = _float_rows([r.std_json for r in rows])
        charts = json.loads("[" + ",".join(r.chart_json or "null" for r in rows) + "]")
        return [run_record(r, light=True, numbers=(v, e), chart=c)
                for r, v, e, c in zip(rows, values, std, charts, strict=True)]

    def existing(self, path: Path) -> None:
        """Refuse a file already in the history (a run is added once)."""
        conn = self._connect()
        try:
            dup = conn.execute("SELECT id, machine_id, file_name FROM runs WHERE file_sha256 = ?",
                               (_sha256(path),)).fetchone()
        finally:
            conn.close()
        if dup is not None:
            raise InputError(f"{path}: this file is already in the history (run {dup.id} of machine {dup.machine_id}, "
                             f"added as {dup.file_name}): a run is added once")

    def add_checkup(self, path: Path, machine_id: str, code: str, measured: tuple[str, str], fit: Any,
                    setup: dict[str, Any], verdict: str, checkup: dict[str, Any], chart: dict[str, Any]) -> RunRecord:
        """Store a check-up of a machine the history knows (its full calibration added it)."""
        values = checkup_values(path, machine_id, code, measured, fit, setup, verdict, checkup, chart)
        names = list(values)
        conn = self._connect()
        try:
            with conn:
                known = conn.execute("SELECT machine_code FROM machines WHERE machine_id = ?", (machine_id,)).fetchone()
                if known is None or known.machine_code != code:
                    raise InputError(f"machine id {machine_id!r} is not a {code} in the history: use the right "
                                     "--machine-id")
                cur = conn.execute(f"INSERT INTO runs ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})",
                                   [values[n] for n in names])
                row = conn.execute("SELECT * FROM runs WHERE id = ?", (cur.lastrowid,)).fetchone()
        except sqlite3.IntegrityError:
            raise InputError(f"{path}: this file is already in the history: a run is added once") from None
        finally:
            conn.close()
        return run_record(row)


def _engine(path: Path) -> Any:
    from pige_sym.verdict.history.store import EngineHistory, connect

    return EngineHistory(connect(str(path), create=False))


def open_history(url: str | None) -> Any:
    """The history a check-up reads and writes: :class:`SqliteHistory` for an SQLite file at :data:`SCHEMA_VERSION`,
    else SQLAlchemy's (:class:`~pige_sym.verdict.history.store.EngineHistory`, which migrates, refuses or connects
    to PostgreSQL)."""
    full = normalise_url(url)
    path = Path(full.removeprefix("sqlite:///")) if full.startswith("sqlite:///") else None
    if path is not None and path.is_file():
        try:
            conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=30)
            try:
                version = conn.execute("SELECT max(version) FROM schema_version").fetchone()[0]
            finally:
                conn.close()
        except sqlite3.Error:
            version = None
        if version == SCHEMA_VERSION:
            return SqliteHistory(path)
    if path is not None:
        return _engine(path)
    from pige_sym.verdict.history.store import EngineHistory, connect

    return EngineHistory(connect(url, create=False))
