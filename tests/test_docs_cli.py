"""What the command line says to its reader: help texts, the README's command table, small behaviours.

- every command's ``--help`` is plain text (no reStructuredText roles or literals) and shows examples;
- the one-line descriptions name the instruments a command takes;
- the README's command table lists every command;
- small behaviours a user trips over (a ballbar plan written with ``--out``, …).
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from pige_sym.cli.main import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
RST = re.compile(r"``|:(mod|func|class|data|meth|attr):`")


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Every (sub)command's parser by its full name, e.g. ``history add``."""
    out = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out[name] = sub
                out |= {f"{name} {k}": v for k, v in _subparsers(sub).items()}
    return out


def _one_liners(parser: argparse.ArgumentParser) -> dict[str, str]:
    out = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out |= {a.dest: a.help or "" for a in action._choices_actions}
    return out


COMMANDS = _subparsers(build_parser())


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_is_plain_text_with_examples(name: str) -> None:
    text = COMMANDS[name].format_help()
    assert not RST.search(text), RST.search(text)
    assert re.search(r"examples?:\n  pige ", text), f"pige {name} --help shows no example"


def test_the_top_level_description_and_the_one_liners_name_the_instruments() -> None:
    parser = build_parser()
    assert all(w in parser.description for w in ("R-test", "touch probe", "ballbar"))
    lines = _one_liners(parser)
    for cmd in ("identify", "simulate", "program", "plan", "diagnose", "report", "check", "history"):
        assert all(w in lines[cmd] for w in ("R-test", "probe", "ballbar")), (cmd, lines[cmd])


def test_the_readme_command_table_lists_every_command() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = {m.group(1) for m in re.finditer(r"^\| `pige ([\w-]+)[^`]*` \|", text, re.M)}
    assert set(_one_liners(build_parser())) <= table


def test_import_probe_marks_the_radii_it_requires() -> None:
    text = " ".join(COMMANDS["import-probe"].format_help().split())
    assert "radius R [mm] (required without --program" in text and "radius r [mm] (required without --program" in text
    assert "(required with --instrument sphere-probe)" in " ".join(COMMANDS["program"].format_help().split())


def test_a_vector_option_takes_a_negative_first_component(tmp_path) -> None:
    args = build_parser().parse_args(["import-probe", "log.txt", "--format", "linuxcnc", "--pivot", "-12,3,4",
                                      "--sphere-radius", "12.7", "--stylus-radius", "1.5", "--out", "x.csv"])
    assert args.pivot == ["-12,3,4"]
    args = build_parser().parse_args(["simulate", "--ball", "-1.5e1,0,80", "--out", "x.csv"])
    assert args.ball == "-1.5e1,0,80"


def test_a_ballbar_plan_with_out_writes_it_and_says_so(tmp_path, capsys) -> None:
    out = tmp_path / "setups.json"
    assert main(["plan", "--instrument", "ballbar", "--noise", "0.2", "--target", "2.5", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    plan = json.loads(out.read_text(encoding="utf-8"))
    assert f"wrote {out}" in printed and len(plan["chosen"]) == len(plan["programs"]) == 4
    assert "--tilt -45" in "".join(plan["programs"]) and "pige program --instrument ballbar" in printed
    assert main(["plan", "--instrument", "ballbar", "--target", "2.5", "--out", str(out)]) == 2  # never clobbered


def _simulate(tmp_path: Path, *args: str) -> Path:
    out = tmp_path / args[-1]
    assert main(["simulate", *args[:-1], "--out", str(out)]) == 0
    return out


def test_progress_bars_stay_off_a_redirected_stderr(tmp_path) -> None:
    import subprocess
    import sys

    run = _simulate(tmp_path, "--seed", "1", "--effect", "angular_error_C", "run.csv")
    done = subprocess.run([sys.executable, "-m", "pige_sym", "diagnose", str(run)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0 and "angular_error_C" in done.stdout
    assert "\r" not in done.stderr and "fit/s" not in done.stderr and done.stderr.strip() == ""


def test_history_show_of_a_missing_database_creates_nothing(tmp_path, capsys) -> None:
    db = tmp_path / "none.db"
    assert main(["history", "show", "DMU50-2", "--db", str(db)]) == 2
    assert not db.exists() and "no history database at" in capsys.readouterr().err


def test_a_semicolon_ballbar_file_gets_the_separator_message(tmp_path, capsys) -> None:
    good = _simulate(tmp_path, "--instrument", "ballbar", "--seed", "1", "bb.csv")
    lines = good.read_text(encoding="utf-8").splitlines()
    bad = tmp_path / "semi.csv"
    bad.write_text("\n".join(x if x.startswith("#") else x.replace(",", ";") for x in lines) + "\n", encoding="utf-8")
    assert main(["identify", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "separated by ';'" in err and "pige-ballbar separates fields by ','" in err and ":10:" in err


def test_a_simulated_ballbar_file_has_readable_numbers(tmp_path) -> None:
    out = _simulate(tmp_path, "--instrument", "ballbar", "--seed", "1", "bb.csv")
    values = [row.split(",")[-1] for row in out.read_text(encoding="utf-8").splitlines()[10:]]
    assert max(len(v.split(".")[-1]) for v in values) <= 4


def test_one_ballbar_file_points_to_the_planner(tmp_path, capsys) -> None:
    out = _simulate(tmp_path, "--instrument", "ballbar", "--seed", "1", "bb.csv")
    capsys.readouterr()
    assert main(["identify", str(out)]) == 0
    assert "pige plan --instrument ballbar" in capsys.readouterr().out
    two = [_simulate(tmp_path, "--instrument", "ballbar", "--setup", s, "--seed", "1", f"{s}.csv")
           for s in ("tangential", "axial")]
    capsys.readouterr()
    assert main(["identify", str(out), *map(str, two)]) == 0
    assert "determine" in capsys.readouterr().out  # three C setups at A=0 still miss the A axis


def test_a_probe_program_that_misses_the_sphere_says_so(tmp_path, capsys) -> None:
    sphere = ["--sphere-radius", "12.7", "--stylus-radius", "1.5"]
    kins = ["--rtcp-off", "M429", "--rtcp-on", "M428", "--stylus-tool", "99", "--stylus-length", "120"]
    prog = tmp_path / "probe.ngc"
    assert main(["program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", *kins, "--sphere", "100,20,60",
                 *sphere, "--out", str(prog)]) == 0
    assert main(["simulate", "--instrument", "sphere-probe", "--dialect", "linuxcnc", *kins, "--sphere", "300,20,60",
                 *sphere, "--program", str(prog), "--out", str(tmp_path / "log.txt")]) == 2
    err = capsys.readouterr().err
    assert ("never reaches it" in err or "the program states sphere_mm" in err) and "inf mm" not in err
    log = tmp_path / "log2.txt"
    assert main(["simulate", "--instrument", "sphere-probe", "--dialect", "linuxcnc", *kins, "--sphere", "100,20,60",
                 *sphere, "--program", str(prog), "--seed", "1", "--out", str(log)]) == 0
    capsys.readouterr()
    assert main(["import-probe", str(log), "--format", "linuxcnc", *sphere, "--out", str(tmp_path / "p.csv")]) == 0
    assert re.search(r"R_eff \d+\.\d{4} mm \(fitted\)", capsys.readouterr().out)


def test_each_module_registers_its_command_and_a_command_alone_parses_as_in_the_whole_parser() -> None:
    """``main`` builds only the named command's parser (35 ms → 3 ms a call): it must be the same parser, and the
    module ``a_b`` must register command ``a-b`` (registry.module_of's convention)."""
    from pige_sym.cli.registry import command_modules, module_of

    top = _one_liners(build_parser())
    assert sorted(top) == sorted(m.replace("_", "-") for m in command_modules())
    for command in top:
        assert module_of(command) == command.replace("-", "_")
        alone = _subparsers(build_parser(command))
        assert set(_one_liners(build_parser(command))) == {command}
        for name, sub in alone.items():
            assert sub.format_help() == COMMANDS[name].format_help(), name
            assert sub.format_usage() == COMMANDS[name].format_usage(), name
    assert module_of("import_probe") is None and module_of("_setup") is None and module_of("main") is None


def test_a_word_that_names_no_command_gets_the_whole_list(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["import_probe", "log.txt"])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'import_probe'" in err and "'identify'" in err and "'import-probe'" in err
