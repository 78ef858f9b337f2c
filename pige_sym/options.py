"""Parsing of command-line values: the one helper for numbers, vectors and ``key=value`` lists.

Grammar::

    number      := an ASCII decimal float literal (``12``, ``-0.5``, ``1e-3``), finite;
                   not ``nan``/``inf``, no ``_`` separators, no non-ASCII digits
    vector      := number ("," number)*            e.g. ``120,0,80``
    assignments := item ("," item)*;  item := key "=" value      e.g. ``harmonic=2,cos_urad=10``

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
