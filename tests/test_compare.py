"""pige compare: measured before/after of two simulated runs, with what is left split by cause."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.kernels import load_kernels
from pige_sym.model.effects import EffectContext, parse_effect
from pige_sym.model.trajectories import cone_frustum
from pige_sym.simulation.simulator import random_pige, simulate
from pige_sym.verdict.compare import compare_measurements
from testdata import load_reference

AC = "wC'A'bXYZ(C1)t"
EFFECT = "angular_error_C:harmonic=2,cos_urad=12,sin_urad=-8"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict[str, float]]:
    """Before: PIGEs and an angular error of C; after: 10 % of the PIGEs left, the same angular error."""
    root = tmp_path_factory.mktemp("compare")
    pige = random_pige(AC, 1)
    eff = [parse_effect(EFFECT, ("A", "C"))]
    traj = cone_frustum(AC, points=30)
    before, _ = simulate(AC, traj, pige=pige, effects=eff, noise_um=0.25, seed=1).write(root / "before.csv")
    after, _ = simulate(AC, traj, pige={k: 0.1 * v for k, v in pige.items()}, effects=eff, noise_um=0.25,
                        seed=2).write(root / "after.csv")
    return before, after, pige


def _norms(path: Path) -> np.ndarray:
    _, cols, _ = load_reference(path)  # independent reader (machine frame files)
    return np.sqrt(cols["dx_um"] ** 2 + cols["dy_um"] ** 2 + cols["dz_um"] ** 2)


def test_per_pose_rms_max_and_improvement(runs: tuple[Path, Path, dict[str, float]]) -> None:
    before, after, _ = runs
    res = compare_measurements(before, after)
    nb, na = _norms(before), _norms(after)
    assert np.allclose(res.before_um, nb) and np.allclose(res.after_um, na)
    assert res.rms_before_um == pytest.approx(np.sqrt((nb[1:] ** 2).mean()))
    assert res.max_after_um == pytest.approx(na[1:].max())
    assert res.improvement == pytest.approx(1 - res.rms_after_um / res.rms_before_um)
    assert res.improvement > 0.6


def test_what_is_left_is_split_by_cause(runs: tuple[Path, Path, dict[str, float]]) -> None:
    before, after, pige = runs
    res = compare_measurements(before, after)
    dec = res.after_parts
    assert dec is not None
    parts = {p.name: p for p in dec.parts}
    assert list(parts) == ["PIGEs", "angular_error_C", "unexplained"]
    kern = load_kernels(AC)
    m = simulate(AC, cone_frustum(AC, points=30), noise_um=0.0).measurement
    truth_pige = kern.deviation(m.angles_deg, np.array([0.1 * pige.get(p, 0.0) for p in kern.PARAMETERS]),
                                m.ball_mm)
    eff = parse_effect(EFFECT, ("A", "C"))
    truth_eff = eff.spec.contribution(EffectContext(kern, m.angles_deg, m.t_s, m.ball_mm), eff.params)

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt((np.linalg.norm(x, axis=1)[1:] ** 2).mean()))

    assert parts["PIGEs"].rms_um == pytest.approx(rms(truth_pige), rel=0.15)
    assert parts["angular_error_C"].rms_um == pytest.approx(rms(truth_eff), rel=0.15)
    assert parts["unexplained"].rms_um < 2.5 * 0.25  # noise only: |noise| RMS ≈ √3 σ ≈ 0.43 µm
    assert dec.explained is not None and dec.explained > 0.95


def test_cli_json_is_strict_and_labelled_measured(runs: tuple[Path, Path, dict[str, float]],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    before, after, _ = runs
    assert main(["compare", str(before), str(after), "--json", "--no-explain"]) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(c))
    assert out["basis"] == "measured" and len(out["poses"]) == 31 and out["after_parts"] is None
    assert main(["compare", str(before), str(after)]) == 0
    text = capsys.readouterr().out
    assert "improvement (RMS)" in text and "angular_error_C" in text


@pytest.mark.parametrize("problem", ["points", "angles", "machine"])
def test_different_programs_are_refused(runs: tuple[Path, Path, dict[str, float]], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str], problem: str) -> None:
    before, _, _ = runs
    if problem == "points":
        other, _ = simulate(AC, cone_frustum(AC, points=20), seed=3).write(tmp_path / "o.csv")
        words = "points"
    elif problem == "angles":
        sim = simulate(AC, cone_frustum(AC, points=30), seed=3)
        sim.measurement.angles_deg[7, 1] += 0.2  # one pose of another program
        other, _ = sim.write(tmp_path / "o.csv")
        words = "data row 8"
    else:
        code = "wC'B'bXYZ(C1)t"
        other, _ = simulate(code, cone_frustum(code, points=30), seed=3).write(tmp_path / "o.csv")
        words = "same machine"
    assert main(["compare", str(before), str(other)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err
