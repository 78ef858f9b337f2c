"""Issue 41: a report a user can act on.

- item 2: the report shows the estimate compensation uses, the model check of the PIGE-only fit, and where the
  two differ (the README's run.csv: the diagnosis moves EB0A by −38.8 µrad, 2.9 combined standard uncertainties);
- item 3: a report made with ``--program`` names the compensated program where it is, not the staging folder;
- item 4: the ballbar report has one badge, the verdict; the agreement of the setups is a plain line;
- item 5 and "every report says what to do next": a "next step" in every verdict state, for an UNDECIDED one
  computed from which PIGEs are undecided and why, with a ``pige plan`` command that runs.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from pige_sym.cli.main import main
from testdata import REPO

AC = "wC'A'bXYZ(C1)t"
TOLERANCES = REPO / "examples" / "tolerances.json"


def _answer(html: str) -> str:
    return html[:html.index('<nav>')]


def _words(html: str) -> str:
    html = re.sub(r"data:image/png;base64,[^\"]+", "", html)
    html = re.sub(r"<style.*?</style>", "", html, flags=re.DOTALL)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html)).replace("&#x27;", "'")


@pytest.fixture(scope="module")
def readme_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The README's first session: run.csv (an angular positioning error of C), its program, the report."""
    folder = tmp_path_factory.mktemp("session")
    assert main(["program", "--machine", AC, "--trajectory", "cone-frustum", "--ball", "120,0,80", "--out",
                 str(folder / "rtest.mpf")]) == 0
    assert main(["simulate", "--machine", AC, "--pige", "random", "--seed", "1", "--effect", "angular_error_C",
                 "--out", str(folder / "run.csv")]) == 0
    assert main(["report", str(folder / "run.csv"), "--out", str(folder / "report"), "--program",
                 str(folder / "rtest.mpf"), "--tolerances", str(TOLERANCES)]) == 0
    return folder, (folder / "report" / "report.html").read_text(encoding="utf-8")


def test_the_compensated_program_is_named_where_it_is(readme_report: tuple[Path, str]) -> None:
    folder, html = readme_report
    assert "pige-partial" not in html  # the staging folder, gone after the report is written
    named = re.findall(r"Compensated NC program written to <code>([^<]+)</code>", html)
    assert named == [str(folder / "report" / "run" / "rtest_compensated.mpf")]
    assert Path(named[0]).is_file() and "compensated by pige_sym" in Path(named[0]).read_text()


def test_the_report_shows_the_estimate_compensation_uses_and_where_it_differs(
        readme_report: tuple[Path, str]) -> None:
    _, html = readme_report
    section = html[html.index('data-section="identification"'):html.index('data-section="diagnosis"')]
    words = _words(section)
    assert ("Used for compensation and for the verdict: the diagnosis' final fit: the PIGEs estimated jointly with "
            "angular_error_C (an angular positioning error of C, 2 per revolution)") in words
    moved = re.search(r"differs from the PIGE-only fit \(pige identify\) by more than their combined uncertainty in "
                      r"EB0A by -38.8 µrad \((\d\.\d)× their combined uncertainty\)", words)
    assert moved and float(moved.group(1)) > 2, words[:800]
    assert 'data-model-check="flagged"' in section and "next step: pige diagnose" in words
    assert "the estimate used for compensation (green: the diagnosis' final fit)" in words  # the figure's caption
    differs = re.search(r'data-differs="pige-only">([^<]*)<', _answer(html))
    assert differs and "EB0A" in differs.group(1) and "EX0C" not in differs.group(1)


@pytest.fixture(scope="module")
def ballbar_report(tmp_path_factory: pytest.TempPathFactory) -> str:
    """docs/ballbar.md's nine setups of one machine (they agree; EY0C is out of tolerance), reported."""
    folder = tmp_path_factory.mktemp("ballbar")
    files = []
    for setup in ("radial", "tangential", "axial"):
        for axis, tilt in (("C", []), ("C", ["--tilt", "-45"]), ("A", [])):
            out = folder / f"{setup}_{axis}{'45' if tilt else ''}.csv"
            assert main(["simulate", "--instrument", "ballbar", "--setup", setup, "--axis", axis, *tilt, "--pige",
                         "random", "--seed", "1", "--out", str(out)]) == 0
            files.append(str(out))
    assert main(["report", *files, "--out", str(folder / "report"), "--tolerances", str(TOLERANCES)]) == 0
    return (folder / "report" / "report.html").read_text(encoding="utf-8")


def test_the_ballbar_report_has_one_badge_the_verdict(ballbar_report: str) -> None:
    answer = _answer(ballbar_report)
    badges = re.findall(r'<span[^>]*class="badge[^"]*"[^>]*>([^<]*)<', answer)
    assert badges == ["FAIL"], badges  # the verdict; before: a green "PASS" for the agreement above it
    assert 'data-verdict="fail"' in answer and "PASS" not in answer
    words = _words(answer)
    assert ("do the files agree? The files agree on one set of PIGEs (F test p = 0.76): they can be identified "
            "together. (a consistency check of the setups, not the verdict)") in words
    section = ballbar_report[ballbar_report.index('data-section="joint"'):]
    assert 'class="badge' not in section[:section.index("</p>")] and 'data-agreement="agree"' in section
    assert "seen jointly nothing beyond the PIGEs: none of the 23 catalogue effects searched" in words
