"""The public API (:mod:`pige_sym.api`): its numpydoc examples run as doctests, and it agrees with the CLI."""

from __future__ import annotations

import doctest
import json

import numpy as np
import pytest

import pige_sym.api as api
from pige_sym.cli.main import main
from pige_sym.errors import InputError, PigeError
from pige_sym.measurements.rtest_writer import write_measurement


def test_every_example_runs() -> None:
    result = doctest.testmod(api, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.attempted >= 25
    assert result.failed == 0


def test_every_public_function_is_documented_with_an_example() -> None:
    for name in api.__all__:
        doc = getattr(api, name).__doc__ or ""
        assert "Parameters" in doc and "Returns" in doc and "Examples" in doc and ">>>" in doc, name


def test_api_and_cli_give_the_same_identification(tmp_path, capsys) -> None:
    run = api.simulate(seed=9)
    path = write_measurement(run, tmp_path / "r.csv")
    from_api = api.identify(path).to_dict()
    assert main(["identify", str(path), "--json"]) == 0
    from_cli = json.loads(capsys.readouterr().out)
    assert list(from_cli["pige"]) == list(from_api["pige"])
    np.testing.assert_allclose(list(from_cli["pige"].values()), list(from_api["pige"].values()), rtol=1e-12)
    np.testing.assert_allclose(list(from_cli["std"].values()), list(from_api["std"].values()), rtol=1e-12)


def test_compensate_refuses_an_estimate_with_an_unidentifiable_pige(tmp_path) -> None:
    prog = tmp_path / "p.mpf"
    prog.write_text("; machine: wC'A'bXYZ(C1)t\nTRAORI\nG90 G1 X10 Y0 Z5 A20 C30 F500\nM30\n")
    partial = api.identify(api.simulate(seed=1), projection="x")
    with pytest.raises(PigeError, match="allow-missing"):
        api.compensate(prog, partial)
    assert api.compensate(prog, partial, allow_missing=True).text != prog.read_text()


def test_bad_input_raises_pige_errors_that_say_what_to_fix() -> None:
    with pytest.raises(PigeError):
        api.read("/nonexistent/run.csv")
    with pytest.raises(PigeError):
        api.simulate("not-a-machine")
    with pytest.raises((InputError, PigeError)):
        api.plan(points=12, limits=["A=90:-90"])


def test_the_readme_python_example_runs(capsys) -> None:
    """The README's "Use it from Python" block runs as pasted."""
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("### Use it from Python"):]
    code = section[section.index("```python\n") + 10:section.index("```", section.index("```python\n") + 10)]
    assert len(code.strip().splitlines()) <= 12
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    assert out[-1] in ("pass", "fail", "undecided")
