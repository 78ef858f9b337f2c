"""Every failure observed in issue 13, as a regression test of the NC interpreter and rewriter."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.program import compensate_nc
from pige_sym.errors import CompensationError, NCProgramError
from pige_sym.kernels import load_kernels
from pige_sym.nc.detect import detect_dialect
from pige_sym.nc.program import parse_program

AC = "wC'A'bXYZ(C1)t"
ERRORS = {"EY0A": 12.0, "EZ0A": -9.0, "EB0A": 25.0, "EC0A": -18.0, "EX0C": -14.0, "EY0C": 10.0, "EA0C": 20.0,
          "EB0C": -22.0}


def _params(values: dict[str, float] | None = None) -> CompensationParameters:
    return CompensationParameters(load_kernels(AC).MACHINE_CODE, dict(ERRORS if values is None else values), {},
                                  None, {}, "test", [])


def _comp(text: str, dialect: str, **kw):  # noqa: ANN202
    return compensate_nc(text, _params(), path="p", dialect=dialect, **kw)


def _changed(a: str, b: str) -> dict[int, tuple[str, str]]:
    la, lb = a.splitlines(), [ln for ln in b.splitlines() if "compensated by pige_sym" not in ln]
    assert len(la) == len(lb)
    return {i + 1: (x, y) for i, (x, y) in enumerate(zip(la, lb, strict=True)) if x != y}


def test_comments_strings_and_labels_are_never_words():
    fanuc = "%\nO1000\nG90 G21 G17\nG00 X10. Y20. Z30. A10. C20.\nG01 X50. (MOVE Z50) F500.\nM30\n%\n"
    blocks = parse_program(fanuc, dialect="fanuc").blocks
    assert blocks[4].after[2] == 30.0  # Z from the comment is not a word
    out = _comp(fanuc, "fanuc").text
    line = next(ln for ln in out.splitlines() if "(MOVE Z50)" in ln)
    assert line.endswith("(MOVE Z50) F500.") and "Z50" not in line.replace("(MOVE Z50)", "")
    siemens = 'G90 G71\nN10 G1 X10 Y20 Z30 A10 C20\nN20 MSG("GO Z50 C1")\nN30 G1 X11\n'
    assert parse_program(siemens, dialect="siemens").blocks[2].kind == ""
    assert 'MSG("GO Z50 C1")' in _comp(siemens, "siemens").text
    with pytest.raises(NCProgramError, match="control flow.*GOTOF"):
        parse_program("G90\nGOTOF LABELC1\nLABELC1:\n", dialect="siemens")


def test_space_after_the_letter_and_exponents():
    prog = parse_program("G90 G21\nG1 X  16.339 Y0. Z0. A0. C0.\n", dialect="linuxcnc")
    assert prog.blocks[1].after[0] == pytest.approx(16.339)
    for dialect in ("fanuc", "linuxcnc"):
        with pytest.raises(NCProgramError, match="exponent"):
            parse_program("G90\nG1 X1e400 Y0. Z0. A0. C0.\n", dialect=dialect)
    with pytest.raises(NCProgramError, match="X1E400"):
        parse_program("G90\nG1 X1e400 Y0 Z0 A0 C0\n", dialect="siemens")
    with pytest.raises(NCProgramError):
        parse_program("G90\nG1 X=nan Y0 Z0 A0 C0\n", dialect="siemens")


def test_incremental_blocks_stay_incremental_and_small():
    text = "G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\nN20 G91 G1 X5\nN30 G1 C10\nN40 G90\n"
    out = _comp(text, "siemens").text
    changed = _changed(text, out)
    for n in (3, 4):
        new = changed[n][1]
        assert new.startswith(("N20 G91 G1 X", "N30 G1 C")) and "AC(" not in new
        for word in new.split()[2 if n == 3 else 2:]:
            if word[0] in "XYZAC" and word[0] not in changed[n][0].split()[-1]:
                assert abs(float(word[1:])) < 0.05, new  # added words are increments, not absolute values
    after = [b.after for b in parse_program(out, dialect="siemens").blocks if b.is_motion]
    nominal = [b.after for b in parse_program(text, dialect="siemens").blocks if b.is_motion]
    assert np.abs(np.array(after) - np.array(nominal)).max() < 0.05


@pytest.mark.parametrize("dialect,block,frame", [
    ("siemens", "N20 SUPA G0 Z0", False), ("siemens", "N20 G53 X10", False), ("siemens", "N20 TRANS X10", True),
    ("siemens", "N20 ROT Z30", True), ("siemens", "N20 MIRROR X0", True), ("siemens", "N20 SCALE X2", True),
    ("fanuc", "N20 G28 Z0.", False), ("fanuc", "N20 G91 G28 Z0.\nG90", False), ("fanuc", "N20 G30 X0.", False),
    ("fanuc", "N20 G92 X0.", True),
    ("fanuc", "N20 G10 L2 P1 X10.", True), ("fanuc", "N20 G53 G00 Z0.", False), ("fanuc", "N20 G68 X0. Y0. R30.", True),
    ("linuxcnc", "N20 G92 X0", True), ("linuxcnc", "N20 G28", False),
])
def test_reference_machine_and_frame_blocks_are_never_changed(dialect, block, frame):
    if dialect == "siemens":
        head, first, nxt = "G90 G71\n", "N10 G1 X120 Y30 Z80 A20 C30\n", "N30 G1 X100 Y10 Z70 A25 C40\n"
    else:
        head, first, nxt = "G90 G21\n", "N10 G01 X120. Y30. Z80. A20. C30.\n", "N30 G01 X100. Y10. Z70. A25. C40.\n"
    text = head + first + block + "\n" + nxt
    res = _comp(text, dialect)
    changed = _changed(text, res.text)
    last = len(text.splitlines())
    assert 2 in changed and 3 not in changed
    if frame:  # a frame makes the program coordinates unknown: nothing after it is compensated
        assert last not in changed
    else:  # a full absolute pose after a reference / machine-coordinate move is known again
        assert last in changed


def test_after_an_arc_the_position_is_the_arc_end():
    text = ("G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\nN20 G1 X100 Y0\nN30 G2 X80 Y20 I0 J20\n"
            "N40 G1 Z70\n")
    prog = parse_program(text, dialect="siemens")
    assert prog.blocks[4].after[:3] == (80.0, 20.0, 70.0)
    out = _comp(text, "siemens").text
    changed = _changed(text, out)
    assert 3 not in changed and 4 not in changed  # the arc and the block ending at its start stay
    new = parse_program(out, dialect="siemens").blocks[-1].after
    assert abs(new[0] - 80.0) < 0.05 and abs(new[1] - 20.0) < 0.05  # not the position before the arc


@pytest.mark.parametrize("dialect,on,off,extra", [
    ("siemens", "TRAORI(1)", "TRAFOOF", ()), ("siemens", "TRAORI", "TRAFOOF", ()),
    ("fanuc", "G43.4 H1", "G49", ()), ("fanuc", "G43.5 H1", "G49", ()), ("fanuc", "M128", "M129", ()),
    ("fanuc", "G234 H1", "G49", ()), ("linuxcnc", "M428", "M429", ("M428", "M429")),
])
def test_rtcp_forms_are_recognised(dialect, on, off, extra):
    dot = "." if dialect == "fanuc" else ""
    text = (f"G90 G21\n{on}\nN10 G1 X1{dot} Y2{dot} Z3{dot} A10{dot} C20{dot}\n{off}\n"
            f"N20 G1 X4{dot}\nN30 G1 X4{dot} Y2{dot} Z3{dot} A10{dot} C20{dot}\n")
    if dialect == "siemens":
        text = text.replace("G21", "G71")
    kw = {"rtcp_on": (extra[0],), "rtcp_off": (extra[1],)} if extra else {}
    res = _comp(text, dialect, **kw)
    changes = {c.line_in: c.rtcp for c in res.report.changes}
    assert changes.get(3) is True and changes.get(6) is False
    # switching RTCP changes what X/Y/Z mean: the next block without a full pose is not touched
    assert 5 not in changes and any(p["line"] == 5 for p in res.report.passed_through)
    if extra:  # not declared: an unknown M code is refused, never taken for machine coordinates
        with pytest.raises(NCProgramError, match="--rtcp-on"):
            _comp(text, dialect)


@pytest.mark.parametrize("dialect,inch", [("fanuc", "G20"), ("siemens", "G70"), ("siemens", "G700"),
                                          ("linuxcnc", "G20")])
def test_inch_programs_are_compensated_in_inch(dialect, inch):
    dot = "." if dialect == "fanuc" else ""
    text = f"G90 {inch}\nN10 G1 X4.5 Y1.2 Z3.1 A20{dot} C30{dot}\n"
    res = _comp(text, dialect)
    new = parse_program(res.text, dialect=dialect, rotary_axes=("A", "C")).blocks[-1].after
    old = parse_program(text, dialect=dialect, rotary_axes=("A", "C")).blocks[-1].after
    assert 0 < np.abs(np.array(new[:3]) - old[:3]).max() < 0.05  # mm: a compensation-sized change
    words = _changed(text, res.text)[2][1].split()
    assert all(len(w.split(".")[1]) <= 5 for w in words if w[0] in "XYZ" and "." in w)


def test_safe_retract_before_the_pose_is_known_passes_through():
    text = "G90 G71\nN10 G0 Z200\nN20 G0 X120 Y30 A20 C30\nN30 G1 Z80\n"
    res = _comp(text, "siemens")
    assert {p["line"] for p in res.report.passed_through} >= {2}
    assert 2 not in _changed(text, res.text)


def test_fanuc_output_keeps_its_dialect():
    text = ("%\r\nO1234 (PART)\r\nG90 G21 G17\r\nG43.4 H1\r\nN10 G00 X120. Y30. Z80. A20. C30.\r\n"
            "/N20 X110.\r\nN30 G01 X100. Y20. F500.\r\nN40 X90.\r\nG49\r\nM30\r\n%\r\n")
    out = _comp(text, "fanuc").text
    assert out.startswith("%\r\nO1234 (PART)\r\n(compensated by pige_sym")
    changed = _changed(text, out)
    assert 6 not in changed  # the skippable block is never changed, '/' stays in front
    assert "G43.4 H1" in out and "\r\nG49\r\n" in out
    assert changed[5][1].startswith("N10 G00 X") and changed[8][1].startswith("N40 X")
    assert 7 not in changed  # X is 110 or 120 depending on the skip switch: the pose before is unknown
    for _, new in changed.values():
        for w in new.split():
            if w[0] in "XYZAC":
                assert "." in w, new  # never an integer on a Fanuc
    assert detect_dialect(out) == "fanuc"
    assert len(parse_program(out).blocks) == len(text.splitlines()) + 1  # reads its own output


def test_fanuc_integer_axis_words_are_refused():
    with pytest.raises(NCProgramError, match="decimal point"):
        parse_program("G90 G21\nG43.4 H1\nG01 X120 Y0. Z0. A0. C0.\n", dialect="fanuc")


def test_header_goes_after_bom_and_program_name():
    text = "\ufeff%_N_PART_MPF\n;$PATH=/_N_MPF_DIR\nG90 G71\nN10 G1 X120 Y30 Z80 A20 C30\n"
    out = _comp(text, "siemens").text
    lines = out.splitlines()
    assert lines[0] == "\ufeff%_N_PART_MPF" and lines[1] == ";$PATH=/_N_MPF_DIR"
    assert lines[2].startswith("; compensated by pige_sym")


def test_max_change_guard_refuses():
    text = "G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\n"
    with pytest.raises(CompensationError, match="exceeds --max-change"):
        compensate_nc(text, _params({"EY0A": 900.0}), dialect="siemens")
    with pytest.raises(CompensationError, match=":2:"):
        compensate_nc(text, _params(), dialect="siemens", max_change_mm=0.001)


def test_cli_refuses_clobbering_and_prints_a_json_report(tmp_path, capsys):
    params = tmp_path / "r.json"
    params.write_text(json.dumps({"machine": AC, "pige": ERRORS}))
    prog = tmp_path / "p.mpf"
    prog.write_text("G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\nM30\n")
    assert main(["compensate", str(prog), "--params", str(params), "--out", str(prog)]) == 2
    out = tmp_path / "c.mpf"
    out.write_text("keep")
    assert main(["compensate", str(prog), "--params", str(params), "--out", str(out)]) == 2
    assert out.read_text() == "keep"
    capsys.readouterr()
    assert main(["compensate", str(prog), "--params", str(params), "--out", str(out), "--force", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["compensated"] == 1 and rep["verified"] and rep["changes"][0]["line_in"] == 2
    ch = rep["changes"][0]
    assert ch["tool_point_error_after_um"] < 0.1 * ch["tool_point_error_before_um"]
    assert main(["compensate", str(prog), "--params", str(params), "--out", str(out), "--force",
                 "--max-change", "0.0001"]) == 2
    assert main(["compensate", str(prog), "--params", str(params), "--out", str(out), "--force",
                 "--max-change", "nan"]) == 2


def test_rotary_commands_never_cross_a_multiple_of_360():
    """C0 -> C-0.0002 could make a roll-over axis turn a full revolution: the orientation is left instead."""
    text = "G90 G71\nN10 G1 X120 Y30 Z80 A20 C0\nN20 G1 X110 A25 C360\nN30 G1 C=DC(0)\n"
    res = compensate_nc(text, _params({k: -v for k, v in ERRORS.items()}), dialect="siemens")  # ΔC < 0 here
    before = [b.after for b in parse_program(text, dialect="siemens").blocks if b.is_motion]
    after = [b.after for b in parse_program(res.text, dialect="siemens").blocks if b.is_motion]
    for old, new in zip(before, after, strict=True):
        assert all(np.floor(n / 360) == np.floor(o / 360) for o, n in zip(old[3:], new[3:], strict=True))
    assert res.report.compensated >= 2 and res.report.orientation_limited_lines == [2, 3, 4]


def test_nothing_after_the_program_end_is_compensated():
    text = ("%\nO1\nG90 G21\nG1 X120. Y30. Z80. A20. C30.\nM30\nO2 (SECOND PROGRAM)\n"
            "G1 X120. Y30. Z80. A20. C30.\nM30\n%\n")
    res = _comp(text, "fanuc")
    assert [c.line_in for c in res.report.changes] == [4]
    assert any(p["line"] == 7 and "end of the program" in p["reason"] for p in res.report.passed_through)


def test_modal_state_is_tracked_through_every_block():
    text = ("G90 G71 G17 G94\nG54\nTRAORI\nN10 G1 X1 Y2 Z3 A4 C5\nG91 G18 G93\nN20 X1 F100\nG70\nN30 G90 G0 X1\n"
            "G55 TRAFOOF\n")
    st = [b.state for b in parse_program(text, dialect="siemens").blocks]
    assert (st[3].rtcp, st[3].offset, st[3].plane, st[3].feed, st[3].incremental) == (True, "G54", "G17", "G94", False)
    assert (st[5].plane, st[5].feed, st[5].incremental, st[5].motion) == ("G18", "G93", True, "G1")
    assert (st[7].inch, st[7].motion, st[7].incremental) == (True, "G0", False)
    assert (st[8].offset, st[8].rtcp) == ("G55", False)
    after = [b.after for b in parse_program(text, dialect="siemens").blocks]
    assert after[5][0] == 2.0 and after[7][0] == 25.4  # incremental, then inch


def test_read_back_catches_a_wrong_output():
    from pige_sym.nc.verify import verify

    text = "G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\nN20 G1 X110\nN30 G91 X1\n"
    prog = parse_program(text, dialect="siemens")
    ok = verify(prog, text, set(), 0, 0, max_mm=0.2, max_deg=0.1)
    assert ok.ok and ok.max_change_mm == 0.0
    moved = verify(prog, text.replace("X110", "X110.5"), {3}, 0, 0, max_mm=0.2, max_deg=0.1)
    assert not moved.ok and any("line 3: X moved by 0.5000 mm" in p for p in moved.problems)
    assert any("line 4: X moved" in p for p in moved.problems)  # the incremental block inherits it
    touched = verify(prog, text.replace("N30 G91 X1", "N30 G91 X1 "), set(), 0, 0, max_mm=0.2, max_deg=0.1)
    assert not touched.ok and "line 4: changed although it should be byte-identical" in touched.problems
    mode = verify(prog, text.replace("G90 G71", "G90 G70"), {1}, 0, 0, max_mm=1e9, max_deg=0.1)
    assert not mode.ok and any("modal state" in p for p in mode.problems)
    header = verify(prog, "; h\n" + text, set(), 1, 0, max_mm=0.2, max_deg=0.1)
    assert header.ok


def test_an_arc_whose_start_moved_is_reported():
    text = ("G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\nN20 G1 Z70\nN30 G1 X100 Y0 Z70 A20 C30\nN40 G1 Z60\n"
            "N50 G2 X80 Y20 I0 J20\n")
    res = _comp(text, "siemens")
    # N40 ends where the arc starts and is kept, but it inherits the X/Y offsets of N30
    assert 5 not in {c.line_in for c in res.report.changes}
    assert any("the arc at line 6 starts" in n for n in res.report.notes)


def test_a_program_without_rtcp_code_says_what_it_assumed():
    plain = _comp("G90 G71\nN10 G1 X120 Y30 Z80 A20 C30\n", "siemens").report.notes
    assert any("no RTCP code before line 2" in n for n in plain)
    for text, dialect in (("G90 G71\nTRAFOOF\nN10 G1 X120 Y30 Z80 A20 C30\n", "siemens"),
                          ("G90 G21\nG43.4 H1\nN10 G1 X120. Y30. Z80. A20. C30.\n", "fanuc")):
        assert not any("RTCP" in n for n in _comp(text, dialect).report.notes)


def test_the_ngc_extension_is_a_hint_and_semicolon_comments_do_not_make_it_siemens() -> None:
    text = "; probing set-up\n; sphere on the table\nG21 G90 G17\nG0 X10 Y0 Z50\nG38.2 Z-5 F100\nM2\n"
    assert detect_dialect(text, "probe.ngc") == "linuxcnc"
    assert detect_dialect("G90 G1 X1 F100\nM30\n" + "; c\n", "part.mpf") == "siemens"
