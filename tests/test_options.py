"""The option-value parser: numbers, vectors and key=value lists (property tests)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pige_sym.errors import InputError
from pige_sym.options import parse_number, parse_number_assignments, parse_vector


@given(st.floats(allow_nan=False, allow_infinity=False, width=64))
def test_every_finite_float_round_trips(x: float) -> None:
    assert parse_number(repr(x), "--v") == x


@pytest.mark.parametrize("text", ["nan", "inf", "-Infinity", "1_000", "١٢", "１２", "1e400", "", "1,5", "0x10", "--1"])
def test_non_numbers_are_refused_with_the_option(text: str) -> None:
    with pytest.raises(InputError, match="--ball"):
        parse_number(text, "--ball")


@given(st.text(max_size=30))
def test_parse_number_never_crashes_and_never_returns_nan(text: str) -> None:
    try:
        value = parse_number(text, "--x")
    except InputError:
        return
    assert math.isfinite(value)


def test_vectors_and_assignments() -> None:
    assert parse_vector("120, 0, 80", "--ball", 3) == [120.0, 0.0, 80.0]
    with pytest.raises(InputError, match="expected 3"):
        parse_vector("1,2", "--ball", 3)
    assert parse_number_assignments("harmonic=2, cos_urad=-5", "--effect") == {"harmonic": 2.0, "cos_urad": -5.0}
    with pytest.raises(InputError, match="twice"):
        parse_number_assignments("a=1,a=2", "--effect")
    with pytest.raises(InputError, match="key=value"):
        parse_number_assignments("a", "--effect")
