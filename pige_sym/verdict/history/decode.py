"""Stored runs read strictly: every field of a ``runs`` row is checked before one of its numbers is used.

A run keeps its estimate as JSON text (parameter names, units, values, standard errors, covariance) beside a few
plain columns.  A row is decoded (:func:`decode_run`) only when it is what
:func:`~pige_sym.verdict.history.store.add_run` or a check-up writes:

- the text columns (machine id, file, times, machine code, method) are text, ``verdict`` text or null;
- ``parameters``: a non-empty list of distinct names; ``units``: an object of name: unit;
- ``values_json`` and ``std_json``: P numbers or ``null`` (undetermined) in strict JSON (no ``NaN`` token),
  finite, standard errors ≥ 0; ``covariance_json``: P lists of P such numbers, with a diagonal ≥ 0;
- ``dof``: a whole number ≥ 0; ``rms_um``: null or a finite number ≥ 0; ``effects_json``: a list of objects;
  ``check_json``: null or an object;
- no estimate beyond ±:data:`~pige_sym.constants.MAX_PIGE` by more than 3 standard errors
  (:func:`~pige_sym.measurements.measurement.unphysical`, what identify refuses): no machine that runs has one;
- from schema version 2 (check-ups): ``kind`` is ``full`` or ``checkup``; ``chart_json`` (what later check-ups
  read) null or an object of exactly the items :meth:`~pige_sym.verdict.checkup.routine.CheckupResult.chart`
  writes, each of its type (names to booleans, to finite numbers); ``setup_json`` and ``checkup_json`` null or an
  object.  A row of a version-1 file has none of these columns: a full calibration with no stored set-up;
- from schema version 3: ``after_correction`` 0 or 1 (a row of an older file: 0).

Anything else raises :class:`~pige_sym.errors.SchemaRefusal` naming the column; the caller turns it into a
one-line refusal naming the database, the run and how to recover
(:func:`~pige_sym.verdict.history.integrity.damaged`).  The same checks run on a run before it is added
(:func:`check_new_run`), so the history never holds what it would refuse to read.

``light`` (what a check-up reads of a long history): a check-up's record carries its chart as ``checkup`` and the
diagonal of its standard errors as covariance (its covariance is still checked), and its set-up and full
``checkup_json`` are not read — those two are checked where a command reads them (``history show``, the report,
the fleet's last check-up).

Speed: a whole history is read at once first (:mod:`~pige_sym.verdict.history.plain_rows`): the number columns
and a check-up's chart are matched against the plain grammar pige writes (regular expressions) and parsed by
``json`` in C, all rows' texts together; only a row that does not match, or whose values break a rule, is read
again by the element-by-element reader here, which accepts or refuses it and says why.  The fast reader accepts
nothing the element-by-element one refuses and gives the same values (``tests/test_history_decode.py`` checks it
on damaged rows and charts), so 1,000 runs are checked in a few hundredths of a second.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np

from pige_sym.constants import MAX_PIGE
from pige_sym.errors import HistoryError, SchemaRefusal
from pige_sym.measurements.measurement import unphysical
from pige_sym.measurements.strict_json import strict_loads
from pige_sym.verdict.history.plain_rows import PLAIN_MATRIX, PLAIN_VECTOR, plain_array, plain_charts, plain_numbers
from pige_sym.verdict.history.records import RunRecord

TEXT_COLUMNS = ("machine_id", "file_name", "file_sha256", "measured_at", "time_source", "added_at", "machine_code",
                "method")
KINDS = ("full", "checkup")
#: The items of a check-up's chart (``chart_json``) and what each holds.
CHART_ITEMS = {"signature": "text", "after_correction": "boolean", "in_control": "flags", "outside": "flags",
               "flagged": "flags", "to_enter": "numbers or null", "tolerance": "numbers"}


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
    fast = plain_array(row[column], PLAIN_VECTOR, (len(names),))
    if fast is not None and not (non_negative and (fast < 0).any()):
        return fast
    data = _json(row, column)
    if not isinstance(data, list) or len(data) != len(names):
        got = f"{len(data)} values" if isinstance(data, list) else _kind(data)
        raise SchemaRefusal(column, f"expected {len(names)} values (one per parameter), got {got}")
    return np.array([_number(x, column, n, non_negative=non_negative) for x, n in zip(data, names, strict=True)])


def _matrix(row: Mapping[str, Any], column: str, names: list[str]) -> np.ndarray:
    p = len(names)
    fast = plain_array(row[column], PLAIN_MATRIX, (p, p))
    if fast is not None and not (np.diagonal(fast) < 0).any():
        return fast
    data = _json(row, column)
    if not isinstance(data, list) or len(data) != p or any(not isinstance(r, list) or len(r) != p for r in data):
        raise SchemaRefusal(column, f"expected a {p} x {p} matrix (one row and column per parameter)")
    out = np.array([[_number(x, column, f"[{i}][{j}]") for j, x in enumerate(r)] for i, r in enumerate(data)])
    negative = [names[i] for i in range(p) if out[i, i] < 0]
    if negative:
        raise SchemaRefusal(column, f"the variance of {negative[0]} is negative")
    return out.reshape(p, p)


#: Parameter names and units already checked, by their texts (many runs share them).
_NAMES: dict[tuple[str, str], tuple[list[str], dict[str, str]]] = {}


def _names(row: Mapping[str, Any]) -> tuple[list[str], dict[str, str]]:
    key = (row["parameters"], row["units"])
    known = _NAMES.get(key) if type(key[0]) is str and type(key[1]) is str else None
    if known is not None:
        return list(known[0]), dict(known[1])
    params = _json(row, "parameters")
    if not isinstance(params, list) or not params or not all(isinstance(x, str) for x in params) \
            or len(set(params)) != len(params):
        raise SchemaRefusal("parameters", "expected a non-empty list of distinct parameter names")
    units = _json(row, "units")
    if not isinstance(units, dict) or not all(isinstance(v, str) for v in units.values()):
        raise SchemaRefusal("units", "expected an object of parameter: unit")
    if len(_NAMES) > 256:
        _NAMES.clear()
    _NAMES[key] = (list(params), dict(units))
    return params, units


def _object(row: Mapping[str, Any], column: str) -> dict[str, Any] | None:
    """A column of JSON text holding an object, or null (also when the row has no such column: schema version 1)."""
    if row.get(column) is None:
        return None
    data = _json(row, column)
    if not isinstance(data, dict):
        raise SchemaRefusal(column, f"expected an object or null, got {_kind(data)}")
    return data


def _chart_item(name: str, x: Any, what: str) -> None:
    """One item of a chart is what :data:`CHART_ITEMS` says (JSON's values are of these exact types)."""
    if what == "text":
        ok = type(x) is str
    elif what == "boolean":
        ok = type(x) is bool
    elif what == "numbers or null" and x is None:
        ok = True
    elif type(x) is not dict:
        ok = False
    elif what == "flags":
        ok = set(map(type, x.values())) <= {bool}
    else:
        allowed = {int, float, type(None)} if what == "numbers or null" else {int, float}
        ok = set(map(type, x.values())) <= allowed and all(map(math.isfinite, (v for v in x.values() if v is not None)))
    if not ok:
        raise SchemaRefusal("chart_json", f"{name}: expected {what}, got {_kind(x)}")


def _chart(row: Mapping[str, Any]) -> dict[str, Any] | None:
    """A check-up's chart (module docstring), or None."""
    chart = _object(row, "chart_json")
    if chart is None:
        return None
    if set(chart) != set(CHART_ITEMS):
        odd = sorted(set(chart) ^ set(CHART_ITEMS))[0]
        raise SchemaRefusal("chart_json", f"{'unknown item' if odd in chart else 'no item'} {odd!r}")
    for name, what in CHART_ITEMS.items():
        _chart_item(name, chart[name], what)
    return chart


def _kind_of(row: Mapping[str, Any]) -> str:
    kind = row.get("kind", "full")
    if kind not in KINDS or not isinstance(kind, str):
        raise SchemaRefusal("kind", f"expected {' or '.join(KINDS)}, got {_kind(kind)}")
    return kind


def decode_run(row: Any, *, light: bool = False) -> RunRecord:
    """The :class:`~pige_sym.verdict.history.records.RunRecord` of a stored row (a SQLAlchemy row or a mapping of
    the ``runs`` columns the database has); ``light``: a check-up as a chart point (module docstring).

    Raises
    ------
    SchemaRefusal
        Naming the column and what is wrong with it (module docstring).
    """
    return _decode(row._mapping if hasattr(row, "_mapping") else row, light, None, None)


def decode_runs(rows: Iterable[Mapping[Any, Any]], refused: Callable[[Mapping[Any, Any], SchemaRefusal], Exception],
                *, light: bool = False) -> list[RunRecord]:
    """Many rows decoded as :func:`decode_run` decodes each, their numbers read together (module docstring); the
    first row it refuses, in the given order, raises ``refused(row, refusal)``."""
    rows = list(rows)
    sizes: list[int | None] = []
    for row in rows:
        try:
            sizes.append(len(_names(row)[0]))
        except (SchemaRefusal, KeyError):  # refused below, in its turn
            sizes.append(None)
    out = []
    for row, numbers, chart in zip(rows, plain_numbers(rows, sizes), plain_charts(rows), strict=True):
        try:
            out.append(_decode(row, light, numbers, chart))
        except SchemaRefusal as exc:
            raise refused(row, exc) from None
    return out


def _decode(get: Mapping[str, Any], light: bool, numbers: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
            plain_chart: dict[str, Any] | None = None) -> RunRecord:
    """:func:`decode_run`; ``numbers``: the values, standard errors and covariance already checked; ``plain_chart``:
    the chart already checked."""
    for column in TEXT_COLUMNS:
        if not isinstance(get[column], str):
            raise SchemaRefusal(column, f"expected text, got {_kind(get[column])}")
    if get["verdict"] is not None and not isinstance(get["verdict"], str):
        raise SchemaRefusal("verdict", f"expected text or null, got {_kind(get['verdict'])}")
    params, units = _names(get)
    if numbers is None:
        values = _vector(get, "values_json", params)
        std = _vector(get, "std_json", params, non_negative=True)
        cov = _matrix(get, "covariance_json", params)
    else:
        values, std, cov = numbers
    dof = get["dof"]
    if isinstance(dof, bool) or not isinstance(dof, int) or dof < 0:
        raise SchemaRefusal("dof", f"expected a whole number >= 0, got {_kind(dof)}")
    rms = get["rms_um"]
    rms_um = None if rms is None else _number(rms, "rms_um", "the RMS", non_negative=True)
    effects = [] if get["effects_json"] == "[]" else _json(get, "effects_json")
    if not isinstance(effects, list) or not all(isinstance(f, dict) for f in effects):
        raise SchemaRefusal("effects_json", "expected a list of objects")
    check = None if get["check_json"] is None else _json(get, "check_json")
    if check is not None and not isinstance(check, dict):
        raise SchemaRefusal("check_json", "expected an object or null")
    if numbers is None:
        check_estimate(params, units, values, std)
    kind = _kind_of(get)
    chart = None if kind != "checkup" else plain_chart if plain_chart is not None else _chart(get)
    setup: dict[str, Any] | None = None
    checkup: dict[str, Any] | None
    if light and chart is not None:
        cov, checkup = np.diag(std**2), chart
    else:
        setup, checkup = _object(get, "setup_json"), _object(get, "checkup_json")
    corrected = get.get("after_correction", 0)
    if type(corrected) is not int or corrected not in (0, 1):
        raise SchemaRefusal("after_correction", f"expected 0 or 1, got {_kind(corrected)}")
    return RunRecord(int(get["id"]), get["machine_id"], get["file_name"], get["file_sha256"], get["measured_at"],
                     get["time_source"], get["added_at"], get["machine_code"], get["method"], params, units, values,
                     std, cov, dof, rms_um, effects, get["verdict"], check, kind, setup, checkup, bool(corrected))


def check_estimate(parameters: list[str], units: Mapping[str, str], values: Any, std: Any) -> None:
    """Refuse an estimate beyond ±:data:`~pige_sym.constants.MAX_PIGE` by more than 3 standard errors (the rule of
    :func:`decode_run`; a check-up's fit is held to it before anything is made of it).

    Raises
    ------
    SchemaRefusal
    """
    absurd = unphysical(parameters, values, std, MAX_PIGE)
    if absurd is not None:
        name, v = absurd
        raise SchemaRefusal("values_json", f"{name} = {v:g} {units.get(name, '')} is beyond ±{MAX_PIGE:g}, more "
                                           "than any machine that runs")


def not_stored(path: Any, exc: SchemaRefusal) -> HistoryError:
    """The refusal of a run the history would not read back (:func:`check_new_run`), naming the file."""
    return HistoryError(f"{path}: not added to the history: its estimate ({exc}) is not one pige stores")


def check_new_run(values: Mapping[str, Any]) -> None:
    """Refuse a run that :func:`decode_run` would refuse to read back, before it is stored (every column, the
    check-up's set-up and findings too).

    Raises
    ------
    SchemaRefusal
    """
    decode_run({**values, "id": 0})
