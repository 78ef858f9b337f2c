"""A parameter file's per-direction positioning map acts once (issue 40, found by the map loop's dry run).

``pige identify --map-per-direction C --json`` writes ``ECC+`` and ``ECC-`` and, beside them, their mean ``ECC`` and
difference ``ECC:reversal``.  Read back, only ``ECC±`` may act: the motions of a pose are the mean plus or minus half
the reversal by the direction of approach, written here — not that plus the mean and the reversal again.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

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


def test_a_joint_identification_keeps_the_files_nominal_pivots(tmp_path) -> None:
    """Several files identified together: the parameter file states the pivots the PIGEs refer to (the LinuxCNC
    map loop found it: without them compensate printed pige's component with pivots at 0, 20 mm off the B line)."""
    from pige_sym import api
    from pige_sym.errors import InputError
    from pige_sym.measurements.measurement import Measurement

    bc = "wC'B'bXYZ(C1)t"
    angles = np.array([[0.0, 0.0], [20.0, 30.0], [-25.0, 120.0], [30.0, 250.0], [-10.0, 300.0]])
    rng = np.random.default_rng(1)
    paths = []
    for i, pivots in enumerate(({"B": [-20.0, 0.0, -15.0], "C": [0.0, 0.0, 0.0]},) * 2
                               + ({"B": [-21.0, 0.0, -15.0], "C": [0.0, 0.0, 0.0]},)):
        dev = rng.normal(scale=0.5, size=(5, 3))
        dev[0] = 0.0
        m = Measurement(machine=bc, ball_mm=np.array([20.0 + i, 10.0, 15.0]), t_s=np.arange(5.0), angles_deg=angles,
                        deviation_um=dev, rotary_axes=("B", "C"), metadata={"machine": bc},
                        pivots_mm={a: np.array(v) for a, v in pivots.items()})
        paths.append(str(api.write(m, tmp_path / f"s{i}.csv")))
    result = api.identify_files(paths[:2])
    assert {a: list(v) for a, v in result.result.pivots_mm.items()} == {"B": [-20.0, 0.0, -15.0], "C": [0.0, 0.0, 0.0]}
    with pytest.raises(InputError, match="one nominal geometry"):
        api.identify_files(paths)
