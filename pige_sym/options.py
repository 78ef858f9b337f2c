"""Parsing of command-line values: the one helper for numbers, vectors and ``key=value`` lists.

Grammar::

    number      := an ASCII decimal float literal (``12``, ``-0.5``, ``1e-3``), finite;
                   not ``nan``/``inf``, no ``_`` separators, no non-ASCII digits
    vector      := number ("," number)*            e.g. ``120,0,80``
    assignments := item ("," item)*;  item := key "=" value      e.g. ``harmonic=2,cos_urad=10``
    names       := name ("," name)*                              e.g. ``C,A``, ``EX0C,EY0C`` (each once, none empty)
    axis range  := axis "=" number ":" number                    e.g. ``A=-120:30`` (repeatable, each axis once)

Every failure raises :class:`~pige_sym.errors.InputError` naming the option (``what``)
and the offending text, so the command exits with status 2 and one line.
"""

from __future__ import annotations

import math
import re

from pige_sym.errors import InputError

#: The one number grammar of pige (options and data files): ASCII decimal, blanks around allowed.
_NUMBER = re.compile(r"[ \t]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?[ \t]*")


def strict_float(text: str) -> float | None:
    """A finite float if ``text`` is a plain ASCII decimal, else None (``1_000``, ``٣``, ``nan``, ``1e400``)."""
    if not _NUMBER.fullmatch(text):
        return None
    value = float(text)
    return value if math.isfinite(value) else None


def parse_number(text: str, what: str) -> float:
    """A finite float from an ASCII decimal literal (``what`` names the option in errors)."""
    value = strict_float(text)
    if value is None:
        if _NUMBER.fullmatch(text):
            raise InputError(f"{what}: {text.strip()!r} is out of range")
        raise InputError(f"{what}: {text.strip()!r} is not a number (plain decimal digits, e.g. 12.5 or 1e-3)")
    return value


def parse_vector(text: str, what: str, length: int | None = None) -> list[float]:
    """Comma-separated numbers, exactly ``length`` of them when given."""
    values = [parse_number(part, what) for part in text.split(",")]
    if length is not None and len(values) != length:
        raise InputError(f"{what}: expected {length} numbers (comma-separated), got {len(values)} in {text!r}")
    return values


def parse_assignments(text: str, what: str) -> list[tuple[str, str]]:
    """``key=value`` items separated by commas, as (key, raw value) pairs in order; empty items are skipped."""
    out = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise InputError(f"{what}: expected key=value, got {item!r}")
        out.append((key.strip(), value.strip()))
    return out


def parse_number_assignments(text: str, what: str) -> dict[str, float]:
    """``key=number`` items as a dict; a repeated key is refused."""
    out: dict[str, float] = {}
    for key, value in parse_assignments(text, what):
        if key in out:
            raise InputError(f"{what}: {key} is given twice")
        out[key] = parse_number(value, f"{what} {key}")
    return out


def parse_names(text: str | None, what: str, example: str) -> tuple[str, ...]:
    """Comma-separated names, upper case, in the order given (None: not given, ``()``).

    An empty list, an empty item (``C,A,``) and a name given twice (``C,C``) are refused: a list that says less
    than it seems to is a typing error, not a request.
    """
    if text is None:
        return ()
    names = tuple(x.strip().upper() for x in text.split(","))
    if not any(names):
        raise InputError(f"{what} {text!r}: give one or more names, e.g. {example}")
    if not all(names):
        raise InputError(f"{what} {text!r}: an empty item (two commas, or one at an end): give e.g. {example}")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"{what} {text!r}: {twice[0]} is given twice: give each once, e.g. {example}")
    return names


def parse_axis_ranges(items: list[str] | None, what: str, axes: tuple[str, ...], *, max_abs: float = 720.0,
                      max_span: float | None = None, example: str = "A=-120:30") -> dict[str, tuple[float, float]]:
    """``AXIS=lo:hi`` items (repeatable, or comma-separated in one) [deg] as axis → (lo, hi).

    Each axis is one of ``axes`` and given once; lo < hi, both finite within ±``max_abs`` (two turns by default),
    ``hi − lo`` at most ``max_span`` when given.
    """
    out: dict[str, tuple[float, float]] = {}
    for item in [x for it in items or [] for x in it.split(",")]:
        axis, eq, span = (x.strip() for x in item.partition("="))
        axis = axis.upper()
        lo_text, colon, hi_text = span.partition(":")
        if not eq or axis not in axes:
            raise InputError(f"{what} {item!r}: give AXIS=lo:hi for a rotary axis ({', '.join(axes)}), e.g. "
                             f"{example}")
        if axis in out:
            raise InputError(f"{what} {axis} is given twice: give each axis once")
        low, high = strict_float(lo_text), strict_float(hi_text)
        if not colon or low is None or high is None or not (-max_abs <= low < high <= max_abs) or (
                max_span is not None and high - low > max_span):
            span_text = f", at most {max_span:g} apart" if max_span is not None else ""
            raise InputError(f"{what} {item!r}: give AXIS=lo:hi in degrees, lo < hi within ±{max_abs:g}"
                             f"{span_text}, e.g. {example}")
        out[axis] = (low, high)
    return out
