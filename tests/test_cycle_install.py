"""``pige cycle install`` without LinuxCNC: the diff without --force, the files with it (backups), twice equals once,
the refusals (exit 2, nothing written), pige's component, and the INI reader's round trip (hypothesis)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from cycle_configs import install_args, tree, write_pige_component, write_stock
from hypothesis import given, settings
from hypothesis import strategies as st

from pige_sym.cli.main import main
from pige_sym.cycle.ini import apply_edits, parse_ini
from pige_sym.errors import InputError


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("kind", ["xyzac", "xyzbc"])
def test_without_force_the_diff_is_printed_and_nothing_written(tmp_path, capsys, kind):
    ini = write_stock(tmp_path, kind)
    before = tree(tmp_path)
    code, out, _ = run(install_args(ini), capsys)
    assert code == 0 and tree(tmp_path) == before
    assert "+REMAP = M451 modalgroup=10 argspec=pq prolog=pige_m451_prolog ngc=pige_m451" in out
    assert "+HALCMD = source ./pige_cycle/values.hal" in out
    assert f"-HALCMD = sets :{'y' if kind == 'xyzac' else 'x'}-offset" in out
    assert "nothing written" in out


def test_with_force_every_file_is_written_and_the_changed_ones_backed_up(tmp_path, capsys):
    ini = write_stock(tmp_path)
    old = ini.read_text()
    code, out, _ = run(install_args(ini, "--force"), capsys)
    assert code == 0
    backups = list(tmp_path.glob("xyzac-trt.ini.pige-backup-*"))
    assert len(backups) == 1 and backups[0].read_text() == old
    new = ini.read_text()
    assert "SUBROUTINE_PATH = ./remap_subs:./pige_cycle/ngc:./pige_cycle/run" in new
    assert "ON_ABORT_COMMAND = O <pige_cycle_abort> call" in new and "[PYTHON]" in new
    assert re.search(r"^# pige cycle install: moved to ./pige_cycle/values.hal: HALCMD = sets :y-offset\s+20$", new,
                     re.M)
    # the lines the INI kept are byte for byte the old ones
    kept = [ln for ln in old.splitlines() if ln in new.splitlines()]
    assert len(kept) == len(old.splitlines()) - 6  # five lines moved, SUBROUTINE_PATH extended
    values = (tmp_path / "pige_cycle" / "values.hal").read_text()
    assert "sets :y-offset 20    # A line y - C line y" in values and "setp xyzac-trt-kins.z-rot-point 0" in values
    settings_text = (tmp_path / "pige_cycle" / "settings.json").read_text()
    assert '"identity_code": "M429"' in settings_text and '"tcp_code": "M428"' in settings_text
    for name in ("ngc/pige_m451.ngc", "ngc/pige_m452.ngc", "ngc/pige_restore.ngc", "python/pige_cycle_remap.py"):
        assert (tmp_path / "pige_cycle" / name).is_file()


def test_a_second_install_gives_the_same_files_as_one(tmp_path, capsys):
    ini = write_stock(tmp_path, "xyzbc")
    args = install_args(ini, "--stylus-tool", "2", "--stylus-length", "10", "--force")
    assert run(args, capsys)[0] == 0
    once = {k: v for k, v in tree(tmp_path).items() if ".pige-backup-" not in k}
    code, out, _ = run(args, capsys)
    assert code == 0 and "nothing to change" in out
    assert {k: v for k, v in tree(tmp_path).items() if ".pige-backup-" not in k} == once
    assert run(args[:-1], capsys)[1].startswith(f"{ini}: the cycle is installed")


def test_the_values_entered_are_kept_by_a_new_install(tmp_path, capsys):
    ini = write_stock(tmp_path)
    assert run(install_args(ini, "--force"), capsys)[0] == 0
    values = tmp_path / "pige_cycle" / "values.hal"
    values.write_text(values.read_text().replace("sets :y-offset 20 ", "sets :y-offset 20.0123 "))
    code, out, _ = run(install_args(ini, "--probe-feed", "40", "--force"), capsys)
    assert code == 0 and "20.0123" in values.read_text()
    assert "wrote" in out and "values.hal" not in out


@pytest.mark.parametrize("case", ["not an ini", "no rs274ngc", "unknown kinematics", "own python", "m451 taken",
                                  "binary", "another ini"])
def test_what_it_cannot_read_is_refused_with_exit_2_and_nothing_written(tmp_path, capsys, case):
    ini = write_stock(tmp_path)
    text = ini.read_text()
    if case == "not an ini":
        ini.write_text("G0 X10\nM2\n")
    elif case == "binary":
        ini.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    elif case == "no rs274ngc":
        ini.write_text(text.replace("[RS274NGC]", "[RS274]"))
    elif case == "unknown kinematics":
        ini.write_text(text.replace("xyzac-trt-kins sparm=identityfirst", "trivkins"))
    elif case == "own python":
        ini.write_text(text + "\n[PYTHON]\nTOPLEVEL = python/toplevel.py\n")
    elif case == "m451 taken":
        ini.write_text(text.replace("ngc=429remap", "ngc=429remap\nREMAP = M451 modalgroup=10 ngc=mine"))
    elif case == "another ini":
        assert run(install_args(write_stock(tmp_path, "xyzbc"), "--force"), capsys)[0] == 0
    before = tree(tmp_path)
    code, out, err = run(install_args(ini, "--force"), capsys)
    assert code == 2 and out == "" and tree(tmp_path) == before
    assert err.startswith("pige cycle: ") and len(err.strip().splitlines()) == 1
    what = {"not an ini": "not a LinuxCNC INI line", "binary": "UTF-8", "no rs274ngc": "no [RS274NGC]",
            "unknown kinematics": "trivkins", "own python": "[PYTHON]", "m451 taken": "M451 is remapped already",
            "another ini": "belongs to xyzbc-trt.ini"}[case]
    assert what in err


def test_pige_s_component_gets_its_8_pige_pins_in_the_values_file(tmp_path, capsys):
    ini = write_pige_component(tmp_path)
    code, out, err = run(install_args(ini, "--force"), capsys)
    assert code == 0, err
    values = (tmp_path / "pige_cycle" / "values.hal").read_text()
    pins = re.findall(r"^setp pige_xyzac_trt\.(\w+) (\S+)", values, re.M)
    assert pins == [("ey0a", "1.5"), ("ez0a", "-2"), ("eb0a", "0"), ("ec0a", "0"), ("ex0c", "3.25"), ("ey0c", "0"),
                    ("ea0c", "0"), ("eb0c", "0")]
    hal = (tmp_path / "kins.hal").read_text()
    assert "# pige cycle install: moved to ./pige_cycle/values.hal: setp pige_xyzac_trt.ex0c 3.25" in hal
    assert "setp pige_xyzac_trt.pivot-a-y 20" in hal.splitlines()  # the pivots stay: the cycle never changes them
    assert '"kinematics": "pige"' in (tmp_path / "pige_cycle" / "settings.json").read_text()


def test_desk_compensate_reads_the_installed_values(tmp_path, capsys):
    """``pige compensate --current INI`` follows the INI's ``source`` into values.hal."""
    from pige_sym.compensation.controllers.hal_config import read_current

    ini = write_stock(tmp_path)
    assert run(install_args(ini, "--force"), capsys)[0] == 0
    cfg = read_current(str(ini))
    assert cfg.signals[":y-offset"] == 20 and cfg.pins["x-rot-point"] == 0
    assert cfg.pin_where["x-rot-point"].endswith("values.hal:3")


def test_the_command_line_refuses_a_bad_option_value(tmp_path):
    ini = write_stock(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "pige_sym", *install_args(ini, "--probe-feed", "-1")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--probe-feed" in proc.stderr


_LINE = st.one_of(
    st.just(""), st.just("# comment"), st.just("; other"), st.just("[SECTION]"), st.just("  [RS274NGC]  "),
    st.from_regex(r"[A-Z_]{1,8} ?= ?[ -~]{0,20}", fullmatch=True),
    st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=0x2FF, exclude_characters="\r\n\x85"),
            max_size=30))


@settings(max_examples=200, deadline=None)
@given(st.lists(_LINE, max_size=12), st.sampled_from(["\n", "\r\n"]))
def test_the_ini_reader_refuses_or_reads_and_keeps_every_byte(lines, nl):
    text = nl.join(lines) + nl
    try:
        doc = parse_ini(text, "t.ini")
    except InputError as exc:
        assert "t.ini" in str(exc)
        return
    assert apply_edits(doc, []) == text
    for e in doc.entries:
        assert e.section in doc.sections and "=" in doc.lines[e.line - 1]


def test_an_edit_replaces_inserts_and_comments_whole_lines_only():
    from pige_sym.cycle.ini import IniEdit

    doc = parse_ini("[A]\r\nX = 1\r\nY = 2\r\n", "t.ini")
    text = apply_edits(doc, [IniEdit(2, "comment", "moved", ""), IniEdit(3, "insert_after", "Z = 3\nW = 4", ""),
                             IniEdit(1, "replace", "[B]", "")])
    assert text == "[B]\r\n# moved: X = 1\r\nY = 2\r\nZ = 3\r\nW = 4\r\n"


def test_a_config_path_linuxcnc_cannot_take_in_a_comment_is_refused(tmp_path):
    from pige_sym.cycle.assets import probe_procedure

    with pytest.raises(InputError, match="must not hold"):
        probe_procedure("(PROBEOPEN pige_probe.txt)\nM2\n", Path("/a (b)/log.txt"), [])
    assert probe_procedure("G0 X1\n(PROBEOPEN pige_probe.txt)\nG38.2 Z0 F50\n(PROBECLOSE)\nM2\n",
                           tmp_path / "log.txt", ["M428"]).splitlines() == [
        "o<pige_cycle_probe> sub", "M428", "G0 X1", f"(PROBEOPEN {tmp_path / 'log.txt'})", "G38.2 Z0 F50",
        "(PROBECLOSE)", "o<pige_cycle_probe> endsub", "M2"]


# -- the shipped configurations themselves (LinuxCNC 2.9's files, copied into tmp) ------------------------------------

#: where Debian's linuxcnc-uspace puts the shipped trt simulations (both INIs share the folder)
SHIPPED = Path("/usr/share/doc/linuxcnc/examples/sample-configs/sim/axis/vismach/5axis/table-rotary-tilting")
#: the stylus of each machine: a tool of the shipped tool table (T9 Z30 on xyzac; xyzbc's table has T2 Z10 only)
SHIPPED_STYLUS = {"xyzac": ("9", "30"), "xyzbc": ("2", "10")}


def shipped_copy(tmp_path: Path, kind: str) -> Path:
    """The shipped folder copied into ``tmp_path`` as it is (skipped without LinuxCNC's files); the INI of ``kind``."""
    import shutil

    if not (SHIPPED / f"{kind}-trt.ini").is_file():
        pytest.skip(f"LinuxCNC's shipped {kind}-trt configuration is not installed (apt: linuxcnc-uspace)")
    folder = tmp_path / "table-rotary-tilting"
    shutil.copytree(SHIPPED, folder)
    return folder / f"{kind}-trt.ini"


def shipped_args(ini: Path, kind: str, *extra: str) -> list[str]:
    tool, length = SHIPPED_STYLUS[kind]
    return ["cycle", "install", str(ini), "--sphere", "20,10,15", "--sphere-radius", "6.35", "--stylus-radius", "1.5",
            "--stylus-tool", tool, "--stylus-length", length, *extra]


@pytest.mark.parametrize("kind", ["xyzac", "xyzbc"])
def test_on_the_shipped_configuration_without_force_the_diff_is_shown_and_no_file_changes(tmp_path, capsys, kind):
    ini = shipped_copy(tmp_path, kind)
    before = tree(tmp_path)
    code, out, err = run(shipped_args(ini, kind), capsys)
    assert code == 0, err
    assert tree(tmp_path) == before  # byte for byte, no file added
    off = "y" if kind == "xyzac" else "x"
    assert "+REMAP = M451 modalgroup=10 argspec=pq prolog=pige_m451_prolog ngc=pige_m451" in out
    assert f"-HALCMD = sets :{off}-offset" in out and "+HALCMD = source ./pige_cycle/values.hal" in out
    assert "nothing written" in out


@pytest.mark.parametrize("kind", ["xyzac", "xyzbc"])
def test_on_the_shipped_configuration_force_backs_up_keeps_its_remaps_and_twice_equals_once(tmp_path, capsys, kind):
    ini = shipped_copy(tmp_path, kind)
    folder = ini.parent
    before = tree(tmp_path)
    code, out, err = run(shipped_args(ini, kind, "--force"), capsys)
    assert code == 0, err
    after = tree(tmp_path)
    changed = sorted(k for k in before if after[k] != before[k])
    assert changed == [f"table-rotary-tilting/{kind}-trt.ini"]  # the other INI, the HAL files, remap_subs: as shipped
    backups = sorted(folder.glob(f"{kind}-trt.ini.pige-backup-*"))
    assert len(backups) == 1 and backups[0].read_bytes() == before[changed[0]]
    old, new = before[changed[0]].decode().splitlines(), ini.read_text().splitlines()
    for line in old:  # every line kept as it was, or commented out as moved (the values' lines), or extended
        assert line in new or f"# pige cycle install: moved to ./pige_cycle/values.hal: {line.strip()}" in new \
            or line.startswith("SUBROUTINE_PATH"), line
    for code_ in ("M428", "M429", "M430"):
        assert any(ln.split() == ["REMAP", "=", code_, "modalgroup=10", f"ngc={code_[1:]}remap"] for ln in new)
    assert "SUBROUTINE_PATH = ./remap_subs:./pige_cycle/ngc:./pige_cycle/run" in new
    settings_text = (folder / "pige_cycle" / "settings.json").read_text()
    assert '"identity_code": "M429"' in settings_text and '"tcp_code": "M428"' in settings_text
    once = {k: v for k, v in after.items() if ".pige-backup-" not in k}
    code, out, err = run(shipped_args(ini, kind, "--force"), capsys)
    assert code == 0 and "nothing to change" in out, (out, err)
    again = tree(tmp_path)
    assert {k: v for k, v in again.items() if ".pige-backup-" not in k} == once
    assert sorted(k for k in again if ".pige-backup-" in k) == sorted(k for k in after if ".pige-backup-" in k)
    assert run(shipped_args(ini, kind), capsys)[1].startswith(f"{ini}: the cycle is installed")
