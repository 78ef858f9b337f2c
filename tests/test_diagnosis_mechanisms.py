"""Diagnosis mechanisms: reduction of partly confounded candidates, outlier clusters, head machines, CLI."""

from __future__ import annotations

import json

import numpy as np

from pige_sym.diagnosis.diagnose import diagnose
from pige_sym.model.effects import EffectInstance, EffectSpec, parse_effect
from pige_sym.model.trajectories import cone_frustum, steps
from pige_sym.simulation.simulator import random_pige, simulate

AC = "wC'A'bXYZ(C1)t"


def test_partly_confounded_candidate_is_reduced_not_rejected() -> None:
    """First-harmonic wobble of C: its co-rotating half is a location error (removed and named),
    the counter-rotating half is fitted and reported in the catalogue's parameters."""
    params = {"rx_cos": 8.0, "rx_sin": -6.0, "ry_cos": 5.0, "ry_sin": 7.0}  # both halves present
    eff = EffectInstance(EffectSpec("wobble_C", {"harmonic": 1}), params)
    sim = simulate(AC, steps(AC), pige=random_pige(AC, 11), effects=[eff], noise_um=0.25, seed=11,
                   ball_mm=(120.0, 30.0, 80.0))
    d = diagnose(sim.measurement)
    f = d.findings[0]
    assert (f.effect, f.options["harmonic"]) == ("wobble_C", 1)
    assert len(f.removed) == 2 and all("co-rotating half" in r for r in f.removed)
    assert all("leaves no trace" in r or "indistinguishable from E" in r for r in f.removed)  # says where it went
    kept, shift = f.identifiable_part(params)
    # the kept part is the counter-rotating half (a, -b, b, a) of the truth
    a, b = (params["rx_cos"] + params["ry_sin"]) / 2, (params["ry_cos"] - params["rx_sin"]) / 2
    np.testing.assert_allclose([kept[p] for p in params], [a, -b, b, a], atol=0.3)
    for p in params:
        assert abs(f.params[p] - kept[p]) < 4 * f.std[p]
    assert "identifiable part only, removed" in f.sentence()
    out = json.loads(json.dumps(d.to_dict(), allow_nan=False))  # strict JSON
    assert out["findings"][0]["removed"] == f.removed and len(out["findings"][0]["null_directions"]) == 2
    final = d.final
    for j, p in enumerate(final.parameters):
        if "." not in p:
            assert abs(final.values[j] - sim.truth["pige"][p] - shift.get(p, 0.0)) < 4 * final.std[j], p


def test_cluster_at_one_tilt_is_signal_not_outliers() -> None:
    """All rows at one tilt deviate together: never outliers (on steps data the tilt harmonics can fit it)."""
    tr = steps(AC)
    sim = simulate(AC, tr, pige=random_pige(AC, 4), noise_um=0.25, seed=4)
    m = sim.measurement
    at = np.flatnonzero(np.isclose(m.angles_deg[:, 0], -60.0))
    m.deviation_um[at] += np.array([4.0, -3.0, 2.0])
    d = diagnose(m)
    assert not set(d.outlier_rows) & set(at.tolist())
    assert all(f.effect != "outliers" for f in d.findings)


def test_run_of_rows_becomes_a_pose_cluster_candidate() -> None:
    """Six consecutive rows offset together: found as a pose_cluster effect with its offset, not as
    outliers and not as a stack of harmonics."""
    offset = np.array([3.0, -2.0, 1.5])
    for seed in (4, 5):
        sim = simulate(AC, cone_frustum(AC, points=60), pige=random_pige(AC, seed), noise_um=0.25, seed=seed)
        m = sim.measurement
        m.deviation_um[20:26] += offset
        d = diagnose(m)
        assert [f.effect for f in d.findings] == ["pose_cluster"] and d.outlier_rows == []
        f = d.findings[0]
        assert f.options == {"t_from_s": m.t_s[20], "t_to_s": m.t_s[25]}
        for name, v in zip(("dx_um", "dy_um", "dz_um"), offset, strict=True):
            assert abs(f.params[name] - v) < 4 * f.std[name]


def test_isolated_outliers_are_found_against_the_extended_model() -> None:
    effs = [parse_effect("outliers:count=2,size_um=6", ("A", "C")),
            parse_effect("angular_error_C:harmonic=2,cos_urad=20,sin_urad=-15", ("A", "C"))]
    sim = simulate(AC, steps(AC), pige=random_pige(AC, 5), effects=effs, noise_um=0.25, seed=5)
    d = diagnose(sim.measurement)
    assert [f.effect for f in d.findings] == ["angular_error_C", "outliers"]
    assert d.outlier_rows == sim.truth["outlier_rows"]


def test_head_machines_diagnose_and_cli_never_exits_2(tmp_path, capsys) -> None:
    from pige_sym.cli.main import main

    for code, spec in (("wbXYZCA(C1)t", "backlash_A:b_urad=25"), ("wC'bXYZB(C1)t", "wobble_B:harmonic=2")):
        from pige_sym.kernels import load_kernels

        eff = parse_effect(spec, load_kernels(code).ROTARY_AXES)
        sim = simulate(code, steps(code), pige=random_pige(code, 2), effects=[eff], noise_um=0.25, seed=2,
                       ball_mm=(120.0, 30.0, 80.0), tool_mm=(0.0, 0.0, -250.0))
        path = tmp_path / f"{code[:3]}.csv"
        sim.write(path)
        status = main(["diagnose", str(path), "--json"])  # in this process: a process adds nothing here
        out = capsys.readouterr()
        assert status == 0, out.err
        assert f'"effect": "{eff.spec.id}"' in out.out


def test_decimated_file_gives_the_same_findings() -> None:
    """A dense file and every 10th row of it name the same effect (scale: same findings)."""
    from pige_sym.model.trajectories import Trajectory, dwell_times

    base = cone_frustum(AC, points=2000)
    tr = Trajectory("dense", base.rotary_axes, base.angles_deg, dwell_times(base.angles_deg, move_s=0.1, dwell_s=0.1),
                    "dense cone")
    eff = parse_effect("squareness_XY:gamma_urad=25", ("A", "C"))
    sim = simulate(AC, tr, pige=random_pige(AC, 6), effects=[eff], noise_um=0.25, seed=6)
    dense = diagnose(sim.measurement)
    m = sim.measurement
    keep = np.arange(0, m.n_rows, 10)
    from pige_sym.measurements.measurement import Measurement

    small = Measurement(**{**m.__dict__, "t_s": m.t_s[keep], "angles_deg": m.angles_deg[keep],
                           "deviation_um": m.deviation_um[keep], "linear_mm": m.linear_mm[keep]})
    dec = diagnose(small)
    assert [f.effect for f in dense.findings] == [f.effect for f in dec.findings] == ["squareness_XY"]


def test_harmonics_the_data_cannot_separate_are_reported_as_alternatives() -> None:
    """Table+head, wobble of the B head over 0..-90 deg: harmonics 1 and 2 are nearly collinear; when the
    wrong one wins, the true one must be listed as an alternative (never silently)."""
    from test_diagnosis_grid import BALL, TABLE_HEAD, TOOL, effect, trajectory

    for seed in (1, 7):
        e = effect("wobble_B", np.random.default_rng(seed), 2)
        sim = simulate(TABLE_HEAD, trajectory(TABLE_HEAD, "tilt-short"), pige=random_pige(TABLE_HEAD, seed),
                       effects=[e], noise_um=0.25, seed=seed, ball_mm=BALL, tool_mm=TOOL)
        f = diagnose(sim.measurement).findings[0]
        assert f.effect == "wobble_B"
        if f.options["harmonic"] != 2:
            assert any(a.startswith("wobble_B h2 ") for a in f.alternatives), f.alternatives
            assert "ambiguous: " in f.sentence() and "wobble_B h2" in f.sentence()
