"""Parser of ISO 10791 machine structure codes (CONVENTIONS §1)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.errors import MachineCodeError, PigeError

VALID = {
    "wC'A'bXYZ(C1)t": ("wC'A'bXYZ(C1)t", ["C", "A"], ["X", "Y", "Z"], ("A", "C")),
    "wC'B'bXYZ(C1)t": ("wC'B'bXYZ(C1)t", ["C", "B"], ["X", "Y", "Z"], ("B", "C")),
    "w C' A' b X Y Z (C1) t": ("wC'A'bXYZ(C1)t", ["C", "A"], ["X", "Y", "Z"], ("A", "C")),
    "wbXYZCA(C1)t": ("wbXYZCA(C1)t", [], ["X", "Y", "Z", "C", "A"], ("A", "C")),
    "wC'bXYZB(C1)t": ("wC'bXYZB(C1)t", ["C"], ["X", "Y", "Z", "B"], ("B", "C")),
    "wC'A'Y'X'bZ(C1)t": ("wC'A'Y'X'bZ(C1)t", ["C", "A", "Y", "X"], ["Z"], ("A", "C")),
    "wC\u2019A\u2032bXYZ(C1)t": ("wC'A'bXYZ(C1)t", ["C", "A"], ["X", "Y", "Z"], ("A", "C")),
    "wC\u02b9bXYZB(C1)t": ("wC'bXYZB(C1)t", ["C"], ["X", "Y", "Z", "B"], ("B", "C")),
    "wC1'C2'bXYZt": ("wC1'C2'bXYZt", ["C1", "C2"], ["X", "Y", "Z"], ("C1", "C2")),
    "wbXYZUt": ("wbXYZUt", [], ["X", "Y", "Z", "U"], ()),
}


@pytest.mark.parametrize("code", sorted(VALID))
def test_valid_codes_parse_and_round_trip(code: str) -> None:
    canonical, wp, tool, rotary = VALID[code]
    m = parse_machine_code(code)
    assert m.canonical == canonical
    assert [a.name for a in m.workpiece_axes] == wp
    assert [a.name for a in m.tool_axes] == tool
    assert tuple(a.name for a in m.rotary_axes) == rotary
    assert parse_machine_code(m.canonical).canonical == canonical
    assert all(a.side == "workpiece" and a.sign == -1 for a in m.workpiece_axes)
    assert all(a.side == "tool" and a.sign == 1 for a in m.tool_axes)


def test_spindle_recorded_and_positions_refer_to_input() -> None:
    m = parse_machine_code("w C' A' b X Y Z (C1) t")
    assert m.spindle == "C1"
    assert m.workpiece_axes[0].position == 2
    assert m.workpiece_axes[1].position == 5


INVALID = [
    # (code, position, fragment of the message)
    ("", 0, "empty"),
    ("C'A'bXYZt", 0, "starts with 'w'"),
    ("wCA'bXYZt", 2, "must be primed"),
    ("wC'A'bXY'Zt", 8, "must not be primed"),
    ("wC'QbXYZt", 3, "unknown character"),
    ("wC'A'bXYZ(C1t", 12, "unbalanced"),
    ("wC'A'bXYZC1)t", 11, "')' without '('"),
    ("wC'A'bXYZ(C1)", 13, "ends too early"),
    ("wC'C'bXYZt", 3, "appears twice"),
    ("wC'bXYZC(C1)t", 7, "appears twice"),
    ("wC'A'bbXYZt", 6, "'b' (bed) appears twice"),
    ("wC'A'tbXYZ", 5, "before 'b'"),
    ("wC'A'bXYZ(C1)tx", 14, "after 't'"),
    ("wwC'bXYZt", 1, "'w' (workpiece) appears twice"),
    ("w'C'bXYZt", 1, "prime must follow"),
    ("wc'bXYZt", 1, "upper case"),
    ("wC'A'b(C1)XYZt", 10, "followed by 't'"),
    ("wC'(C1)bXYZt", 3, "after 'b'"),
    ("wC'A'bXYZ()t", 10, "spindle axis letter"),
    ("wC'A'bXYZ(C1)(C2)t", 13, "followed by 't'"),
]


@pytest.mark.parametrize(("code", "position", "fragment"), INVALID)
def test_invalid_codes_refused_with_position(code: str, position: int, fragment: str) -> None:
    with pytest.raises(MachineCodeError) as info:
        parse_machine_code(code)
    assert info.value.position == position, str(info.value)
    assert fragment in str(info.value)
    assert f"position {position}" in str(info.value)
    assert isinstance(info.value, PigeError)


@settings(max_examples=400, deadline=None)
@given(st.text(alphabet="wbtXYZUVWABC'’()0123 qx\u2032\u00b2\u0661\uff11\u00bd", max_size=16))
def test_random_strings_never_crash_with_anything_but_pige_error(code: str) -> None:
    try:
        m = parse_machine_code(code)
    except PigeError as exc:
        assert "position" in str(exc)
    else:
        assert parse_machine_code(m.canonical).canonical == m.canonical


axis_names = st.sampled_from(list("XYZUVWABC")).flatmap(
    lambda letter: st.sampled_from([letter, letter + "1", letter + "2"])
)


@settings(max_examples=200, deadline=None)
@given(st.lists(axis_names, unique=True, max_size=6), st.integers(0, 6), st.booleans(), st.booleans())
def test_generated_valid_codes_round_trip(names: list[str], split: int, spindle: bool, spaces: bool) -> None:
    split = min(split, len(names))
    sep = " " if spaces else ""
    wp = sep.join(n + "'" for n in names[:split])
    tl = sep.join(names[split:])
    code = sep.join(["w", wp, "b", tl, "(C9)" if spindle else "", "t"])
    m = parse_machine_code(code)
    assert [a.name for a in m.workpiece_axes] == names[:split]
    assert [a.name for a in m.tool_axes] == names[split:]
    assert parse_machine_code(m.canonical) == parse_machine_code(m.canonical)


def test_cli_bad_code_exits_2_with_one_line() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "pige_sym", "gen", "wCA'bXYZ(C1)t"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "position 2" in lines[0] and "Traceback" not in proc.stderr


def test_suffixes_are_ascii_numbers_and_names_compare_as_numbers() -> None:
    assert parse_machine_code("wC01'A'bXYZ(C2)t").canonical == "wC1'A'bXYZ(C2)t"
    with pytest.raises(MachineCodeError, match="appears twice"):
        parse_machine_code("wC1'C01'bXYZt")  # the same axis written twice
    for bad, pos in (("wC\u00b2'bXYZt", 2), ("wC\u0661'bXYZt", 2), ("wC1\uff12'bXYZt", 3), ("wbXYZ(C\u00b9)t", 7)):
        with pytest.raises(MachineCodeError, match="ASCII digits") as info:
            parse_machine_code(bad)
        assert info.value.position == pos


def test_spindle_may_not_take_a_positioning_axis_name_and_long_codes_are_refused() -> None:
    for code in ("wC1'A'bXYZ(C1)t", "wC'A'bXYZ(C)t", "wbXYZCA(C0)tx"[:-1].replace("C0", "C"), "wC01'bXYZ(C1)t"):
        with pytest.raises(MachineCodeError, match="name of a positioning axis"):
            parse_machine_code(code)
    assert parse_machine_code("wC'A'bXYZ(C1)t").spindle == "C1"
    with pytest.raises(MachineCodeError, match="at most 64 characters"):
        parse_machine_code("w" + "C'" * 1000 + "bt")
    with pytest.raises(MachineCodeError, match="at most 3 digits"):
        parse_machine_code("wC1234'bXYZt")
