"""A parameter file's per-direction positioning map acts once (issue 40, found by the map loop's dry run).

``pige identify --map-per-direction C --json`` writes ``ECC+`` and ``ECC-`` and, beside them, their mean ``ECC`` and
difference ``ECC:reversal``.  Read back, only ``ECC±`` may act: the motions of a pose are the mean plus or minus half
the reversal by the direction of approach, written here — not that plus the mean and the reversal again.
"""

from __future__ import annotations

import json

import numpy as np

from pige_sym.compensation.parameters import load_parameters
from pige_sym.kernels import load_kernels

AC = "wC'A'bXYZ(C1)t"


def test_phi_per_direction_acts_once(tmp_path) -> None:
    grid = np.arange(12) * 30.0
    rng = np.random.default_rng(2)
    plus, minus = rng.normal(scale=30, size=12), rng.normal(scale=30, size=12)

    def entry(v: np.ndarray) -> dict:
        return {"value": list(v), "std": [1.0] * 12, "unit": "urad", "kind": "positioning"}

    doc = {"machine": AC, "pige": {n: 0.0 for n in load_kernels(AC).LOCATION_PARAMETERS},
           "error_motions": {"C": {"angle_deg": list(grid), "full_turn": True, "ECC": entry(0.5 * (plus + minus)),
                                   "ECC:reversal": entry(plus - minus), "ECC+": entry(plus), "ECC-": entry(minus)}}}
    path = tmp_path / "maps.json"
    path.write_text(json.dumps(doc))
    params = load_parameters(path)
    assert sorted(params.error_maps.axes["C"].values) == ["ECC+", "ECC-"]
    kern = load_kernels(AC)
    angles = np.column_stack([np.zeros(12), grid])
    for direction in (-1, 0, 1):
        approach = np.column_stack([np.zeros(12), np.full(12, direction)])
        rz = params.error_maps.pose_motions(kern, angles, approach)[:, 6 * 1 + 5]
        expected = -(0.5 * (plus + minus) + 0.5 * direction * (plus - minus))  # phi turns the table by s = -1
        assert np.abs(rz - expected).max() < 1e-9
