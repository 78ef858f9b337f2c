"""``pige identify --map-step 0.5`` costs what the data determine, not the square of the grid (issue 47, item 4).

On 144 poses measured every 30°, a 0.5° grid has 5,406 map values of which 96 have a measured pose at their angle.
Before, every value was a column of the joint fit: the (p + M)² column transform, the files' (p + M)² normal
matrices and eigen-decompositions of 5,416 columns (over 300 s and 1 GB).  Now a value no row sees is left out of
the fit (it is reported undetermined, "no measured pose within 0.5° …", as before), and the §10 projection is
applied motion by motion: the largest matrix factored is the same as on the 15° grid, the memory grows with the
grid's values, and the answer is the same (the oracle: the 15° and 0.5° fits of the same files agree with the old
code's JSON — tests/test_maps.py holds the truth; here the same files on two grids give the same PIGEs and the
same values at the measured angles).  Counted, not timed: the times are in benchmarks/bench_scale_maps.py.
"""

from __future__ import annotations

import tracemalloc
from typing import Any

import numpy as np
import pytest

from pige_sym.identification.maps import MapSpec, identify_maps
from pige_sym.model.error_motions import AxisMaps, ErrorMaps, MapGrid
from pige_sym.model.trajectories import Trajectory
from pige_sym.simulation.simulator import random_pige, simulate

AC = "wC'A'bXYZ(C1)t"
SETUPS = ((110.0, 0.0, 40.0), (-50.0, 95.0, 90.0), (-60.0, -90.0, 140.0))


def _files() -> list[tuple[str, Any]]:
    """Three R-test setups of 48 poses each (C every 30° at A 0, −30, −60, −90), hidden maps of harmonics 2–3."""
    rng = np.random.default_rng(0)
    maps = {}
    for axis, grid, full in (("C", np.arange(0.0, 360.0, 10.0), True), ("A", np.arange(-90.0, 0.1, 10.0), False)):
        t = np.radians(grid)
        maps[axis] = AxisMaps(MapGrid(axis, grid, full), {f"E{c}{axis}": 2.0 * np.cos(2 * t + rng.uniform(0, 6))
                                                          + np.sin(3 * t) for c in "XYZABC"})
    angles = [(0.0, 0.0)] + [(a, c) for a in (0.0, -30.0, -60.0, -90.0) for c in np.arange(0.0, 360.0, 30.0)][:47]
    a = np.array(angles)
    traj = Trajectory("map sweep", ("A", "C"), a, np.arange(len(a)) * 8.0, "map sweep")
    truth = random_pige(AC, 1)
    return [(f"setup{i}", simulate(AC, traj, pige=truth, ball_mm=ball, noise_um=0.2, seed=i,
                                   error_maps=ErrorMaps(maps)).measurement) for i, ball in enumerate(SETUPS)]


@pytest.fixture(scope="module")
def files() -> list[tuple[str, Any]]:
    return _files()


def _measured(files: list[tuple[str, Any]], step: float, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, int, float]:
    """(result, the largest matrix factored, tracemalloc's peak [bytes]) of identify --map C,A on ``step``."""
    largest = [0]
    for name in ("eigh", "svd", "lstsq", "solve", "inv", "pinv"):
        original = getattr(np.linalg, name)

        def counted(m: Any, *args: Any, _f: Any = original, **kwargs: Any) -> Any:
            largest[0] = max(largest[0], min(np.shape(m)[-2:]))
            return _f(m, *args, **kwargs)

        monkeypatch.setattr(np.linalg, name, counted)
    tracemalloc.start()
    try:
        result = identify_maps(files, MapSpec(("C", "A"), step))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        monkeypatch.undo()
    return result, largest[0], peak


def test_a_fine_grid_costs_what_the_data_determine(files: list[tuple[str, Any]],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    coarse, largest_coarse, peak_coarse = _measured(files, 15.0, monkeypatch)
    fine, largest_fine, peak_fine = _measured(files, 0.5, monkeypatch)
    values = {step: sum(m.grid.n * len(m.motions) for m in r.maps.values()) for step, r in ((15, coarse), (0.5, fine))}
    assert values == {15: 186, 0.5: 5406}
    assert largest_fine <= largest_coarse + 12, (largest_coarse, largest_fine)  # not 5,416 columns
    assert peak_fine <= 40 * peak_coarse, (peak_coarse, peak_fine)  # M grew 29-fold: linear, not M²
    assert peak_fine < 150e6
    # the same files on two grids: the same PIGEs, the same values where a pose was measured
    np.testing.assert_allclose(fine.result.values, coarse.result.values, rtol=1e-6, atol=1e-6, equal_nan=True)
    for axis in ("C", "A"):
        c, f = coarse.maps[axis], fine.maps[axis]
        measured = np.isfinite(c.value["EX" + axis]) if axis == "C" else np.isfinite(c.value["EY" + axis])
        for motion in c.value:
            at = np.isin(f.grid.angles_deg, c.grid.angles_deg[np.isfinite(c.value[motion])])
            assert np.isfinite(f.value[motion][at]).all() and np.isnan(f.value[motion][~at]).all()
            np.testing.assert_allclose(f.value[motion][at], c.value[motion][np.isfinite(c.value[motion])],
                                       rtol=1e-6, atol=1e-6)
        assert measured.sum() > 3
    unseen = [u for u in fine.undetermined if "no measured pose" in u.why]
    assert len(unseen) == (720 - 12) + (181 - 4)  # every grid angle without a pose, named
