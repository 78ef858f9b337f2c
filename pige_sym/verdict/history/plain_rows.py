"""The plain text pige writes into a history's columns, read for a whole history at once.

:mod:`~pige_sym.verdict.history.decode` checks every stored run before it is used; with 1,000 runs, reading each
JSON text alone, element by element, took most of ``pige checkup``'s second.  Most texts are exactly what pige
wrote, in a grammar a regular expression recognises:

- a number column (``values_json``, ``std_json``): ``[`` numbers or ``null`` separated by commas ``]`` — JSON
  numbers only (no ``NaN``/``Infinity`` token, no ``true``, no text); ``covariance_json``: ``[`` such lists ``]``;
- a check-up's chart (``chart_json``): the object :meth:`~pige_sym.verdict.checkup.routine.CheckupResult.chart`
  writes, its seven items in their order, names of letters, digits, ``_`` and ``.``, numbers of at most 18 digits
  before the point.

A text in its grammar is one whole JSON value, so the texts of all runs joined in one list parse (one ``json``
call, in C) to exactly their own values.  The rules are then applied to all numbers at once (counts, finite,
standard errors and variances ≥ 0, no estimate beyond ±:data:`~pige_sym.constants.MAX_PIGE` by 3 standard errors;
a chart's names counted, so a repeated name is seen; its numbers finite).  Whatever is not in the grammar, or breaks
a rule, is left to the element-by-element reader (None here), which accepts or refuses it with its reason: these
readers accept nothing it refuses (``tests/test_history_decode.py``).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from pige_sym.constants import MAX_PIGE

_WS = r"[ \t\n\r]*"
_ITEM = r"(?:-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?|null)"
_LIST = rf"\[{_WS}(?:{_ITEM}(?:{_WS},{_WS}{_ITEM})*)?{_WS}\]"
PLAIN_VECTOR = re.compile(_LIST)
PLAIN_MATRIX = re.compile(rf"\[{_WS}(?:{_LIST}(?:{_WS},{_WS}{_LIST})*)?{_WS}\]")

_NAME = r'"[A-Za-z0-9_.]+"'
_NUMBER = r"-?(?:0|[1-9][0-9]{0,17})(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?"


def _object_of(value: str) -> str:
    return rf"\{{(?:{_NAME}: {value}(?:, {_NAME}: {value})*)?\}}"


_FLAGS = _object_of("(?:true|false)")
PLAIN_CHART = re.compile(
    rf'\{{"signature": "[^"\\\x00-\x1f]*", "after_correction": (?:true|false), "in_control": {_FLAGS}, '
    rf'"outside": {_FLAGS}, "flagged": {_FLAGS}, "to_enter": (?:null|{_object_of(f"(?:{_NUMBER}|null)")}), '
    rf'"tolerance": {_object_of(_NUMBER)}\}}')
#: The items of a plain chart, in the order pige writes them; the last five are objects of name: value.
CHART_KEYS = ("signature", "after_correction", "in_control", "outside", "flagged", "to_enter", "tolerance")
_CHART_DICTS = CHART_KEYS[2:]


def plain_array(text: Any, grammar: re.Pattern[str], shape: tuple[int, ...]) -> np.ndarray | None:
    """The numbers of one column in the plain grammar, all finite or null, of ``shape``; None: read it element by
    element."""
    if type(text) is not str or grammar.fullmatch(text) is None:
        return None
    try:
        out = np.array(json.loads(text), dtype=float)
    except (ValueError, OverflowError):  # ragged rows; an integer beyond the float range
        return None
    return out if out.shape == shape and not np.isinf(out).any() else None


def _joined(texts: list[str]) -> list[Any] | None:
    """The values of texts each in a plain grammar (so joined they are one list of exactly their values)."""
    try:
        return list(json.loads("[" + ",".join(texts) + "]"))
    except ValueError:  # pragma: no cover - the grammars admit only what json reads
        return None


def _number_texts(rows: list[Mapping[Any, Any]], sizes: list[int | None]) -> tuple[list[int], list[int]]:
    """(rows whose names are sound and whose three number columns are in the plain grammar, their sizes P)."""
    picked, kept = [], []
    for k, (row, p) in enumerate(zip(rows, sizes, strict=True)):
        v, s, c = row["values_json"], row["std_json"], row["covariance_json"]
        if p is not None and type(v) is str and type(s) is str and type(c) is str and PLAIN_VECTOR.fullmatch(v) \
                and PLAIN_VECTOR.fullmatch(s) and PLAIN_MATRIX.fullmatch(c):
            picked.append(k)
            kept.append(p)
    return picked, kept


def plain_numbers(rows: list[Mapping[Any, Any]], sizes: list[int | None]
                  ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """Per row its (values, std, covariance) when they are plain and break no rule, else None; ``sizes``: each row's
    number of parameters (None: its names are not sound)."""
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = [None] * len(rows)
    picked, sizes_of = _number_texts(rows, sizes)
    lists = [_joined([rows[k][c] for k in picked]) for c in ("values_json", "std_json", "covariance_json")]
    if any(x is None for x in lists):  # pragma: no cover
        return out
    vl, sl, cl = lists[0] or [], lists[1] or [], lists[2] or []
    keep = [i for i, p in enumerate(sizes_of) if len(vl[i]) == p and len(sl[i]) == p and len(cl[i]) == p
            and all(len(r) == p for r in cl[i])]
    if not keep:
        return out
    try:
        v = np.array([x for i in keep for x in vl[i]], dtype=float)
        s = np.array([x for i in keep for x in sl[i]], dtype=float)
        c = np.array([x for i in keep for r in cl[i] for x in r], dtype=float)
    except OverflowError:  # an integer beyond the float range: element by element
        return out
    p = np.array([sizes_of[i] for i in keep])
    ends, cends = np.cumsum(p), np.cumsum(p * p)
    starts, cstarts = ends - p, cends - p * p
    owner, cowner = np.repeat(np.arange(len(keep)), p), np.repeat(np.arange(len(keep)), p * p)
    diagonal = np.concatenate([np.arange(n) * (n + 1) + o for n, o in zip(p.tolist(), cstarts.tolist(), strict=True)])
    s0 = np.where(np.isfinite(s), s, 0.0)
    bad = np.zeros(len(keep), dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):  # inf and NaN as in Python's arithmetic (no warning)
        absurd = np.isfinite(v) & (np.abs(v) - 3 * s0 > MAX_PIGE)
    bad[owner[np.isinf(v) | np.isinf(s) | (s < 0) | absurd]] = True
    bad[cowner[np.isinf(c)]] = True
    bad[cowner[diagonal[c[diagonal] < 0]]] = True
    for j, i in enumerate(keep):
        if not bad[j]:
            a, b, n = int(starts[j]), int(ends[j]), int(p[j])
            out[picked[i]] = (v[a:b], s[a:b], c[int(cstarts[j]):int(cends[j])].reshape(n, n))
    return out


def plain_charts(rows: list[Mapping[Any, Any]]) -> list[dict[str, Any] | None]:
    """Per row its check-up's chart when it is plain and breaks no rule, else None (also for a full calibration)."""
    out: list[dict[str, Any] | None] = [None] * len(rows)
    picked = [k for k, row in enumerate(rows) if row.get("kind") == "checkup" and type(row.get("chart_json")) is str
              and PLAIN_CHART.fullmatch(row["chart_json"])]
    charts = _joined([rows[k]["chart_json"] for k in picked])
    if charts is None:  # pragma: no cover - the grammar admits only what json reads
        return out
    for k, chart in zip(picked, charts, strict=True):
        inner = [chart[key] or {} for key in _CHART_DICTS]
        finite = all(math.isfinite(v) for d in inner[3:] for v in d.values() if v is not None)  # 1e999 is inf
        # each name is followed by '": ' (no name and no signature holds a quote), so a name given twice in one
        # object counts twice in the text and once in its object
        if finite and rows[k]["chart_json"].count('": ') == len(CHART_KEYS) + sum(map(len, inner)):
            out[k] = chart
    return out
