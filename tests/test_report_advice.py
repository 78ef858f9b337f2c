"""Issue 41: a report a user can act on.

- item 2: the report shows the estimate compensation uses, the model check of the PIGE-only fit, and where the
  two differ (the README's run.csv: the diagnosis moves EB0A by −38.8 µrad, 2.9 combined standard uncertainties);
- item 3: a report made with ``--program`` names the compensated program where it is, not the staging folder;
- item 4: the ballbar report has one badge, the verdict; the agreement of the setups is a plain line;
- item 5 and "every report says what to do next": a "next step" in every verdict state, for an UNDECIDED one
  computed from which PIGEs are undecided and why, with a ``pige plan`` command that runs.
"""

from __future__ import annotations

import json
import re
import shlex
from html import unescape as html_unescape
from pathlib import Path

import pytest

from pige_sym.cli.main import main
from testdata import REPO, figures_not_drawn

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
def ballbar_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[str], str]:
    """docs/ballbar.md's nine setups of one machine (they agree; EY0C is out of tolerance), reported."""
    folder = tmp_path_factory.mktemp("ballbar")
    files = []
    for setup in ("radial", "tangential", "axial"):
        for axis, tilt in (("C", []), ("C", ["--tilt", "-45"]), ("A", [])):
            out = folder / f"{setup}_{axis}{'45' if tilt else ''}.csv"
            assert main(["simulate", "--instrument", "ballbar", "--setup", setup, "--axis", axis, *tilt, "--pige",
                         "random", "--seed", "1", "--out", str(out)]) == 0
            files.append(str(out))
    with pytest.MonkeyPatch.context() as words_only:  # the joint figure is drawn and checked in test_report_joint.py
        figures_not_drawn(words_only)
        assert main(["report", *files, "--out", str(folder / "report"), "--tolerances", str(TOLERANCES)]) == 0
    return files, (folder / "report" / "report.html").read_text(encoding="utf-8")


def test_the_ballbar_report_has_one_badge_the_verdict(ballbar_report: tuple[list[str], str]) -> None:
    _, html = ballbar_report
    answer = _answer(html)
    badges = re.findall(r'<span[^>]*class="badge[^"]*"[^>]*>([^<]*)<', answer)
    assert badges == ["FAIL"], badges  # the verdict; before: a green "PASS" for the agreement above it
    assert 'data-verdict="fail"' in answer and "PASS" not in answer
    words = _words(answer)
    assert ("do the files agree? The files agree on one set of PIGEs (F test p = 0.76): they can be identified "
            "together. (a consistency check of the setups, not the verdict)") in words
    section = html[html.index('data-section="joint"'):]
    assert 'class="badge' not in section[:section.index("</p>")] and 'data-agreement="agree"' in section
    assert "seen jointly nothing beyond the PIGEs: none of the 23 catalogue effects searched" in words


def _next_step(html: str) -> tuple[str, list[str], list[str]]:
    """The first screen's next step: its sentence, reasons and commands."""
    cell = re.search(r'<span data-next-step="1">(.*?)</span>(.*?)</td>', _answer(html), re.DOTALL)
    assert cell, _answer(html)[-2000:]
    reasons = [html_unescape(r) for r in re.findall(r"<li>(.*?)</li>", cell.group(2))]
    commands = [html_unescape(c) for c in re.findall(r'<code class="cmd">(.*?)</code>', cell.group(2))]
    return html_unescape(cell.group(1)), reasons, commands


def _undecided_tolerances(path: Path, estimate: dict[str, float], std: dict[str, float], names: list[str]) -> Path:
    """Limits that leave ``names`` undecided (|v| + 1 u: inside the ±2u guard band), the rest loose."""
    limits = {n: abs(estimate[n]) + std[n] for n in names}
    path.write_text(json.dumps({"format": "pige-tolerances 1", "defaults": {"um": 100, "urad": 200},
                                "limits": limits}))
    return path


def _planned_std(command: str, folder: Path, capsys: pytest.CaptureFixture[str],
                 monkeypatch: pytest.MonkeyPatch) -> dict[str, float]:
    """Run a suggested ``pige plan`` command (in ``folder``) with --json; its predicted std per PIGE."""
    monkeypatch.chdir(folder)
    words = shlex.split(command.split("   #")[0])
    assert words[:2] == ["pige", "plan"], command
    capsys.readouterr()
    assert main([*words[1:], "--json", *(["--force"] if "--out" in words else [])]) == 0
    return json.loads(capsys.readouterr().out)["std"]


def test_every_verdict_state_says_what_to_do_next(readme_report: tuple[Path, str], tmp_path: Path) -> None:
    from pige_sym.report import gather_report, render_html

    folder, html = readme_report
    what, _, commands = _next_step(html)  # FAIL: correct with the estimate used, measure again, compare
    assert what.startswith("Out of tolerance (EY0C): correct the machine with the estimate this report used")
    assert commands == [f"pige diagnose {folder / 'run.csv'} --json > diagnosis.json",
                        f"pige compensate {folder / 'rtest.mpf'} --params diagnosis.json --out "
                        f"{folder / 'rtest_comp.mpf'}"]  # the measurement after it is named in words
    assert "then measure the same test again and compare the two files (pige compare, this file first)" in what
    what, _, commands = _next_step(render_html(gather_report([folder / "run.csv"])))  # not judged
    assert what.startswith("Judge the estimate against your tolerances (pige check this file with --tolerances")
    assert commands == [f"pige diagnose {folder / 'run.csv'} --json > diagnosis.json",
                        "pige compensate --params diagnosis.json --controller table"]
    assert main(["simulate", "--machine", AC, "--pige", "EX0C=0.4,EY0C=-0.3,EB0A=2", "--seed", "2", "--out",
                 str(tmp_path / "after.csv")]) == 0
    what, _, commands = _next_step(render_html(gather_report([tmp_path / "after.csv"], tolerances=TOLERANCES)))
    assert what.startswith("In tolerance: nothing to correct") and "(pige history add this file" in what
    assert commands == []  # the machine's name in a history is the user's: said in words
    compare = render_html(gather_report([], compare=(folder / "run.csv", tmp_path / "after.csv")))
    what, _, commands = _next_step(compare)
    assert "removed 97% of the RMS deviation" in what and commands == [f"pige diagnose {tmp_path / 'after.csv'}"]


def test_an_undecided_rtest_verdict_names_the_test_that_decides_it(readme_report: tuple[Path, str], tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str],
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from pige_sym.report import gather_report, render_html

    folder, _ = readme_report
    diag = gather_report([folder / "run.csv"]).measurements[0].primary
    est = dict(zip(diag.parameters, diag.values.tolist(), strict=True))
    std = dict(zip(diag.parameters, diag.std.tolist(), strict=True))
    tol = _undecided_tolerances(tmp_path / "tol.json", est, std, ["EB0A", "EZ0A"])
    what, reasons, commands = _next_step(render_html(gather_report([folder / "run.csv"], tolerances=tol)))
    assert what.startswith("Undecided: EZ0A, EB0A cannot be called in or out of tolerance") and len(reasons) == 2
    need = {}
    for name, reason in zip(["EZ0A", "EB0A"], reasons, strict=True):
        found = re.search(rf"^{name} = .* deciding needs u ≤ ([\d.]+) \S+ \(([\d.]+)× smaller\): (\d+) poses of this "
                          r"test instead of 30", reason)
        assert found, reason
        need[name] = float(found.group(1))
        assert need[name] == pytest.approx(std[name] / 2, rel=0.05)  # (|v| + u − |v|) / k, k = 2
        assert int(found.group(3)) == pytest.approx(30 * 4, abs=3)  # u twice too large: 4x the poses
    assert ("a larger tilt range" in reasons[1]) and ("tilt" not in reasons[0])  # EB0A is an orientation error
    assert len(commands) == 1 and commands[0].startswith(f'pige plan --machine "{AC}" --points 1')
    planned = _planned_std(commands[0], tmp_path, capsys, monkeypatch)  # the suggested command runs, decides both
    assert all(planned[n] <= need[n] for n in need), (planned, need)


def test_an_undecided_probe_verdict_names_a_probe_plan(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    import contextlib
    import io

    from pige_sym import api
    from pige_sym.report import gather_report, render_html
    from testdata import simulated_probe_file

    with contextlib.redirect_stdout(io.StringIO()):
        probe = simulated_probe_file(tmp_path, 5, "angular_error_C:harmonic=2,cos_urad=0,sin_urad=0")
    res = api.identify(probe)
    est = dict(zip(res.parameters, res.values.tolist(), strict=True))
    std = dict(zip(res.parameters, res.std.tolist(), strict=True))
    tol = _undecided_tolerances(tmp_path / "tol.json", est, std, ["EC0A"])
    html = render_html(gather_report([probe], tolerances=tol, method="gauss-newton"))
    what, reasons, commands = _next_step(html)
    assert what.startswith("Undecided: EC0A") and reasons[0].startswith("EC0A = ") and "a sphere farther" in reasons[0]
    assert commands[0].startswith(f'pige plan --instrument sphere-probe --machine "{AC}" --sphere ')
    assert "--sphere-radius 12.7 --stylus-radius 1.5" in commands[0]
    planned = _planned_std(commands[0], tmp_path, capsys, monkeypatch)
    assert planned["EC0A"] <= std["EC0A"] / 2 * 1.05, (planned["EC0A"], std["EC0A"])


def test_a_history_report_says_what_to_do_next(readme_report: tuple[Path, str], tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    figures_not_drawn(monkeypatch)  # words only: the trend figure is drawn and checked in test_report.py
    folder, _ = readme_report
    db = f"sqlite:///{tmp_path / 'history.db'}"
    assert main(["simulate", "--machine", AC, "--pige", "EX0C=0.4,EY0C=-0.3,EB0A=2", "--seed", "2", "--out",
                 str(tmp_path / "after.csv")]) == 0
    for date, path in (("2026-01-05", folder / "run.csv"), ("2026-02-05", tmp_path / "after.csv")):
        assert main(["history", "add", str(path), "--machine-id", "M-5", "--date", date, "--db", db]) == 0
    assert main(["report", "--history", "M-5", "--db", db, "--out", str(tmp_path / "h")]) == 0
    what, _, commands = _next_step((tmp_path / "h" / "report.html").read_text(encoding="utf-8"))
    assert "changed in the last run: measure again to confirm before acting" in what and "EY0C" in what
    assert "and add it to this history (pige history add, --machine-id M-5)" in what and commands == []


def test_the_ballbar_next_step_runs(ballbar_report: tuple[list[str], str], tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    """The joint section's advice: compensate from `pige diagnose F1 F2 … --json` (before, compensate refused the
    joint JSON's keys: 'unknown key agreement'); the commands are printed with the files' names
    (tests/test_report_commands.py runs them)."""
    files, html = ballbar_report
    assert f'<code class="cmd">pige diagnose {" ".join(files)} --json &gt; diagnosis.json</code>' in html
    capsys.readouterr()
    assert main(["diagnose", *files, "--json"]) == 0
    (tmp_path / "joint.json").write_text(capsys.readouterr().out)
    assert main(["compensate", "--params", str(tmp_path / "joint.json"), "--controller", "linuxcnc"]) == 0
    assert "entered by the trt pins: EY0A, EZ0A, EX0C, EY0C" in capsys.readouterr().out


def test_an_undecided_ballbar_verdict_says_what_decides_it(ballbar_report: tuple[list[str], str],
                                                           tmp_path: Path) -> None:
    from pige_sym.report import gather_report, render_html

    files, _ = ballbar_report
    joint = gather_report(files).joints[0].diagnosis.final
    est = dict(zip(joint.parameters, joint.values.tolist(), strict=True))
    std = dict(zip(joint.parameters, joint.std.tolist(), strict=True))
    tol = _undecided_tolerances(tmp_path / "tol.json", est, std, ["EB0A"])
    answer = html_unescape(_words(_answer(render_html(gather_report(files, tolerances=tol)))))
    found = re.search(r"next step undecided: EB0A needs u ≤ ([\d.]+) µrad \(now ([\d.]+)\): ([\d.]+)× the points per "
                      r"setup \(u falls as 1/√points\), or setups that see it better: pige plan --instrument ballbar "
                      rf'--machine "{re.escape(AC)}" --noise [\d.]+ --target ([\d.]+) --out setups.json', answer)
    assert found, answer[:1500]
    assert float(found.group(1)) == pytest.approx(std["EB0A"] / 2, rel=0.05) and float(found.group(3)) == \
        pytest.approx(4, rel=0.1) and found.group(4) == found.group(1)
