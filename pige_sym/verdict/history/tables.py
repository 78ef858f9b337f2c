"""The history tables as the code queries them (SQLAlchemy Core), after every migration.

``machines``: one row per machine id (the shop's name for a machine) with its ISO 10791 code.
``runs``: one calibration run: the measurement file's SHA-256 (unique: a file is added once),
when it was measured, the estimate (parameter names, units, values, standard errors and full
covariance as JSON text, ``null`` where undetermined), the accepted effects, and the verdict
of ``pige check`` when tolerances were given (of a check-up: ``ok``, ``drifted`` or ``out``); ``kind``: ``full``
(a calibration, ``pige history add``) or ``checkup`` (``pige checkup``); ``setup_json``: the set-up the file was
measured with (:mod:`~pige_sym.measurements.run_setup`: instrument, sphere or ball, pivots, sense, tool, the
probing program's controller state), null for runs stored before schema version 2; ``checkup_json``: what a
check-up found (control limits, trend, verdict, the changes to enter); ``chart_json``: the few items of it later
check-ups read (signature, flags, correction, tolerance), small so that a long history reads fast;
``after_correction``: 1 when the run was measured after a correction was entered (``--corrected``: it starts a
segment of the check-ups' chart), else 0.
``schema_version``: applied migrations.
Times are ISO 8601 UTC text so that SQLite and PostgreSQL store them alike.
"""

from __future__ import annotations

import sqlalchemy as sa

metadata = sa.MetaData()

schema_version = sa.Table(
    "schema_version", metadata,
    sa.Column("version", sa.Integer, primary_key=True, autoincrement=False),
    sa.Column("description", sa.Text, nullable=False),
    sa.Column("applied_at", sa.String(40), nullable=False),
)

machines = sa.Table(
    "machines", metadata,
    sa.Column("machine_id", sa.String(200), primary_key=True),
    sa.Column("machine_code", sa.String(100), nullable=False),
    sa.Column("created_at", sa.String(40), nullable=False),
)

runs = sa.Table(
    "runs", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("machine_id", sa.String(200), sa.ForeignKey("machines.machine_id"), nullable=False, index=True),
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
    sa.Column("check_json", sa.Text, nullable=True),
    sa.Column("kind", sa.String(20), nullable=False, server_default="full"),
    sa.Column("setup_json", sa.Text, nullable=True),
    sa.Column("checkup_json", sa.Text, nullable=True),
    sa.Column("chart_json", sa.Text, nullable=True),
    sa.Column("after_correction", sa.Integer, nullable=False, server_default="0"),
)
