"""Test planning (``pige plan``): prediction vs identification, gain over the default cone, the prediction holding
over simulated runs, limits, reveal rules, the angle file through program / rtest-sim / acquire, grading, report."""

from __future__ import annotations

import functools
import json
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import optimize

from pige_sym.acquisition.virtual_run import start_virtual_device
from pige_sym.cli.main import main
from pige_sym.diagnosis.diagnose import diagnose
from pige_sym.errors import InputError
from pige_sym.identification.least_squares import identify
from pige_sym.kernels import load_kernels
from pige_sym.measurements.rtest import read_angle_file, read_measurement
from pige_sym.model.effects import parse_effect
from pige_sym.model.trajectories import Trajectory, cone_frustum, steps
from pige_sym.planning import PlanRequest, Setup, grade_test, parse_limits, plan_test, predict
from pige_sym.planning.families import linear_violation
from pige_sym.planning.plan import schedule_times
from pige_sym.planning.prediction import Estimable, criterion_gradient, projected_coefficients
from pige_sym.planning.search import search_ball_region, within_limits
from pige_sym.simulation.simulator import random_pige, simulate

AC, BC, HEAD, MIXED = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"
TOOL = {HEAD: (0.0, 0.0, -250.0), MIXED: (0.0, 0.0, -250.0)}
BALL = (120.0, 0.0, 80.0)
NOISE = 0.25


def _setup(code: str, ball=BALL, noise: float = NOISE) -> Setup:
    return Setup(code, ball, TOOL.get(code), noise_um=noise)


def _limits(code: str, extra: list[str] | None = None):
    """Tilt axis -90:90 (contains the default cone), rotary axis endless."""
    kern = load_kernels(code)
    tilt = "A" if "A" in kern.ROTARY_AXES else "B"
    return parse_limits([f"{tilt}=-90:90"] + (extra or []), kern)


def _plan(code: str, points: int = 30, **kw):
    return plan_test(PlanRequest(_setup(code), points, kw.pop("limits", None) or _limits(code), **kw))


@functools.cache
def _default_plan(code: str):
    """The plan of the measures (30 poses, tilt -90..90), made once per machine and timed."""
    t0 = time.perf_counter()
    plan = _plan(code)
    return plan, time.perf_counter() - t0


def _traj(code: str, angles: np.ndarray) -> Trajectory:
    return Trajectory("plan", load_kernels(code).ROTARY_AXES, angles, schedule_times(angles.shape[0], 5, 7), "plan")


# ------------------------------------------------------------------------------------------ prediction


@pytest.mark.parametrize("code", [AC, HEAD])
def test_prediction_is_what_identify_reports_for_the_same_noise(code) -> None:
    """Independent route: simulate + identify gives covariance σ̂²(AᵀA)⁺; rescaled to σ it is the prediction."""
    tr = cone_frustum(code, points=20)
    sim = simulate(code, tr, pige=random_pige(code, 1), ball_mm=BALL, tool_mm=TOOL.get(code), noise_um=NOISE, seed=3)
    res = identify(sim.measurement)
    pred = predict(_setup(code), tr.angles_deg)
    scale = (NOISE / res.sigma_um) ** 2
    np.testing.assert_allclose(pred.covariance, res.covariance * scale, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(pred.std, res.std * np.sqrt(scale), rtol=1e-6)
    assert pred.condition == pytest.approx(res.condition, rel=1e-6) and pred.rank == res.rank == 8


@pytest.mark.parametrize("projection, with_zero", [("y", False), ("xyz", True), ("0.6,0.8,0", True)])
def test_prediction_follows_projection_and_zero_position_errors(projection, with_zero) -> None:
    from pige_sym.model.projection import parse_projection

    tr = cone_frustum(BC, points=24, incl_axis="Y")
    sim = simulate(BC, tr, pige=random_pige(BC, 2), ball_mm=BALL, noise_um=NOISE, seed=5)
    res = identify(sim.measurement, projection=projection, with_zero=with_zero)
    setup = Setup(BC, BALL, noise_um=NOISE, projection=parse_projection(projection), with_zero=with_zero)
    pred = predict(setup, tr.angles_deg)
    assert pred.names == res.parameters
    ok = np.isfinite(res.values)
    assert list(np.array(pred.names)[~ok]) == pred.undetermined
    np.testing.assert_allclose(pred.std[ok], res.std[ok] * NOISE / res.sigma_um, rtol=1e-6)


def test_undetermined_parameters_are_named_never_given_a_number(tmp_path, capsys) -> None:
    """Steps at tilt 0 only: the A axis never moves, so its PIGEs cannot be determined (identify agrees)."""
    tr = steps(AC, tilts=(0.0,))
    pred = predict(_setup(AC), tr.angles_deg)
    sim = simulate(AC, tr, pige=random_pige(AC, 2), ball_mm=BALL, noise_um=NOISE, seed=1)
    res = identify(sim.measurement)
    assert pred.undetermined == ["EY0A", "EZ0A", "EB0A", "EC0A"]
    for name in pred.undetermined:  # identify gives no meaningful number for them either (NaN or round-off noise)
        j = res.parameters.index(name)
        assert not np.isfinite(res.values[j]) or res.std[j] > 1e6
    assert np.all(np.isfinite(pred.std[4:]))
    assert all(pred.std_dict()[n] is None for n in pred.undetermined)
    path = tmp_path / "steps0.csv"
    path.write_text("A_deg,C_deg\n" + "\n".join(f"{a},{c}" for a, c in tr.angles_deg) + "\n")
    assert main(["plan", "--grade", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["undetermined"]) == set(pred.undetermined)
    assert all(out["std"][n] is None for n in pred.undetermined)
    assert out["condition"] is None and "NaN" not in json.dumps(out)


@pytest.mark.parametrize("criterion", ["worst", "A", "D"])
def test_criterion_gradient_matches_finite_differences(criterion) -> None:
    setup = _setup(BC)
    rng = np.random.default_rng(5)
    poses = np.column_stack([rng.uniform(-80, 80, 12), rng.uniform(-180, 180, 12)])
    coef = projected_coefficients(setup)
    est = Estimable.full(8)

    def f(x):
        return criterion_gradient(setup, x.reshape(-1, 2), coef, est, criterion)[0]

    def g(x):
        return criterion_gradient(setup, x.reshape(-1, 2), coef, est, criterion)[1].ravel()

    x0 = poses.ravel()
    err = optimize.check_grad(f, g, x0, epsilon=1e-5)
    assert err < 1e-4 * max(1.0, np.linalg.norm(g(x0)))


# ------------------------------------------------------------------------------------------ measures


@pytest.mark.parametrize("code", [AC, BC, HEAD, MIXED])
def test_planned_worst_std_is_at_most_half_the_default_cone_and_fast(code) -> None:
    plan, elapsed = _default_plan(code)
    assert plan.baseline is not None and plan.baseline_within_limits is True
    cone = cone_frustum(code, points=30).angles_deg
    assert plan.baseline.worst == pytest.approx(predict(_setup(code), cone).worst, rel=1e-12)
    assert plan.points == 30 and plan.prediction.worst <= 0.5 * plan.baseline.worst, (
        plan.prediction.worst, plan.baseline.worst)
    assert within_limits(plan.angles_deg, plan.setup, plan.limits)
    assert np.all(plan.angles_deg[0] == 0)
    assert elapsed <= 10.0


def _empirical_ratio(code: str, plan, runs: int) -> np.ndarray:
    """Empirical std of (estimate - truth) over runs, divided by the predicted std, per PIGE."""
    tr = _traj(code, plan.angles_deg)
    errs = []
    for seed in range(runs):
        truth = random_pige(code, 1000 + seed)
        sim = simulate(code, tr, pige=truth, ball_mm=plan.setup.ball_mm, tool_mm=TOOL.get(code), noise_um=NOISE,
                       seed=seed)
        res = identify(sim.measurement)
        errs.append([res.value(p) - truth[p] for p in res.parameters])
    emp = np.sqrt((np.array(errs) ** 2).mean(axis=0))
    return emp / plan.prediction.std


def test_prediction_holds_over_50_simulated_runs_ac() -> None:
    plan = _default_plan(AC)[0]
    ratio = _empirical_ratio(AC, plan, 50)
    assert np.all((ratio >= 0.65) & (ratio <= 1.5)), dict(zip(plan.prediction.names, np.round(ratio, 3), strict=True))


@pytest.mark.slow
def test_single_rotary_axis_machine_gets_a_stepped_or_free_plan(tmp_path, monkeypatch) -> None:
    """A machine with one rotary axis (kernels generated on first use): no cone, no baseline, still a plan."""
    code = "wC'bXYZ(C1)t"
    plan = plan_test(PlanRequest(Setup(code, BALL), 12, parse_limits(None, load_kernels(code))))
    assert plan.baseline is None and plan.family in ("steps", "free") and not plan.prediction.undetermined
    assert not plan.reveal["squareness_YZ"].revealable and "no Z travel" in plan.reveal["squareness_YZ"].reason


@pytest.mark.slow
@pytest.mark.parametrize("code", [AC, BC, HEAD, MIXED])
def test_prediction_holds_over_50_simulated_runs_every_machine(code) -> None:
    plan = _default_plan(code)[0]
    ratio = _empirical_ratio(code, plan, 50)
    assert np.all((ratio >= 0.65) & (ratio <= 1.5)), dict(zip(plan.prediction.names, np.round(ratio, 3), strict=True))


# ------------------------------------------------------------------------------------------ limits, ball, criteria


@pytest.mark.parametrize("criterion", ["worst", "A", "D"])
def test_batched_scores_equal_one_by_one_scores(criterion) -> None:
    """The population is scored at once in the search: same values as scoring each table alone,
    including tables that leave a linear limit, singular designs and unbuildable ones."""
    from pige_sym.planning.families import Structure
    from pige_sym.planning.prediction import SINGULAR
    from pige_sym.planning.search import _Context, _score, _score_batch, _structural_estimable

    kern = load_kernels(AC)
    limits = parse_limits(["A=-90:90", "Z=-60:200"], kern)
    req = PlanRequest(_setup(AC), 12, limits, criterion=criterion)
    ctx = _Context(req, Structure(), _structural_estimable(req), [], schedule_times(13, 5, 5))
    rng = np.random.default_rng(4)
    tables: list = [np.vstack([np.zeros(2), np.column_stack([rng.uniform(-90, 90, 12), rng.uniform(0, 360, 12)])])
                    for _ in range(6)]
    tables.append(np.vstack([np.zeros(2), np.column_stack([np.full(12, 30.0), np.linspace(0, 330, 12)])]))
    tables.append(np.zeros((13, 2)))  # every pose the reference: singular
    tables.append(None)
    balls = [np.asarray(BALL, dtype=float)] * len(tables)
    batch = _score_batch(ctx, tables, balls)
    single = [2 * SINGULAR if t is None else _score(ctx, t, balls[0]) for t in tables]
    left_limits = [linear_violation(kern, t, req.setup, limits).max() > 1e-6 for t in tables[:-1]]
    assert any(left_limits) and not all(left_limits) and single[-2] == SINGULAR
    np.testing.assert_allclose(batch, single, rtol=1e-9)


def test_rotary_and_linear_limits_are_respected() -> None:
    kern = load_kernels(AC)
    limits = parse_limits(["A=-40:100", "C=-90:270", "Z=-60:200"], kern)
    plan = _plan(AC, 12, limits=limits)
    a = plan.angles_deg
    assert a[:, 0].min() >= -40 and a[:, 0].max() <= 100 and a[:, 1].min() >= -90 and a[:, 1].max() <= 270
    # tolerance as documented in planning.search.within_limits: the 1e-4 deg rounding of the file, 1 µm on X/Y/Z
    assert linear_violation(kern, a, plan.setup, limits).max() <= 1e-3
    z = kern.linear_commands(a, plan.setup.ball_mm)[:, 2]
    assert z.min() >= -60 - 1e-3
    unconstrained = _plan(AC, 6, limits=parse_limits(["A=-40:100", "C=-90:270"], kern))
    assert kern.linear_commands(unconstrained.angles_deg, BALL)[:, 2].min() < -60  # the Z limit was binding


def test_ball_region_is_searched_and_respected() -> None:
    req = PlanRequest(_setup(AC, ball=(100.0, 0.0, 60.0)), 8, _limits(AC), {0: (60.0, 160.0), 2: (40.0, 120.0)})
    plan = plan_test(req)
    x, y, z = plan.setup.ball_mm
    assert 60 <= x <= 160 and y == 0 and 40 <= z <= 120
    assert plan.default_setup_baseline is not None
    fixed = plan_test(PlanRequest(_setup(AC, ball=(100.0, 0.0, 60.0)), 8, _limits(AC)))
    assert plan.prediction.worst <= fixed.prediction.worst * 1.02


def test_each_criterion_wins_on_its_own_measure() -> None:
    worst = _plan(BC, 12, criterion="worst")
    dopt = _plan(BC, 12, criterion="D")
    assert worst.prediction.criterion("worst") <= dopt.prediction.criterion("worst") * 1.001
    assert dopt.prediction.criterion("D") <= worst.prediction.criterion("D") * 1.001


# ------------------------------------------------------------------------------------------ reveal


def test_default_cone_cannot_reveal_backlash_and_says_why() -> None:
    cone = cone_frustum(AC, points=30)
    graded = grade_test(_setup(AC), cone.angles_deg, schedule_times(31, 5, 7))
    st = graded.reveal["backlash_C"]
    assert not st.revealable and "no reversal" in st.reason and all(v is None or v > 0 for v in st.std.values())
    assert not graded.reveal["thermal_drift"].revealable


def test_forced_reveal_gives_reversals_and_repeated_reference_and_diagnosis_finds_them() -> None:
    plan = _plan(AC, 30, reveal=("backlash_C", "thermal_drift"))
    assert plan.reveal["backlash_C"].revealable and plan.reveal["backlash_C"].forced
    assert plan.reveal["thermal_drift"].revealable
    a = plan.angles_deg
    assert (np.abs(a[1:]).max(axis=1) == 0).sum() >= 2  # reference pose measured again
    # round trip: inject backlash into a simulation of the plan; the diagnosis finds it
    eff = parse_effect("backlash_C:b_urad=30", ("A", "C"))
    sim = simulate(AC, _traj(AC, a), pige=random_pige(AC, 4), ball_mm=plan.setup.ball_mm, effects=[eff],
                   noise_um=NOISE, seed=4)
    found = [f.effect for f in diagnose(sim.measurement, candidates=["backlash_C", "thermal_drift"]).findings]
    assert "backlash_C" in found


def test_unrevealable_effect_is_refused_with_a_reason(capsys, tmp_path) -> None:
    assert main(["plan", "--points", "12", "--reveal", "setup_offset", "--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err
    assert "setup_offset" in err and "not even 400 random poses" in err and "confounded" in err
    assert not (tmp_path / "p.csv").exists()
    with pytest.raises(InputError, match="wobble_A"):
        _plan(HEAD, 12, reveal=("wobble_A",))


# ------------------------------------------------------------------------------------------ CLI and the file


def test_cli_plan_json_file_and_grade_agree(tmp_path, capsys) -> None:
    out = tmp_path / "plan.csv"
    assert main(["plan", "--machine", AC, "--points", "16", "--limits", "A=-90:90", "--out", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    for key in ("std", "baseline_std", "ball_mm", "criterion", "condition", "reveal"):
        assert key in data
    assert data["criterion"] == "worst" and data["ball_mm"] == list(BALL)
    assert max(data["std"].values()) <= 0.5 * max(data["baseline_std"].values())
    axes, angles, t = read_angle_file(out)
    assert axes == ("A", "C") and angles.shape == (17, 2) and np.all(angles[0] == 0) and t is not None
    # grading the written file and the NC program made from it gives the same figures
    assert main(["plan", "--grade", str(out), "--json"]) == 0
    graded = json.loads(capsys.readouterr().out)
    assert graded["std"] == pytest.approx(data["std"], rel=1e-9)
    mpf = tmp_path / "plan.mpf"
    assert main(["program", "--machine", AC, "--trajectory", str(out), "--out", str(mpf)]) == 0
    capsys.readouterr()
    assert main(["plan", "--grade", str(mpf), "--json"]) == 0
    from_nc = json.loads(capsys.readouterr().out)
    assert from_nc["std"] == pytest.approx(data["std"], rel=1e-3)
    # never clobbers
    assert main(["plan", "--points", "16", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err


def test_plan_file_runs_through_rtest_sim_and_acquire(tmp_path, capsys) -> None:
    out = tmp_path / "plan.csv"
    assert main(["plan", "--machine", AC, "--points", "12", "--out", str(out)]) == 0
    capsys.readouterr()
    run = tmp_path / "run.csv"
    truth_path = tmp_path / "dev.truth.json"
    with start_virtual_device(AC, str(out), seed=7, time_scale=400, truth=truth_path,
                              extra_args=["--linger", "1"]) as dev:
        status = main(["acquire", "--port", dev.url, "--machine", AC, "--program", str(out), "--out", str(run),
                       "--no-progress", "--timeout", "0.25"])
    assert status == 0
    m = read_measurement(run)
    assert m.n_rows == 13
    np.testing.assert_allclose(m.angles_deg, read_angle_file(out)[1], atol=1e-9)
    truth = json.loads(truth_path.read_text())
    res = identify(m)
    z = [(res.value(p) - truth["pige"][p]) / res.std[i] for i, p in enumerate(res.parameters)]
    assert res.rank == 8 and np.all(np.abs(z) < 4)


@pytest.mark.parametrize("argv, message", [
    (["--limits", "A=10:90"], "excludes 0"),
    (["--limits", "Q=0:1"], "not an axis"),
    (["--limits", "A=90:-90"], "lo < hi"),
    (["--time", "30"], "holds"),
    (["--points", "40", "--time", "300"], "more than --time"),
    (["--criterion", "A", "--reveal", "gremlins"], "unknown effect"),
    (["--ball-region", "w=0:1"], "--ball-region"),
    (["--noise", "nan"], "noise"),
])
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, argv, message) -> None:
    assert main(["plan", *argv, "--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@settings(max_examples=60, deadline=None)
@given(st.floats(-720, 0, allow_nan=False), st.floats(0, 720, allow_nan=False),
       st.floats(-2000, 2000, allow_nan=False), st.floats(0.001, 500, allow_nan=False))
def test_limits_round_trip(lo, hi, zlo, zspan) -> None:
    if lo == hi:
        return
    limits = parse_limits([f"A={lo!r}:{hi!r},Z={zlo!r}:{zlo + zspan!r}"], load_kernels(AC))
    assert limits.rotary["A"] == (lo, hi) and limits.linear["Z"] == (zlo, zlo + zspan)
    assert limits.rotary["C"] == (-np.inf, np.inf) and limits.assumed == []
    wlo, whi = limits.search_bounds("A")
    assert lo <= wlo <= 0 <= whi <= hi and whi - wlo <= 360


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="ACXYZxyzQ=:,.-+0123456789e nai", max_size=24))
def test_limit_and_ball_region_parsers_refuse_cleanly(text) -> None:
    """Any text either parses into finite ranges or raises InputError (never another exception)."""
    for parse in (lambda t: parse_limits([t], load_kernels(AC)), search_ball_region):
        try:
            out = parse(text)
        except InputError:
            continue
        ranges = list(out.values()) if isinstance(out, dict) else [*out.rotary.values(), *out.linear.values()]
        for lo, hi in ranges:
            assert lo <= hi


def test_time_budget_sets_the_points(tmp_path, capsys) -> None:
    assert main(["plan", "--time", "200", "--out", str(tmp_path / "p.csv"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["points"] == 16 and data["duration_s"] <= 200


def test_grade_refuses_an_out_file(tmp_path, capsys) -> None:
    assert main(["plan", "--grade", "cone-frustum", "--out", str(tmp_path / "x.csv")]) == 2
    with pytest.raises(InputError, match="tool"):
        Setup(HEAD, BALL)


# ------------------------------------------------------------------------------------------ report section


def test_report_section_has_every_pige_and_an_embedded_figure(tmp_path) -> None:
    from pige_sym.report.plan_section import plan_section

    plan = _default_plan(HEAD)[0]
    html, png = plan_section(plan, tmp_path)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert 'data-section="plan"' in html and "data:image/png;base64," in html
    for name in plan.prediction.names:
        assert f"<td>{name}</td>" in html
    assert html.count("<tr class=") == len(plan.reveal)
