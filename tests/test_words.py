"""Issue 41 item 7: the words a user reads say one thing, in the instrument's terms, and nothing they cannot mean.

Each test runs what a user runs (the README's run.csv, the ballbar setups of docs/ballbar.md, the probe demo on a
head, a history with tolerances, ``pige --help``) and reads what it prints or writes.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from pige_sym.cli.main import build_parser, main
from testdata import REPO, figures_not_drawn

AC = "wC'A'bXYZ(C1)t"
TOLERANCES = REPO / "examples" / "tolerances.json"


def _page_text(html: str) -> str:
    """The visible words of a report page (no images, no markup)."""
    html = re.sub(r"data:image/png;base64,[^\"]+", "", html)
    html = re.sub(r"<style.*?</style>", "", html, flags=re.DOTALL)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html))


@pytest.fixture(scope="module")
def readme_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The README's run.csv: an AC table with random PIGEs and an angular positioning error of C."""
    folder = tmp_path_factory.mktemp("readme")
    assert main(["simulate", "--machine", AC, "--pige", "random", "--seed", "1", "--effect", "angular_error_C",
                 "--out", str(folder / "run.csv")]) == 0
    return folder / "run.csv"


def test_diagnose_and_the_report_name_a_finding_in_the_same_words(readme_run: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str],
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The finding's words in diagnose's output and on the page (made without its figures: test_report_print
    draws the figures of the same kind of run, an R-test file with an angular error of C)."""
    import pige_sym.report.html as html_page
    from pige_sym.report import gather_report, write_report

    monkeypatch.setattr(html_page, "draw_figures", lambda rep, folder: [])

    capsys.readouterr()
    assert main(["diagnose", str(readme_run)]) == 0
    printed = capsys.readouterr().out
    name = "angular_error_C (an angular positioning error of C, 2 per revolution)"
    assert f"- {name}: " in printed and "harmonic=2:" not in printed
    data = gather_report([readme_run])
    page = _page_text(write_report(data, tmp_path / "out").read_text(encoding="utf-8"))
    lead = page[:page.index("Overview")]
    assert f"the machine shows {name}" in lead and "per rev)" not in page


def test_rejected_candidates_say_what_their_numbers_mean(readme_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["diagnose", str(readme_run)]) == 0
    rejected = capsys.readouterr().out.split("rejected candidates:")[1].split("final estimates")[0]
    lines = [x.strip() for x in rejected.splitlines() if "not supported" in x]
    assert lines
    for line in lines:  # each test's value with the threshold it is judged against, once
        assert re.search(r"the BIC (rises by|falls by only) [\d.]+ with it \(ΔBIC -?[\d.]+, accepted at -10 or "
                         r"less\), the F test gives p = \S+ \(accepted at 0.0001 or less\), the held-out RMS "
                         r"(shrinks|grows) by [\d.]+% \(accepted when it shrinks by 2% or more\)", line), line
        assert line.count("ΔBIC") == 1 and "—" not in line and "by -" not in line


def test_diagnose_of_ballbar_setups_groups_the_files_and_states_the_joint_search(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # the files named as docs/ballbar.md names them
    files = []
    for setup in ("radial", "tangential", "axial"):
        for axis, tilt in (("C", []), ("C", ["--tilt", "-45"]), ("A", [])):
            out = f"{setup}_{axis}{'45' if tilt else ''}.csv"
            assert main(["simulate", "--instrument", "ballbar", "--setup", setup, "--axis", axis, *tilt, "--pige",
                         "random", "--seed", "1", "--out", out]) == 0
            files.append(out)
    capsys.readouterr()
    assert main(["diagnose", *files]) == 0
    printed = capsys.readouterr().out
    assert printed.count("agreement only") == 1  # one line for the nine, not nine identical ones
    assert "- 9 files (radial_C.csv, radial_C45.csv, radial_A.csv, tangential_C.csv" in printed
    joint = re.search(r"Searched jointly over the 9 setups: none of the (\d+) catalogue effects .* improves the joint "
                      r"fit enough to be accepted: the PIGEs alone explain the setups \(joint residual RMS [\d.]+ um\)",
                      printed)
    assert joint and int(joint.group(1)) > 10, printed
    capsys.readouterr()
    assert main(["diagnose", *files, "--json"]) == 0
    assert '"joint_effects": "Searched jointly over the 9 setups' in capsys.readouterr().out


def test_a_head_probe_report_and_the_probe_demo_use_the_probe_words(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "head-demo"
    assert main(["demo", "--instrument", "sphere-probe", "--machine", "wC'bXYZB(C1)t", "--out", str(out),
                 "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "the tolerances given" not in printed  # none were given: it names the file it judged against
    assert f"tolerances {out / 'tolerances.json'}, guard band" in printed
    page = _page_text((out / "report" / "report.html").read_text(encoding="utf-8"))
    assert not re.search(r"\bball\b", page), re.findall(r".{60}\bball\b.{60}", page)
    assert "tool (stylus tip centre from the last tool-side pivot) 0, 0, -150 mm" in page
    assert "155 contacts (5 per pose)" in page and "5–5" not in page


def test_a_probe_program_counts_its_contacts_per_pose_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", AC, "--sphere",
                 "100,20,60", "--sphere-radius", "12.7", "--stylus-radius", "1.5", "--stylus-tool", "99",
                 "--stylus-length", "120", "--rtcp-off", "M429", "--rtcp-on", "M428",
                 "--out", str(tmp_path / "p.ngc")]) == 0
    printed = capsys.readouterr().out
    assert "155 contacts (5 per pose)" in printed and "5-5" not in printed


def test_a_history_report_with_tolerances_judges_the_last_run(readme_run: Path, tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    figures_not_drawn(monkeypatch)  # words only: the trend figure is drawn and checked in test_report.py
    db = f"sqlite:///{tmp_path / 'history.db'}"
    assert main(["simulate", "--machine", AC, "--pige", "EX0C=0.4,EY0C=-0.3,EB0A=2", "--seed", "2", "--out",
                 str(tmp_path / "after.csv")]) == 0
    for date, path in (("2026-01-05", readme_run), ("2026-02-05", tmp_path / "after.csv")):
        assert main(["history", "add", str(path), "--machine-id", "M-41", "--date", date, "--db", db]) == 0
    assert main(["report", "--history", "M-41", "--db", db, "--tolerances", str(TOLERANCES), "--out",
                 str(tmp_path / "h")]) == 0
    html = (tmp_path / "h" / "report.html").read_text(encoding="utf-8")
    answer = html[:html.index('data-section="history"')]
    assert 'data-verdict="pass"' in answer and "not judged" not in answer  # after.csv is well inside the limits
    assert f"run 2 against {TOLERANCES}: all 8 items pass" in _page_text(answer)


def test_pige_help_shows_examples_that_parse() -> None:
    parser = build_parser()
    text = parser.format_help()
    assert "\nexamples" in text
    lines = [x.strip() for x in text.split("\nexamples")[1].splitlines() if x.strip().startswith("pige ")]
    assert len(lines) >= 6
    for line in lines:
        words = shlex.split(line.split(" # ")[0].split(" > ")[0])[1:]
        args = parser.parse_args(words)  # every example is a valid command line
        assert args.command == words[0]
