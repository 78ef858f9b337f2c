"""Identification: round trips, honest uncertainty, identifiability, robust loss, references."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pige_sym.identification.least_squares import identify
from pige_sym.identification.result import IdentificationResult
from pige_sym.measurements.rtest import read_measurement
from pige_sym.model.effects import parse_effect
from pige_sym.model.trajectories import cone_frustum, figure_eight
from pige_sym.simulation.simulator import random_pige, simulate
from testdata import reference_files, require_shared

AC, BC = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t"
BALLS = {AC: (120.0, 0.0, 80.0), BC: (60.0, 90.0, 110.0)}


def trajectory(code: str, name: str):
    return cone_frustum(code, incl_axis="X" if code == AC else "Y") if name == "cone" else figure_eight(code)


@pytest.mark.parametrize("code", [AC, BC])
@pytest.mark.parametrize("traj", ["cone", "fig8"])
@pytest.mark.parametrize("method", ["gauss-newton", "double-differential"])
def test_round_trip_within_four_standard_errors(code, traj, method) -> None:
    tr = trajectory(code, traj)
    for seed in range(5):
        truth = random_pige(code, seed)
        sim = simulate(code, tr, pige=truth, ball_mm=BALLS[code], noise_um=0.25, seed=100 + seed)
        res = identify(sim.measurement, method=method)
        assert res.rank == 8 and not res.unidentifiable
        z = [(res.value(p) - truth[p]) / res.std[i] for i, p in enumerate(res.parameters)]
        assert np.max(np.abs(z)) < 4, (seed, np.round(z, 2))
        assert 0.15 < res.rms_um < 0.35


@pytest.mark.parametrize("code", [AC, BC])
def test_standard_errors_match_spread_of_repeated_simulations(code) -> None:
    tr = cone_frustum(code, incl_axis="X" if code == AC else "Y")
    truth = random_pige(code, 7)
    estimates, stds = [], []
    for seed in range(500):  # the sample std of 500 draws is good to ~3 %
        sim = simulate(code, tr, pige=truth, ball_mm=BALLS[code], noise_um=0.3, seed=seed)
        res = identify(sim.measurement)
        estimates.append(res.values)
        stds.append(res.std)
    spread = np.std(estimates, axis=0, ddof=1)
    mean_std = np.mean(stds, axis=0)
    np.testing.assert_allclose(mean_std / spread, 1.0, atol=0.25)


@pytest.mark.parametrize("path", reference_files("*clean*.csv"), ids=lambda p: p.name)
@pytest.mark.parametrize("method", ["gauss-newton", "double-differential"])
def test_reference_clean_files_within_four_standard_errors(path, method) -> None:
    require_shared()
    m = read_measurement(path)
    truth = json.loads(path.with_name(path.stem + ".truth.json").read_text())["pige"]
    res = identify(m, method=method)
    for i, p in enumerate(res.parameters):
        assert abs(res.values[i] - truth[p]) < 4 * res.std[i], (p, res.values[i], truth[p], res.std[i])


def test_projection_x_on_ac_reports_unidentifiable_instead_of_numbers() -> None:
    sim = simulate(AC, cone_frustum(AC), pige=random_pige(AC, 1), noise_um=0.25, seed=1)
    res = identify(sim.measurement, projection="x")
    assert res.rank < 8 and res.unidentifiable
    d = res.to_dict()
    undetermined = [p for p, v in d["pige"].items() if v is None]
    assert {"EY0A", "EZ0A"} <= set(undetermined)
    assert all(d["std"][p] is None for p in undetermined)
    assert any("EY0A" in c for c in d["unidentifiable"])
    assert np.isinf(res.condition) and d["condition"] is None


def test_robust_loss_flags_injected_outliers() -> None:
    eff = parse_effect("outliers:count=3,size_um=8", ("A", "C"))
    sim = simulate(AC, cone_frustum(AC, points=40), pige=random_pige(AC, 2), effects=[eff], noise_um=0.25, seed=5)
    res = identify(sim.measurement, loss="soft_l1")
    assert res.outlier_rows == sim.truth["outlier_rows"]
    truth = sim.truth["pige"]
    z = [(res.value(p) - truth[p]) / res.std[i] for i, p in enumerate(res.parameters)]
    assert np.max(np.abs(z)) < 4
    clean = identify(simulate(AC, cone_frustum(AC, points=40), pige=truth, noise_um=0.25, seed=5).measurement,
                     loss="soft_l1")
    assert clean.outlier_rows == []


def test_double_differential_reports_stages() -> None:
    sim = simulate(AC, cone_frustum(AC), pige=random_pige(AC, 3), noise_um=0.25, seed=3)
    res = identify(sim.measurement, method="double-differential", projection="y")
    d = res.to_dict()
    assert d["stages"][0]["solved"] == res.parameters
    fixed = [p for s in d["stages"] for p in s["fixed"]]
    assert len(fixed) == len(set(fixed))
    # projection y on AC leaves a combination undetermined: no number for the parameters in it
    assert res.unidentifiable and any(v is None for v in d["pige"].values())


def test_json_round_trip_and_cli(tmp_path, capsys) -> None:
    from pige_sym.cli.main import main

    sim = simulate(AC, cone_frustum(AC), pige=random_pige(AC, 4), noise_um=0.25, seed=4)
    path = tmp_path / "run.csv"
    sim.write(path)
    status = main(["identify", str(path), "--json", "--method", "double-differential"])  # in this process
    out = capsys.readouterr()
    assert status == 0, out.err
    d = json.loads(out.out)
    for key in ("pige", "std", "units", "rank", "condition", "rms_um", "method", "unidentifiable", "outlier_rows",
                "stages"):
        assert key in d
    back = IdentificationResult.from_dict(d)
    assert back.parameters == list(d["pige"])
    assert main(["identify", str(path), "--projection", "q"]) == 2  # an exception would end the test
    err = capsys.readouterr().err
    assert "projection" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_large_input_uses_basis_sums() -> None:
    from pige_sym.identification.problem import build_problem

    tr = cone_frustum(AC, points=20000)
    sim = simulate(AC, tr, pige=random_pige(AC, 5), noise_um=0.25, seed=5)
    prob = build_problem(sim.measurement, "xyz", explicit=False)
    assert prob.design is None
    res = identify(sim.measurement)
    assert np.all(np.abs(res.values - np.array([sim.truth["pige"][p] for p in res.parameters])) < 4 * res.std)


def test_near_zero_column_is_unobserved_not_amplified() -> None:
    """A ~1e-18 column (round-off) must not be scaled up into a value of 1e17: no value, named."""
    from pige_sym.identification.spectrum import solve_scaled

    rng = np.random.default_rng(0)
    a = rng.normal(size=(60, 3))
    a[:, 2] = 1e-18 * rng.normal(size=60)
    y = a[:, :2] @ np.array([1.5, -2.0]) + 0.01 * rng.normal(size=60)
    sol = solve_scaled(a.T @ a, a.T @ y, float(y @ y))
    assert sol.unobserved == [2] and np.isinf(sol.vif[2])
    assert np.all(np.isfinite(sol.vif[:2])) and np.allclose(sol.values[:2], [1.5, -2.0], atol=0.05)
    sim = simulate(AC, cone_frustum(AC), pige=random_pige(AC, 1), noise_um=0.25, seed=1)
    res = identify(sim.measurement, projection="x")
    assert {"EY0A", "EZ0A"} <= set(res.unobserved)
    d = res.to_dict()
    assert d["pige"]["EY0A"] is None and d["pige"]["EZ0A"] is None
    assert all(abs(v) < 1e3 for v in d["pige"].values() if v is not None)


@pytest.mark.parametrize("projection", ["x", "y", "z"])
def test_single_projection_gn_and_double_differential_agree(projection) -> None:
    """Both methods give values for exactly the identifiable PIGEs, consistent with the truth,
    and the projection study reports identify's undetermined combinations."""
    from pige_sym.identification.studies import projection_study

    tr = cone_frustum(AC)
    sim = simulate(AC, tr, pige=random_pige(AC, 3), noise_um=0.25, seed=3)
    gn = identify(sim.measurement, projection=projection)
    dd = identify(sim.measurement, method="double-differential", projection=projection)
    determined = np.isfinite(gn.values)
    assert determined.any() and not determined.all()
    np.testing.assert_array_equal(np.isfinite(dd.values), determined)
    truth = np.array([sim.truth["pige"][p] for p in gn.parameters])
    for res in (gn, dd):
        assert np.all(np.abs(res.values - truth)[determined] < 4 * res.std[determined])
    assert gn.unidentifiable == dd.unidentifiable
    study = projection_study(AC, tr, projections=[projection], presets=2, progress=False)
    row = study.rows[0]
    listed = set(row.unobserved) | set(row.unidentifiable)
    expected = set(gn.unobserved) | {c for c in gn.unidentifiable
                                     if not any(c.startswith(f"{u} [") and c.count("[") == 1 for u in gn.unobserved)}
    assert listed == expected


def test_the_student_t_quantile_matches_scipy() -> None:
    from scipy.special import stdtrit

    from pige_sym.identification.result import student_t_975

    for dof in [*range(1, 300), 999, 1000, 1001, 5000, 10**5, 3 * 10**6]:
        assert student_t_975(dof) == pytest.approx(float(stdtrit(dof, 0.975)), rel=1e-11), dof
