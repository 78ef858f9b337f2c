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
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import sqlalchemy as sa

from pige_sym.errors import FileFormatError, InputError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.run_setup import setup_of
from pige_sym.verdict.history import tables as T
from pige_sym.verdict.history.migrations import migrate

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
    """Engine of the history database, schema migrated.

    ``create=False`` (reading: ``history show``, ``report --history``) refuses an SQLite file that does not
    exist instead of creating an empty database there.

    Raises
    ------
    InputError
        The database cannot be opened or reached (message with the URL, password hidden), or (``create=False``)
        the SQLite file does not exist.
    """
    full = normalise_url(url)
    if full.startswith("sqlite:///"):
        path = Path(full.removeprefix("sqlite:///"))
        if not create and str(path) not in ("", ":memory:") and not path.is_file():
            raise InputError(f"no history database at {path} (pige history add creates one; --db or "
                             f"$PIGE_HISTORY_DB name another)")
        if str(path) not in ("", ":memory:"):
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise InputError(f"--db {path}: cannot create {path.parent} ({exc.strerror or exc})") from None
    engine = sa.create_engine(full)
    if engine.dialect.name == "sqlite":
        @sa.event.listens_for(engine, "connect")
        def _fk(dbapi_conn: Any, _record: Any) -> None:
            dbapi_conn.execute("PRAGMA foreign_keys=ON")
    try:
        migrate(engine)
    except sa.exc.SQLAlchemyError as exc:
        shown = engine.url.render_as_string(hide_password=True)
        raise InputError(f"history database {shown}: {str(exc.orig if hasattr(exc, 'orig') else exc).strip()}"
                         .splitlines()[0]) from None
    return engine


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
        })


def _dumps(x: Any) -> str:
    from pige_sym.files import to_json

    return to_json(x, indent=None)


def _floats(text: str) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in json.loads(text)], dtype=float)


_SHARED: dict[str, Any] = {}


def _shared(text: str) -> Any:
    """``json.loads`` of a text many runs repeat (their parameter names and units), parsed once."""
    if text not in _SHARED:
        _SHARED[text] = json.loads(text)
    return _SHARED[text]


def run_record(row: Any, *, light: bool = False, numbers: tuple[np.ndarray, np.ndarray] | None = None,
               chart: Any = None) -> RunRecord:
    """The record of a row of ``runs``; ``light`` (a check-up read as a chart point): its ``checkup`` is the small
    ``chart_json`` (``chart``: parsed already), its covariance the diagonal of its standard errors, its set-up not
    read; ``numbers``: its values and standard errors parsed already."""
    params = list(_shared(row.parameters))
    values, std = numbers if numbers is not None else (_floats(row.values_json), _floats(row.std_json))
    as_point = light and row.kind == "checkup" and getattr(row, "chart_json", None) is not None
    if as_point:
        cov = np.diag(std**2)
    else:
        cov = np.array([[np.nan if v is None else v for v in r] for r in json.loads(row.covariance_json)], dtype=float)
    checkup_text = row.chart_json if as_point else getattr(row, "checkup_json", None)
    setup_text = None if as_point else getattr(row, "setup_json", None)
    checkup = chart if as_point and chart is not None else None if checkup_text is None else json.loads(checkup_text)
    return RunRecord(row.id, row.machine_id, row.file_name, row.file_sha256, row.measured_at, row.time_source,
                     row.added_at, row.machine_code, row.method, params, dict(_shared(row.units)),
                     values, std, cov.reshape(len(params), len(params)),
                     int(row.dof), row.rms_um, list(_shared(row.effects_json)), row.verdict,
                     None if row.check_json is None else json.loads(row.check_json), row.kind,
                     None if setup_text is None else json.loads(setup_text), checkup)


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
        "kind": "full", "setup_json": _dumps(setup_of(m.items[0]).to_dict())
        if len(m.items) == 1 and isinstance(m.items[0], Measurement) else None,
    }
    for attempt in range(3):
        try:
            row = _insert_run(engine, machine_id, code, now, values, p)
            break
        except sa.exc.IntegrityError:
            with engine.connect() as conn:
                if _existing(conn, sha) is not None or attempt == 2:  # another user added the same file meanwhile
                    raise InputError(f"{p}: this file is already in the history: a run is added once") from None
            # else: another process created the machine at the same moment; its row is there now
    return run_record(row)


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


def machine_ids(engine: sa.Engine) -> list[str]:
    """Every machine id in the history, sorted."""
    with engine.connect() as conn:
        return sorted(conn.execute(sa.select(T.machines.c.machine_id)).scalars())


def list_runs(engine: sa.Engine, machine_id: str, *, light: bool = False) -> list[RunRecord]:
    """Runs of a machine in measurement order (time, then insertion); ``light``: check-ups as chart points
    (:func:`run_record`), what ``pige checkup`` reads of a long history.

    Raises
    ------
    InputError
        No such machine id (the message lists the known ones).
    """
    columns = [c for c in T.runs.c if not light or c.name != "checkup_json"]
    with engine.connect() as conn:
        rows = conn.execute(sa.select(*columns).where(T.runs.c.machine_id == machine_id)
                            .order_by(T.runs.c.measured_at, T.runs.c.id)).all()
    if not rows:
        known = machine_ids(engine)
        raise InputError(f"no machine {machine_id!r} in the history {engine.url.render_as_string(hide_password=True)}"
                         f"; known: {', '.join(known) or 'none (add a run with pige history add)'}")
    if not light:
        return [run_record(r) for r in rows]
    values = _float_rows([r.values_json for r in rows])  # one parse for the whole history
    std = _float_rows([r.std_json for r in rows])
    charts = json.loads("[" + ",".join(r.chart_json or "null" for r in rows) + "]")
    return [run_record(r, light=True, numbers=(v, e), chart=c) for r, v, e, c in zip(rows, values, std, charts,
                                                                                       strict=True)]


def _float_rows(texts: list[str]) -> list[np.ndarray]:
    """Many JSON arrays of numbers or null (NaN) parsed at once."""
    return [np.array(row, dtype=float) for row in json.loads("[" + ",".join(texts).replace("null", "NaN") + "]")]


def existing_run(engine: sa.Engine, path: Path) -> None:
    """Refuse a file that is already in the history (a run is added once).

    Raises
    ------
    InputError
    """
    with engine.connect() as conn:
        dup = _existing(conn, _sha256(path))
    if dup is not None:
        raise InputError(f"{path}: this file is already in the history (run {dup.id} of machine {dup.machine_id}, "
                         f"added as {dup.file_name}): a run is added once")


def add_checkup_run(engine: sa.Engine, path: Path, machine_id: str, code: str, measured: tuple[str, str], fit: Any,
                    setup: dict[str, Any], verdict: str, checkup: dict[str, Any], chart: dict[str, Any]) -> RunRecord:
    """Store a check-up (``kind = checkup``): its PIGEs' estimate (:class:`~pige_sym.identification.subset.SubsetFit`),
    the set-up it was measured with, its verdict and what it found (:mod:`pige_sym.verdict.checkup`).

    Raises
    ------
    InputError
        The file is already stored (also when another user stored it meanwhile).
    """
    now = datetime.now(timezone.utc).isoformat(timespec="seconds")
    values = {
        "machine_id": machine_id, "file_sha256": _sha256(path), "file_name": str(path.resolve()),
        "measured_at": measured[0], "time_source": measured[1], "added_at": now, "machine_code": code,
        "method": "checkup", "parameters": _dumps(fit.parameters), "units": _dumps(fit.units),
        "values_json": _dumps(fit.values), "std_json": _dumps(fit.std), "covariance_json": _dumps(fit.covariance),
        "dof": int(fit.dof), "rms_um": float(fit.rms_um) if math.isfinite(fit.rms_um) else None,
        "effects_json": "[]", "verdict": verdict, "check_json": None, "kind": "checkup",
        "setup_json": _dumps(setup), "checkup_json": _dumps(checkup), "chart_json": _dumps(chart),
    }
    try:
        return run_record(_insert_run(engine, machine_id, code, now, values, path))
    except sa.exc.IntegrityError:
        raise InputError(f"{path}: this file is already in the history: a run is added once") from None
