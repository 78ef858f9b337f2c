"""Machine history: every calibration run and check-up of a machine in a database, and what changed between runs.

- :mod:`~pige_sym.verdict.history.tables` the tables (SQLAlchemy Core), :mod:`~pige_sym.verdict.history.migrations`
  the versioned schema changes that build them (kept in the repository, applied when a command writes);
- :mod:`~pige_sym.verdict.history.connection` open the database (SQLite file by default, PostgreSQL by URL):
  checked first, a damaged one refused unchanged; read-only to read (nothing migrated), migrated to write;
- :mod:`~pige_sym.verdict.history.integrity` those checks (pages, schema version, tables and columns, every stored
  run) and the one-line refusal, without SQLAlchemy;
- :mod:`~pige_sym.verdict.history.store` add a run, list a machine's runs, store a check-up (SQLAlchemy);
- :mod:`~pige_sym.verdict.history.records` the run record, the database URLs and a check-up's row, without
  SQLAlchemy; :mod:`~pige_sym.verdict.history.decode` a stored run read strictly (every column checked), and the
  same checks before a run is added; :mod:`~pige_sym.verdict.history.plain_rows` the plain text pige writes, read
  for a whole history at once (what the strict reader accepts, faster);
- :mod:`~pige_sym.verdict.history.sqlite_fast` what ``pige checkup`` reads and writes of an SQLite history with the
  standard library's ``sqlite3``, with the same checks (SQLAlchemy's import alone is most of the check-up's time
  budget);
- :mod:`~pige_sym.verdict.history.changes` the change of each parameter between two runs and its
  significance from both covariances (pure NumPy/SciPy, no database).

The names below are imported when first used (PEP 562), so that importing one light module of the package does not
import SQLAlchemy.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Change", "Comparison", "RunRecord", "add_run", "compare_runs", "connect", "default_url", "list_runs"]
_WHERE = {"Change": "changes", "Comparison": "changes", "compare_runs": "changes", "RunRecord": "records",
          "default_url": "records", "add_run": "store", "connect": "connection", "list_runs": "store"}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
