"""R-test files of a map oracle machine (tests/map_oracle.py), written as pige reads them: the test files of the
error maps (tests/test_maps.py, tests/test_map_advice.py) share them.

Each setup is one file: the reference pose, then C stepped through a turn at every A of the grid (A approached from
0), the oracle's deviations (µm) with Gaussian noise on every pose but the reference.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from map_oracle import OracleMachine

from pige_sym import api
from pige_sym.measurements.measurement import Measurement

AC = "wC'A'bXYZ(C1)t"


def grid_poses(a_grid: np.ndarray, c_grid: np.ndarray) -> list[dict[str, float]]:
    """The reference pose, then C through ``c_grid`` [deg] at every A of ``a_grid`` [deg], from A 0 down."""
    out = [{"A": 0.0, "C": 0.0}]
    for a in a_grid[::-1]:
        out += [{"A": float(a), "C": float(c)} for c in c_grid]
    return out


def write_setups(folder: Path, oracle: OracleMachine, setups: tuple[tuple[float, float, float], ...],
                 poses: list[dict[str, float]], noise: float, seed: int, first: int = 0) -> list[str]:
    """One R-test file per ball position (mm) of ``setups``: ``setup{first}.csv``, ``setup{first + 1}.csv`` …;
    ``noise`` [µm] the standard deviation added; returns the paths."""
    rng = np.random.default_rng(seed)
    angles = np.array([[p["A"], p["C"]] for p in poses])
    paths = []
    for i, ball in enumerate(setups, start=first):
        dev = oracle.rtest(poses, np.array(ball))
        dev[1:] += rng.normal(scale=noise, size=dev[1:].shape)
        m = Measurement(machine=AC, ball_mm=np.array(ball), t_s=np.arange(len(poses)) * 8.0, angles_deg=angles,
                        deviation_um=dev, rotary_axes=("A", "C"), metadata={"machine": AC, "source": "map oracle"})
        paths.append(str(api.write(m, folder / f"setup{i}.csv")))
    return paths
