"""The interpreter's and rewriter's fast paths give exactly what the full paths give.

Plain blocks (``[N…] [G0|G1] [axis words in machine order] [F…] [; comment]``) are read in batches
and rewritten all at once; the read-back of the tool's own output goes through the same batches.
These property tests feed random plain and near-plain blocks (other spacing and case, words out
of order or glued together, exponents, absurd values, ISO integers, arcs, cycles, block skip, mode
changes in between) to both paths and require identical blocks, identical rewritten text, and a
read-back that catches a wrong output.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from property_budget import examples

from pige_sym.errors import PigeError
from pige_sym.nc.dialects import get_dialect
from pige_sym.nc.interpreter import Interpreter, Program, split_lines
from pige_sym.nc.lexer import word_spans
from pige_sym.nc.program import format_number, format_numbers
from pige_sym.nc.rewrite import rewrite_program
from pige_sym.nc.verify import verify

AXES = ("A", "C")
DECIMALS = st.one_of(st.floats(-360, 360, allow_nan=False).map(lambda v: f"{v:.4f}"),
                    st.sampled_from(["0", "-0", "+.5", "5.", "-.25", "007.500", "0.", "-0.0", "12", "-3"]))
NUMBERS = st.one_of(DECIMALS, DECIMALS, DECIMALS, st.integers(-999, 999).map(str),
                    st.sampled_from(["1e5", "1.2.3", "200000.", "nan", "", "+-1"]))
SPACE = st.sampled_from([" ", " ", " ", "", "\t", "  "])


@st.composite
def cam_block(draw: st.DrawFn, dialect: str) -> str:
    """A CAM-style plain block: every axis, in machine order, with a decimal point (what most programs hold)."""
    n = f"N{draw(st.integers(1, 99999))} " if draw(st.booleans()) else ""
    g = draw(st.sampled_from(["G1 ", "G0 ", "G01 ", ""]))
    sep = draw(st.sampled_from([" ", " ", "\t", "  "]))
    words = sep.join(a + draw(st.floats(-360, 360, allow_nan=False).map(lambda v: f"{v:.{draw(st.integers(1, 5))}f}"))
                     for a in "XYZAC")
    tail = draw(st.sampled_from(["", " F2000", " F150.5 ; c X1", " ;"]))
    return n + g + words + tail


@st.composite
def plain_block(draw: st.DrawFn, dialect: str) -> str:
    """A plain block, or one that is nearly plain (the fast paths must leave those to the full path)."""
    if draw(st.integers(0, 4)):
        return draw(cam_block(dialect))
    words = []
    if draw(st.booleans()):
        words.append(draw(st.sampled_from(["N", "n", "N "])) + str(draw(st.integers(0, 99999))))
    if draw(st.booleans()):
        words.append(draw(st.sampled_from(["G1", "G0", "G01", "G00", "g1", "G 1", "G001", "G2", "G1.", "G91", "G+1"])))
    letters = draw(st.lists(st.sampled_from("XYZACB"), unique=True, max_size=5))
    if draw(st.integers(0, 3)):
        letters.sort(key="XYZACB".index)  # machine order, mostly
    for letter in letters:
        case = letter.lower() if draw(st.integers(0, 9)) == 0 else letter
        words.append(case + draw(st.sampled_from(["", "", " ", "\t"])) + draw(NUMBERS))
    if draw(st.booleans()):
        words.append("F" + draw(st.sampled_from(["2000", "150.5", "1e3"])))
    line = draw(st.sampled_from(["", " ", "\t"]))
    for w in words:
        line += w + draw(SPACE)
    comment = draw(st.sampled_from(["", "", "; X10 c", ";", " (MOVE Z5)", "(c)"]))
    return line + comment


@st.composite
def other_block(draw: st.DrawFn, dialect: str) -> str:
    inch, metric, rtcp_on, rtcp_off = (("G70", "G71", "TRAORI", "TRAFOOF") if dialect == "siemens"
                                       else ("G20", "G21", "G43.4 H1", "G49"))
    point = "." if dialect == "fanuc" else ""
    return draw(st.sampled_from([
        "G90", "G91", inch, metric, rtcp_on, rtcp_off, "G17", "G94", "M8", "G54", "G55", "", "%",
        f"G81 X1{point} Y2{point} Z-3{point} R1{point}", "G80", f"G2 X1{point} Y1{point} I1{point} J0{point}",
        f"/N5 G1 X3{point}", f"G4 {'F1' if dialect == 'siemens' else 'P1'}", "G41", "G40", "M30",
        "SUPA G0 Z0" if dialect == "siemens" else "G53 G0 Z0.",
    ]))


@st.composite
def programs(draw: st.DrawFn) -> tuple[str, str]:
    dialect = draw(st.sampled_from(["siemens", "fanuc", "linuxcnc"]))
    body = draw(st.lists(st.one_of(plain_block(dialect), plain_block(dialect), other_block(dialect)),
                         min_size=1, max_size=30))
    ending = draw(st.sampled_from(["\n", "\r\n"]))
    head = "G90 G71 TRAORI" if dialect == "siemens" else "G90 G21"
    return dialect, ending.join([head, *body]) + draw(st.sampled_from([ending, ""]))


def _read(text: str, dialect: str, fast: bool) -> list | str:
    interp = Interpreter(get_dialect(dialect), AXES, fast=fast)
    try:
        return interp.run(split_lines(text))
    except PigeError as exc:
        return f"error: {exc}"


def _words(block) -> list:  # noqa: ANN001
    spans = word_spans(block.text, block.axis_words)
    return sorted((k, t.value, t.has_point, t.function, spans[k]) for k, t in block.axis_words.items())


def _summary(blocks: list | str) -> list | str:
    if isinstance(blocks, str):
        return blocks
    return [(b.line_no, b.text, b.ending, b.kind, b.reason, b.before, b.after, b.state, b.stop, b.skip, b.dwell,
             b.dwell_s, b.incremental_axes, _words(b)) for b in blocks]


@settings(max_examples=examples(400), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs())
def test_batch_and_full_path_read_the_same_blocks(prog):
    dialect, text = prog
    fast, full = _read(text, dialect, True), _read(text, dialect, False)
    assert _summary(fast) == _summary(full)


def _program(text: str, dialect: str, fast: bool) -> Program | None:
    blocks = _read(text, dialect, fast)
    if isinstance(blocks, str):
        return None
    interp = Interpreter(get_dialect(dialect), AXES)
    return Program("p", blocks, get_dialect(dialect), interp.axes)


@settings(max_examples=examples(300), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs(), st.lists(st.floats(-0.2, 0.2, allow_nan=False), min_size=5, max_size=5),
       st.integers(0, 2**31))
def test_batch_and_line_by_line_rewrites_are_identical(prog, shift, seed):
    dialect, text = prog
    fast, full = _program(text, dialect, True), _program(text, dialect, False)
    if fast is None or full is None:
        return
    rng = np.random.default_rng(seed)
    targets = {}
    for b in fast.blocks:
        if b.compensable:
            move = np.where(rng.random(5) < 0.5, 0.0, shift)  # some axes keep their value exactly
            targets[b.line_no] = tuple(float(v) for v in np.array(b.after, dtype=float) + move)
    a, b = rewrite_program(fast, targets, header=["h"]), rewrite_program(full, targets, header=["h"])
    assert a.text == b.text
    assert [(c.line_in, c.line_out, c.text_in, c.text_out, c.words) for c in a.changed] == \
        [(c.line_in, c.line_out, c.text_in, c.text_out, c.words) for c in b.changed]
    assert a.skipped == b.skipped and a.header_lines == b.header_lines
    if a.changed:
        at = next(i for i, line in enumerate(a.text.splitlines()) if "h" in line and line.startswith(("(", ";")))
        check = verify(fast, a.text, {c.line_in for c in a.changed}, a.header_lines, at, max_mm=1.0, max_deg=1.0,
                       targets=targets)
        assert check.ok, check.problems


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.floats(-1e5, 1e5, allow_nan=False), st.sampled_from([0.0, -0.0, -1e-9, 5e-5, -5e-5,
                                                                                  0.00005, 2.5, -120.0])),
                min_size=1, max_size=30),
       st.lists(st.sampled_from([1, 3, 4, 5]), min_size=30, max_size=30), st.booleans())
def test_format_numbers_is_format_number(values, decimals, point):
    dec = np.array(decimals[:len(values)])
    assert format_numbers(np.array(values), dec, point=point) == \
        [format_number(v, int(d), point=point) for v, d in zip(values, dec, strict=True)]
    same = np.full(len(values), dec[0])
    assert format_numbers(np.array(values), same, point=point) == \
        [format_number(v, int(dec[0]), point=point) for v in values]


TEXT = ("G90 G71 TRAORI\nN10 G1 X120 Y30 Z80 A20 C30 F100 ; go\nN20 G1 X110 Y31 Z80 A20 C30 F100\n"
        "N30 G1 X100 Z79\nN40 G91 X1\n")
TARGETS = {2: (120.01, 30.0, 80.0, 20.0, 30.0), 3: (110.0, 31.02, 80.0, 20.0, 30.0),
           4: (100.0, 31.0, 79.0, 20.0, 30.01)}


@pytest.mark.parametrize("wrong", [
    ("N10 G1 X120.01", "N10 G1 X120.02"),  # a wrong digit
    ("F100 ; go", "F101 ; go"),  # another word's number
    ("; go", "; gp"),  # a comment
    ("Y31.02 Z80", "Y31.02  Z80"),  # a space
    ("Y30 Z80 A20 C30 F100 ; go", "Y30 Z80 A20 C30 ; go"),  # a dropped F word
    ("N20 G1 X110 Y31.02 Z80", "N20 G1 X110 Y31.02"),  # a dropped axis word (same position as before)
    ("Z79 Y31 C30.01", "Z79 Y31 C30.02"),  # an added word with a wrong value
    ("Z79 Y31 C30.01", "Z79 Y31  C30.01"),  # an added word written otherwise
    ("N40 G91 X1", "N40 G91 X1.0"),  # an unchanged line
    ("F100\nN30", "F100\r\nN30"),  # the line ending of a changed line
])
def test_the_read_back_catches_a_wrong_rewrite(wrong):
    prog = _program(TEXT, "siemens", True)
    assert prog is not None
    rw = rewrite_program(prog, TARGETS)
    changed = {c.line_in for c in rw.changed}
    assert changed == {2, 3, 4}
    good = verify(prog, rw.text, changed, 0, 0, max_mm=0.2, max_deg=0.1, targets=TARGETS)
    assert good.ok, good.problems
    old, new = wrong
    assert old in rw.text
    bad = verify(prog, rw.text.replace(old, new), changed, 0, 0, max_mm=0.2, max_deg=0.1, targets=TARGETS)
    assert not bad.ok
