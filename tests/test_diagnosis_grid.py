"""Hidden-effect and null grids of the diagnosis over machines, axes, harmonics and pairs.

Sizes are drawn per seed in realistic ranges (10–40 µrad, 1–5 µm, drift 2–7 µm).  A case
passes when the hidden effect(s) are named first, every parameter lies within 4 standard
errors of the part of the truth the data can determine (``Finding.identifiable_part``) and
every PIGE within 4 standard errors of the truth plus what a removed (confounded) part of
the effect shifts into it; or, when the effect is wholly confounded with the PIGEs on that
machine and trajectory, nothing is found and the confounding PIGEs are named.  A
representative subset runs by default; the whole grid is marked ``slow``
(``pytest -m slow tests/test_diagnosis_grid.py``).

The whole grid checks about 5000 parameters, so a handful of 4σ exceedances is what honest
standard errors produce by chance (expected ≈ 0.3 per run).  There, each case must name its
effect(s) and keep every parameter within 5 standard errors (p ≈ 6e-7 each), and the grid as
a whole must be calibrated: no more 4σ exceedances than chance allows at 0.1 % (Poisson), and
an RMS z-score within [0.8, 1.25] (standard errors neither too small nor too large).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from pige_sym.diagnosis.diagnose import diagnose
from pige_sym.kernels import load_kernels
from pige_sym.model.effects import EffectInstance, EffectSpec
from pige_sym.model.trajectories import cone_frustum, figure_eight, steps
from pige_sym.simulation.simulator import random_pige, simulate

AC, BC, FORK, TABLE_HEAD = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"
MACHINES = (AC, BC, FORK, TABLE_HEAD)
RANGES = {"angular_error": (10, 40), "wobble": (10, 40), "backlash": (10, 40), "squareness": (10, 40),
          "radial_runout": (1, 5), "thermal_drift": (2, 7), "setup_offset": (5, 20)}
BALL, TOOL = (120.0, 30.0, 80.0), (0.0, 0.0, -250.0)


def roles(code: str) -> tuple[str, str]:
    """(tilt axis, rotary axis) of a machine."""
    k = load_kernels(code)
    rot = next(a for a in k.ROTARY_AXES if a[0] == "ABC"[k.SPINDLE_DIRECTION])
    return next(a for a in k.ROTARY_AXES if a != rot), rot


def effect(eid: str, rng: np.random.Generator, harmonic: int | None = None, counter: int = 0) -> EffectInstance:
    """An effect with random realistic sizes (module docstring)."""
    opts: dict[str, float] = {} if harmonic is None else {"harmonic": harmonic}
    spec0 = EffectSpec(eid, opts)
    if spec0.kind == "thermal_drift":
        opts = {"tau_s": float(rng.uniform(150, 400))}
    spec = EffectSpec(eid, opts)
    lo, hi = RANGES[spec.kind]
    params = {p: float(rng.choice([-1, 1]) * rng.uniform(lo, hi)) for p in spec.param_names}
    if counter:  # a first-harmonic tilt turning against the axis' body: (a, ∓b, ±b, ±a)
        n = spec.param_names  # counter = +1: the body turns by R(−θ) in its carrier frame (table axes)
        a, b = params[n[0]], params[n[1]]
        params = {n[0]: a, n[1]: -counter * b, n[2]: counter * b, n[3]: counter * a}
    return EffectInstance(spec, params)


def trajectory(code: str, kind: str):
    """The test trajectories (module docstring): ``cone``, ``fig8``, ``steps``, ``tilt`` and ``tilt-short``."""
    if kind == "cone":
        return cone_frustum(code, points=40, incl_axis="X" if code == AC else "Y")
    if kind == "fig8":
        return figure_eight(code)
    if kind == "tilt":  # C sweeps at 19 tilts over ±90°: the tilt axis' harmonics and the squareness are observable
        return steps(code, step_deg=45.0, tilts=tuple(float(t) for t in np.arange(90, -100, -10)))
    if kind == "tilt-short":  # 10 tilts over 0..-90° only: neighbouring tilt-axis harmonics nearly collinear
        return steps(code, step_deg=45.0, tilts=tuple(float(t) for t in np.arange(0, -100, -10)))
    return steps(code)


def cases() -> list[tuple[str, str, str, int | None, bool, str]]:
    """(machine, effect id, second effect id or '', harmonic, counter-rotating, trajectory)."""
    out = []
    for code in MACHINES:
        tilt, rot = roles(code)
        for h in (1, 2, 3):
            out.append((code, f"angular_error_{rot}", "", h, False, "steps"))
            out.append((code, f"wobble_{rot}", "", h, False, "steps"))
            out.append((code, f"radial_runout_{rot}", "", h, False, "steps"))
            out.append((code, f"angular_error_{tilt}", "", h, False, "tilt"))
            out.append((code, f"wobble_{tilt}", "", h, False, "tilt"))
            out.append((code, f"radial_runout_{tilt}", "", h, False, "tilt"))
        if rot in load_kernels(code).WORKPIECE_ROTARY:  # "against the table": table axes only
            out.append((code, f"wobble_{rot}", "", 1, True, "steps"))
        out.append((code, f"backlash_{rot}", "", None, False, "steps"))
        out.append((code, f"backlash_{tilt}", "", None, False, "steps"))
        out += [(code, f"squareness_{p}", "", None, False, "tilt") for p in ("XY", "YZ", "ZX")]
        out.append((code, "thermal_drift", "", None, False, "cone"))
        out.append((code, "setup_offset", "", None, False, "cone"))
        out.append((code, f"angular_error_{rot}", f"backlash_{rot}", 2, False, "steps"))
        out.append((code, f"radial_runout_{rot}", "thermal_drift", 2, False, "steps"))
    return out


ALL = cases()
SUBSET = [
    (AC, "wobble_C", "", 1, True, "steps"), (AC, "wobble_C", "", 1, False, "steps"),
    (BC, "angular_error_C", "", 2, False, "steps"), (BC, "angular_error_B", "", 1, False, "tilt"),
    (FORK, "backlash_A", "", None, False, "steps"), (FORK, "angular_error_C", "backlash_C", 2, False, "steps"),
    (TABLE_HEAD, "radial_runout_C", "", 3, False, "steps"), (TABLE_HEAD, "backlash_B", "", None, False, "steps"),
    (AC, "thermal_drift", "", None, False, "cone"), (BC, "squareness_XY", "", None, False, "tilt"),
]


def run_case(code: str, eid: str, eid2: str, h: int | None, counter: bool, traj: str, seed: int,
             limit: float = 4.0) -> str | None:
    """None when the case passes (every parameter within ``limit`` standard errors), else what failed."""
    message, _ = case_result(code, eid, eid2, h, counter, traj, seed, limit)
    return message


@functools.cache
def case_result(code: str, eid: str, eid2: str, h: int | None, counter: bool, traj: str, seed: int,
                limit: float = 4.0) -> tuple[str | None, tuple[float, ...]]:
    """What failed (or None) and the z-scores of every checked parameter (effects, then PIGEs)."""
    rng = np.random.default_rng(seed)
    sense = (1 if eid[-1] in load_kernels(code).WORKPIECE_ROTARY else -1) if counter else 0
    first = effect(eid, rng, h if eid.split("_")[0] in ("angular", "wobble", "radial") else None, sense)
    effs = [first] + ([effect(eid2, rng, 2 if eid2.split("_")[0] in ("angular", "wobble", "radial") else None)]
                      if eid2 else [])
    tool = TOOL if load_kernels(code).TOOL_ROTARY else None
    sim = simulate(code, trajectory(code, traj), pige=random_pige(code, seed), effects=effs, noise_um=0.25,
                   seed=seed, ball_mm=BALL, tool_mm=tool)
    d = diagnose(sim.measurement)
    named = [(f.effect, f.options.get("harmonic")) for f in d.findings]
    rejected = {r.effect: r.reason for r in d.rejected}
    if not eid2 and not named and rejected.get(eid, "").startswith("unidentifiable with the PIGEs: "):
        # wholly confounded on this machine and trajectory (e.g. squareness YZ with the B head tilt on a
        # cone): the right answer is no finding and the confounding named, e.g. "... from EA0B [urad]"
        return (None if " E" in rejected[eid] else f"confounded but not named: {rejected[eid]}"), ()
    want = {(e.spec.id, e.spec.options.get("harmonic")) for e in effs}
    if set(named[: len(effs)]) != want:
        return f"named {named}, hidden {sorted(want, key=str)}", ()
    shift_total: dict[str, float] = {}
    zs: list[float] = []
    failed: str | None = None
    for e in effs:
        f = next(f for f in d.findings if f.effect == e.spec.id)
        kept, shift = f.identifiable_part(e.params)
        for k, v in shift.items():
            shift_total[k] = shift_total.get(k, 0.0) + v
        for p, v in kept.items():
            zs.append((f.params[p] - v) / f.std[p])
            if not abs(zs[-1]) < limit:
                failed = failed or f"{e.spec.id}.{p} = {f.params[p]:.3g} ± {f.std[p]:.2g}, truth part {v:.3g}"
        if counter and e is first and shift:
            return f"counter-rotating wobble moved PIGEs {shift}", tuple(zs)
    final = d.final
    for j, p in enumerate(final.parameters):
        if "." in p:
            continue
        truth = sim.truth["pige"][p] + shift_total.get(p, 0.0)
        zs.append((final.values[j] - truth) / final.std[j])
        if not abs(zs[-1]) < limit:
            failed = failed or f"PIGE {p} = {final.values[j]:.3g} ± {final.std[j]:.2g}, truth {truth:.3g}"
    return failed, tuple(zs)


def ids(c: tuple) -> str:
    code, eid, eid2, h, counter, traj = c
    return f"{code}-{eid}{'+' + eid2 if eid2 else ''}-h{h}{'-counter' if counter else ''}-{traj}"


@pytest.mark.parametrize("case", SUBSET, ids=ids)
def test_hidden_effect_subset(case) -> None:
    assert run_case(*case, seed=7) is None, run_case(*case, seed=7)


GRID_SEEDS = (1, 2, 3)


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=ids)
def test_hidden_effect_full_grid(case) -> None:
    """Named right, every parameter within 5σ (the 4σ rate is judged over the grid, below)."""
    fails = [f"seed {s}: {msg}" for s in GRID_SEEDS if (msg := case_result(*case, seed=s, limit=5.0)[0]) is not None]
    assert not fails, fails


def chance_exceedances(n_checks: int, sigma: float = 4.0, alpha: float = 1e-3) -> int:
    """Most |z| > ``sigma`` among ``n_checks`` honest z-scores that chance gives with probability >= 1 - alpha."""
    from scipy import stats

    p = 2 * stats.norm.sf(sigma)
    return int(stats.poisson.ppf(1 - alpha, n_checks * p))


def test_chance_exceedance_bound() -> None:
    """The bound the full grid uses: about 5000 checks allow 3 exceedances of 4σ (expected 0.32)."""
    assert chance_exceedances(5000) == 3
    assert chance_exceedances(100) == 1


@pytest.mark.slow
def test_full_grid_standard_errors_are_calibrated() -> None:
    """Over the whole grid: 4σ exceedances no more than chance allows, RMS z within [0.8, 1.25]."""
    zs = np.array([z for case in ALL for s in GRID_SEEDS for z in case_result(*case, seed=s, limit=5.0)[1]])
    beyond = int(np.sum(np.abs(zs) >= 4.0))
    rms = float(np.sqrt(np.mean(zs**2)))
    assert zs.size > 3000
    assert beyond <= chance_exceedances(zs.size), (beyond, zs.size)
    assert 0.8 <= rms <= 1.25, rms


def silent_wrong_name(code: str, eid: str, traj: str, seed: int) -> str | None:
    """None unless a finding is named while the hidden effect is neither named nor listed as an alternative."""
    rng = np.random.default_rng(seed)
    e = effect(eid, rng)
    tool = TOOL if load_kernels(code).TOOL_ROTARY else None
    sim = simulate(code, trajectory(code, traj), pige=random_pige(code, seed), effects=[e], noise_um=0.25, seed=seed,
                   ball_mm=BALL, tool_mm=tool)
    findings = diagnose(sim.measurement).findings
    if not findings or any(f.effect == eid for f in findings):
        return None
    if any(a.startswith(f"{eid} ") for f in findings for a in f.alternatives):
        return None
    return f"named {[(f.effect, f.alternatives) for f in findings]}, hidden {eid}"


AMBIGUOUS_CASES = [(code, f"squareness_{p}") for code in MACHINES for p in ("XY", "YZ", "ZX")]


@pytest.mark.parametrize(("code", "eid", "seed"), [(AC, "squareness_ZX", 3), (BC, "squareness_YZ", 3)])
def test_squareness_on_a_cone_is_reported_ambiguous(code, eid, seed) -> None:
    """On the cone these name another squareness first (nearly collinear): the hidden one must be listed."""
    assert silent_wrong_name(code, eid, "cone", seed) is None, silent_wrong_name(code, eid, "cone", seed)


@pytest.mark.slow
@pytest.mark.parametrize(("code", "eid"), AMBIGUOUS_CASES, ids=[f"{c}-{e}" for c, e in AMBIGUOUS_CASES])
def test_ambiguity_reported_full_grid(code, eid) -> None:
    fails = [f"seed {s}: {msg}" for s in range(1, 11) if (msg := silent_wrong_name(code, eid, "cone", s)) is not None]
    assert not fails, fails


NULL_CASES = [(code, traj) for code in MACHINES for traj in ("cone", "fig8", "steps", "tilt")]


def quiet_share(code: str, traj: str, seeds: range) -> float:
    tool = TOOL if load_kernels(code).TOOL_ROTARY else None
    quiet = 0
    for s in seeds:
        sim = simulate(code, trajectory(code, traj), pige=random_pige(code, s), noise_um=0.25, seed=900 + s,
                       ball_mm=BALL, tool_mm=tool)
        quiet += not diagnose(sim.measurement).findings
    return quiet / len(seeds)


@pytest.mark.parametrize(("code", "traj"), [(FORK, "cone"), (TABLE_HEAD, "steps")])
def test_null_head_machines(code, traj) -> None:
    assert quiet_share(code, traj, range(10)) >= 0.9  # 10 seeds: at most one false finding


@pytest.mark.slow
@pytest.mark.parametrize(("code", "traj"), NULL_CASES)
def test_null_full_grid(code, traj) -> None:
    assert quiet_share(code, traj, range(40)) >= 0.95
