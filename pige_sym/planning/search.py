"""Planning and grading: search the families and the ball position, pick the best test, describe it.

Search
------
Every family of :mod:`pige_sym.planning.families` is optimised per discrete variant with
``scipy.optimize.differential_evolution`` (seeded, so a plan is reproducible) over its
continuous parameters and, with ``--ball-region``, the ball position, on the PIGE model
(the poses already carry the structure the forced effects need).  Free poses are
optimised with ``scipy.optimize.minimize`` (L-BFGS-B, analytic gradient of the smooth
criterion, linear-axis limits as a quadratic penalty), started from the best family's
poses and from seeded random poses.  A candidate that leaves a limit, or on which a
forced effect (``--reveal``) cannot be determined jointly with the PIGEs, is dropped; the
remaining candidate with the lowest criterion on the joint model (PIGEs plus the forced
effects' parameters, so e.g. a forced wobble is planned for) wins.  Angles are rounded to 1e-4° before the final
prediction, so the figures describe the file that is written.

Baseline
--------
The default cone frustum (:func:`pige_sym.model.trajectories.cone_frustum` defaults) with the
same number of poses, the same noise and the plan's ball; when the ball was searched,
also the default cone at the ball given with ``--ball``.

Angle file
----------
``# `` comment lines (machine, ball, criterion, predicted figures, how to use it), then
``t_s,<axis>_deg,...``; the first row is the reference pose; ``t_s`` follows the schedule of
:mod:`pige_sym.nc.rtest_program` (move, then dwell, per pose).  ``pige program``,
``pige rtest-sim`` and ``pige acquire`` read it as a trajectory.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize

from pige_sym.errors import InputError
from pige_sym.model.effects import DRIFT_KINDS
from pige_sym.planning.families import (
    Family,
    Limits,
    Structure,
    families,
    fit_rotary,
    linear_violation,
    order_path,
)
from pige_sym.planning.plan import ROUND_DEG, Plan, PlanRequest, default_cone, schedule_times
from pige_sym.planning.prediction import (
    CRITERIA,
    SINGULAR,
    Estimable,
    Setup,
    criterion_and_dn,
    criterion_gradient,
    criterion_values,
    design_rows,
    normal_matrix,
    predict,
    projected_coefficients,
)
from pige_sym.planning.reveal import effect_columns, effect_spec, reveal_report, reveal_status

PENALTY = 0.1


RICH_POSES = 400


FREE_WARM_STARTS = 1  # best family candidates that start a free-pose search


FREE_RANDOM_STARTS = 1  # seeded random starts of the free-pose search


@dataclass
class _Context:
    req: PlanRequest
    structure: Structure
    est: Estimable
    forced: list[str]
    t_s: np.ndarray

    @property
    def kern(self) -> Any:
        return self.req.setup.kernels


def _ball(ctx: _Context, x: np.ndarray) -> np.ndarray:
    ball = ctx.req.setup.ball_mm.copy()
    for j, i in enumerate(sorted(ctx.req.ball_region)):
        ball[i] = x[j]
    return ball


def _joint(ctx: _Context, setup: Setup, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """Design rows (no reference row) and forced-effect columns."""
    rows = design_rows(setup, angles[1:], projected_coefficients(setup))
    if not ctx.forced:
        return rows, None, []
    cols, names = [], []
    for e in ctx.forced:
        spec = effect_spec(e, tuple(ctx.kern.ROTARY_AXES))
        cols.append(effect_columns(setup, spec, angles, ctx.t_s)[1:])
        names += [f"{e}.{p}" for p in spec.param_names]
    return rows, np.concatenate(cols, axis=2), names


def _joint_estimable(ctx: _Context, q: int) -> Estimable:
    p, r = ctx.est.basis.shape
    basis = np.zeros((p + q, r + q))
    basis[:p, :r] = ctx.est.basis
    basis[p:, r:] = np.eye(q)
    return Estimable(basis, np.concatenate([ctx.est.covered, np.ones(q, dtype=bool)]))


def _finish(ctx: _Context, core: np.ndarray) -> np.ndarray | None:
    """Full angle table (reference row first) within the limits, or None."""
    poses = ctx.structure.expand(core, ctx.req.points)
    angles = fit_rotary(np.vstack([np.zeros(poses.shape[1]), poses]), tuple(ctx.kern.ROTARY_AXES), ctx.req.limits)
    return angles


def _score(ctx: _Context, angles: np.ndarray, ball: np.ndarray, *, joint: bool = False) -> float:
    """Smooth criterion of a full angle table (large when infeasible).

    The searches use the PIGE model (the structure of the forced effects is already in the
    poses); ``joint`` adds the forced effects' parameters, for ranking the final candidates.
    """
    setup = ctx.req.setup.with_ball(ball)
    viol = linear_violation(ctx.kern, angles, setup, ctx.req.limits).max(initial=0.0)
    if viol > 1e-6:
        return SINGULAR + viol
    if not joint:
        rows = design_rows(setup, angles[1:], projected_coefficients(setup))
        return criterion_and_dn(normal_matrix(rows), ctx.est, ctx.req.criterion, setup.noise_um, gradient=False)[0]
    rows, extra, names = _joint(ctx, setup, angles)
    est = ctx.est if extra is None else _joint_estimable(ctx, extra.shape[2])
    value, _ = criterion_and_dn(normal_matrix(rows, extra), est, ctx.req.criterion, setup.noise_um, gradient=False)
    return value


@dataclass
class _Candidate:
    family: str
    description: str
    angles: np.ndarray
    ball: np.ndarray
    score: float


def _score_batch(ctx: _Context, tables: list[np.ndarray | None], balls: list[np.ndarray]) -> np.ndarray:
    """:func:`_score` (PIGE model) of many angle tables at once, shape=(S,); ``None`` = not buildable.

    Tables of one ball and one shape share one basis call, one stacked ``AᵀA`` and one
    batched criterion; the values equal the one-by-one scores.
    """
    out = np.full(len(tables), 2 * SINGULAR)
    groups: dict[tuple[bytes, tuple[int, ...]], list[tuple[int, np.ndarray]]] = {}
    for i, (angles, ball) in enumerate(zip(tables, balls, strict=True)):
        if angles is not None:
            groups.setdefault((ball.tobytes(), angles.shape), []).append((i, angles))
    for members in groups.values():
        idx = [i for i, _ in members]
        setup = ctx.req.setup.with_ball(balls[idx[0]])
        stack = np.stack([angles for _, angles in members])  # (S, n + 1, k)
        s_count, rows, k = stack.shape
        ok = np.ones(s_count, dtype=bool)
        if ctx.req.limits.linear:
            viol = linear_violation(ctx.kern, stack.reshape(-1, k), setup, ctx.req.limits).reshape(s_count, rows)
            worst = viol.max(axis=1)
            ok = worst <= 1e-6
            out[np.asarray(idx)[~ok]] = SINGULAR + worst[~ok]
        if not ok.any():
            continue
        coef = projected_coefficients(setup)  # (K, m, P)
        basis = np.asarray(setup.kernels.basis(stack[ok, 1:].reshape(-1, k))).reshape(int(ok.sum()), rows - 1, -1)
        gram = np.einsum("snk,snl->skl", basis, basis)
        normals = np.einsum("kmp,skl,lmq->spq", coef, gram, coef, optimize=True)
        out[np.asarray(idx)[ok]] = criterion_values(normals, ctx.est, ctx.req.criterion, setup.noise_um)
    return out


def _search_family(ctx: _Context, fam: Family) -> list[_Candidate]:
    region = [ctx.req.ball_region[i] for i in sorted(ctx.req.ball_region)]
    n_core = ctx.structure.core_count(ctx.req.points)
    out = []
    for vi, variant in enumerate(fam.variants):
        nb = len(fam.bounds)

        def build(x: np.ndarray, variant: dict[str, Any] = variant, nb: int = nb) -> np.ndarray | None:
            try:
                return _finish(ctx, fam.make(x[:nb], variant, n_core))
            except (InputError, ValueError, FloatingPointError):
                return None

        def objective(xs: np.ndarray, build: Any = build, nb: int = nb) -> np.ndarray:
            # the whole population at once: xs (N, S) -> (S,)
            return _score_batch(ctx, [build(x) for x in xs.T], [_ball(ctx, x[nb:]) for x in xs.T])

        res = optimize.differential_evolution(objective, fam.bounds + region, seed=ctx.req.seed + vi, maxiter=6,
                                              popsize=5, tol=1e-3, polish=False, init="latinhypercube",
                                              vectorized=True, updating="deferred")
        angles = build(res.x)
        if angles is not None and res.fun < SINGULAR:
            out.append(_Candidate(fam.name, fam.describe(res.x[:nb], variant), angles, _ball(ctx, res.x[nb:]),
                                  float(res.fun)))
    return out


def _free_objective(ctx: _Context, x: np.ndarray, n_core: int, k: int) -> tuple[float, np.ndarray]:
    nb = len(ctx.req.ball_region)
    core = x[:n_core * k].reshape(n_core, k)
    ball = _ball(ctx, x[n_core * k:])
    setup = ctx.req.setup.with_ball(ball)
    weights = ctx.structure.weights(n_core, ctx.req.points)
    value, grad = criterion_gradient(setup, core, projected_coefficients(setup), ctx.est, ctx.req.criterion, weights)
    full = np.concatenate([grad.ravel(), np.zeros(nb)])
    if ctx.req.limits.linear:
        pen, pgrad = _linear_penalty(ctx, setup, core)
        value += pen
        full[:n_core * k] += pgrad.ravel()
    for j in range(nb):  # ball: central differences of the whole criterion (a few evaluations)
        h = 1e-3
        xp, xm = x.copy(), x.copy()
        xp[n_core * k + j] += h
        xm[n_core * k + j] -= h
        full[n_core * k + j] = (_free_value(ctx, xp, n_core, k) - _free_value(ctx, xm, n_core, k)) / (2 * h)
    return value, full


def _free_value(ctx: _Context, x: np.ndarray, n_core: int, k: int) -> float:
    core = x[:n_core * k].reshape(n_core, k)
    setup = ctx.req.setup.with_ball(_ball(ctx, x[n_core * k:]))
    weights = ctx.structure.weights(n_core, ctx.req.points)
    value, _ = criterion_gradient(setup, core, projected_coefficients(setup), ctx.est, ctx.req.criterion, weights)
    return value + (_linear_penalty(ctx, setup, core)[0] if ctx.req.limits.linear else 0.0)


def _linear_penalty(ctx: _Context, setup: Setup, core: np.ndarray) -> tuple[float, np.ndarray]:
    """``PENALTY·Σ violation²`` [mm²] of the X/Y/Z limits and its gradient per pose angle."""
    v0 = linear_violation(ctx.kern, core, setup, ctx.req.limits)
    grad = np.zeros_like(core)
    for a in range(core.shape[1]):
        step = np.zeros(core.shape[1])
        step[a] = 1e-3
        vp = linear_violation(ctx.kern, core + step, setup, ctx.req.limits)
        vm = linear_violation(ctx.kern, core - step, setup, ctx.req.limits)
        grad[:, a] = PENALTY * (vp**2 - vm**2) / 2e-3
    return PENALTY * float((v0**2).sum()), grad


def _search_free(ctx: _Context, starts: list[np.ndarray]) -> list[_Candidate]:
    axes = tuple(ctx.kern.ROTARY_AXES)
    k = len(axes)
    n_core = ctx.structure.core_count(ctx.req.points)
    bounds = [ctx.req.limits.search_bounds(a) for a in axes] * n_core
    bounds += [ctx.req.ball_region[i] for i in sorted(ctx.req.ball_region)]
    lo, hi = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])
    rng = np.random.default_rng(ctx.req.seed)
    ball0 = [ctx.req.setup.ball_mm[i] for i in sorted(ctx.req.ball_region)]
    x0s = [np.clip(np.concatenate([s.ravel(), ball0]), lo, hi) for s in starts if s.shape == (n_core, k)]
    x0s += [np.clip(np.concatenate([rng.uniform(lo[:n_core * k], hi[:n_core * k]), ball0]), lo, hi)
            for _ in range(FREE_RANDOM_STARTS)]
    out = []
    for x0 in x0s:
        res = optimize.minimize(lambda x: _free_objective(ctx, x, n_core, k), x0, jac=True, method="L-BFGS-B",
                                bounds=list(zip(lo, hi, strict=True)), options={"maxiter": 150, "maxfun": 300})
        ball = _ball(ctx, res.x[n_core * k:])
        core = order_path(_repair_linear(ctx, res.x[:n_core * k].reshape(n_core, k), ball))
        angles = _finish(ctx, core)
        if angles is not None:
            out.append(_Candidate("free", f"free poses ({n_core} chosen)", angles, ball, _score(ctx, angles, ball)))
    return out


def _repair_linear(ctx: _Context, core: np.ndarray, ball: np.ndarray) -> np.ndarray:
    """Move poses that still leave a linear limit toward the reference pose until they fit (bisection).

    The reference pose is within the limits (checked when parsing them), so a fitting point exists
    on the segment; the penalty leaves only small violations, so the poses move little.
    """
    if not ctx.req.limits.linear:
        return core
    setup = ctx.req.setup.with_ball(ball)
    out = core.copy()
    bad = np.flatnonzero(linear_violation(ctx.kern, out, setup, ctx.req.limits) > 0)
    for i in bad:
        lo, hi = 0.0, 1.0  # fraction of the pose kept: lo fits, hi does not
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            ok = linear_violation(ctx.kern, core[i:i + 1] * mid, setup, ctx.req.limits)[0] <= 0
            lo, hi = (mid, hi) if ok else (lo, mid)
        out[i] = core[i] * lo
    return out


def _rich_poses(req: PlanRequest) -> tuple[Setup, np.ndarray]:
    """Many random poses within the limits (reference row first) and the set-up at the ball region's centre."""
    kern = req.setup.kernels
    rng = np.random.default_rng(req.seed + 1000)
    ball = req.setup.ball_mm.copy()
    for i, (lo, hi) in req.ball_region.items():
        ball[i] = 0.5 * (lo + hi)
    poses = np.column_stack([rng.uniform(*req.limits.search_bounds(a), RICH_POSES) for a in kern.ROTARY_AXES])
    return req.setup.with_ball(ball), np.vstack([np.zeros(poses.shape[1]), poses])


def _structural_estimable(req: PlanRequest) -> Estimable:
    """Estimable subspace from many random poses within the limits (what no test can do better)."""
    setup, angles = _rich_poses(req)
    return Estimable.from_rich_design(normal_matrix(design_rows(setup, angles[1:])))


def _check_forced_possible(req: PlanRequest, forced: list[str]) -> None:
    """Refuse at once an effect that even many random poses cannot tell apart from the PIGEs.

    Backlash and thermal drift are left to the search: they need order and repeats, not poses.
    """
    setup, angles = _rich_poses(req)
    t_s = schedule_times(angles.shape[0], req.move_s, req.dwell_s)
    for effect in forced:
        if effect in DRIFT_KINDS or effect.startswith("backlash_"):
            continue
        status = reveal_status(setup, effect, angles, t_s)
        if not status.revealable:
            raise InputError(f"--reveal {effect}: no test within these limits can tell it from the PIGEs "
                             f"(not even {RICH_POSES} random poses): {status.reason}")


def _core_of(angles: np.ndarray, structure: Structure) -> np.ndarray:
    poses = angles[1:]
    if structure.reference_returns:
        poses = poses[np.abs(poses).max(axis=1) > 0]
    return poses


def plan_test(req: PlanRequest) -> Plan:
    """Search the families and the ball for the test that minimises the criterion (module docstring)."""
    t0 = time.perf_counter()
    kern = req.setup.kernels
    axes = tuple(kern.ROTARY_AXES)
    structure = Structure.for_reveal(req.reveal, axes, req.points)
    forced = [e for e in req.reveal if e != "outliers"]
    _check_forced_possible(req, forced)
    ctx = _Context(req, structure, _structural_estimable(req), forced,
                   schedule_times(req.points + 1, req.move_s, req.dwell_s))
    cands: list[_Candidate] = []
    for fam in families(kern, req.limits, structure.core_count(req.points)):
        cands += _search_family(ctx, fam)
    cands.sort(key=lambda c: c.score)
    n_core = structure.core_count(req.points)
    starts = [core for c in cands[:FREE_WARM_STARTS] if (core := _core_of(c.angles, structure)).shape[0] == n_core]
    cands += _search_free(ctx, starts)
    if forced:
        for c in cands:
            c.score = _score(ctx, c.angles, c.ball, joint=True)
    cands.sort(key=lambda c: c.score)
    for cand in cands:
        angles = np.round(cand.angles, ROUND_DEG)
        plan = _describe(req.setup.with_ball(np.round(cand.ball, 3)), angles, ctx.t_s, cand.family,
                         cand.description, req.criterion, req.reveal, req.limits,
                         ball_searched=bool(req.ball_region), ball_given=req.setup.ball_mm)
        if (not plan.prediction.undetermined and all(plan.reveal[e].revealable for e in req.reveal)
                and within_limits(angles, plan.setup, req.limits)):
            plan.planning_s = time.perf_counter() - t0
            plan.duration_s = float(ctx.t_s[-1] + req.dwell_s)
            return plan
    missing = ", ".join(req.reveal) or "the PIGEs"
    raise InputError(f"no test with {req.points} poses within these limits determines {missing}: "
                     "give more points or wider limits")


def within_limits(angles: np.ndarray, setup: Setup, limits: Limits) -> bool:
    """True when every pose respects the rotary limits (as given, no shift) and the linear ones.

    Tolerances: the file's angle resolution (``10^-ROUND_DEG`` deg) and 1 µm on X/Y/Z.
    """
    axes = tuple(setup.kernels.ROTARY_AXES)
    tol = 10.0 ** -ROUND_DEG
    for k, a in enumerate(axes):
        lo, hi = limits.rotary[a]
        if angles[:, k].min() < lo - tol or angles[:, k].max() > hi + tol:
            return False
    return bool(linear_violation(setup.kernels, angles, setup, limits).max(initial=0.0) <= 1e-3)


def _describe(setup: Setup, angles: np.ndarray, t_s: np.ndarray, family: str, description: str, criterion: str,
              forced: tuple[str, ...], limits: Limits | None, *, ball_searched: bool = False,
              ball_given: np.ndarray | None = None) -> Plan:
    pred = predict(setup, angles)
    cone = default_cone(setup, angles.shape[0] - 1)
    baseline = None if cone is None else predict(setup, cone)
    default_setup = None
    if ball_searched and cone is not None and ball_given is not None:
        default_setup = predict(setup.with_ball(ball_given), cone)
    in_limits = None
    if cone is not None and limits is not None:
        shifted = fit_rotary(cone, tuple(setup.kernels.ROTARY_AXES), limits)
        in_limits = shifted is not None and within_limits(shifted, setup, limits)
    return Plan(setup.machine, tuple(setup.kernels.ROTARY_AXES), angles, t_s, family, description, setup, criterion,
                pred, baseline, default_setup, reveal_report(setup, angles, t_s, forced), limits, in_limits)


def grade_test(setup: Setup, angles_deg: np.ndarray, t_s: np.ndarray, *, description: str = "graded test",
               criterion: str = "worst", limits: Limits | None = None, duration_s: float | None = None) -> Plan:
    """The predicted figures of an existing test (same as a plan's, family ``graded``)."""
    if criterion not in CRITERIA:
        raise InputError(f"unknown criterion {criterion!r}: use {', '.join(CRITERIA)}")
    angles = np.asarray(angles_deg, dtype=float)
    if angles.shape[0] < 2 or np.abs(angles[0]).max() > 1e-9:
        raise InputError("a test starts at the reference pose (all rotary axes 0) and has at least one more pose")
    plan = _describe(setup, angles, np.asarray(t_s, dtype=float), "graded", description, criterion, (), limits)
    plan.duration_s = float(t_s[-1]) if duration_s is None else float(duration_s)
    return plan


def search_ball_region(text: str | None) -> dict[int, tuple[float, float]]:
    """``x=lo:hi,y=lo:hi,z=lo:hi`` (any subset) [mm] for ``--ball-region``."""
    out: dict[int, tuple[float, float]] = {}
    for item in filter(None, (x.strip() for x in (text or "").split(","))):
        axis, eq, rng = item.partition("=")
        axis = axis.strip().lower()
        if not eq or axis not in ("x", "y", "z"):
            raise InputError(f"--ball-region: expected x=lo:hi, y=lo:hi or z=lo:hi, got {item!r}")
        lo_s, colon, hi_s = rng.partition(":")
        try:
            lo, hi = float(lo_s), float(hi_s)
        except ValueError:
            raise InputError(f"--ball-region {axis}: expected lo:hi numbers [mm], got {rng!r}") from None
        if not colon or not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
            raise InputError(f"--ball-region {axis}: expected lo:hi with finite lo <= hi, got {rng!r}")
        out["xyz".index(axis)] = (lo, hi)
    return out
