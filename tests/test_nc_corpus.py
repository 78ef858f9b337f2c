"""Realistic programs (tests/nc_corpus/, written for these tests) and their expected outcomes (expected.json).

Each program goes through ``pige compensate``'s engine as it is.  Checked for every program:
the outcome (compensated or refused at a given line), the lines that must stay byte-identical,
the blocks reported as passed through, at least ``min_changed`` changed blocks, and that every
changed line differs from the original only in the values of its axis words, each by a
compensation-sized amount.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.program import compensate_nc
from pige_sym.errors import NCProgramError
from pige_sym.kernels import load_kernels
from pige_sym.nc.detect import detect_dialect

CORPUS = Path(__file__).parent / "nc_corpus"
EXPECTED = json.loads((CORPUS / "expected.json").read_text())
ERRORS = {"A": {"EY0A": 12.0, "EZ0A": -9.0, "EB0A": 25.0, "EC0A": -18.0},
          "B": {"EX0B": 12.0, "EZ0B": -9.0, "EA0B": 25.0, "EC0B": -18.0},
          "C": {"EX0C": -14.0, "EY0C": 10.0, "EA0C": 20.0, "EB0C": -22.0}}
_WORD = re.compile(r"(?<![A-Z_])([XYZABC])[ \t]*(=\s*(?:[A-Z]+\()?)?\s*([-+]?(?:\d+\.?\d*|\.\d+))\)?",
                   re.IGNORECASE)


_COMMENT = re.compile(r";|(?<![A-Z])\(", re.IGNORECASE)


def _params(machine: str) -> CompensationParameters:
    kern = load_kernels(machine)
    values = {k: v for ax in kern.ROTARY_AXES for k, v in ERRORS[ax].items()}
    return CompensationParameters(kern.MACHINE_CODE, values, {}, None, {}, "corpus", [])


def _body(text: str) -> list[str]:
    return [ln for ln in text.splitlines(keepends=True) if "compensated by pige_sym" not in ln]


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_corpus_program(name):
    exp = EXPECTED[name]
    text = (CORPUS / name).read_text(encoding="utf-8")
    assert detect_dialect(text, name) == exp["dialect"]
    params = _params(exp["machine"])
    kw = {"rtcp_on": tuple(exp.get("rtcp_on", ())), "rtcp_off": tuple(exp.get("rtcp_off", ()))}
    if exp["outcome"] == "refused":
        with pytest.raises(NCProgramError, match=rf"{re.escape(name)}:{exp['line']}:"):
            compensate_nc(text, params, path=name, **kw)
        out = compensate_nc(text, params, path=name, pass_through=True, **kw).text
        body, orig = _body(out), text.splitlines(keepends=True)
        assert all(body[n - 1] == orig[n - 1] for n in exp["pass_through_unchanged"])
        return
    res = compensate_nc(text, params, path=name, **kw)
    orig, body = text.splitlines(keepends=True), _body(res.text)
    assert len(body) == len(orig)
    for n in exp["unchanged"]:
        assert body[n - 1] == orig[n - 1], (n, body[n - 1])
    passed = {p["line"] for p in res.report.passed_through}
    assert set(exp["passed"]) <= passed, passed
    assert res.report.compensated >= exp["min_changed"]
    for old, new in zip(orig, body, strict=True):
        if old != new:
            _only_axis_values_changed(old, new, inch="G20" in text)


def _only_axis_values_changed(old: str, new: str, *, inch: bool) -> None:
    """Same text once axis words are taken out; every value present before moves by a compensation-sized amount."""
    code_old, code_new = _COMMENT.split(old, maxsplit=1), _COMMENT.split(new, maxsplit=1)
    assert code_old[1:] == code_new[1:], (old, new)  # comments untouched
    assert " ".join(_WORD.sub("", code_old[0]).split()) == " ".join(_WORD.sub("", code_new[0]).split()), (old, new)
    w_old = {m.group(1).upper(): float(m.group(3)) for m in _WORD.finditer(code_old[0])}
    w_new = {m.group(1).upper(): float(m.group(3)) for m in _WORD.finditer(code_new[0])}
    forms_old = {m.group(1).upper(): (m.group(2) or "").upper() for m in _WORD.finditer(code_old[0])}
    forms_new = {m.group(1).upper(): (m.group(2) or "").upper() for m in _WORD.finditer(code_new[0])}
    assert set(w_old) <= set(w_new) and all(forms_new[a] == f for a, f in forms_old.items()), (old, new)
    limit = 0.2 / 25.4 if inch else 0.2
    for ax, v in w_old.items():
        assert abs(w_new[ax] - v) <= (0.1 if ax in "ABC" else limit) + 1e-9, (old, new)
