"""The checks of a history database before anything is read from it or added to it, and the refusal of a damaged one.

In this order (the schema version first: it is recorded last, once a migration's tables all exist, so a database
another process is creating this moment is never taken for a damaged one):

1. SQLite's page check (``PRAGMA quick_check``; PostgreSQL keeps its own pages);
2. the schema version: none recorded and no run stored is a new (empty) database, which writing creates; none
   recorded but runs stored, or something other than version numbers, is damage; a version newer than this pige is
   refused (upgrade pige);
3. pige's tables, and the columns each has at that version (:data:`COLUMNS`: a version-1 file lacks the check-up's
   columns, and is read as it is);
4. every stored run, of every machine, in the order of their ids, read strictly as a light record
   (:func:`~pige_sym.verdict.history.decode.decode_run`: every column but a check-up's set-up and findings, which
   are checked where they are read).

A damaged database is refused in one line (:func:`damaged`): the file (or the URL, password hidden), what is
damaged — the run and column when known — and how to recover; pige changes nothing in a database it refuses
(reading opens it read-only).  The checks read through a :class:`Reader`, so that the SQLAlchemy path
(:mod:`~pige_sym.verdict.history.store`) and ``pige checkup``'s ``sqlite3`` path
(:mod:`~pige_sym.verdict.history.sqlite_fast`) check alike.  Plain Python: no SQLAlchemy import.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from pige_sym.errors import HistoryError, InputError, SchemaRefusal

#: The schema version this code writes: the last migration's (:mod:`~pige_sym.verdict.history.migrations`).
SCHEMA_VERSION = 3

_RUNS_V1 = ("id", "machine_id", "file_sha256", "file_name", "measured_at", "time_source", "added_at", "machine_code",
            "method", "parameters", "units", "values_json", "std_json", "covariance_json", "dof", "rms_um",
            "effects_json", "verdict", "check_json")

#: The columns of pige's tables at each schema version (``tests/test_history.py`` checks them against the migrations
#: and :mod:`~pige_sym.verdict.history.tables`).
COLUMNS: dict[int, dict[str, tuple[str, ...]]] = {
    1: {"schema_version": ("version", "description", "applied_at"),
        "machines": ("machine_id", "machine_code", "created_at"),
        "runs": _RUNS_V1},
    2: {"schema_version": ("version", "description", "applied_at"),
        "machines": ("machine_id", "machine_code", "created_at"),
        "runs": (*_RUNS_V1, "kind", "setup_json", "checkup_json", "chart_json")},
    3: {"schema_version": ("version", "description", "applied_at"),
        "machines": ("machine_id", "machine_code", "created_at"),
        "runs": (*_RUNS_V1, "kind", "setup_json", "checkup_json", "chart_json", "after_correction")},
}


class Reader(Protocol):
    """What the checks read of a database (one open connection)."""

    def quick_check(self) -> list[str] | None:
        """SQLite's page check (``["ok"]`` when sound); None: not SQLite."""

    def versions(self) -> list[Any] | None:
        """The rows of ``schema_version.version``; None: no such table."""

    def tables(self) -> set[str]:
        """The tables the database has now."""

    def columns(self, table: str) -> set[str]:
        """The columns of a table."""

    def has_run(self) -> bool:
        """Whether the table ``runs`` exists and holds a row."""

    def runs(self, columns: tuple[str, ...]) -> Iterable[Mapping[Any, Any]]:
        """Every run (those columns, the values as stored: no conversion), in the order of their ids."""


@dataclass
class Checked:
    """What the checks found: ``empty`` (none of pige's tables: a new database) or ``ready`` at ``version``."""

    state: str
    version: int = 0
    records: list[Any] = field(default_factory=list)

    def columns(self, table: str = "runs") -> tuple[str, ...]:
        return COLUMNS[self.version][table]


def damaged(shown: str, what: str, sqlite: bool) -> HistoryError:
    """The one-line refusal of a damaged database (module docstring)."""
    backup = "restore the file from a backup" if sqlite else "restore the database from a backup"
    return HistoryError(f"history database {shown} is damaged ({what}): {backup}; pige has changed nothing in it")


def check_database(reader: Reader, shown: str, sqlite: bool, *, keep: bool = False) -> Checked:
    """The checks of the module docstring; ``keep``: the runs' light records in :attr:`Checked.records` (every
    machine's, in the order of their ids).

    Raises
    ------
    InputError
        The database is newer than this pige.
    HistoryError
        Damaged (module docstring).
    """
    pages = reader.quick_check()
    if pages is not None and pages != ["ok"]:
        raise damaged(shown, f"SQLite's page check: {pages[0] if pages else 'no answer'}", sqlite)
    versions = reader.versions() or []
    names = reader.tables()  # after the version (module docstring)
    if not versions:
        if not reader.has_run():
            return Checked("empty")
        why = "the table schema_version is missing" if "schema_version" not in names else "no schema version recorded"
        raise damaged(shown, f"{why}, but runs are stored", sqlite)
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in versions) or min(versions) < 1:
        raise damaged(shown, f"schema_version holds {versions[:3]}, not pige's version numbers", sqlite)
    version = max(versions)
    if version > SCHEMA_VERSION:
        raise InputError(f"history database {shown} has schema version {version}, newer than this pige_sym knows "
                         f"({SCHEMA_VERSION}): upgrade pige_sym")
    checked = Checked("ready", version)
    for table, wanted in COLUMNS[version].items():
        if table not in names:
            raise damaged(shown, f"the table {table} is missing", sqlite)
        have = reader.columns(table)
        missing = [c for c in wanted if c not in have]
        if missing:
            raise damaged(shown, f"the table {table} has no column {missing[0]}", sqlite)
    light = tuple(c for c in checked.columns() if c != "checkup_json")  # what a light record reads
    checked.records = check_runs(reader.runs(light), shown, sqlite)
    if not keep:
        checked.records = []
    return checked


def check_runs(rows: Iterable[Mapping[Any, Any]], shown: str, sqlite: bool, *, light: bool = True) -> list[Any]:
    """Every row decoded strictly (:func:`~pige_sym.verdict.history.decode.decode_run`); the first damaged one
    refused naming its run and column.

    Raises
    ------
    HistoryError
    """
    from pige_sym.verdict.history.decode import decode_runs

    def refused(row: Mapping[Any, Any], exc: SchemaRefusal) -> HistoryError:
        return damaged(shown, f"run {row['id']}, {exc}", sqlite)

    return decode_runs(rows, refused, light=light)


def no_machine(machine_id: str, shown: str, known: list[str]) -> InputError:
    """The refusal of a machine id the history does not hold (the known ones listed)."""
    return InputError(f"no machine {machine_id!r} in the history {shown}; known: "
                      f"{', '.join(known) or 'none (add a run with pige history add)'}")
