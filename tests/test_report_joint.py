"""The report's joint section: ballbar setups (and, with --joint, several R-test/probe files) of one machine."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from pige_sym.cli.main import main
from pige_sym.report import gather_report, write_report
from pige_sym.simulation.simulator import random_pige
from testdata import REPO, figures_not_drawn

AC = "wC'A'bXYZ(C1)t"
TOLERANCES = REPO / "examples" / "tolerances.json"
FOUR = [("tangential", "C", 0.0), ("tangential", "C", -45.0), ("tangential", "A", 0.0), ("axial", "C", 0.0)]


def _setup(folder: Path, kind: str, axis: str, tilt: float, seed: int, pige: str) -> Path:
    out = folder / f"{kind}_{axis}{tilt:g}.csv"
    assert main(["simulate", "--instrument", "ballbar", "--setup", kind, "--axis", axis, "--tilt", str(tilt),
                 "--pige", pige, "--seed", str(seed), "--noise", "0.1", "--out", str(out)]) == 0
    return out


def _pige_text(values: dict[str, float]) -> str:
    return ",".join(f"{k}={v!r}" for k, v in values.items())


@pytest.fixture(scope="module")
def four_setups(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], dict[str, float]]:
    folder = tmp_path_factory.mktemp("ballbar")
    truth = random_pige(AC, 8)
    return [_setup(folder, k, a, t, i, _pige_text(truth)) for i, (k, a, t) in enumerate(FOUR)], truth


def _rows(section: str) -> dict[str, list[str]]:
    """PIGE table rows of a joint section: name -> cell texts."""
    table = section[section.index("<h3>Joint estimate"):]
    out = {}
    for row in re.findall(r"<tr[^>]*>(.*?)</tr>", table, re.DOTALL):
        cells = [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.DOTALL)]
        if cells and cells[0].startswith("E"):
            out[cells[0]] = cells
    return out


def test_ballbar_setups_get_a_joint_section_that_leads_the_page(four_setups, tmp_path, capsys) -> None:
    paths, truth = four_setups
    out = tmp_path / "rep"
    assert main(["report", *map(str, paths), "--out", str(out), "--tolerances", str(TOLERANCES)]) == 0
    printed = capsys.readouterr().out
    # the smallest set that determines all 8 measures no combination twice: agreement not testable, said
    assert "joint (4 files of wC'A'bXYZ(C1)t): verdict" in printed and "agreement not testable" in printed
    text = (out / "report.html").read_text(encoding="utf-8")
    assert "Five-axis calibration report (ballbar)" in text
    answer = re.search(r'<section data-section="answer" id="answer">(.*?)</section>', text, re.DOTALL)
    assert answer and 'id="answer-j1"' in answer.group(1) and 'data-verdict="' in answer.group(1)
    assert "8 of 8 PIGEs" in answer.group(1)
    assert 'id="m1"' not in text  # a ballbar setup has no section of its own
    section = text[text.index('data-section="joint"'):]
    for p in paths:
        assert p.name in section.replace("<wbr>", "")
    rows = _rows(section)
    assert sorted(rows) == sorted(truth)
    for name, cells in rows.items():  # value, std, unit, true, error/std
        value, std, true, z = float(cells[1]), float(cells[2]), float(cells[4]), float(cells[5])
        assert true == pytest.approx(truth[name], abs=1e-3)
        assert z == pytest.approx((value - true) / std, abs=0.02) and abs(z) < 4.5
    assert "Conformance of the joint estimate" in section
    assert "agreement cannot be tested" in section
    assert (out / "_report" / "joint_1.png").read_bytes().startswith(b"\x89PNG")
    assert "joint fit of it" in section and section.count("data:image/png;base64,") >= 1


def test_one_setup_names_what_it_cannot_determine_and_json_carries_the_joint(four_setups, tmp_path, capsys) -> None:
    paths, _ = four_setups
    assert main(["report", str(paths[0]), "--out", str(tmp_path / "one"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    joint = data["joint"][0]
    assert joint["files"] == [str(paths[0])] and data["measurements"] == []
    diag = joint["diagnosis"]
    assert diag["unidentifiable"] and any(v is None for v in diag["pige"].values())
    text = (tmp_path / "one" / "report.html").read_text(encoding="utf-8")
    section = text[text.index('data-section="joint"'):]
    assert "not determined" in section and "one file: nothing to compare it with" in section.lower()
    assert sum(c[1] == "not determined" for c in _rows(section).values()) == sum(
        v is None for v in diag["pige"].values())


def test_mixed_rtest_and_ballbar_and_a_moved_setup_is_named(four_setups, tmp_path, monkeypatch) -> None:
    figures_not_drawn(monkeypatch)  # words only: the R-test and joint figures are drawn in test_report.py and above
    paths, truth = four_setups
    moved = _setup(tmp_path, "tangential", "C", -20.0, 9, _pige_text(truth | {"EX0C": truth["EX0C"] + 8.0}))
    rtest = tmp_path / "rtest.csv"
    assert main(["simulate", "--pige", _pige_text(truth), "--seed", "3", "--noise", "0.2", "--out", str(rtest)]) == 0
    data = gather_report([rtest, *paths, moved])
    html = write_report(data, tmp_path / "rep").read_text(encoding="utf-8")
    assert len(data.measurements) == 1 and len(data.joints) == 1
    d = data.joints[0].diagnosis
    assert [f.disagrees for f in d.files] == [False] * 5 + [True]
    assert d.files[0].checked == "catalogue diagnosis" and d.files[1].checked.startswith("agreement only")
    assert "do not agree on one set of PIGEs" in html and "the file that disagrees: tangential_C-20.csv" in html
    assert 'id="m1"' in html and "Five-axis calibration report (R-test, ballbar)" in html


def test_rtest_files_are_joint_only_when_asked(tmp_path) -> None:
    files = []
    for seed in (1, 2):
        files.append(tmp_path / f"run{seed}.csv")
        assert main(["simulate", "--pige", "EX0C=3", "--seed", str(seed), "--out", str(files[-1])]) == 0
    assert gather_report(files).joints == []
    data = gather_report(files, joint=True)
    assert len(data.joints) == 1 and len(data.measurements) == 2
    assert data.joints[0].diagnosis.agreement is not None


def test_a_file_given_twice_is_refused(four_setups, tmp_path, capsys) -> None:
    paths, _ = four_setups
    assert main(["report", str(paths[0]), str(paths[0]), "--out", str(tmp_path / "x")]) == 2
    assert "given twice" in capsys.readouterr().err


NINE = [(k, a, t) for k in ("radial", "tangential", "axial") for a, t in (("C", 0.0), ("C", -45.0), ("A", 0.0))]


@pytest.fixture(scope="module")
def nine_with_an_effect(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], dict[str, float]]:
    """Nine setups of one machine with an angular positioning error of C at harmonic 2 (15/−10 µrad)."""
    folder = tmp_path_factory.mktemp("ballbar-effect")
    truth = random_pige(AC, 4)
    paths = []
    for i, (kind, axis, tilt) in enumerate(NINE):
        out = folder / f"bb_{kind}_{axis}{tilt:g}.csv"
        assert main(["simulate", "--instrument", "ballbar", "--setup", kind, "--axis", axis, "--tilt", str(tilt),
                     "--pige", _pige_text(truth), "--seed", str(40 + i), "--noise", "0.1",
                     "--effect", "angular_error_C:harmonic=2,cos_urad=15,sin_urad=-10", "--out", str(out)]) == 0
        paths.append(out)
    return paths, truth


def test_the_report_judges_what_pige_check_judges_with_one_estimate(nine_with_an_effect, tmp_path, capsys) -> None:
    """Issue 34 items 1-4: one estimate and one verdict in the report and in `pige check`; no nan; the effect's
    true values; each file's σ from the fit with the effect."""
    paths, truth = nine_with_an_effect
    files = [str(p) for p in paths]
    assert main(["check", *files, "--tolerances", str(TOLERANCES), "--json"]) in (0, 1)
    cli = json.loads(capsys.readouterr().out)
    data = gather_report(files, tolerances=TOLERANCES)
    (jr,) = data.joints
    assert [f.effect for f in jr.diagnosis.effects] == ["angular_error_C"]
    report = jr.check.to_dict()
    assert [(i["name"], i["status"]) for i in report["items"]] == [(i["name"], i["status"]) for i in cli["items"]]
    assert {i["name"] for i in report["items"]} >= {"angular_error_C.cos_urad", "angular_error_C.sin_urad"}
    assert report["verdict"] == cli["verdict"] and not report.get("not_assessed")
    html = write_report(data, tmp_path / "rep").read_text(encoding="utf-8")
    assert not re.search(r"\bnan\b", html, re.IGNORECASE) and "file(s)" not in html and "not assessed" not in html
    answer = re.search(r'<section data-section="answer".*?</section>', html, re.DOTALL).group(0)
    assert f"all {len(report['items'])} items pass" in answer or "FAIL" in answer or "UNDECIDED" in answer
    assert "PIGEs of the joint estimate" in answer and "EX0C" in answer and "next" in answer
    rows = {}
    section = html[html.index("<h3>Joint estimate"):]
    for row in re.findall(r"<tr[^>]*>(.*?)</tr>", section, re.DOTALL):
        cells = [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.DOTALL)]
        if cells:
            rows[cells[0]] = cells
    assert float(rows["angular_error_C.cos_urad"][4]) == 15.0 and float(rows["angular_error_C.sin_urad"][4]) == -10.0
    assert abs(float(rows["angular_error_C.cos_urad"][5])) < 4 and abs(float(rows["EX0C"][5])) < 4
    final = jr.diagnosis.extended
    assert final is not None and max(f.sigma_um for f in final.files) < 0.2  # noise 0.1: not the PIGE-only 1.3
    table = html[html.index("<h3>The files"):html.index("<h3>Conformance")]
    shown = [float(re.sub(r"<[^>]+>", "", c)) for c in re.findall(r'<td class="num">([0-9.]+)</td>', table)]
    assert shown and max(shown) < 60  # rows, σ and RMS: no σ of the PIGE-only fit (≈1.3 µm) among them
    assert all(s < 0.2 for s in shown if s < 10)
