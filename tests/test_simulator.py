"""Trajectories, projections, effects and the simulator (issue: simulator & file format)."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pige_sym import load_kernels
from pige_sym.errors import InputError
from pige_sym.measurements.rtest import read_measurement
from pige_sym.model.effects import EffectContext, EffectSpec, parse_effect
from pige_sym.model.projection import parse_projection
from pige_sym.model.trajectories import approach_directions, cone_frustum, figure_eight, from_angle_file, steps
from pige_sym.simulation.simulator import parse_pige, random_pige, simulate
from testdata import REPO, reference_files, require_shared

AC, BC = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t"


def rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def tool_direction_independent(code: str, angles_deg: np.ndarray) -> np.ndarray:
    """Spindle (Z) direction in W for a table-table machine: CONVENTIONS §2, primed axes turn by −θ."""
    outer = 0 if "A'" in code else 1
    out = []
    for a_out, c in np.radians(angles_deg):
        r_w = rot(outer, -a_out) @ rot(2, -c)
        out.append(r_w.T @ np.array([0.0, 0.0, 1.0]))
    return np.array(out)


@pytest.mark.parametrize(("code", "incl_axis"), [(AC, "X"), (AC, "Y"), (BC, "X"), (BC, "Y")])
def test_cone_puts_intended_direction_on_spindle(code, incl_axis) -> None:
    tr = cone_frustum(code, half_angle=30, incl=10, incl_axis=incl_axis, points=24, turns=1.5)
    assert np.all(tr.angles_deg[0] == 0) and tr.t_s[0] == 0
    v = tool_direction_independent(code, tr.angles_deg[1:])
    iota = np.radians(10)
    axis = np.array([0, -np.sin(iota), np.cos(iota)]) if incl_axis == "X" else np.array([np.sin(iota), 0, np.cos(iota)])
    np.testing.assert_allclose(v @ axis, np.cos(np.radians(30)), atol=1e-12)  # on the cone
    phi = np.unwrap(np.arctan2(v @ np.cross(axis, [1, 0, 0] - axis[0] * axis), v @ ([1, 0, 0] - axis[0] * axis)))
    np.testing.assert_allclose(np.diff(phi), 2 * np.pi / 24, atol=1e-9)  # evenly spaced, one sense
    assert np.abs(np.diff(tr.angles_deg[1:], axis=0)).max() < 40  # continuous motion (unwrapped)


@pytest.mark.parametrize("code", [AC, BC])
def test_figure_eight_and_steps_shapes(code) -> None:
    f8 = figure_eight(code, amp_tilt=20, amp_rotary=50, points=40)
    tilt_col = 0
    assert np.isclose(np.abs(f8.angles_deg[:, tilt_col]).max(), 20, atol=0.5)
    assert np.isclose(np.abs(f8.angles_deg[:, 1]).max(), 50, atol=0.5)
    st = steps(code, step_deg=45, tilts=(0, -45))
    appr = approach_directions(st.angles_deg)
    assert {1, -1} <= set(appr[:, 1].tolist())  # both directions of approach
    assert np.all(np.diff(st.t_s) == 10.0)


def _approach_by_rows(a: np.ndarray) -> np.ndarray:
    """Oracle, row by row: the sign of the last non-zero move of each axis so far, 0 before any move."""
    out = np.zeros(a.shape, dtype=int)
    for i in range(1, a.shape[0]):
        step = np.sign(a[i] - a[i - 1]).astype(int)
        out[i] = np.where(step != 0, step, out[i - 1])
    return out


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 2), st.lists(st.lists(st.integers(-2, 2), min_size=2, max_size=2), max_size=25))
def test_approach_directions_is_the_last_move_row_by_row(k: int, rows: list[list[int]]) -> None:
    a = np.array(rows, dtype=float).reshape(-1, 2)[:, :k] if k else np.array([r[0] for r in rows], dtype=float)
    got = approach_directions(a)
    assert got.shape == a.shape and got.dtype == np.int_ and np.array_equal(got, _approach_by_rows(a))


@pytest.mark.parametrize("name", ["ac_cone_exact", "bc_cone_exact", "ac_fig8_exact", "bc_fig8_clean",
                                  "ac_steps_angular_error_C"])
def test_trajectories_reproduce_reference_angles(name) -> None:
    require_shared()
    from testdata import REFERENCE

    m = read_measurement(REFERENCE / f"{name}.csv")
    if "cone" in name:
        incl = m.trajectory.split("incl_axis=")[1][0]
        tr = cone_frustum(m.machine, incl_axis=incl)
    elif "fig8" in name:
        tr = figure_eight(m.machine)
    else:
        tr = steps(m.machine)
    np.testing.assert_allclose(tr.angles_deg, m.angles_deg, atol=1e-4)  # files hold 4 decimals
    np.testing.assert_allclose(tr.t_s, m.t_s)


@pytest.mark.parametrize("path", reference_files("*_exact.csv"), ids=lambda p: p.name)
def test_simulating_reference_truth_reproduces_exact_files(tmp_path, path) -> None:
    require_shared()
    m = read_measurement(path)
    truth = json.loads(path.with_name(path.stem + ".truth.json").read_text())
    angle_file = tmp_path / "angles.csv"
    angle_file.write_text("t_s," + ",".join(f"{a}_deg" for a in m.rotary_axes) + "\n" + "\n".join(
        ",".join(repr(float(x)) for x in (t, *a)) for t, a in zip(m.t_s, m.angles_deg, strict=True)) + "\n")
    tr = from_angle_file(m.machine, angle_file)
    sim = simulate(m.machine, tr, pige=truth["pige"], ball_mm=m.ball_mm, noise_um=0.0)
    assert np.abs(sim.measurement.deviation_um - m.deviation_um).max() < 1e-3


def test_simulated_angular_error_matches_reference() -> None:
    require_shared()
    from testdata import REFERENCE

    m = read_measurement(REFERENCE / "ac_steps_angular_error_C.csv")
    truth = json.loads((REFERENCE / "ac_steps_angular_error_C.truth.json").read_text())
    et = truth["effect_truth"]
    eff = parse_effect(f"angular_error_C:harmonic={et['harmonic']},cos_urad={et['cos_urad']},sin_urad={et['sin_urad']}",
                       m.rotary_axes)
    sim = simulate(m.machine, steps(m.machine), pige=truth["pige"], ball_mm=m.ball_mm, effects=[eff], noise_um=0.0)
    resid = sim.measurement.deviation_um - m.deviation_um
    assert np.sqrt((resid**2).mean()) < 0.35  # the file's noise sigma is 0.25 µm


def test_commanded_linear_positions_with_offset_pivots_match_hand_formula() -> None:
    # AC table whose A and C axes do not intersect: C line offset in Y, A line offset in Z.
    p_a = np.array([0.0, 0.0, -60.0])
    p_c = np.array([0.0, 25.0, 0.0])
    ball = np.array([100.0, 20.0, 50.0])
    tr = cone_frustum(AC, points=12)
    sim = simulate(AC, tr, pige={}, ball_mm=ball, pivots_mm={"A": p_a, "C": p_c}, noise_um=0.0)
    for (a, c), xyz in zip(tr.angles_deg, sim.measurement.linear_mm, strict=True):
        ra, rc = np.radians(a), np.radians(c)
        # C' turns the work by -C about its line through p_c, then A' by -A about its line through p_a
        v = ball - p_c
        v = np.array([v[0] * np.cos(rc) + v[1] * np.sin(rc), -v[0] * np.sin(rc) + v[1] * np.cos(rc), v[2]]) + p_c
        w = v - p_a
        w = np.array([w[0], w[1] * np.cos(ra) + w[2] * np.sin(ra), -w[1] * np.sin(ra) + w[2] * np.cos(ra)]) + p_a
        np.testing.assert_allclose(xyz, w, atol=1e-10)


def test_projection_parsing() -> None:
    assert parse_projection("xyz").is_full
    np.testing.assert_allclose(parse_projection("y").directions, [[0, 1, 0]])
    np.testing.assert_allclose(parse_projection("3,4,0").directions, [[0.6, 0.8, 0]])
    r = rot(2, 0.3)
    pr = parse_projection("htm:" + ",".join(map(str, r.ravel())) + "@y")
    np.testing.assert_allclose(pr.directions, [r[:, 1]])
    d = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_allclose(parse_projection("htm:" + ",".join(map(str, r.ravel()))).apply_data(d), d @ r)
    for bad in ["w", "1,2", "0,0,0", "htm:1,2,3", "htm:1,0,0,0,2,0,0,0,1"]:
        with pytest.raises(InputError):
            parse_projection(bad)


@pytest.mark.parametrize("effect", ["thermal_drift", "angular_error_C", "wobble_A", "radial_runout_C",
                                    "backlash_C", "squareness_XY", "squareness_YZ", "squareness_ZX", "setup_offset"])
def test_effect_columns_are_linear_and_zero_at_reference(effect) -> None:
    kern = load_kernels(AC)
    tr = steps(AC, step_deg=60)
    ctx = EffectContext(kern, tr.angles_deg, tr.t_s, np.array([120.0, 10.0, 80.0]))
    spec = EffectSpec(effect, {"harmonic": 2, "tau_s": 100.0})
    cols = spec.columns(ctx)
    assert cols.shape == (len(tr.t_s), 3, len(spec.param_names))
    np.testing.assert_allclose(cols[0], 0, atol=1e-12)
    assert np.abs(cols).max() > 1e-3
    p = {n: float(i + 1) for i, n in enumerate(spec.param_names)}
    np.testing.assert_allclose(spec.contribution(ctx, p), cols @ np.arange(1.0, len(p) + 1))


def test_effect_signs_on_simple_cases() -> None:
    kern = load_kernels(AC)
    angles = np.array([[0.0, 0.0], [0.0, 90.0], [0.0, 180.0]])
    ball = np.array([100.0, 0.0, 0.0])
    ctx = EffectContext(kern, angles, np.array([0.0, 10.0, 20.0]), ball)
    # C stands at θ + e: the work (nest) turns by −e more, so ball − nest = +e × r, tangential
    col = EffectSpec("angular_error_C", {"harmonic": 1}).columns(ctx)[:, :, 0]  # e = cos θ [µrad]
    # at C=90 the point (100,0,0) sits at (0,-100,0); e = cos 90° = 0 → only the zeroing term remains
    # at C=180 e = -1 µrad: nest at (-100,0,0) turned by +1 µrad → nest y = -0.1 µm, ball-nest dy = +0.1 µm
    # zeroing: reference offset (e=1: nest y=-0.1 µm → d=(0,0.1,0)) turned with the table by -180° → (0,-0.1,0)
    np.testing.assert_allclose(col[2], [0.0, 0.1 - (-0.1), 0.0], atol=1e-9)
    drift = EffectSpec("thermal_drift", {"tau_s": 10.0}).columns(ctx)
    np.testing.assert_allclose(drift[1, :, 0], [1 - np.exp(-1), 0, 0])


def test_random_pige_ranges_and_parsing(tmp_path) -> None:
    vals = random_pige(AC, seed=4)
    kern = load_kernels(AC)
    for name, v in vals.items():
        assert 1.0 <= abs(v) <= 15.0 + 1e-12, (name, v)
    assert parse_pige("EXOC=3,eb0a=-2", AC) == {"EX0C": 3.0, "EB0A": -2.0}
    f = tmp_path / "t.json"
    f.write_text(json.dumps({"pige": {"EY0A": 1.5}}))
    assert parse_pige(str(f), AC) == {"EY0A": 1.5}
    with pytest.raises(InputError, match="unknown parameter"):
        parse_pige("EX0B=1", AC)
    assert set(vals) == set(kern.LOCATION_PARAMETERS)


def test_simulator_noise_outliers_and_table_frame() -> None:
    tr = cone_frustum(AC)
    eff = parse_effect("outliers:count=3,size_um=12", ("A", "C"))
    a = simulate(AC, tr, pige={"EY0A": 5}, effects=[eff], noise_um=0.0, seed=2)
    assert len(a.truth["outlier_rows"]) == 3 and 0 not in a.truth["outlier_rows"]
    b = simulate(AC, tr, pige={"EY0A": 5}, noise_um=0.0, seed=2, frame="table")
    kern = load_kernels(AC)
    back = b.measurement.deviation_machine_um(kern)
    clean = simulate(AC, tr, pige={"EY0A": 5}, noise_um=0.0).measurement.deviation_um
    np.testing.assert_allclose(back, clean, atol=1e-12)
    noisy = simulate(AC, tr, pige={}, noise_um=0.5, seed=9).measurement.deviation_um
    assert 0.35 < noisy[1:].std() < 0.65 and np.all(noisy[0] == 0)


def test_cli_simulate_fast_and_valid(tmp_path) -> None:
    out = tmp_path / "run.csv"
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pige_sym", "simulate", "--machine", AC, "--trajectory",
                           "cone-frustum", "--pige", "random", "--seed", "1", "--out", str(out)],
                          capture_output=True, text=True, cwd=REPO, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert time.perf_counter() - t0 < 10  # process start included; the simulation itself is ~ms
    m = read_measurement(out)
    assert m.n_rows == 31 and m.linear_mm is not None
    assert json.loads(out.with_name("run.truth.json").read_text())["seed"] == 1
    bad = subprocess.run([sys.executable, "-m", "pige_sym", "simulate", "--effect", "wobble_B", "--out",
                          str(out)], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "wobble_B" in bad.stderr
