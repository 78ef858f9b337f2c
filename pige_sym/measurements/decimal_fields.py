"""Vectorised parsing of ASCII decimal fields, bit-identical to :func:`pige_sym.options.strict_float`.

Grammar of one field (the tool's one number grammar, ``options._NUMBER``)::

    field := [+-]? (digits [. digits?] | . digits) ([eE] [+-]? digits)?

Input is a byte buffer and the offsets of the separator that ends each field (``,`` or
``\\n``; the last field may end at the buffer's end).  The result is exactly what
``strict_float`` gives for every field's text, or ``None`` when one field is not a number
(the caller then re-reads the chunk strictly to name the line).

Method (NumPy only; no Python work per field on the common path):

1. An ``e``/``E`` ends the mantissa; the exponent after it (``[+-]`` and up to four digits,
   :data:`MAX_EXPONENT_BYTES`) is read column by column over the fields that have one.
2. The last :data:`WINDOW` bytes of every mantissa are gathered into a ``(WINDOW, n)`` byte
   matrix, one row per column position, so every later step is a long, contiguous
   ``uint8`` operation.
3. Column by column: which bytes belong to the field, which are digits, the dot; the sign
   is read at the field's first byte.  A field whose mantissa is not plain
   ``digits[.digits]`` (a blank, a stray character, two dots), is longer than the window or
   has more than :data:`MAX_DIGITS` digits is *deferred*.
4. The digits are accumulated (Horner, exact int32 groups, the dot skipped) into the exact
   integer mantissa ``M < 10**19`` (``uint64``); the decimal power ``p`` is the exponent minus
   the digits after the dot.  ``|p| > MAX_POWER`` (22) is deferred.
5. ``p <= 0``: ``M / 10**-p = (M / 5**-p) * 2**p``, the quotient by ``5**-p`` (an exact
   double) computed in double-double arithmetic: ``q = fl(M) / 5**-p``, the residual
   ``M - q * 5**-p`` exactly (Dekker's two-product), ``q + residual / 5**-p`` rounded once;
   scaling by ``2**p`` is exact.  ``p > 0``: ``M * 10**p`` as Dekker's exact product of
   ``fl(M)`` and ``10**p`` (an exact double) plus the rest of ``M`` times ``10**p``, rounded
   once.  The result is the correctly rounded value unless the exact value lies within
   ``2**-30`` ulp of a rounding midpoint (the approximation error is below ``2**-48`` ulp);
   those fields are deferred.
6. Deferred fields are parsed one by one with ``strict_float``.

So the fast path never decides a value it cannot prove: it either reproduces the correctly
rounded double (which is what ``float()`` returns) or hands the text to ``strict_float``.
Deferred in practice: exact rounding ties, numbers with more than 19 digits or longer than
20 bytes before the exponent, and 17-digit numbers below about 1e-6 (``p < -22``).
"""

from __future__ import annotations

import numpy as np

from pige_sym.options import strict_float

#: Bytes of a field's tail examined by the vectorised path (longer fields are deferred).
WINDOW = 20
#: Most significant digits whose integer still fits ``uint64`` exactly (10**19 < 2**64).
MAX_DIGITS = 19
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp's splitter for a 53-bit significand
#: Largest decimal power handled vectorised: 5**22 and 10**22 are exact doubles.
MAX_POWER = 22
#: Most bytes after the ``e`` handled vectorised (sign and up to four digits).
MAX_EXPONENT_BYTES = 5
_FIVE = np.array([5.0**k for k in range(MAX_POWER + 1)])


def _split(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Veltkamp's split: ``x == hi + lo`` exactly, each half with at most 26 significant bits."""
    t = x * _SPLIT
    hi = t - (t - x)
    return hi, x - hi


_FIVE_HI, _FIVE_LO = _split(_FIVE)
_TEN = np.array([float(10**k) for k in range(MAX_POWER + 1)])  # exact: 10**22 = 5**22 * 2**22
_TEN_HI, _TEN_LO = _split(_TEN)
_MIDPOINT_MARGIN = 2.0**-30
_HALF_POWERS = np.array([2.0**-k for k in range(MAX_POWER + 1)])  # exact
_ASCII_ZERO, _DOT, _PLUS, _MINUS = 48, 46, 43, 45
#: Column groups accumulated in int32 (at most 9 digits each), and each column's group.
_GROUPS = ((0, 7), (7, 14), (14, WINDOW))
_GROUP_OF = [next(g for g, (lo, hi) in enumerate(_GROUPS) if lo <= j < hi) for j in range(WINDOW)]


def field_ends(buf: np.ndarray) -> np.ndarray:
    """Offsets of the byte ending each field: every ``,`` and ``\\n``, plus ``len(buf)`` if the
    buffer does not end with a separator.

    Parameters
    ----------
    buf : ndarray, shape=(n_bytes,), uint8
        The text.

    Returns
    -------
    ndarray, shape=(n_fields,), int64
    """
    ends = np.flatnonzero((buf == ord(",")) | (buf == ord("\n")))
    if buf.size and buf[-1] not in (ord(","), ord("\n")):
        ends = np.append(ends, buf.size)
    return ends


def field_starts(ends: np.ndarray) -> np.ndarray:
    """Offset of each field's first byte when every field starts after the previous one's separator.

    Parameters
    ----------
    ends : ndarray, shape=(n_fields,), int64
        :func:`field_ends`.

    Returns
    -------
    ndarray, shape=(n_fields,), int64
    """
    starts = np.empty_like(ends)
    starts[:1] = 0
    starts[1:] = ends[:-1] + 1
    return starts


def parse_decimal_fields(buf: np.ndarray, ends: np.ndarray, starts: np.ndarray | None = None) -> np.ndarray | None:
    """Every field of ``buf`` as a float64, exactly ``strict_float`` of its text.

    Parameters
    ----------
    buf : ndarray, shape=(n_bytes,), uint8
        The text; field ``i`` is ``buf[starts[i] : ends[i]]``.
    ends : ndarray, shape=(n_fields,), int64
        Offset of the separator after each field (:func:`field_ends`).
    starts : ndarray, shape=(n_fields,), int64, optional
        Offset of each field's first byte; default: every field starts after the previous
        field's separator (the first at 0), i.e. ``ends`` lists every field of ``buf``.

    Returns
    -------
    ndarray, shape=(n_fields,), float64, or None
        None when a field is not a number under the grammar (module docstring).
    """
    n = ends.size
    if n == 0:
        return np.empty(0)
    if starts is None:
        starts = field_starts(ends)
    mantissa_end, exponent, deferred = _exponents(buf, starts, ends)
    mantissa, k, negative, deferred_mantissa = _mantissas(buf, mantissa_end, mantissa_end - starts)
    deferred |= deferred_mantissa
    power = exponent - k
    deferred |= np.abs(power) > MAX_POWER
    values, ambiguous = _scaled(mantissa, np.clip(power, -MAX_POWER, MAX_POWER))
    np.negative(values, out=values, where=negative)
    for i in np.flatnonzero(deferred | ambiguous):
        value = strict_float(buf[starts[i] : ends[i]].tobytes().decode("ascii", "replace"))
        if value is None:
            return None
        values[i] = value
    return values


def _exponents(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each field's mantissa ends (its ``e``/``E`` or its end), the exponent's value (0 without
    one), and the fields whose exponent the vectorised path leaves to ``strict_float`` (two ``e``,
    more than :data:`MAX_EXPONENT_BYTES` bytes after it, or not ``[+-]digits``)."""
    n = ends.size
    mantissa_end, exponent, deferred = ends.copy(), np.zeros(n, np.int64), np.zeros(n, bool)
    e_at = np.flatnonzero((buf | np.uint8(0x20)) == ord("e"))  # 'E' | 0x20 == 'e'; no other byte maps to it
    if not e_at.size:
        return mantissa_end, exponent, deferred
    field = np.searchsorted(ends, e_at)
    inside = field < n
    inside[inside] = e_at[inside] >= starts[field[inside]]  # an 'e' in a text column is not ours
    e_at, field = e_at[inside], field[inside]
    twice = np.bincount(field, minlength=n) > 1
    mantissa_end[field] = e_at
    size = ends[field] - e_at - 1
    value, sign = np.zeros(field.size, np.int64), np.ones(field.size, np.int64)
    n_digits = np.zeros(field.size, np.int64)
    bad = size > MAX_EXPONENT_BYTES
    for c in range(MAX_EXPONENT_BYTES):
        present = c < size
        byte = buf[np.minimum(e_at + 1 + c, buf.size - 1)]
        digit = byte.astype(np.int64) - _ASCII_ZERO
        is_digit = (digit >= 0) & (digit < 10)
        signed = (c == 0) & ((byte == _PLUS) | (byte == _MINUS))
        sign[signed & (byte == _MINUS)] = -1
        bad |= present & ~(is_digit | signed)
        n_digits += present & is_digit
        value = np.where(present & is_digit, value * 10 + digit, value)
    bad |= n_digits == 0  # "1e", "1e+"
    exponent[field] = sign * value
    deferred[field[bad]] = True
    deferred |= twice
    return mantissa_end, exponent, deferred


def _columns(buf: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The last :data:`WINDOW` bytes before each field's end, one row per column: shape (WINDOW, n)."""
    padded = np.concatenate((np.full(WINDOW, ord(","), np.uint8), buf))
    columns = np.empty((WINDOW, ends.size), np.uint8)
    index = ends.copy()  # padded[ends + j] is buf[ends - WINDOW + j]
    for j in range(WINDOW):
        np.take(padded, index, out=columns[j])
        index += 1
    return columns


def _mantissas(
    buf: np.ndarray, ends: np.ndarray, length: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integer mantissa (uint64), digits after the dot, sign and the deferred mask of each field.

    The bytes before each field and its sign are first replaced by ``0`` (leading zeros).  Then
    one pass over the columns, left to right, accumulates the digits by Horner's rule in exact
    int32 groups of columns (:data:`_GROUPS`); at the dot the multiplier is 1 instead of 10, so
    the dot is skipped.  Any byte that is neither a digit nor a dot defers the field.
    """
    n = ends.size
    columns = _columns(buf, ends)
    first = np.clip(WINDOW - length, 0, WINDOW - 1)  # column of the field's first byte
    sign = columns[first, np.arange(n)]
    negative = sign == _MINUS
    has_sign = negative | (sign == _PLUS)
    columns[first[has_sign], np.flatnonzero(has_sign)] = _ASCII_ZERO
    first8 = first.astype(np.uint8)
    groups = [np.zeros(n, np.int32) for _ in _GROUPS]
    dot_after = np.zeros(n, np.uint8)  # 1 + column of the dot, 0 if none
    n_dots = np.zeros(n, np.uint8)
    stray = np.zeros(n, bool)
    for j in range(WINDOW):
        byte = columns[j]
        np.copyto(byte, np.uint8(_ASCII_ZERO), where=first8 > j)
        digit = byte - np.uint8(_ASCII_ZERO)
        is_digit = digit < 10
        is_dot = byte == _DOT
        stray |= ~(is_digit | is_dot)
        n_dots += is_dot
        np.maximum(dot_after, is_dot * np.uint8(j + 1), out=dot_after)
        acc = groups[_GROUP_OF[j]]
        acc *= np.uint8(10) - np.uint8(9) * is_dot
        acc += digit * is_digit
    n_digits = length - has_sign - n_dots
    deferred = (length > WINDOW) | stray | (n_dots > 1) | (n_digits < 1) | (n_digits > MAX_DIGITS)
    mantissa = groups[0].astype(np.uint64)
    for (lo, hi), acc in zip(_GROUPS[1:], groups[1:], strict=True):
        dot_here = (dot_after > lo) & (dot_after <= hi)  # the dot is in columns lo..hi-1
        mantissa *= np.where(dot_here, np.uint64(10 ** (hi - lo - 1)), np.uint64(10 ** (hi - lo)))
        mantissa += acc.view(np.uint32)
    k = WINDOW - dot_after.astype(np.int64)
    k[dot_after == 0] = 0
    return mantissa, k, negative, deferred


def _scaled(mantissa: np.ndarray, power: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correctly rounded ``mantissa * 10**power`` (float64, ``|power| <= MAX_POWER``) and the fields
    too close to a rounding midpoint to tell."""
    values, ambiguous = _quotients(mantissa, np.maximum(-power, 0))
    up = np.flatnonzero(power > 0)
    if up.size:
        values[up], ambiguous[up] = _products(mantissa[up], power[up])
    return values, ambiguous


def _split_mantissa(mantissa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``mantissa`` (uint64) as ``hi + lo``: ``hi`` its nearest double, ``lo`` the exact rest (float64)."""
    m_hi = mantissa.astype(np.float64)
    # a field of more than 19 digits (sent to the strict parser, its value here unused) can round to 2**64,
    # which uint64 cannot hold: its cast is invalid, harmlessly
    with np.errstate(invalid="ignore"):
        m_lo = (mantissa.view(np.int64) - m_hi.astype(np.uint64).view(np.int64)).astype(np.float64)
    return m_hi, m_lo


def _rounded(head: np.ndarray, tail: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``fl(head + tail)`` for a double-double approximation (``|tail| <= ulp(head)``-ish, error below
    ``2**-48`` ulp) and whether the exact value may sit within :data:`_MIDPOINT_MARGIN` ulp of a midpoint."""
    total = head + tail
    rest = np.abs((head - total) + tail)  # exact: |head| >= |tail| (Fast2Sum)
    # the power of two of total's binade (0 for 0): rest / ulp near 1/2 (or 1/4 below a power of two)
    binade = (total.view(np.uint64) & np.uint64(0x7FF0000000000000)).view(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        in_ulps = rest / binade * 2.0**52
    ambiguous = (np.abs(in_ulps - 0.5) <= _MIDPOINT_MARGIN) | (np.abs(in_ulps - 0.25) <= _MIDPOINT_MARGIN)
    return total, ambiguous


def _quotients(mantissa: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correctly rounded ``mantissa / 10**k`` (float64, ``0 <= k <= MAX_POWER``) and the ambiguous fields."""
    five, five_hi, five_lo = _FIVE[k], _FIVE_HI[k], _FIVE_LO[k]
    m_hi, m_lo = _split_mantissa(mantissa)
    q = m_hi / five
    product, product_err = _two_product(q, five, five_hi, five_lo)
    residual = ((m_hi - product) - product_err) + m_lo  # M - q * 5**k, to 2**-52 relative
    total, ambiguous = _rounded(q, residual / five)
    return total * _HALF_POWERS[k], ambiguous


def _products(mantissa: np.ndarray, power: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correctly rounded ``mantissa * 10**power`` (float64, ``0 < power <= MAX_POWER``) and the ambiguous fields."""
    ten, ten_hi, ten_lo = _TEN[power], _TEN_HI[power], _TEN_LO[power]
    m_hi, m_lo = _split_mantissa(mantissa)
    product, product_err = _two_product(m_hi, ten, ten_hi, ten_lo)
    return _rounded(product, product_err + m_lo * ten)


def _two_product(
    a: np.ndarray, b: np.ndarray, b_hi: np.ndarray, b_lo: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Dekker's two-product: ``a * b == p + e`` exactly (``b`` already split into ``b_hi + b_lo``)."""
    p = a * b
    a_hi, a_lo = _split(a)
    e = ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo
    return p, e
