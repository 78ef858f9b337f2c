"""The history's records without SQLAlchemy: database URLs, the run record, the row a check-up writes.

Everything here is plain Python and NumPy, so that ``pige checkup`` can read an SQLite history with the standard
library's ``sqlite3`` (:mod:`~pige_sym.verdict.history.sqlite_fast`) without importing SQLAlchemy.  A stored row
becomes a :class:`RunRecord` only through :func:`~pige_sym.verdict.history.decode.decode_run`, which checks every
field first.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.errors import FileFormatError, InputError

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


@dataclass
class RunRecord:
    """One stored run (the estimate in the attribute names :func:`~pige_sym.verdict.history.compare_runs` reads).

    Attributes
    ----------
    values, std : ndarray, shape=(P,) [µm, µrad]
        NaN where undetermined.
    covariance : ndarray, shape=(P, P)
    effects : list of dict
        Accepted findings (effect, options, params, std, units).
    check : dict or None
        ``pige check`` result when tolerances were given at ``add``.
    kind : {"full", "checkup"}
        A calibration (``pige history add``) or a check-up (``pige checkup``).
    setup : dict or None
        The set-up the file was measured with (:class:`~pige_sym.measurements.run_setup.RunSetup` as a dict);
        None for a set of files and for runs stored before schema version 2.
    checkup : dict or None
        What a check-up found (:mod:`pige_sym.verdict.checkup`).
    after_correction : bool
        Measured after a correction was entered (``--corrected``; False for runs stored before schema version 3).
    """

    id: int
    machine_id: str
    file_name: str
    file_sha256: str
    measured_at: str
    time_source: str
    added_at: str
    machine_code: str
    method: str
    parameters: list[str]
    units: dict[str, str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    dof: int
    rms_um: float | None
    effects: list[dict[str, Any]] = field(default_factory=list)
    verdict: str | None = None
    check: dict[str, Any] | None = None
    kind: str = "full"
    setup: dict[str, Any] | None = None
    checkup: dict[str, Any] | None = None
    after_correction: bool = False

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        return json_ready({
            "id": self.id, "machine_id": self.machine_id, "file": self.file_name, "sha256": self.file_sha256,
            "measured_at": self.measured_at, "time_source": self.time_source, "added_at": self.added_at,
            "machine": self.machine_code, "method": self.method,
            "pige": dict(zip(self.parameters, self.values, strict=True)),
            "std": dict(zip(self.parameters, self.std, strict=True)), "units": self.units,
            "covariance": {"parameters": self.parameters, "matrix": self.covariance}, "dof": self.dof,
            "rms_um": self.rms_um, "effects": [f.get("effect") for f in self.effects], "verdict": self.verdict,
            "check": self.check, "kind": self.kind, "setup": self.setup, "checkup": self.checkup,
            "after_correction": self.after_correction,
        })


def dumps(x: Any) -> str:
    """The JSON text a column holds (one line, ``null`` for NaN: :func:`~pige_sym.files.to_json`)."""
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


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex): how the history knows a file it holds."""
    from pige_sym.files import read_input_bytes

    return hashlib.sha256(read_input_bytes(path)).hexdigest()


def checkup_values(path: Path, machine_id: str, code: str, measured: tuple[str, str], fit: Any, setup: dict[str, Any],
                   verdict: str, checkup: dict[str, Any], chart: dict[str, Any]) -> dict[str, Any]:
    """The ``runs`` row of a check-up (``kind = checkup``): its PIGEs' estimate
    (:class:`~pige_sym.identification.subset.SubsetFit`), the set-up it was measured with, its verdict, what it found
    (:mod:`pige_sym.verdict.checkup`) and the part of it later check-ups read (``chart``)."""
    now = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return {
        "machine_id": machine_id, "file_sha256": file_sha256(path), "file_name": str(path.resolve()),
        "measured_at": measured[0], "time_source": measured[1], "added_at": now, "machine_code": code,
        "method": "checkup", "parameters": dumps(fit.parameters), "units": dumps(fit.units),
        "values_json": dumps(fit.values), "std_json": dumps(fit.std), "covariance_json": dumps(fit.covariance),
        "dof": int(fit.dof), "rms_um": float(fit.rms_um) if math.isfinite(fit.rms_um) else None,
        "effects_json": "[]", "verdict": verdict, "check_json": None, "kind": "checkup",
        "setup_json": dumps(setup), "checkup_json": dumps(checkup), "chart_json": dumps(chart),
        "after_correction": int(bool(chart.get("after_correction"))),
    }


def fleet_of(records: list[RunRecord], machine_code: str, machine_id: str) -> list[list[RunRecord]]:
    """Per other machine of structure ``machine_code`` its runs in measurement order, by machine id (a check-up's
    fleet, :mod:`pige_sym.verdict.checkup.scatter`)."""
    by: dict[str, list[RunRecord]] = {}
    for r in records:
        if r.machine_code == machine_code and r.machine_id != machine_id:
            by.setdefault(r.machine_id, []).append(r)
    return [sorted(v, key=lambda r: (r.measured_at, r.id)) for _, v in sorted(by.items())]
