"""The vectorised decimal parser against the tool's one number grammar (``options.strict_float``).

Every check is bit-exact (``float64`` bit patterns compared), on: hypothesis strings of the
numeric alphabet, the usual ways numbers get written (``repr``, ``%.17g``, ``%.6f``, ``%.3e``),
seeded bulk samples of 17–19-digit mantissas, and the adversarial inputs of correct rounding:
decimal strings that are *exactly* the midpoint between two neighbouring doubles (ties to
even), and those one unit of the last digit either side of it.
"""

from __future__ import annotations

from decimal import Decimal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from property_budget import examples

from pige_sym.measurements.decimal_fields import MAX_DIGITS, WINDOW, field_ends, parse_decimal_fields
from pige_sym.options import strict_float


def parse(fields: list[str], sep: str = ",") -> np.ndarray | None:
    buf = np.frombuffer("".join(f + sep for f in fields).encode("ascii", "replace"), np.uint8)
    ends = field_ends(buf)
    assert ends.size == len(fields)
    return parse_decimal_fields(buf, ends)


def expected(fields: list[str]) -> np.ndarray | None:
    values = [strict_float(f) for f in fields]
    return None if any(v is None for v in values) else np.array(values, dtype=np.float64)


def assert_bit_exact(fields: list[str]) -> None:
    got, want = parse(fields), expected(fields)
    if want is None:
        assert got is None, fields
        return
    assert got is not None, fields
    bad = np.flatnonzero(got.view(np.int64) != want.view(np.int64))
    assert not bad.size, [(fields[i], got[i], want[i]) for i in bad[:5]]


ALPHABET = "0123456789.+-eE \t"  # no separators: each generated text is one field
field_text = st.text(alphabet=ALPHABET, max_size=24)


@settings(max_examples=examples(400), deadline=None)
@given(st.lists(field_text, min_size=1, max_size=30))
def test_random_numeric_text_matches_strict_float(fields) -> None:
    assert_bit_exact(fields)


doubles = st.floats(allow_nan=False, allow_infinity=False, width=64)
written = st.one_of(doubles.map(repr), doubles.map(lambda x: f"{x:.17g}"), doubles.map(lambda x: f"{x:.6f}"),
                    doubles.map(lambda x: f"{x:.3e}"), doubles.map(lambda x: f"{x:.16E}"),
                    st.integers(-10**20, 10**20).map(str),
                    st.tuples(st.integers(-10**19, 10**19), st.integers(-30, 30)).map(lambda p: f"{p[0]}e{p[1]:+03d}"))


@settings(max_examples=examples(400), deadline=None)
@given(st.lists(written, min_size=1, max_size=30))
def test_numbers_as_programs_write_them(fields) -> None:
    assert_bit_exact(fields)


@pytest.mark.parametrize("text", [
    "0", "-0", "+0", "-0.0", "0.", ".5", "+.5", "-.5", "5.", "000123.5", "00000000000000000001",
    "1234567890123456789", "12345678901234567890", "9999999999999999999", "0.9999999999999999999",
    ".1234567890123456789", "123456789.0123456789", "1" * WINDOW, "1" * (WINDOW + 1), "0." + "0" * 18 + "1",
    "9007199254740993", "9007199254740993.0", "4503599627370496.5", "4503599627370497.5", "2251799813685248.25",
    "-1e5", "1E+05", "1e-400", "1e400", "1e0005", "1e00005", "1.5e-22", "9999999999999999999e22", "1e23",
    "1e-23", "5e-324", "1.7976931348623157e308", "1e+", "1e-", "1e+-5", "1e5e3", "1.e5", ".5e-3", "-.5E+3",
    "1.5 ", " 1.5", "\t2", "", ".", "-", "+", "-.", "1.2.3", "--1", "+-1",
    "1-", "1+1", "e5", "1e", "1e+", "0x10", "1_0", "nan", "inf", "١", "1;5",
])
def test_edge_cases(text) -> None:
    assert_bit_exact([text])
    assert_bit_exact(["1.25", text, "-3"])


def test_newlines_and_commas_both_separate_and_the_last_field_may_be_open() -> None:
    buf = np.frombuffer(b"1.5,2\n-3,4.25\n5", np.uint8)
    assert field_ends(buf).tolist() == [3, 5, 8, 13, 15]
    values = parse_decimal_fields(buf, field_ends(buf))
    assert values is not None and values.tolist() == [1.5, 2.0, -3.0, 4.25, 5.0]


def _midpoints(rng: np.random.Generator, n: int) -> list[str]:
    """Exact decimal midpoints between neighbouring doubles, written in at most MAX_DIGITS digits,
    and the strings one unit of the last digit below and above each."""
    out: list[str] = []
    while len(out) < 3 * n:
        x = float(rng.uniform(2.0**50, 2.0**63)) * 2.0 ** -int(rng.integers(0, 12))
        mid = (Decimal(x) + Decimal(np.nextafter(x, np.inf))) / 2
        digits = mid.normalize().as_tuple().digits
        if len(digits) > MAX_DIGITS:
            continue
        text = f"{mid:f}"
        unit = Decimal(1).scaleb(mid.normalize().as_tuple().exponent)  # type: ignore[arg-type]
        out += [text, f"{mid - unit:f}", f"{mid + unit:f}"]
    return out


def test_exact_midpoints_round_half_to_even() -> None:
    fields = _midpoints(np.random.default_rng(1), 3000)
    assert any(len(f.replace(".", "")) >= 18 for f in fields)
    assert_bit_exact(fields)


def test_bulk_long_mantissas_seeded() -> None:
    rng = np.random.default_rng(2)
    n = 200_000
    digits = rng.integers(1, MAX_DIGITS + 1, n)
    fields = []
    for d, dot, neg in zip(digits, rng.integers(0, MAX_DIGITS + 1, n), rng.random(n) < 0.5, strict=True):
        s = "".join(map(str, rng.integers(0, 10, int(d))))
        s = s if dot >= d else s[:dot] + "." + s[dot:]
        fields.append(("-" if neg else "") + s)
    assert_bit_exact(fields)


def test_exponent_forms_seeded() -> None:
    """``%e`` output of devices and ``repr`` of small numbers: every mantissa/exponent combination
    the vectorised path takes (|power| <= 22), including 17–19-digit mantissas scaled up."""
    rng = np.random.default_rng(4)
    x = rng.normal(0, 1, 60_000) * 10.0 ** rng.integers(-12, 12, 60_000)
    fields = [f"{v:.6e}" for v in x] + [f"{v:.16e}" for v in x] + [repr(float(v)) for v in x]
    fields += [f"{int(m)}e{int(p)}" for m, p in zip(rng.integers(1, 2**63, 20_000, dtype=np.uint64),
                                                    rng.integers(-25, 25, 20_000), strict=True)]
    assert_bit_exact(fields)


def test_doubles_round_trip_through_repr_seeded() -> None:
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(0, 10, 100_000), rng.uniform(-400, 400, 100_000),
                        np.cumsum(rng.uniform(0, 0.05, 100_000))])
    fields = [repr(float(v)) for v in x]
    got = parse(fields)
    assert got is not None and np.array_equal(got.view(np.int64), x.view(np.int64))


def test_exact_midpoints_are_deferred_to_strict_float() -> None:
    """The fast path does not decide a tie itself: a value on a rounding midpoint is flagged."""
    from pige_sym.measurements.decimal_fields import _quotients

    mantissa = np.array([9007199254740993, 45035996273704965, 12345], dtype=np.uint64)  # 2**53 + 1; its 5x / 10
    values, ambiguous = _quotients(mantissa, np.array([0, 1, 2]))
    assert ambiguous.tolist() == [True, True, False]
    assert values[2] == 123.45
