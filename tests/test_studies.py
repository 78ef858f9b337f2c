"""Projection study (the paper's finding, as our model states it) and Sobol indices."""

from __future__ import annotations

import numpy as np
import pytest

from pige_sym.identification.studies import projection_study, sobol_study
from pige_sym.model.trajectories import cone_frustum, figure_eight

AC, BC = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t"


@pytest.mark.parametrize("traj", ["cone", "fig8"])
def test_paper_projection_finding_in_our_model(traj) -> None:
    """AC: y is better than x; BC: x is better than y. But no single projection has full rank:
    one combination stays undetermined; the full 3-D data determine all 8 PIGEs."""
    results = {}
    for code, incl in ((AC, "X"), (BC, "Y")):
        tr = cone_frustum(code, incl_axis=incl) if traj == "cone" else figure_eight(code)
        study = projection_study(code, tr, presets=10, progress=False)
        results[code] = {r.projection: r for r in study.rows}
    ac, bc = results[AC], results[BC]
    assert ac["x"].rank == 4 and ac["y"].rank == 7  # x loses EY0A, EZ0A entirely
    assert set(ac["x"].unobserved) == {"EY0A", "EZ0A"}
    assert bc["y"].rank == 4 and bc["x"].rank == 7  # the reverse for BC
    assert set(bc["y"].unobserved) == {"EX0B", "EZ0B"}
    for r in (ac["x"], ac["y"], ac["z"], bc["x"], bc["y"], bc["z"]):
        assert r.rank < 8 and r.success_rate == 0.0
    for r in (ac["xyz"], bc["xyz"]):
        assert r.rank == 8 and np.isfinite(r.condition) and r.condition < 50
        assert r.success_rate >= 0.8


def test_exact_sobol_indices_agree_with_scipy_monte_carlo() -> None:
    """The closed form against scipy.stats.sobol_indices (an independent estimator) on a large sample."""
    tr = cone_frustum(AC)
    exact = sobol_study(AC, tr)
    mc = sobol_study(AC, tr, n=2**14, seed=3)
    assert exact.n_samples is None and exact.method.startswith("exact")
    np.testing.assert_allclose(exact.first_order, mc.first_order, atol=0.02)
    np.testing.assert_allclose(exact.total_order, mc.total_order, atol=0.02)


def test_exact_sobol_of_a_small_quadratic_form_by_brute_force() -> None:
    """x1² + 3 x1 x2 + 0.5 x2², x ~ U(±1) x U(±2): conditional variances by quadrature on a grid."""
    from pige_sym.identification.studies import exact_sobol_quadratic

    m = np.array([[1.0, 1.5], [1.5, 0.5]])
    half = np.array([1.0, 2.0])
    g = 801  # midpoint grid on each axis
    x1 = (np.arange(g) + 0.5) / g * 2 * half[0] - half[0]
    x2 = (np.arange(g) + 0.5) / g * 2 * half[1] - half[1]
    f = m[0, 0] * x1[:, None] ** 2 + 2 * m[0, 1] * x1[:, None] * x2[None, :] + m[1, 1] * x2[None, :] ** 2
    v = f.var()
    s1 = np.array([f.mean(axis=1).var(), f.mean(axis=0).var()]) / v
    st = np.array([f.var(axis=0).mean(), f.var(axis=1).mean()]) / v
    first, total = exact_sobol_quadratic(m, half)
    np.testing.assert_allclose(first, s1, atol=1e-4)
    np.testing.assert_allclose(total, st, atol=1e-4)
    assert np.isnan(exact_sobol_quadratic(np.zeros((2, 2)), half)[0]).all()


def test_sobol_indices_are_consistent() -> None:
    tr = cone_frustum(AC)
    s = sobol_study(AC, tr, n=1024)
    assert s.first_order.shape == (4, 8)
    assert np.all(s.total_order >= s.first_order - 0.05)
    x = s.projections.index("x")
    # the x projection does not see the A-axis offsets at all
    assert s.total_order[x, 0] < 1e-6 and s.total_order[x, 1] < 1e-6


def test_the_projection_table_says_why_it_lists_more_combinations_than_missing_rank(capsys) -> None:
    from pige_sym.cli.main import main

    assert main(["study", "projection", "--presets", "5"]) == 0
    out = capsys.readouterr().out
    assert "why more undetermined combinations than missing rank" in out
