"""``pige demo`` end to end: virtual device over a pty, acquisition, identification, diagnosis,
compensation and report, with the hidden effect found."""

from __future__ import annotations

import json
import re
import sys

import pytest

from pige_sym.cli.main import main
from pige_sym.measurements.rtest import read_measurement

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="the virtual device needs a POSIX pty")


def test_demo_finds_the_hidden_effect_and_writes_everything(tmp_path, capsys):
    out = tmp_path / "demo"
    status = main(["demo", "--out", str(out), "--quiet", "--time-scale", "2000"])
    text = capsys.readouterr().out
    assert status == 0, text
    assert "hidden effect: angular_error_C; diagnosis found: angular_error_C -> FOUND" in text
    m = read_measurement(out / "rtest.csv")
    assert m.n_rows == 31
    diagnosis = json.loads((out / "diagnosis.json").read_text())
    assert diagnosis["findings"][0]["effect"] == "angular_error_C"
    truth = json.loads((out / "rtest.truth.json").read_text())
    # the final PIGEs (with the accepted effect) lie within 4 standard errors of the device's truth
    for name, value in truth["pige"].items():
        if name in diagnosis["pige"] and diagnosis["std"].get(name) is not None:
            assert abs(diagnosis["pige"][name] - value) < 4 * diagnosis["std"][name], name
    original = (out / "rtest_cone.mpf").read_text().splitlines()
    compensated = (out / "rtest_cone_comp.mpf").read_text().splitlines()
    assert len(compensated) > len(original)  # header comment naming the parameters
    assert sum(line.startswith("N") for line in compensated) == sum(line.startswith("N") for line in original)
    html = (out / "report" / "report.html").read_text()
    assert "angular_error_C" in html and "data:image/png;base64," in html
    assert "Compensated with the PIGEs: angular_error_C" in html
    assert "; compensated extension: angular_error_C harmonic=2" in "\n".join(compensated)
    # the first screen answers "in tolerance?" against the shipped example limits, in plain words
    assert "in tolerance? " in text and (out / "tolerances.json").exists()
    lead = html[:html.index('id="overview"')]
    assert "verdict" in lead.lower() and "sidecar" not in lead and not re.findall(r"\bu(?:m|rad)\b", lead)
    assert html.count('data-figure="compensation"') == 1  # the NC program is the measured test: one row, one figure


def test_demo_says_when_the_hidden_effect_is_missed(tmp_path, capsys):
    """Exit status 1 when the diagnosis does not name the hidden effect (here: none big enough to find)."""
    out = tmp_path / "demo"
    status = main(["demo", "--out", str(out), "--quiet", "--time-scale", "2000",
                   "--effect", "squareness_XY:gamma_urad=0.01"])
    text = capsys.readouterr().out
    assert status == 1
    assert "NOT FOUND" in text


def test_demo_does_not_replace_an_earlier_demo_without_force(tmp_path) -> None:
    from pige_sym.cli import main

    out = tmp_path / "demo-out"
    out.mkdir()
    (out / "rtest.csv").write_text("kept\n")
    assert main(["demo", "--out", str(out), "--quiet"]) == 2
    assert (out / "rtest.csv").read_text() == "kept\n"


def test_the_demo_tolerances_are_the_shipped_example() -> None:
    """The demo judges against examples/tolerances.json, byte for byte (written into --out, so a wheel needs none)."""
    from pathlib import Path

    from pige_sym.cli.demo import DEMO_TOLERANCES

    assert (Path(__file__).resolve().parents[1] / "examples" / "tolerances.json").read_text() == DEMO_TOLERANCES
