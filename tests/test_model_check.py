"""Issue 41 item 2: ``pige identify`` says when the PIGE model does not explain a file down to its noise, and names
``pige diagnose`` as the next step (:mod:`pige_sym.identification.model_check`).

The README's run.csv (an angular positioning error of C hidden in it) is flagged; files with noise only are not
(R-test: 200 simulations, probe imports: 12), at the stated false-alarm rate of 1e-3; the F and chi-square tails
written out (no SciPy import in ``pige identify``) are SciPy's.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

import pige_sym.api as pige
from pige_sym.cli.main import main
from pige_sym.identification.model_check import ALPHA, check_model, f_quantile, f_upper_tail
from testdata import simulated_probe_file

AC = "wC'A'bXYZ(C1)t"


@pytest.mark.parametrize("dof", [1, 8, 82, 500, 600_000])
@pytest.mark.parametrize("dof0", [1, 10, 61, 300, math.inf])
def test_the_f_and_chi_square_tails_are_those_of_scipy(dof: int, dof0: float) -> None:
    from scipy.special import chdtrc, chdtri, fdtrc, fdtri

    exact = chdtri(dof, ALPHA) / dof if math.isinf(dof0) else fdtri(dof, dof0, 1 - ALPHA)
    assert f_quantile(1 - ALPHA, dof, dof0) == pytest.approx(exact, rel=1e-8)
    for f in (0.05, 0.8, 1.0, 1.3, 2.0, 6.0):
        tail = chdtrc(dof, dof * f) if math.isinf(dof0) else fdtrc(dof, dof0, f)
        assert f_upper_tail(f, dof, dof0) == pytest.approx(tail, rel=1e-8, abs=1e-14)


def test_the_readme_run_is_flagged_with_the_next_step(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--machine", AC, "--pige", "random", "--seed", "1", "--effect", "angular_error_C",
                 "--out", "run.csv"]) == 0
    capsys.readouterr()
    assert main(["identify", "run.csv"]) == 0
    printed = capsys.readouterr().out
    assert "model check: the residual is well above the noise: the PIGE model misses something" in printed
    assert "Next step: pige diagnose run.csv" in printed and "99.9 % quantile" in printed
    assert main(["identify", "run.csv", "--json"]) == 0
    printed = capsys.readouterr().out
    check = json.loads(printed)["model_check"]
    Path("identify.json").write_text(printed)  # still a parameter file: compensate reads it
    assert main(["compensate", "--params", "identify.json", "--controller", "siemens"]) == 0
    assert check["flagged"] and check["next_step"] == "pige diagnose run.csv" and check["alpha"] == ALPHA
    assert check["noise_um"] == 0.25 and check["test"] == "chi-square" and check["ratio"] > 10  # 4x the noise
    # the same file with the noise stated as large as its residual: explained
    assert main(["identify", "run.csv", "--noise", "1.2"]) == 0
    assert "model check: the PIGEs explain these data down to the noise" in capsys.readouterr().out
    assert main(["identify", "run.csv", "--noise", "-1"]) == 2


def test_noise_only_rtest_files_are_not_flagged() -> None:
    flagged, p = 0, []
    for seed in range(200):
        run = pige.simulate(seed=seed, noise_um=0.25)
        check = check_model(run, pige.identify(run))
        assert check is not None
        flagged += check.flagged
        p.append(check.p_value)
    assert flagged <= 2  # expected 0.2 at ALPHA = 1e-3; P(≥ 3) < 0.002
    assert 0.35 < float(np.median(p)) < 0.65  # the test is calibrated: p uniform under the model


def test_probe_imports_judged_against_their_own_covariances(tmp_path: Path) -> None:
    """The contact scatter is estimated from few contacts per pose: an F test (a chi-square test flagged 2 of 20
    noise-only probe files); a sphere creeping on its stand is flagged."""
    with contextlib.redirect_stdout(io.StringIO()):
        clean = [simulated_probe_file(tmp_path / f"c{s}", s, "angular_error_C:harmonic=2,cos_urad=0,sin_urad=0")
                 for s in range(12) if (tmp_path / f"c{s}").mkdir() is None]
        (tmp_path / "drift").mkdir()
        drift = simulated_probe_file(tmp_path / "drift", 3, "table_drift:vx_um=6,vy_um=-4,vz_um=8,tau_s=10")
    for path in clean:
        m = pige.read(path)
        check = check_model(m, pige.identify(m))
        assert check is not None and not check.flagged, check.text()
        assert check.test_name == "F" and 40 < check.noise_dof < 100  # 155 contacts − 3·31 − 1 = 61
    m = pige.read(drift)
    check = check_model(m, pige.identify(m))
    assert check is not None and check.flagged and check.next_step == f"pige diagnose {drift}"
