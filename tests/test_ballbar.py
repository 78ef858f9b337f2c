"""The double ballbar (CONVENTIONS §8): exact lengths, the file format, joint multi-setup identification."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.errors import FileFormatError
from pige_sym.identification.joint import identify_joint
from pige_sym.identification.least_squares import identify
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import format_ballbar, read_ballbar, write_ballbar
from pige_sym.model.trajectories import make_trajectory
from pige_sym.simulation.ballbar import ballbar_setup, simulate_ballbar
from pige_sym.simulation.exact_table import nominal_table_point, table_point
from pige_sym.simulation.simulator import random_pige, simulate

AC, BC = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t"
SETS = [(kind, axis, tilt) for kind in ("radial", "tangential", "axial") for axis, tilt in (("C", 0.0), ("C", -45.0),
                                                                                            ("A", 0.0))]


@pytest.mark.parametrize("machine", [AC, BC])
def test_the_exact_table_agrees_with_the_first_order_kernels(machine) -> None:
    """An independent exact rigid-body chain (Rodrigues rotations about the erroneous axis lines)."""
    kern = load_kernels(machine)
    a = make_trajectory(machine, "cone-frustum").angles_deg
    values = random_pige(machine, 3) | {kern.ZERO_PARAMETERS[0]: 20.0, kern.ZERO_PARAMETERS[1]: -15.0}
    q = np.array([120.0, 0.0, 80.0])
    raw = (nominal_table_point(machine, a, q) - table_point(machine, a, q, values)) * 1e3
    d = raw - np.einsum("nij,j->ni", kern.workpiece_rotation(a), raw[0])
    first_order = kern.deviation(a, np.array([values.get(n, 0.0) for n in kern.PARAMETERS]), q)
    np.testing.assert_allclose(d, first_order, atol=1e-3)
    assert np.abs(first_order).max() > 5


def _runs(truth: dict[str, float], noise: float = 0.2, machine: str = AC) -> list:
    tilt_axis = "A" if machine == AC else "B"
    return [(f"{k} {a if a == 'C' else tilt_axis} {t:g}",
             simulate_ballbar(machine, ballbar_setup(machine, k, a if a == "C" else tilt_axis, tilt_deg=t),
                              pige=truth, noise_um=noise, seed=i))
            for i, (k, a, t) in enumerate(SETS)]


@pytest.mark.parametrize("machine", [AC, BC])
def test_nine_setups_determine_every_pige_with_honest_errors(machine) -> None:
    truth = random_pige(machine, 5)
    result = identify_joint(_runs(truth, machine=machine)).result
    assert result.rank == 8 and not result.unidentifiable
    z = [(result.value(n) - truth[n]) / result.std[i] for i, n in enumerate(result.parameters)]
    assert max(abs(v) for v in z) < 4.0, np.round(z, 2)


def test_a_single_setup_names_what_it_cannot_see_and_gives_it_no_value() -> None:
    truth = random_pige(AC, 5)
    label, run = _runs(truth)[0]
    result = identify_joint([(label, run)]).result
    assert result.rank < 8 and result.unidentifiable
    assert np.isnan(result.values).sum() >= 8 - result.rank
    assert all(np.isnan(result.std[i]) for i in range(8) if np.isnan(result.values[i]))


def test_a_constant_added_to_a_relative_file_changes_nothing() -> None:
    runs = _runs(random_pige(AC, 7))
    base = identify_joint(runs).result
    shifted = [(lab, dataclasses.replace(r, dl_um=r.dl_um + 37.0)) if i == 2 else (lab, r)
               for i, (lab, r) in enumerate(runs)]
    moved = identify_joint(shifted).result
    np.testing.assert_allclose(moved.values, base.values, atol=1e-9)
    np.testing.assert_allclose(moved.std, base.std, rtol=1e-9)


def test_mixed_rtest_and_ballbar_agree_with_each_alone() -> None:
    truth = random_pige(AC, 9)
    rtest = simulate(AC, make_trajectory(AC, "cone-frustum"), pige=truth, noise_um=0.3, seed=1).measurement
    alone_r = identify(rtest)
    alone_b = identify_joint(_runs(truth)).result
    mixed = identify_joint([("rtest", rtest), *_runs(truth)])
    joint = mixed.result
    for i in range(8):
        for other in (alone_r, alone_b):
            gap = abs(joint.values[i] - other.values[i])
            assert gap < 3 * np.hypot(joint.std[i], other.std[i]), joint.parameters[i]
        assert joint.std[i] <= min(alone_r.std[i], alone_b.std[i]) * 1.05
    assert [f.instrument for f in mixed.files][:2] == ["rtest", "ballbar"]


def test_the_format_round_trips_and_bad_files_are_refused_with_their_line(tmp_path) -> None:
    label, run = _runs(random_pige(AC, 2))[0]
    path = write_ballbar(run, tmp_path / "r.csv")
    back = read_ballbar(path)
    np.testing.assert_array_equal(back.dl_um, run.dl_um)
    np.testing.assert_array_equal(back.angles_deg, run.angles_deg)
    text = format_ballbar(run)
    lines = text.splitlines()
    header = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    cases = {
        "first dL_um is not 0": lines[:header + 1] + [lines[header + 1].rsplit(",", 1)[0] + ",0.5"]
        + lines[header + 2:],
        "not a finite number": lines[:header + 3] + [lines[header + 3].rsplit(",", 1)[0] + ",nan"] + lines[header + 4:],
        "columns must be": lines[:header] + ["t_s,A_deg,dL_um"] + lines[header + 1:],
        "bar length": [ln.replace("# offset_mm: 100.0, 0.0, 0.0", "# offset_mm: 1.0, 0.0, 0.0") for ln in lines],
        "missing required metadata '# zero": [ln for ln in lines if not ln.startswith("# zero")],
    }
    for fragment, body in cases.items():
        bad = tmp_path / "bad.csv"
        bad.write_text("\n".join(body) + "\n")
        with pytest.raises(FileFormatError, match=fragment) as err:
            read_ballbar(bad)
        assert ":" in str(err.value).split(fragment)[0]


def test_the_commands(tmp_path, capsys) -> None:
    files = []
    for kind, axis, tilt in SETS:
        out = tmp_path / f"{kind}_{axis}{tilt:g}.csv"
        assert main(["simulate", "--instrument", "ballbar", "--setup", kind, "--axis", axis, "--tilt", str(tilt),
                     "--pige", "EX0C=6,EY0A=-4", "--seed", "3", "--noise", "0.1", "--out", str(out)]) == 0
        files.append(str(out))
    capsys.readouterr()
    assert main(["identify", *files]) == 0
    out = capsys.readouterr().out
    assert "rank 8/8" in out and "own sigma" in out
    assert main(["identify", files[0]]) == 0
    assert "not identifiable" in capsys.readouterr().out
    assert main(["program", "--instrument", "ballbar", "--setup", "tangential", "--axis", "C",
                 "--out", str(tmp_path / "bb.mpf")]) == 0
    assert "TRAORI" in (tmp_path / "bb.mpf").read_text()
    assert main(["plan", "--instrument", "ballbar", "--noise", "0.2", "--target", "3"]) == 0
    assert "chosen:" in capsys.readouterr().out


def _exact_length(machine: str, setup, pige: dict[str, float], angles_true: np.ndarray,
                  tool_shift_um: np.ndarray | None = None) -> np.ndarray:
    """Oracle: |T − P| − L0 [µm] with the table at ``angles_true`` and the tool ball moved by a machine-frame shift."""
    tool = nominal_table_point(machine, setup.angles_deg, setup.table_ball_mm + setup.offset_mm)
    if tool_shift_um is not None:
        tool = tool + tool_shift_um * 1e-3
    ball = table_point(machine, angles_true, setup.table_ball_mm, pige)
    return (np.linalg.norm(tool - ball, axis=1) - np.linalg.norm(setup.offset_mm)) * 1e3


@pytest.mark.parametrize("kind,axis,tilt,seen", [("tangential", "C", -30.0, True), ("tangential", "A", 0.0, True),
                                                  ("radial", "A", 0.0, False), ("axial", "C", 0.0, False)])
def test_an_angular_error_in_the_ballbar_simulation_is_the_table_standing_elsewhere(kind, axis, tilt, seen) -> None:
    """Oracle: the exact chain with the swept axis at θ + c·cos 2θ (CONVENTIONS: the axis stands at θ + e(θ))."""
    from pige_sym.model.effects import parse_effect

    setup = ballbar_setup(AC, kind, axis, tilt_deg=tilt)
    truth = {"EX0C": 4.0, "EA0C": -6.0}
    effect = parse_effect(f"angular_error_{axis}:harmonic=2,cos_urad=40,sin_urad=-25", ("A", "C"))
    run = simulate_ballbar(AC, setup, pige=truth, noise_um=0.0, effects=[effect])
    k = ("A", "C").index(axis)
    theta = np.radians(setup.angles_deg[:, k])
    true_angles = setup.angles_deg.copy()
    true_angles[:, k] += np.degrees((40.0 * np.cos(2 * theta) - 25.0 * np.sin(2 * theta)) * 1e-6)
    oracle = _exact_length(AC, setup, truth, true_angles)
    oracle -= oracle[0]
    without = simulate_ballbar(AC, setup, pige=truth, noise_um=0.0).dl_um
    np.testing.assert_allclose(run.dl_um, oracle, atol=2e-3)
    # only a tangential bar sees the table turning about the swept axis (first order)
    assert (np.abs(run.dl_um - without).max() > 0.5) == seen


def test_a_thermal_drift_in_the_ballbar_simulation_moves_the_tool_ball(tmp_path) -> None:
    """Oracle: the tool ball shifted by v·(1 − exp(−t/τ)) in the machine frame, t = 2 s per pose, absolute zero."""
    from pige_sym.model.effects import parse_effect

    setup = ballbar_setup(AC, "radial", "C", tilt_deg=-20.0)
    effect = parse_effect("thermal_drift:vx_um=3,vy_um=-2,vz_um=1.5,tau_s=40", ("A", "C"))
    run = simulate_ballbar(AC, setup, pige={"EY0A": 2.0}, noise_um=0.0, zero="absolute", effects=[effect])
    f = 1.0 - np.exp(-run.t_s / 40.0)
    oracle = _exact_length(AC, setup, {"EY0A": 2.0}, setup.angles_deg, np.outer(f, [3.0, -2.0, 1.5]))
    np.testing.assert_allclose(run.dl_um, oracle, atol=2e-3)
    out = tmp_path / "drift.csv"
    assert main(["simulate", "--instrument", "ballbar", "--setup", "radial", "--axis", "C", "--tilt", "-20",
                 "--pige", "EY0A=2", "--effect", "thermal_drift:vx_um=3,vy_um=-2,vz_um=1.5,tau_s=40",
                 "--effect", "outliers:size_um=30,count=2", "--noise", "0", "--zero", "absolute",
                 "--out", str(out)]) == 0
    import json

    truth = json.loads((tmp_path / "drift.truth.json").read_text())
    assert [e["effect"] for e in truth["effects"]] == ["thermal_drift", "outliers"]
    rows = truth["outlier_rows"]
    assert len(rows) == 2
    read = read_ballbar(out)
    jump = np.abs(read.dl_um - oracle)
    assert set(np.flatnonzero(jump > 1e-2)) <= set(rows)
