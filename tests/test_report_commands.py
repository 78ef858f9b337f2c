"""Every follow-up command a report prints runs as printed (issue 50's rule, beyond the maps' report).

The R-test, probe and ballbar reports' next steps in the verdict states that print commands, the history page and
the measured before/after page: each command is taken from the page (``<code class="cmd">``), checked for
placeholders (``PROGRAM``, ``TOL.json``, ``AFTER.csv``, ``<…>``: before, a report without ``--program`` printed
``pige compensate PROGRAM --params diagnosis.json --out PROGRAM_comp``, the ballbar report ``pige diagnose FILES``),
and run in-process in a folder of its own, as a shell would run it (``> file`` writes the output there, ``#`` starts
the shell's comment).  What a report cannot know yet (a later measurement, a tolerance file not given) is said in
words, never as a placeholder in a command or beside one.
"""

from __future__ import annotations

import contextlib
import html
import io
import json
import re
import shlex
from pathlib import Path

import pytest

from pige_sym.cli.main import main
from testdata import REPO, figures_not_drawn, simulated_probe_file

AC = "wC'A'bXYZ(C1)t"
TOLERANCES = REPO / "examples" / "tolerances.json"
PLACEHOLDER = re.compile(r"\b(PROGRAM\w*|FILES?|PARAMS|TOL\.json|AFTER\.csv|NEXT\.csv|MACHINE|STYLE|REPORT)\b"
                         r"|<[a-z][a-z ]*>")


@pytest.fixture(autouse=True)
def _figures_not_drawn(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests read the pages' commands and words, and run the commands: the figures, 60 % of a report's CPU
    (drawn, embedded and checked by test_report.py, test_report_print.py and test_maps.py), are left out of the
    reports made here (the pages' figure slots empty; every command and sentence unchanged)."""
    figures_not_drawn(monkeypatch)


def _commands(page: str) -> list[str]:
    return [html.unescape(c) for c in re.findall(r'<code class="cmd">(.*?)</code>', page, flags=re.S)]


def _words(page: str) -> str:
    page = re.sub(r"data:image/png;base64,[^\"]+", "", page)
    page = re.sub(r"<(style|script).*?</\1>", "", page, flags=re.S)
    return html.unescape(re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", page)))


def _run(command: str, folder: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> str:
    """``command`` run as a shell would in ``folder``: its words (``#`` a comment), ``> file`` the output there."""
    folder.mkdir(parents=True, exist_ok=True)
    monkeypatch.chdir(folder)
    line, redirect, target = command.partition(" > ")
    words = shlex.split(line, comments=True)
    assert words[0] == "pige", command
    capsys.readouterr()
    assert main(words[1:]) == 0, command
    out = capsys.readouterr().out
    if redirect:
        (folder / shlex.split(target, comments=True)[0]).write_text(out, encoding="utf-8")
    return out


def _report(args: list[str], out: Path) -> str:
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["report", *args, "--out", str(out), "--no-figures"]) == 0
    return (out / "report.html").read_text(encoding="utf-8")


def _runs_as_printed(page: str, folder: Path, capsys: pytest.CaptureFixture[str],
                     monkeypatch: pytest.MonkeyPatch) -> list[str]:
    commands = _commands(page)
    for command in commands:
        assert not PLACEHOLDER.search(command), command
        _run(command, folder, capsys, monkeypatch)
    found = PLACEHOLDER.search(_words(page))
    assert found is None, _words(page)[max(0, found.start() - 200): found.end() + 100]
    return commands


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An R-test run with its program (EY0C out of examples/tolerances.json) and a run after a correction."""
    folder = tmp_path_factory.mktemp("session")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["program", "--machine", AC, "--trajectory", "cone-frustum", "--ball", "120,0,80", "--out",
                     str(folder / "rtest.mpf")]) == 0
        assert main(["simulate", "--machine", AC, "--pige", "random", "--seed", "1", "--effect", "angular_error_C",
                     "--out", str(folder / "run.csv")]) == 0
        assert main(["simulate", "--machine", AC, "--pige", "EX0C=0.4,EY0C=-0.3,EB0A=2", "--seed", "2", "--out",
                     str(folder / "after.csv")]) == 0
    return folder


def test_an_rtest_report_without_a_program_prints_commands_that_run(session: Path, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str],
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    page = _report([str(session / "run.csv")], tmp_path / "report")
    commands = _runs_as_printed(page, tmp_path / "run", capsys, monkeypatch)
    assert commands == [f"pige diagnose {session / 'run.csv'} --json > diagnosis.json",
                        "pige compensate --params diagnosis.json --controller table"]
    assert json.loads((tmp_path / "run" / "diagnosis.json").read_text())["machine"]


def test_a_failing_rtest_report_with_its_program_corrects_that_program(session: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    page = _report([str(session / "run.csv"), "--program", str(session / "rtest.mpf"), "--tolerances",
                    str(TOLERANCES)], tmp_path / "report")
    assert 'data-verdict="fail"' in page
    commands = _runs_as_printed(page, tmp_path / "run", capsys, monkeypatch)
    assert commands[1] == (f"pige compensate {session / 'rtest.mpf'} --params diagnosis.json --out "
                           f"{session / 'rtest_comp.mpf'}")
    assert "compensated by pige_sym" in (session / "rtest_comp.mpf").read_text()


def test_the_before_after_and_history_pages_print_commands_that_run(session: Path, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str],
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    page = _report(["--compare", str(session / "run.csv"), str(session / "after.csv")], tmp_path / "compare")
    assert _runs_as_printed(page, tmp_path / "c", capsys, monkeypatch) == [f"pige diagnose {session / 'after.csv'}"]
    db = f"sqlite:///{tmp_path / 'history.db'}"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["history", "add", str(session / "run.csv"), "--machine-id", "M-5", "--tolerances",
                     str(TOLERANCES), "--db", db]) == 0
    page = _report(["--history", "M-5", "--db", db], tmp_path / "history")
    commands = _runs_as_printed(page, tmp_path / "h", capsys, monkeypatch)
    assert commands[0].startswith("pige diagnose ") and "--machine-id M-5" in _words(page)
    moved = tmp_path / "moved.csv"  # a run out of tolerance whose file is gone: no command names it
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "--machine", AC, "--pige", "EX0C=3,EY0C=30", "--seed", "3", "--out", str(moved)]) == 0
        assert main(["history", "add", str(moved), "--machine-id", "M-6", "--tolerances", str(TOLERANCES), "--db",
                     db]) == 0
    moved.unlink()
    page = _report(["--history", "M-6", "--db", db], tmp_path / "history6")
    assert _runs_as_printed(page, tmp_path / "h6", capsys, monkeypatch) == []
    assert f"added as {moved}, is not there any more" in _words(page)


def test_a_probe_report_prints_commands_that_run(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        probe = simulated_probe_file(tmp_path, 5, "angular_error_C:harmonic=2,cos_urad=0,sin_urad=0")
    page = _report([str(probe)], tmp_path / "report")
    commands = _runs_as_printed(page, tmp_path / "run", capsys, monkeypatch)
    assert commands[0] == f"pige diagnose {probe} --json > diagnosis.json"


def test_a_ballbar_report_prints_commands_that_run(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/ballbar.md's nine setups (EY0C out of tolerance): before, the joint section's advice was words with
    placeholders (``pige compensate PROGRAM --params joint.json (with pige diagnose FILES --json > joint.json)``)."""
    files = []
    with contextlib.redirect_stdout(io.StringIO()):
        for setup in ("radial", "tangential", "axial"):
            for axis, tilt in (("C", []), ("C", ["--tilt", "-45"]), ("A", [])):
                out = tmp_path / f"{setup}_{axis}{'45' if tilt else ''}.csv"
                assert main(["simulate", "--instrument", "ballbar", "--setup", setup, "--axis", axis, *tilt,
                             "--pige", "random", "--seed", "1", "--out", str(out)]) == 0
                files.append(str(out))
    page = _report([*files, "--tolerances", str(TOLERANCES)], tmp_path / "report")
    commands = _runs_as_printed(page, tmp_path / "run", capsys, monkeypatch)
    assert commands == [f"pige diagnose {' '.join(files)} --json > diagnosis.json",
                        "pige compensate --params diagnosis.json --controller table"]
    assert set(json.loads((tmp_path / "run" / "diagnosis.json").read_text())["pige"]) >= {"EY0C", "EX0C"}
