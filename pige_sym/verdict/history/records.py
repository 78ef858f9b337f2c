"""Stored runs read strictly: every field of a ``runs`` row is checked before one of its numbers is used.

A run keeps its estimate as JSON text (parameter names, units, values, standard errors, covariance) beside a few
plain columns.  A row is decoded (:func:`decode_run`) only when it is what
:func:`~pige_sym.verdict.history.store.add_run` writes:

- the text columns (machine id, file, times, machine code, method) are text, ``verdict`` text or null;
- ``parameters``: a non-empty list of distinct names; ``units``: an object of name: unit;
- ``values_json`` and ``std_json``: P numbers or ``null`` (undetermined) in strict JSON (no ``NaN`` token),
  finite, standard errors ≥ 0; ``covariance_json``: P lists of P such numbers, with a diagonal ≥ 0;
- ``dof``: a whole number ≥ 0; ``rms_um``: null or a finite number ≥ 0; ``effects_json``: a list of objects;
  ``check_json``: null or an object;
- no estimate beyond ±:data:`~pige_sym.measurements.schema.MAX_PIGE` by more than 3 standard errors
  (:func:`~pige_sym.measurements.measurement.unphysical`, what identify refuses): no machine that runs has one.

Anything else raises :class:`~pige_sym.errors.SchemaRefusal` naming the column; the store turns it into a
one-line refusal naming the database, the run and how to recover.  The same checks run on a run before it is added
(:func:`check_new_run`), so the history never holds what it would refuse to read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import SchemaRefusal
from pige_sym.measurements.measurement import unphysical
from pige_sym.measurements.schema import MAX_PIGE, strict_loads

TEXT_COLUMNS = ("machine_id", "file_name", "file_sha256", "measured_at", "time_source", "added_at", "machine_code",
                "method")


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
            "check": self.check,
        })


def _kind(x: Any) -> str:
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, (int, float)):
        return f"the number {x!r}"
    if isinstance(x, str):
        return f"the text {x[:20]!r}"
    return f"a {type(x).__name__}"


def _json(row: Mapping[str, Any], column: str) -> Any:
    text = row[column]
    if not isinstance(text, str):
        raise SchemaRefusal(column, f"expected JSON text, got {_kind(text)}")
    try:
        return strict_loads(text)
    except ValueError as exc:
        raise SchemaRefusal(column, f"not valid JSON ({str(exc).splitlines()[0][:80]})") from None


def _number(x: Any, column: str, where: str, *, non_negative: bool = False) -> float:
    """A stored number (None: undetermined, NaN)."""
    if x is None:
        return math.nan
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise SchemaRefusal(column, f"{where}: expected a finite number or null, got {_kind(x)}")
    if non_negative and x < 0:
        raise SchemaRefusal(column, f"{where}: {x!r} is negative")
    return float(x)


def _vector(row: Mapping[str, Any], column: str, names: list[str], *, non_negative: bool = False) -> np.ndarray:
    data = _json(row, column)
    if not isinstance(data, list) or len(data) != len(names):
        got = f"{len(data)} values" if isinstance(data, list) else _kind(data)
        raise SchemaRefusal(column, f"expected {len(names)} values (one per parameter), got {got}")
    return np.array([_number(x, column, n, non_negative=non_negative) for x, n in zip(data, names, strict=True)])


def _matrix(row: Mapping[str, Any], column: str, names: list[str]) -> np.ndarray:
    data = _json(row, column)
    p = len(names)
    if not isinstance(data, list) or len(data) != p or any(not isinstance(r, list) or len(r) != p for r in data):
        raise SchemaRefusal(column, f"expected a {p} x {p} matrix (one row and column per parameter)")
    out = np.array([[_number(x, column, f"[{i}][{j}]") for j, x in enumerate(r)] for i, r in enumerate(data)])
    negative = [names[i] for i in range(p) if out[i, i] < 0]
    if negative:
        raise SchemaRefusal(column, f"the variance of {negative[0]} is negative")
    return out.reshape(p, p)


def _names(row: Mapping[str, Any]) -> tuple[list[str], dict[str, str]]:
    params = _json(row, "parameters")
    if not isinstance(params, list) or not params or not all(isinstance(x, str) for x in params) \
            or len(set(params)) != len(params):
        raise SchemaRefusal("parameters", "expected a non-empty list of distinct parameter names")
    units = _json(row, "units")
    if not isinstance(units, dict) or not all(isinstance(v, str) for v in units.values()):
        raise SchemaRefusal("units", "expected an object of parameter: unit")
    return params, units


def decode_run(row: Any) -> RunRecord:
    """The :class:`RunRecord` of a stored row (a SQLAlchemy row or a mapping of the ``runs`` columns).

    Raises
    ------
    SchemaRefusal
        Naming the column and what is wrong with it (module docstring).
    """
    get: Mapping[str, Any] = row._mapping if hasattr(row, "_mapping") else row
    for column in TEXT_COLUMNS:
        if not isinstance(get[column], str):
            raise SchemaRefusal(column, f"expected text, got {_kind(get[column])}")
    if get["verdict"] is not None and not isinstance(get["verdict"], str):
        raise SchemaRefusal("verdict", f"expected text or null, got {_kind(get['verdict'])}")
    params, units = _names(get)
    values = _vector(get, "values_json", params)
    std = _vector(get, "std_json", params, non_negative=True)
    cov = _matrix(get, "covariance_json", params)
    dof = get["dof"]
    if isinstance(dof, bool) or not isinstance(dof, int) or dof < 0:
        raise SchemaRefusal("dof", f"expected a whole number >= 0, got {_kind(dof)}")
    rms = get["rms_um"]
    rms_um = None if rms is None else _number(rms, "rms_um", "the RMS", non_negative=True)
    effects = _json(get, "effects_json")
    if not isinstance(effects, list) or not all(isinstance(f, dict) for f in effects):
        raise SchemaRefusal("effects_json", "expected a list of objects")
    check = None if get["check_json"] is None else _json(get, "check_json")
    if check is not None and not isinstance(check, dict):
        raise SchemaRefusal("check_json", "expected an object or null")
    absurd = unphysical(params, values, std, MAX_PIGE)
    if absurd is not None:
        name, v = absurd
        raise SchemaRefusal("values_json", f"{name} = {v:g} {units.get(name, '')} is beyond ±{MAX_PIGE:g}, more "
                                           "than any machine that runs")
    return RunRecord(int(get["id"]), get["machine_id"], get["file_name"], get["file_sha256"], get["measured_at"],
                     get["time_source"], get["added_at"], get["machine_code"], get["method"], params, units, values,
                     std, cov, dof, rms_um, effects, get["verdict"], check)


def check_new_run(values: Mapping[str, Any]) -> None:
    """Refuse a run that :func:`decode_run` would refuse to read back, before it is stored.

    Raises
    ------
    SchemaRefusal
    """
    decode_run({**values, "id": 0})
