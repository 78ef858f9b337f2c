"""Stored runs read strictly and fast (pige_sym.verdict.history.decode, integrity): the merge of issue 42's check-up
history (schema 2, read with sqlite3 in under a second) with issue 43's strict reader (every stored run checked).

Oracles written here: the element-by-element reader (every fast path switched off) for the fast one, on damaged
number columns drawn by hypothesis, several rows at a time (the fast reader parses a whole history's texts joined);
issue 43's strict JSON reader as it was written (the repeated-key loop, the depth walk on every value) for the
faster one; the migrations themselves for the columns each schema version has.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from property_budget import examples

from pige_sym.errors import SchemaRefusal
from pige_sym.verdict.history import decode
from pige_sym.verdict.history.decode import check_new_run, decode_run, decode_runs

NAMES = ["EX0C", "EY0C", "EA0C"]
UNITS = {"EX0C": "um", "EY0C": "um", "EA0C": "urad"}
CHART = {"signature": "EX0C|0.0,0.0", "after_correction": False, "in_control": {"EX0C": True},
         "outside": {"EX0C": False}, "flagged": {"EX0C": False}, "to_enter": {"EX0C": 1.5, "EY0C": None},
         "tolerance": {"EX0C": 8.0}}


def row(i: int = 1, **changed: Any) -> dict[str, Any]:
    """A run as a history of schema version 2 holds it (a full calibration unless changed)."""
    out = {"id": i, "machine_id": "M", "file_name": f"/runs/f{i}.csv", "file_sha256": f"{i:064x}",
           "measured_at": "2026-01-01T00:00:00+00:00", "time_source": "--date", "added_at": "2026-01-02T00:00:00",
           "machine_code": "wC'A'bXYZ(C1)t", "method": "gauss-newton", "parameters": json.dumps(NAMES),
           "units": json.dumps(UNITS), "values_json": "[1.5, -2, null]", "std_json": "[0.1, 0.2, null]",
           "covariance_json": "[[0.01, 0, 0], [0, 0.04, 0], [0, 0, null]]", "dof": 20, "rms_um": 0.3,
           "effects_json": "[]", "verdict": None, "check_json": None, "kind": "full", "setup_json": None,
           "checkup_json": None, "chart_json": None}
    return out | changed


def _refused(r: Any, exc: SchemaRefusal) -> Exception:
    return ValueError(f"run {r['id']}, {exc}")


def outcome(rows: list[dict[str, Any]], light: bool) -> Any:
    """What decoding the rows gives: the records' fields, or the refusal's words."""
    try:
        records = decode_runs(rows, _refused, light=light)
    except ValueError as exc:
        return str(exc)
    return [(r.id, r.kind, r.values.tolist(), r.std.tolist(), np.asarray(r.covariance).tolist(), r.checkup, r.setup)
            for r in records]


def element_by_element(fn: Callable[[], Any]) -> Any:
    """``fn()`` with every fast path of the reader switched off."""
    with mock.patch.object(decode, "plain_array", lambda *a: None), \
            mock.patch.object(decode, "plain_numbers", lambda rows, sizes: [None] * len(rows)), \
            mock.patch.object(decode, "plain_charts", lambda rows: [None] * len(rows)):
        return fn()


def same(a: Any, b: Any) -> bool:
    """Equal outcomes (NaN equal to NaN)."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return json.dumps(a, default=str).replace("NaN", "null") == json.dumps(b, default=str).replace("NaN", "null")


# ----------------------------------------------------------------------------- the fast reader, against the slow one

_SOUND = st.one_of(st.floats(-20.0, 20.0).map(repr), st.floats(0.0, 1e-3).map(repr), st.just("null"),
                   st.integers(-30, 30).map(str))
_SPECIAL = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.sampled_from(["1e999", "-1e999", "9" * 400, "-1e308", "-0.25"]),  # beyond the floats, or negative
    st.sampled_from(["1e4", "-10000.5", "10003", "1e308", "-1e308", "1e999", "-1e999", "1e-999", "-0.5", "-0",
                     "NaN", "Infinity", "-Infinity", "true", "false", '"1"', "[1]", "{}", "01", "1.", ".5", "+1",
                     "12345678901234567890", "-123456789012345678901234", "9" * 400, "1 2", ""]))
_SEPARATORS = st.sampled_from([",", " ,", ",\n", ",\t", ",\u00a0", ",,", " "])


@st.composite
def number_text(draw: st.DrawFn, depth: int) -> str:
    """A vector (depth 1) or 3 x 3 matrix (depth 2) column: sound numbers with at most a damage or two — a special
    element, a size, a separator, a bracket, rows of other lengths with the same count."""
    rows = [[draw(_SOUND) for _ in range(3)] for _ in range(3 if depth == 2 else 1)]
    damage = draw(st.sampled_from(["none", "none", "element", "element", "element", "size", "separator", "bracket",
                                   "ragged"]))
    if damage == "element":
        rows[draw(st.integers(0, len(rows) - 1))][draw(st.integers(0, 2))] = draw(_SPECIAL)
    elif damage == "size":
        rows[-1] = rows[-1][:draw(st.integers(0, 2))] if draw(st.booleans()) else rows[-1] + [draw(_SOUND)]
        if depth == 2 and draw(st.booleans()):
            rows = rows[:2] if draw(st.booleans()) else rows + [[draw(_SOUND) for _ in range(3)]]
    elif damage == "ragged" and depth == 2:
        rows = [rows[0][:2], rows[0][2:] + rows[1], rows[2]]  # 2 + 4 + 3: nine numbers, not three rows of three
    sep = draw(_SEPARATORS) if damage == "separator" else ", "
    lists = ["[" + sep.join(r) + "]" for r in rows]
    text = lists[0] if depth == 1 else "[" + ", ".join(lists) + "]"
    if damage == "bracket":
        text = draw(st.sampled_from([text[1:], text[:-1], f" {text} ", text + "]", "[" + text]))
    return text


_CHART_DAMAGES = [('"EX0C": false}', '"EX0C": false, "EX0C": true}'), ('"EX0C": false}', '"EY0C": false}'),
                  (', "tolerance"', ', "extra": 1, "tolerance"'), ('"signature": "EX0C|0.0,0.0", ', ""),
                  ('"EX0C|0.0,0.0"', '"EX0C|\\u0030"'), ('"EX0C|0.0,0.0"', "1"), (": ", ":"), (", ", ","),
                  ("null", "{}"), ("}", "}}"), ("{", "[{"), ("true", "1"), ("false", '"false"'),
                  ('"to_enter": {', '"to_enter": {"EX0C": 0, '), ('"tolerance": {', '"tolerance": {"EX0C": 0, ')]
_NUMBER_IN_TEXT = re.compile(r"(?<=: )-?[0-9][0-9.eE+-]*")


@st.composite
def chart_text(draw: st.DrawFn) -> str:
    """A check-up's chart as pige writes it (names, order, numbers drawn), with at most two damages."""
    names = draw(st.lists(st.sampled_from(["EX0C", "EY0C", "EA0C", "angular_error_C.cos_urad"]), min_size=1,
                          max_size=3, unique=True))
    number = st.floats(-20, 20)
    chart = {"signature": draw(st.sampled_from(["EX0C|0.0,0.0", "", "-1.5;ü"])),
             "after_correction": draw(st.booleans()),
             **{k: {n: draw(st.booleans()) for n in names} for k in ("in_control", "outside", "flagged")},
             "to_enter": draw(st.one_of(st.none(), st.fixed_dictionaries({n: st.one_of(st.none(), number)
                                                                         for n in names}))),
             "tolerance": {n: draw(st.one_of(number, st.integers(-5, 5))) for n in names}}
    if draw(st.booleans()):
        chart = dict(reversed(list(chart.items())))  # sound, not in pige's order: the element-by-element reader
    text = json.dumps(chart if draw(st.integers(0, 3)) else CHART)
    for _ in range(draw(st.integers(0, 2))):
        numbers = list(_NUMBER_IN_TEXT.finditer(text))
        if numbers and draw(st.booleans()):  # a number of to_enter or tolerance
            at = draw(st.sampled_from(numbers))
            text = text[:at.start()] + draw(_SPECIAL) + text[at.end():]
        else:
            old, new = draw(st.sampled_from(_CHART_DAMAGES))
            text = text.replace(old, new, 1)
    return text


@st.composite
def damaged_rows(draw: st.DrawFn) -> list[dict[str, Any]]:
    rows = []
    for i in range(draw(st.integers(1, 4))):
        changed: dict[str, Any] = {}
        if draw(st.booleans()):
            changed |= {"kind": "checkup", "chart_json": draw(chart_text())}
        for column, depth in (("values_json", 1), ("std_json", 1), ("covariance_json", 2)):
            if draw(st.integers(0, 3 if changed else 1)) == 0:  # a row with a chart: its numbers mostly sound
                changed[column] = draw(number_text(depth))
        rows.append(row(i + 1, **changed))
    if len(rows) > 1 and draw(st.booleans()):  # two texts that are one list only when joined
        rows[0]["values_json"], rows[1]["values_json"] = "[1.5, -2", "null]"
    return rows


@settings(max_examples=examples(400), deadline=None)
@given(damaged_rows(), st.booleans())
def test_the_fast_reader_accepts_and_refuses_what_the_element_by_element_reader_does(rows: list[dict[str, Any]],
                                                                                     light: bool) -> None:
    fast = outcome(rows, light)
    slow = element_by_element(lambda: outcome(rows, light))
    assert same(fast, slow), (fast, slow)
    for r in rows:  # one row at a time too: alone in a history, and decode_run (the per-column fast path)
        assert same(outcome([r], light), element_by_element(lambda r=r: outcome([r], light)))

        def one(r: dict[str, Any] = r) -> Any:
            try:
                rec = decode_run(r, light=light)
            except SchemaRefusal as exc:
                return str(exc)
            return [rec.values.tolist(), rec.std.tolist(), np.asarray(rec.covariance).tolist()]

        assert same(one(), element_by_element(one))


def test_the_fast_reader_is_used_and_can_be_told_apart() -> None:
    """The oracle differs from the fast reader where it must: it reads a sound history element by element."""
    rows = [row(i) for i in range(1, 4)] + [row(i, kind="checkup", chart_json=json.dumps(CHART)) for i in (4, 5)]
    alone = AssertionError("a column read alone")
    with mock.patch.object(decode, "_vector", side_effect=alone), \
            mock.patch.object(decode, "_matrix", side_effect=alone), \
            mock.patch.object(decode, "_chart", side_effect=alone):
        assert len(decode_runs(rows, _refused)) == 5  # the whole history's numbers and charts read together
        with pytest.raises(AssertionError, match="read alone"):
            element_by_element(lambda: decode_runs(rows, _refused))


def test_the_plain_chart_is_the_one_pige_writes() -> None:
    """The chart's grammar (plain_rows) names the items the strict reader checks, in the order pige writes them."""
    from pige_sym.verdict.history.plain_rows import CHART_KEYS, PLAIN_CHART
    from pige_sym.verdict.history.records import dumps

    assert CHART_KEYS == tuple(decode.CHART_ITEMS)
    assert PLAIN_CHART.fullmatch(dumps(CHART)) and PLAIN_CHART.fullmatch(dumps(CHART | {"to_enter": None}))


@pytest.mark.parametrize("column, text, said", [
    ("values_json", "[1.5, 2e308, null]", "values_json: EY0C: expected a finite number or null, got the number inf"),
    ("values_json", "[1.5, 1e308, null]", "values_json: EY0C = 1e+308 um is beyond ±10000"),
    ("values_json", "[1.5, -10030.5, null]", "values_json: EY0C = -10030.5 um is beyond ±10000"),
    ("std_json", "[0.1, -0.2, null]", "std_json: EY0C: -0.2 is negative"),
    ("covariance_json", "[[0.01, 0, 0], [0, -0.04, 0], [0, 0, null]]", "the variance of EY0C is negative"),
    ("covariance_json", "[[0.01, 0, 0], [0, 0.04, 0]]", "expected a 3 x 3 matrix"),
    ("values_json", "[1.5, " + "9" * 400 + ", null]", "values_json: EY0C: expected a finite number or null"),
    ("covariance_json", "[[0.01, 0], [0, 0.04, 0, 0], [0, 0, null]]", "expected a 3 x 3 matrix"),
    ("covariance_json", "[[0.01, 0, 0], [0, 0.04, 1e999], [0, 0, null]]", "[1][2]: expected a finite number"),
])
def test_each_rule_refuses_among_sound_runs(column: str, text: str, said: str) -> None:
    rows = [row(1), row(2, **{column: text}), row(3)]
    with pytest.raises(ValueError, match="^run 2, ") as caught:
        decode_runs(rows, _refused)
    assert said in str(caught.value)


def test_an_estimate_beyond_the_bound_by_less_than_3_std_is_kept() -> None:
    """The rule is identify's: beyond ±1e4 by more than 3 standard errors (not a bound on the value alone)."""
    r = row(1, values_json="[10002, 0, null]", std_json="[1, 0.2, null]")
    assert decode_runs([r], _refused)[0].values[0] == 10002
    assert decode_run(r).values[0] == 10002


# ---------------------------------------------------------------------------------- the check-up's columns (schema 2)

@pytest.mark.parametrize("changed, said", [
    ({"kind": "calibration"}, "kind: expected full or checkup, got the text 'calibration'"),
    ({"kind": 1}, "kind: expected full or checkup, got the number 1"),
    ({"kind": "checkup", "chart_json": "{"}, "chart_json: not valid JSON"),
    ({"kind": "checkup", "chart_json": "[]"}, "chart_json: expected an object or null, got a list"),
    ({"kind": "checkup", "chart_json": json.dumps({k: v for k, v in CHART.items() if k != "flagged"})},
     "chart_json: no item 'flagged'"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART | {"extra": 1})}, "chart_json: unknown item 'extra'"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART | {"tolerance": {"EX0C": "8"}})},
     "chart_json: tolerance: expected numbers"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART | {"in_control": {"EX0C": 1}})},
     "chart_json: in_control: expected flags"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART | {"to_enter": {"EX0C": True}})},
     "chart_json: to_enter: expected numbers or null"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART | {"signature": None})}, "chart_json: signature: expected"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART).replace("1.5", "NaN")}, "NaN is not allowed"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART).replace("1.5", "1e999")},
     "chart_json: to_enter: expected numbers or null"),
    ({"kind": "checkup", "chart_json": json.dumps(CHART).replace('"EX0C": true', '"EX0C": true, "EX0C": false')},
     "chart_json: not valid JSON (duplicate key 'EX0C'"),
    ({"setup_json": "[1]"}, "setup_json: expected an object or null, got a list"),
])
def test_the_check_up_columns_are_read_strictly(changed: dict[str, Any], said: str) -> None:
    with pytest.raises(ValueError, match="^run 1, ") as caught:
        decode_runs([row(1, **changed)], _refused, light=True)
    assert said in str(caught.value)
    with pytest.raises(SchemaRefusal, match=said.split(": ", 1)[0]):
        check_new_run({k: v for k, v in row(1, **changed).items() if k != "id"})  # and never stored


def test_a_check_up_reads_its_chart_and_leaves_its_findings_to_the_commands_that_show_them() -> None:
    """Light (what a check-up reads of 1,000 runs): the chart, not the long findings; those are read strictly where
    they are shown (history show, the report, the fleet's last check-up)."""
    r = row(1, kind="checkup", chart_json=json.dumps(CHART), checkup_json="{not json", setup_json="[]")
    light = decode_run(r, light=True)
    assert light.checkup == CHART and light.setup is None and np.allclose(np.diag(light.covariance)[:2], [0.01, 0.04])
    with pytest.raises(SchemaRefusal, match="setup_json: expected an object or null"):
        decode_run(r)
    with pytest.raises(SchemaRefusal, match="checkup_json: not valid JSON"):
        decode_run(r | {"setup_json": None})


def test_a_run_of_schema_1_is_a_full_calibration_with_no_set_up() -> None:
    old = {k: v for k, v in row(1).items() if k not in ("kind", "setup_json", "checkup_json", "chart_json")}
    for rec in (decode_run(old), decode_runs([old], _refused, light=True)[0]):
        assert (rec.kind, rec.setup, rec.checkup, rec.values[0]) == ("full", None, None, 1.5)


def test_the_columns_of_each_schema_version_are_the_migrations() -> None:
    import sqlalchemy as sa

    from pige_sym.verdict.history import tables as T
    from pige_sym.verdict.history.integrity import COLUMNS, SCHEMA_VERSION
    from pige_sym.verdict.history.migrations import MIGRATIONS

    assert SCHEMA_VERSION == max(m.version for m in MIGRATIONS) == max(COLUMNS)
    assert {t.name: tuple(c.name for c in t.columns) for t in T.metadata.sorted_tables} == COLUMNS[SCHEMA_VERSION]
    engine = sa.create_engine("sqlite://")
    with engine.begin() as conn:
        conn.execute(sa.text("CREATE TABLE schema_version (version INTEGER PRIMARY KEY, description TEXT NOT NULL, "
                             "applied_at VARCHAR(40) NOT NULL)"))
        for m in MIGRATIONS:
            m.apply(conn)
            have = {t: tuple(r[1] for r in conn.execute(sa.text(f"PRAGMA table_info({t})"))) for t in COLUMNS[1]}
            assert have == COLUMNS[m.version], m.version


# ------------------------------------------------------------------------------ strict JSON, faster, the same answers

def _no_repeats_as_written(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"duplicate key {k!r}: it appears twice in one object")
        out[k] = v
    return out


def _depth_as_written(x: Any, limit: int, level: int = 1) -> int:
    if level > limit:
        return level
    if isinstance(x, dict):
        return max([_depth_as_written(v, limit, level + 1) for v in x.values()], default=level)
    if isinstance(x, list):
        return max([_depth_as_written(v, limit, level + 1) for v in x], default=level)
    return level


def strict_loads_as_written(text: str) -> Any:
    """Issue 43's strict reader before the merge made it cheaper (the oracle)."""
    from pige_sym.measurements.strict_json import MAX_DEPTH, _json_int, _reject_constant

    try:
        data = json.loads(text, parse_constant=_reject_constant, parse_int=_json_int,
                          object_pairs_hook=_no_repeats_as_written)
    except RecursionError:
        raise ValueError(f"nested deeper than {MAX_DEPTH} levels") from None
    if _depth_as_written(data, MAX_DEPTH) > MAX_DEPTH:
        raise ValueError(f"nested deeper than {MAX_DEPTH} levels")
    return data


_KEYS = st.sampled_from(["a", "b", "c", "[", "{", 'q"['])  # a quote in a key: an escape in the text
_JSON_TEXT = st.recursive(
    st.sampled_from(["1", "null", "true", '"x"', '"[["', '"a\\"["', '"\\\\"', "NaN", "12345678901234567890"]),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3).map(lambda xs: "[" + ",".join(xs) + "]"),
        st.lists(st.tuples(_KEYS, inner), max_size=3).map(
            lambda kv: "{" + ",".join(f"{json.dumps(k)}: {v}" for k, v in kv) + "}")),
    max_leaves=40)


@settings(max_examples=300, deadline=None)
@given(_JSON_TEXT, st.integers(0, 20))
def test_strict_json_answers_as_it_was_written(text: str, wrap: int) -> None:
    from pige_sym.measurements.strict_json import strict_loads

    text = "[" * wrap + text + "]" * wrap  # deep nesting, near the limit of 16 levels

    def answer(read: Callable[[str], Any]) -> Any:
        try:
            return ("value", read(text))
        except ValueError as exc:
            return ("refused", str(exc).split(":")[0] if isinstance(exc, json.JSONDecodeError) else str(exc))

    got, expected = answer(strict_loads), answer(strict_loads_as_written)
    assert got[0] == expected[0] and (got[0] == "refused" and got == expected or
                                      json.dumps(got[1]) == json.dumps(expected[1])), (text, got, expected)
