"""Identification of PIGEs from R-test data: least squares, identifiability, uncertainty.

Model
-----
With the generated kernels the deviation is ``d = J(θ)·p`` (first order, exactly
linear in the parameters p), ``J = basis(θ) @ G(geometry)``.  Observations are the
projected deviations ``n_i·d`` of every row but the reference row (zero by
definition), stacked into ``y`` (N values); the design is ``A`` (N × P).  Extra model
columns (the diagnosis' extensions) may be appended to A.

Normal equations are formed from the basis sums ``BᵀB`` (K × K) and ``BᵀY``, so a
solve costs O(nK²) once and then nothing that depends on n.  Columns are scaled to
unit norm (µm and µrad become comparable); everything below refers to the scaled
matrix ``Ã = A·S`` with singular values ``s_1 ≥ … ≥ s_P``.

Methods
-------
``gauss-newton`` (default)
    Gauss–Newton on the scaled problem.  The model is linear in the parameters, so
    it converges in one step (a second step checks it); with ``loss=soft_l1`` or
    ``huber`` a robust fit (``scipy.optimize.least_squares``) flags outlier rows
    (row residual norm beyond ``outlier_threshold`` robust sigmas), which are then
    excluded from the final least-squares fit and listed.
``double-differential`` (the paper's scheme)
    Stage 1 solves all parameters.  A parameter is *accurately determined* when it is
    individually identifiable (no weight in a near-null direction) and its variance
    inflation factor ``VIF_j = (ÃᵀÃ)⁻¹_jj`` is at most ``vif_max`` (default 10:
    collinearity with the others inflates its variance less than tenfold).  Those
    are fixed and substituted into the model; the next stage re-linearises and
    solves the rest, applying the same rule to the reduced problem; this repeats
    until all are fixed or a stage fixes nothing.  Every stage is reported.  A
    parameter fixed only at a later stage is determined *conditionally* on the
    earlier ones: its reported standard error is the honest marginal one of the
    joint problem, and if the joint problem cannot determine it at all, it is
    listed as unidentifiable with no standard error.

Uncertainty and identifiability
-------------------------------
``σ² = RSS/(N − rank)``; covariance ``σ²·(AᵀA)⁺``; 95 % intervals from Student's t.
Rank: singular values with ``s_i/s_1 > rank_rtol`` (1e-5, above what round-off in the normal matrix makes of a
structural null, :data:`~pige_sym.identification.spectrum.RANK_RTOL`).  The condition number is
``s_1/s_rank`` (``inf`` when rank-deficient).  Observability indices:
O1 = (∏s_i)^(1/P)/√N (Borm & Menq), O2 = s_P/s_1 (Driels & Pathre), O3 = s_P
(Nahvi), O4 = s_P²/s_1 (noise amplification, Nahvi & Hollerbach), O5 = 1/Σ(1/s_i)
(Sun & Hollerbach); all 0 when the smallest singular value is round-off.  Near-null directions (``s_i/s_1 ≤
null_rtol``, 1e-4) are named as parameter combinations, by their canonical basis
(:mod:`~pige_sym.identification.canonical`: the same on every processor); a parameter whose weight in their span
(its row's norm in an orthonormal basis of it) exceeds ``NULL_WEIGHT`` (1e-3) has no value reported (``None``).
"""

from __future__ import annotations

import math

import numpy as np

from pige_sym.constants import LOSSES as LOSSES
from pige_sym.constants import METHODS as METHODS
from pige_sym.errors import IdentificationError as IdentificationError
from pige_sym.errors import InputError
from pige_sym.identification.instruments import instrument
from pige_sym.identification.problem import ExtraColumns, Problem, build_problem
from pige_sym.identification.result import IdentificationResult, Stage, not_identifiable
from pige_sym.identification.spectrum import Solution, observability, solve_scaled
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.schema import refuse_unphysical
from pige_sym.model.projection import Projection, parse_projection


def _result(problem: Problem, sol: Solution, *, method: str, projection: str, loss: str, machine: str,
            measurement: Measurement, outliers: list[int], stages: list[Stage] | None = None,
            values: np.ndarray | None = None) -> IdentificationResult:
    names = problem.names
    p = len(names)
    dof = max(problem.n_obs - sol.rank, 0)
    sigma2 = sol.rss / dof if dof > 0 else float("nan")
    cov = sol.cov_unit * sigma2
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    ident = np.isfinite(sol.vif)
    vals = (sol.values if values is None else values).copy()
    vals[~ident] = np.nan
    std = np.where(ident, std, np.nan)
    smax = sol.svals[0] if sol.svals.size and sol.svals[0] > 0 else 1.0
    cond = float(smax / sol.svals[sol.rank - 1]) if sol.rank == p and sol.rank > 0 else float("inf")
    null_space, combos = not_identifiable(sol.null_space, list(names), problem.units)
    if problem.design is not None and problem.data is not None:
        model = np.einsum("nmp,p->nm", problem.design, np.nan_to_num(sol.values if values is None else values))
        resid = problem.data - model
    else:
        resid = np.zeros((0, problem.m))
    rms = math.sqrt(sol.rss / max(problem.n_obs, 1))
    return IdentificationResult(
        machine=machine, method=method, projection=projection, loss=loss, parameters=list(names),
        units=dict(problem.units), values=vals, std=std, covariance=cov, identifiable=ident, rms_um=rms,
        sigma_um=math.sqrt(sigma2) if math.isfinite(sigma2) else float("nan"), dof=dof, n_rows=problem.n_rows,
        n_obs=problem.n_obs, rank=sol.rank, condition=cond, singular_values=sol.svals,
        observability=observability(sol.svals, problem.n_obs), unidentifiable=combos, outlier_rows=outliers,
        residuals_um=resid, stages=stages or [], ball_mm=[float(x) for x in measurement.ball_mm],
        pivots_mm={k: [float(x) for x in v] for k, v in measurement.pivots_mm.items()},
        tool_mm=None if measurement.tool_mm is None else [float(x) for x in measurement.tool_mm],
        vif=sol.vif, unobserved=[names[j] for j in sol.unobserved], axis_sense=dict(measurement.axis_sense),
        null_space=null_space,
    )


def _robust_rows(problem: Problem, loss: str, threshold: float) -> list[int]:
    """Rows flagged as outliers by a robust fit (0-based data-row indices)."""
    if problem.design is None or problem.data is None:
        raise IdentificationError("a robust loss needs the explicit design (too many points: use loss=linear)")
    rows = problem.rows
    a = problem.design[rows].reshape(-1, problem.design.shape[2])
    y = problem.data[rows].reshape(-1)
    first = solve_scaled(problem.normal, problem.rhs, problem.yy)
    r0 = y - a @ first.values
    scale_r = 1.4826 * np.median(np.abs(r0 - np.median(r0))) or 1e-6
    diag = np.sqrt(np.clip((a**2).sum(axis=0), 1e-300, None))

    def fun(xs: np.ndarray) -> np.ndarray:
        return (a @ (xs / diag) - y) / scale_r

    def jac(xs: np.ndarray) -> np.ndarray:
        return a / diag / scale_r

    from scipy import optimize
    from scipy.special import chdtri, ndtr

    fit = optimize.least_squares(fun, first.values * diag, jac=jac, loss=loss, f_scale=1.0, method="trf")
    resid = (a @ (fit.x / diag) - y).reshape(rows.size, problem.m)
    clean = np.abs(resid)
    sigma_rob = 1.4826 * np.median(clean) if np.median(clean) > 0 else scale_r
    norms = np.sqrt((resid**2).sum(axis=1)) / sigma_rob
    limit = math.sqrt(chdtri(problem.m, 2.0 - 2.0 * ndtr(threshold)))  # chi2.ppf(2Φ(t) − 1, m)
    return [int(r) for r in rows[norms > limit]]


def identify(measurement: Measurement, *, method: str = "gauss-newton", projection: str | Projection = "xyz",
             loss: str = "linear", with_zero: bool = False, extra: ExtraColumns | None = None,
             vif_max: float = 10.0, outlier_threshold: float = 4.0,
             rows: np.ndarray | None = None) -> IdentificationResult:
    """Identify the PIGEs of a measurement.

    Parameters
    ----------
    measurement : Measurement
    method : {"gauss-newton", "double-differential"}
    projection : str or Projection
        Excitation projection (CONVENTIONS §5).
    loss : {"linear", "soft_l1", "huber"}
        Robust losses flag outlier rows, which are excluded from the final fit.
    with_zero : bool
        Also estimate zero-position errors.
    extra : ExtraColumns, optional
        Extension columns estimated jointly.
    vif_max : float
        Double-differential acceptance threshold (module docstring).
    outlier_threshold : float
        Robust-sigma multiple (as a two-sided normal quantile) beyond which a row is an outlier.
    rows : array of int, optional
        Rows to use (default all but the reference).

    Returns
    -------
    IdentificationResult
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}: use {' or '.join(METHODS)}")
    if loss not in LOSSES:
        raise InputError(f"unknown loss {loss!r}: use {', '.join(LOSSES)}")
    proj = parse_projection(projection)
    problem = build_problem(measurement, proj, with_zero=with_zero, extra=extra, rows=rows,
                            explicit=True if loss != "linear" else None)
    outliers: list[int] = []
    if loss != "linear" and instrument(measurement) != "rtest":
        raise InputError(f"loss={loss}: robust fits treat rows as independent; the rows of a "
                         f"{instrument(measurement)} measurement are correlated (use loss=linear)")
    if loss != "linear":
        outliers = _robust_rows(problem, loss, outlier_threshold)
        if outliers:
            keep = np.setdiff1d(problem.rows, outliers)
            problem = build_problem(measurement, proj, with_zero=with_zero, extra=extra, rows=keep, explicit=True)
    if problem.n_obs < len(problem.names):
        raise IdentificationError(
            f"{problem.n_obs} observations cannot determine {len(problem.names)} parameters: measure more points"
        )
    sol = solve_scaled(problem.normal, problem.rhs, problem.yy)
    if method == "gauss-newton":
        # Gauss–Newton: x1 = x0 + Δ with Δ from the linearised (scaled) normal equations, from x0 = 0.
        # The first-order model is linear in the parameters, so Δ at x1 is zero (checked) for every
        # parameter the data determine; along near-null directions (parameters reported as not
        # identifiable, infinite VIF) the second step is round-off amplified and is not checked.
        step = solve_scaled(problem.normal, problem.rhs - problem.normal @ sol.values, problem.yy).values
        determined = np.isfinite(sol.vif)
        if np.abs(step[determined]).max(initial=0) > 1e-6 * max(1.0, np.abs(sol.values[determined]).max(initial=0)):
            raise IdentificationError("Gauss–Newton did not converge")  # pragma: no cover - linear model
        result = _result(problem, sol, method=method, projection=proj.name, loss=loss, machine=measurement.machine,
                         measurement=measurement, outliers=outliers)
    else:
        result = _double_differential(problem, sol, proj.name, loss, measurement, outliers, vif_max)
    if extra is None:  # a fit of the PIGEs alone (the diagnosis' trial fits carry extension columns)
        refuse_unphysical(result.parameters, result.values, result.std, result.units,
                          measurement.path or "the measurement")
    return result


def _double_differential(problem: Problem, joint: Solution, projection: str, loss: str, measurement: Measurement,
                         outliers: list[int], vif_max: float) -> IdentificationResult:
    names = problem.names
    p = len(names)
    fixed = np.zeros(p, dtype=bool)
    values = np.zeros(p)
    stages: list[Stage] = []
    stage_no = 0
    while not fixed.all():
        stage_no += 1
        free = np.flatnonzero(~fixed)
        # substitute the fixed parameters, re-linearise, solve the free ones
        n_ff = problem.normal[np.ix_(free, free)]
        rhs = problem.rhs[free] - problem.normal[np.ix_(free, fixed.nonzero()[0])] @ values[fixed]
        sol = solve_scaled(n_ff, rhs, problem.yy)
        dof = max(problem.n_obs - sol.rank - int(fixed.sum()), 1)
        full = values.copy()
        full[free] = sol.values
        rss = max(float(problem.yy - 2 * full @ problem.rhs + full @ problem.normal @ full), 0.0)
        sigma2 = rss / dof
        std_c = np.sqrt(np.clip(np.diag(sol.cov_unit) * sigma2, 0, None))
        accept = np.isfinite(sol.vif) & (sol.vif <= vif_max)
        if not accept.any():
            # a differential may accept the best-determined remaining parameters one at a time
            finite = np.isfinite(sol.vif)
            if finite.any():
                accept = np.zeros_like(finite)
                accept[int(np.argmin(np.where(finite, sol.vif, np.inf)))] = True
        solved = [names[j] for j in free]
        newly = [names[free[i]] for i in np.flatnonzero(accept)]
        stages.append(Stage(
            index=stage_no, solved=solved, fixed=newly,
            values={names[j]: float(sol.values[i]) for i, j in enumerate(free)},
            std={names[j]: (float(std_c[i]) if np.isfinite(sol.vif[i]) else None) for i, j in enumerate(free)},
            vif={names[j]: float(sol.vif[i]) for i, j in enumerate(free)},
            rank=sol.rank,
            condition=float(sol.svals[0] / sol.svals[sol.rank - 1]) if sol.rank == free.size else float("inf"),
        ))
        if not accept.any():
            break
        for i in np.flatnonzero(accept):
            values[free[i]] = sol.values[i]
            fixed[free[i]] = True
    final = values.copy()
    final[~fixed] = np.nan
    result = _result(problem, joint, method="double-differential", projection=projection, loss=loss,
                     machine=measurement.machine, measurement=measurement, outliers=outliers, stages=stages,
                     values=np.where(fixed, values, joint.values))
    # parameters the joint problem cannot determine stay undetermined, whatever stage fixed them
    result.values = np.where(result.identifiable & fixed, final, np.nan)
    return result
