"""Machine history: every calibration run of a machine in a database, and what changed between runs.

- :mod:`~pige_sym.verdict.history.tables` the tables (SQLAlchemy Core), :mod:`~pige_sym.verdict.history.migrations`
  the versioned schema changes that build them (kept in the repository, applied on connect);
- :mod:`~pige_sym.verdict.history.store` connect (SQLite file by default, PostgreSQL by URL; a damaged database
  refused unchanged), add a run, list a machine's runs;
- :mod:`~pige_sym.verdict.history.records` a stored run, read strictly (every column checked);
- :mod:`~pige_sym.verdict.history.changes` the change of each parameter between two runs and its
  significance from both covariances (pure NumPy/SciPy, no database).
"""

from pige_sym.verdict.history.changes import Change, Comparison, compare_runs
from pige_sym.verdict.history.records import RunRecord
from pige_sym.verdict.history.store import add_run, connect, default_url, list_runs

__all__ = ["Change", "Comparison", "RunRecord", "add_run", "compare_runs", "connect", "default_url", "list_runs"]
