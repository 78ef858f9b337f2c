"""The report's joint section: ballbar setups (and, with --joint, several R-test/probe files) of one machine."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from conftest import REPO
from pige_sym.cli.main import main
from pige_sym.report import gather_report, write_report
from pige_sym.simulation.simulator import random_pige

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
        assert p.name in section
    rows = _rows(section)
    assert sorted(rows) == sorted(truth)
    for name, cells in rows.items():  # value, std, unit, true, error/std
        value, std, true, z = float(cells[1]), float(cells[2]), float(cells[4]), float(cells[5])
        assert true == pytest.approx(truth[name], abs=1e-3)
        assert z == pytest.approx((value - true) / std, abs=0.02) and abs(z) < 4.5
    assert "Conformance of the joint estimate" in section
    assert "agreement cannot be tested" in section
    assert (out / "_report" / "joint_1.png").read_bytes().startswith(b"\x89PNG")
    assert "joint PIGE-only fit" in section and section.count("data:image/png;base64,") >= 1


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


def test_mixed_rtest_and_ballbar_and_a_moved_setup_is_named(four_setups, tmp_path) -> None:
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
