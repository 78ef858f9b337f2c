"""Strict JSON text: what every JSON file pige reads must be before its schema is checked.

Only regular files (no FIFO or device), at most :data:`MAX_JSON_BYTES`, UTF-8 (a BOM is allowed), strict JSON:
``NaN``/``Infinity`` tokens, repeated keys and nesting deeper than :data:`MAX_DEPTH` are refused.  An integer
longer than :data:`MAX_INT_DIGITS` digits is read as the float it denotes (a 400-digit one is ``inf``, refused
wherever a finite number is required, as ``1e400`` is).  The schemas: :mod:`pige_sym.measurements.schema`.
"""

from __future__ import annotations

import json
import re
from itertools import accumulate
from typing import Any

from pige_sym.errors import FileFormatError
from pige_sym.files import PathLike, open_regular_file

MAX_JSON_BYTES = 16 * 2**20
MAX_DEPTH = 16
def _reject_constant(token: str) -> float:
    raise ValueError(f"{token} is not allowed in pige JSON (use null for 'no value')")


#: Digits of the longest integer read as an int (a 64-bit count); a longer one is the float it denotes.
MAX_INT_DIGITS = 18


def _json_int(text: str) -> int | float:
    """A JSON integer: an int, or beyond :data:`MAX_INT_DIGITS` digits the float (``inf``) no ``float()`` overflows."""
    return int(text) if len(text.lstrip("-")) <= MAX_INT_DIGITS else float(text)


def _no_repeats(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):  # the first key that repeats, named
        seen: set[str] = set()
        for k, _ in pairs:
            if k in seen:
                raise ValueError(f"duplicate key {k!r}: it appears twice in one object")
            seen.add(k)
    return out


_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")
_STEP = {"[": 1, "{": 1, "]": -1, "}": -1}


def _outside_strings(text: str) -> str:
    """A JSON text without its strings (of a valid text: without a backslash every quote opens or closes one)."""
    return "".join(text.split('"')[::2]) if "\\" not in text else _STRING.sub("", text)


def _bracket_depth(outside: str) -> int:
    """How deeply the brackets of a JSON text nest (given :func:`_outside_strings` of it; 0 for a scalar): the value's
    containers nest as deep, so its :func:`_depth` is this or one more (a scan of the text, not a walk of the value)."""
    brackets = _NOT_BRACKET.sub("", outside)
    return max(accumulate(map(_STEP.__getitem__, brackets)), default=0)


def _depth(x: Any, limit: int, level: int = 1) -> int:
    if level > limit:
        return level
    if isinstance(x, dict):
        return max([_depth(v, limit, level + 1) for v in x.values()], default=level)
    if isinstance(x, list):
        return max([_depth(v, limit, level + 1) for v in x], default=level)
    return level


def load_json(path: PathLike, what: str = "JSON file") -> Any:
    """Parse a JSON file strictly (module docstring); returns plain Python values.

    Raises
    ------
    FileFormatError
        Not a regular file, too large, not UTF-8, not strict JSON, or nested too deeply.
    """
    p = str(path)
    with open_regular_file(path) as fh:
        raw = fh.read(MAX_JSON_BYTES + 1)
    if len(raw) > MAX_JSON_BYTES:
        raise FileFormatError(p, None, f"{what} larger than {MAX_JSON_BYTES // 2**20} MiB")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(p, None, f"{what} is not UTF-8 text ({exc.reason} at byte {exc.start}): save it as "
                              "UTF-8") from None
    try:
        return strict_loads(text)
    except json.JSONDecodeError as exc:
        raise FileFormatError(p, exc.lineno, f"not valid JSON: {exc.msg}") from None
    except ValueError as exc:
        raise FileFormatError(p, None, f"not valid pige JSON: {exc}") from None


def strict_loads(text: str) -> Any:
    """The JSON value of ``text`` by :func:`load_json`'s rules; ValueError (``JSONDecodeError``: with the line)."""
    try:
        data = json.loads(text, parse_constant=_reject_constant, parse_int=_json_int, object_pairs_hook=_no_repeats)
    except RecursionError:
        raise ValueError(f"nested deeper than {MAX_DEPTH} levels") from None
    # a value nests at most one level deeper than the text opens brackets: most texts need no walk, and of the others
    # (a check-up's findings) only those whose brackets nest to the limit itself (the depth counted in the text)
    if text.count("[") + text.count("{") + 1 > MAX_DEPTH:
        nesting = _bracket_depth(_outside_strings(text))
        if nesting > MAX_DEPTH or nesting == MAX_DEPTH and _depth(data, MAX_DEPTH) > MAX_DEPTH:
            raise ValueError(f"nested deeper than {MAX_DEPTH} levels")
    return data
