"""Versioned schema migrations of the history database, applied in order on connect.

Each migration is a function of an open connection inside a transaction; its number is
recorded in ``schema_version``.  A database newer than this code (a version we do not know)
is refused rather than written.  To change the schema: append a migration (never edit an
applied one) and update :mod:`~pige_sym.verdict.history.tables` to the result.  On PostgreSQL the
migrations run under a transaction-level advisory lock, so two users connecting at once do not
both apply them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone

import sqlalchemy as sa

from pige_sym.errors import InputError


@dataclass(frozen=True)
class Migration:
    """One schema change: ``apply(connection)``."""

    version: int
    description: str
    apply: Callable[[sa.Connection], None]


def _v1(conn: sa.Connection) -> None:
    md = sa.MetaData()
    sa.Table("machines", md,
             sa.Column("machine_id", sa.String(200), primary_key=True),
             sa.Column("machine_code", sa.String(100), nullable=False),
             sa.Column("created_at", sa.String(40), nullable=False))
    sa.Table("runs", md,
             sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
             sa.Column("machine_id", sa.String(200), sa.ForeignKey("machines.machine_id"), nullable=False,
                       index=True),
             sa.Column("file_sha256", sa.String(64), nullable=False, unique=True),
             sa.Column("file_name", sa.Text, nullable=False),
             sa.Column("measured_at", sa.String(40), nullable=False),
             sa.Column("time_source", sa.String(40), nullable=False),
             sa.Column("added_at", sa.String(40), nullable=False),
             sa.Column("machine_code", sa.String(100), nullable=False),
             sa.Column("method", sa.String(40), nullable=False),
             sa.Column("parameters", sa.Text, nullable=False),
             sa.Column("units", sa.Text, nullable=False),
             sa.Column("values_json", sa.Text, nullable=False),
             sa.Column("std_json", sa.Text, nullable=False),
             sa.Column("covariance_json", sa.Text, nullable=False),
             sa.Column("dof", sa.Integer, nullable=False),
             sa.Column("rms_um", sa.Float, nullable=True),
             sa.Column("effects_json", sa.Text, nullable=False),
             sa.Column("verdict", sa.String(20), nullable=True),
             sa.Column("check_json", sa.Text, nullable=True))
    md.create_all(conn)


def _v2(conn: sa.Connection) -> None:
    """Check-ups: the kind of a run, the set-up it was measured with, what the check-up found, what later ones read."""
    for ddl in ("ALTER TABLE runs ADD COLUMN kind VARCHAR(20) DEFAULT 'full' NOT NULL",
                "ALTER TABLE runs ADD COLUMN setup_json TEXT",
                "ALTER TABLE runs ADD COLUMN checkup_json TEXT",
                "ALTER TABLE runs ADD COLUMN chart_json TEXT"):
        conn.execute(sa.text(ddl))


def _v3(conn: sa.Connection) -> None:
    """A run measured after a correction was entered (``--corrected``): it starts a segment of the check-ups' chart."""
    conn.execute(sa.text("ALTER TABLE runs ADD COLUMN after_correction INTEGER DEFAULT 0 NOT NULL"))


MIGRATIONS: tuple[Migration, ...] = (
    Migration(1, "machines and runs (estimate with full covariance, effects, verdict)", _v1),
    Migration(2, "check-ups: runs.kind (full or checkup), runs.setup_json, runs.checkup_json, runs.chart_json", _v2),
    Migration(3, "runs.after_correction: measured after a correction was entered (--corrected)", _v3),
)


def _version_table(conn: sa.Connection) -> sa.Table:
    md = sa.MetaData()
    table = sa.Table("schema_version", md,
                     sa.Column("version", sa.Integer, primary_key=True, autoincrement=False),
                     sa.Column("description", sa.Text, nullable=False),
                     sa.Column("applied_at", sa.String(40), nullable=False))
    md.create_all(conn)
    return table


#: Attempts of a migration that lost a race with another process creating the same tables.
MIGRATION_ATTEMPTS = 8


def migrate(engine: sa.Engine) -> int:
    """Apply the missing migrations; returns the schema version.

    Safe when several processes connect to a new database at once: on PostgreSQL an advisory lock
    serialises them; on SQLite (no such lock) a process whose ``CREATE TABLE`` or version row lost the
    race to another one rolls back and starts again, and then finds the migration applied.

    Raises
    ------
    InputError
        The database has a schema version this code does not know (written by a newer pige_sym).
    """
    import time

    for attempt in range(MIGRATION_ATTEMPTS):
        try:
            return _migrate_once(engine)
        except (sa.exc.OperationalError, sa.exc.ProgrammingError, sa.exc.IntegrityError) as exc:
            raced = isinstance(exc, sa.exc.IntegrityError) or "already exists" in str(exc) or "locked" in str(exc)
            if not raced or attempt == MIGRATION_ATTEMPTS - 1:
                raise
            time.sleep(0.05 * (attempt + 1))
    raise AssertionError("unreachable")  # pragma: no cover


def _migrate_once(engine: sa.Engine) -> int:
    with engine.begin() as conn:
        if conn.dialect.name == "postgresql":
            conn.execute(sa.text("SELECT pg_advisory_xact_lock(7142030117)"))
        table = _version_table(conn)
        done = {int(v) for v in conn.execute(sa.select(table.c.version)).scalars()}
        known = {m.version for m in MIGRATIONS}
        newer = sorted(done - known)
        if newer:
            raise InputError(f"history database {engine.url.render_as_string(hide_password=True)} has schema "
                             f"version {newer[-1]}, newer than this pige_sym knows ({max(known)}): upgrade pige_sym")
        for mig in MIGRATIONS:
            if mig.version in done:
                continue
            mig.apply(conn)
            conn.execute(sa.insert(table).values(version=mig.version, description=mig.description,
                                                 applied_at=datetime.now(timezone.utc).isoformat(timespec="seconds")))
    return max(known)
