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
Rank: singular values with ``s_i/s_1 > rank_rtol`` (1e-7).  The condition number is
``s_1/s_rank`` (``inf`` when rank-deficient).  Observability indices:
O1 = (∏s_i)^(1/P)/√N (Borm & Menq), O2 = s_P/s_1 (Driels & Pathre), O3 = s_P
(Nahvi), O4 = s_P²/s_1 (noise amplification, Nahvi & Hollerbach), O5 = 1/Σ(1/s_i)
(Sun & Hollerbach).  Near-null directions (``s_i/s_1 ≤ null_rtol``, 1e-4) are named
as parameter combinations; a parameter with weight > 0.05 in one of them has no
value reported (``None``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.constants import LOSSES as LOSSES
from pige_sym.constants import METHODS as METHODS
from pige_sym.errors import IdentificationError as IdentificationError
from pige_sym.errors import InputError
from pige_sym.io import Measurement
from pige_sym.kernels import load_kernels
from pige_sym.projection import Projection, parse_projection

RANK_RTOL = 1e-7
NULL_RTOL = 1e-4
NULL_WEIGHT = 1e-3
ZERO_COLUMN_RTOL = 1e-9


@dataclass
class ExtraColumns:
    """Additional model columns (e.g. a diagnosis extension), evaluated on the data rows.

    Attributes
    ----------
    names : list of str
    units : dict of str to str
    columns : ndarray, shape=(n, 3, q)
        Deviation per unit parameter (machine frame), one slice per parameter, all rows
        including the reference row.
    """

    names: list[str]
    units: dict[str, str]
    columns: np.ndarray


@dataclass
class Stage:
    """One differential of the double-differential scheme."""

    index: int
    solved: list[str]
    fixed: list[str]
    values: dict[str, float]
    std: dict[str, float | None]
    vif: dict[str, float]
    rank: int
    condition: float

    def to_dict(self) -> dict[str, Any]:
        return {"stage": self.index, "solved": self.solved, "fixed": self.fixed, "values": self.values,
                "std": self.std, "vif": {k: _json_float(v) for k, v in self.vif.items()}, "rank": self.rank,
                "condition": _json_float(self.condition)}


@dataclass
class IdentificationResult:
    """Estimated parameters with their uncertainty and identifiability.

    Attributes
    ----------
    parameters : list of str
        Names in order (PIGEs, optional zero-position errors, extra columns).
    values : ndarray, shape=(P,)
        Estimates [µm or µrad]; NaN where the data cannot determine the parameter.
    std : ndarray, shape=(P,)
        Standard errors (NaN where undetermined).
    covariance : ndarray, shape=(P, P)
    residuals_um : ndarray, shape=(n, m)
        Observed minus model for every row (reference row included), projected.
    """

    machine: str
    method: str
    projection: str
    loss: str
    parameters: list[str]
    units: dict[str, str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    identifiable: np.ndarray
    rms_um: float
    sigma_um: float
    dof: int
    n_rows: int
    n_obs: int
    rank: int
    condition: float
    singular_values: np.ndarray
    observability: dict[str, float]
    unidentifiable: list[str]
    outlier_rows: list[int]
    residuals_um: np.ndarray
    stages: list[Stage] = field(default_factory=list)
    ball_mm: list[float] = field(default_factory=list)
    pivots_mm: dict[str, list[float]] = field(default_factory=dict)
    tool_mm: list[float] | None = None
    vif: np.ndarray | None = None
    unobserved: list[str] = field(default_factory=list)

    def value(self, name: str) -> float:
        return float(self.values[self.parameters.index(name)])

    def ci95(self) -> np.ndarray:
        """95 % confidence intervals, shape=(P, 2)."""
        from scipy.special import stdtrit  # Student-t quantile (scipy.stats.t.ppf without its import cost)

        t = stdtrit(max(self.dof, 1), 0.975)
        return np.column_stack([self.values - t * self.std, self.values + t * self.std])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (values ``None`` where undetermined)."""
        ci = self.ci95()
        out: dict[str, Any] = {
            "machine": self.machine,
            "method": self.method,
            "projection": self.projection,
            "loss": self.loss,
            "pige": {p: _json_float(v) for p, v in zip(self.parameters, self.values, strict=True)},
            "std": {p: _json_float(v) for p, v in zip(self.parameters, self.std, strict=True)},
            "ci95": {p: [_json_float(a), _json_float(b)] for p, (a, b) in zip(self.parameters, ci, strict=True)},
            "units": self.units,
            "rank": self.rank,
            "n_parameters": len(self.parameters),
            "condition": _json_float(self.condition),
            "rms_um": self.rms_um,
            "sigma_um": self.sigma_um,
            "dof": self.dof,
            "n_rows": self.n_rows,
            "n_obs": self.n_obs,
            "observability": {k: _json_float(v) for k, v in self.observability.items()},
            "unidentifiable": self.unidentifiable,
            "unobserved": self.unobserved,
            "outlier_rows": self.outlier_rows,
            "ball_mm": self.ball_mm,
            "pivots_mm": self.pivots_mm,
            "tool_mm": self.tool_mm,
        }
        if self.vif is not None:
            out["vif"] = {p: _json_float(v) for p, v in zip(self.parameters, self.vif, strict=True)}
        if self.method == "double-differential":
            out["stages"] = [s.to_dict() for s in self.stages]
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IdentificationResult:
        """Rebuild a result (without residuals or covariance) from :meth:`to_dict` output."""
        params = list(d["pige"])
        vals = np.array([np.nan if d["pige"][p] is None else d["pige"][p] for p in params], dtype=float)
        std = np.array([np.nan if d["std"].get(p) is None else d["std"][p] for p in params], dtype=float)
        return cls(
            machine=d["machine"], method=d.get("method", "gauss-newton"), projection=d.get("projection", "xyz"),
            loss=d.get("loss", "linear"), parameters=params, units=d.get("units", {}), values=vals, std=std,
            covariance=np.diag(np.nan_to_num(std) ** 2), identifiable=np.isfinite(vals),
            rms_um=float(d.get("rms_um", np.nan)), sigma_um=float(d.get("sigma_um", np.nan)),
            dof=int(d.get("dof", 0)), n_rows=int(d.get("n_rows", 0)), n_obs=int(d.get("n_obs", 0)),
            rank=int(d.get("rank", 0)), condition=float(d["condition"]) if d.get("condition") is not None else np.inf,
            singular_values=np.array([]), observability={}, unidentifiable=list(d.get("unidentifiable", [])),
            outlier_rows=list(d.get("outlier_rows", [])), residuals_um=np.zeros((0, 0)),
            ball_mm=list(d.get("ball_mm", [])), pivots_mm=dict(d.get("pivots_mm", {})), tool_mm=d.get("tool_mm"),
        )


def _json_float(x: float) -> float | None:
    x = float(x)
    return None if not math.isfinite(x) else x


@dataclass
class Problem:
    """A linear least-squares identification problem, ready to solve.

    Built once per measurement/projection; holds the normal equations in
    parameter units and, when small enough, the explicit design for per-row work.
    """

    names: list[str]
    units: dict[str, str]
    normal: np.ndarray  # (P, P)  AᵀA
    rhs: np.ndarray  # (P,)  Aᵀy
    yy: float
    n_obs: int
    n_rows: int
    m: int
    design: np.ndarray | None  # (n, m, P) all rows (reference row included) or None
    data: np.ndarray | None  # (n, m)
    rows: np.ndarray  # indices of rows used in the fit


def build_problem(measurement: Measurement, projection: str | Projection = "xyz", *, with_zero: bool = False,
                  extra: ExtraColumns | None = None, rows: np.ndarray | None = None,
                  explicit: bool | None = None) -> Problem:
    """Assemble the least-squares problem of a measurement.

    Parameters
    ----------
    measurement : Measurement
    projection : str or Projection
        ``xyz``, ``x``, ``y``, ``z``, a vector … (CONVENTIONS §5), in the measurement frame.
    with_zero : bool
        Also estimate the zero-position errors.
    extra : ExtraColumns, optional
        Additional columns appended after the PIGEs.
    rows : array of int, optional
        Rows to fit (default: all but the reference row 0).
    explicit : bool, optional
        Keep the explicit design (needed for robust fits and diagnosis); default when
        the problem is small (n·m·P ≤ 5e6).
    """
    kern = load_kernels(measurement.machine)
    proj = parse_projection(projection)
    names = list(kern.LOCATION_PARAMETERS) + (list(kern.ZERO_PARAMETERS) if with_zero else [])
    p_idx = [kern.PARAMETERS.index(n) for n in names]
    units = {n: kern.UNITS[n] for n in names}
    n = measurement.n_rows
    if rows is None:
        rows = np.arange(1, n)
    rows = np.asarray(rows, dtype=int)
    if rows.size == 0:
        raise IdentificationError("no data rows to fit (only the reference row)")
    dirs = proj.directions
    if measurement.frame == "table":
        # observations n·d_W = (R_w n)·d_M: per-row directions in the machine frame
        rot = kern.workpiece_rotation(measurement.angles_deg)
        dirs_rows = np.einsum("nij,mj->nmi", rot, dirs)
    else:
        dirs_rows = None
    y_all = proj.apply_data(measurement.deviation_um)  # (n, m): projection in the measurement frame
    m = dirs.shape[0]
    q = 0 if extra is None else len(extra.names)
    if explicit is None:
        explicit = extra is not None or n * m * (len(names) + q) <= 5_000_000
    g = kern.coefficients(measurement.ball_mm, measurement.pivots_mm or None, measurement.tool_mm)[:, :, p_idx]
    if explicit or dirs_rows is not None:
        jac = kern.basis(measurement.angles_deg) @ g.reshape(g.shape[0], -1)
        jac = jac.reshape(n, 3, len(names))
        if dirs_rows is None:
            design = np.einsum("mi,nip->nmp", dirs, jac)
        else:
            design = np.einsum("nmi,nip->nmp", dirs_rows, jac)
        if extra is not None:
            ex = extra.columns
            ex_p = np.einsum("mi,niq->nmq", dirs, ex) if dirs_rows is None else np.einsum("nmi,niq->nmq", dirs_rows, ex)
            design = np.concatenate([design, ex_p], axis=2)
            names = names + list(extra.names)
            units = units | dict(extra.units)
        a = design[rows].reshape(-1, design.shape[2])
        y = y_all[rows].reshape(-1)
        return Problem(names, units, a.T @ a, a.T @ y, float(y @ y), a.shape[0], n, m, design, y_all, rows)
    # basis sums: AᵀA = Σ_m G_mᵀ (BᵀB) G_m
    b = kern.basis(measurement.angles_deg[rows])
    gram = b.T @ b
    g_d = np.einsum("mi,kip->mkp", dirs, g)  # (m, K, P)
    by = b.T @ y_all[rows]  # (K, m)
    normal = np.einsum("mkp,kl,mlq->pq", g_d, gram, g_d)
    rhs = np.einsum("mkp,km->p", g_d, by)
    yy = float((y_all[rows] ** 2).sum())
    return Problem(names, units, normal, rhs, yy, rows.size * m, n, m, None, y_all, rows)


@dataclass
class _Solution:
    values: np.ndarray
    cov_unit: np.ndarray  # (AᵀA)⁺ in parameter units
    rss: float
    rank: int
    svals: np.ndarray  # scaled singular values
    null_vectors: np.ndarray  # (P, r) in parameter units, normalised to max |.| = 1
    vif: np.ndarray
    unobserved: list[int] = field(default_factory=list)  # zero or near-zero columns


@dataclass
class ScaledSpectrum:
    """Eigen-decomposition of a column-scaled normal matrix with the rank and null-space rules.

    Attributes
    ----------
    svals : (P,) singular values of the scaled design, descending
    vectors : (P, P) right singular vectors (columns), same order
    rank : int
        Singular values above ``RANK_RTOL`` times the largest.
    pinv : (P, P) pseudo-inverse of the scaled normal matrix
    near_null : (P,) bool, singular values at or below ``NULL_RTOL`` times the largest
    """

    svals: np.ndarray
    vectors: np.ndarray
    rank: int
    pinv: np.ndarray
    near_null: np.ndarray

    @property
    def smax(self) -> float:
        return float(self.svals[0]) if self.svals.size and self.svals[0] > 0 else 1.0

    def null_weight(self) -> np.ndarray:
        """(P,) largest weight of each parameter in a near-null direction (0 when there is none)."""
        if not self.near_null.any():
            return np.zeros(self.vectors.shape[0])
        return np.abs(self.vectors[:, self.near_null]).max(axis=1)


def scaled_spectrum(scaled_normal: np.ndarray) -> ScaledSpectrum:
    """Spectrum, rank and pseudo-inverse of a column-scaled normal matrix (identification and planning share it)."""
    w, v = np.linalg.eigh(scaled_normal)
    w = np.clip(w, 0, None)[::-1]
    v = v[:, ::-1]
    svals = np.sqrt(w)
    smax = svals[0] if svals.size and svals[0] > 0 else 1.0
    keep = svals > RANK_RTOL * smax
    inv_w = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    return ScaledSpectrum(svals, v, int(keep.sum()), (v * inv_w) @ v.T, svals <= NULL_RTOL * smax)


def _solve(normal: np.ndarray, rhs: np.ndarray, yy: float) -> _Solution:
    p = normal.shape[0]
    diag = np.sqrt(np.clip(np.diag(normal), 0, None))
    # a zero or near-zero column (parameter not observed) is removed, never scaled up: scaling a
    # ~1e-18 column to unit norm would turn round-off into a "value" of 1e17
    dead = diag <= ZERO_COLUMN_RTOL * max(float(diag.max(initial=0.0)), 1e-300)
    scale = 1.0 / np.where(dead, 1.0, diag)
    ns = normal * np.outer(scale, scale)
    ns[dead, :] = 0.0
    ns[:, dead] = 0.0
    rhs = np.where(dead, 0.0, rhs)
    spec = scaled_spectrum(ns)
    svals, v, rank, pinv_scaled, near_null = spec.svals, spec.vectors, spec.rank, spec.pinv, spec.near_null
    xs = pinv_scaled @ (rhs * scale)
    values = xs * scale
    cov_unit = pinv_scaled * np.outer(scale, scale)
    rss = max(float(yy - 2 * values @ rhs + values @ normal @ values), 0.0)
    nulls = v[:, near_null] * scale[:, None] if near_null.any() else np.zeros((p, 0))
    for j in range(nulls.shape[1]):
        nulls[:, j] /= np.abs(nulls[:, j]).max()
    vif = np.diag(pinv_scaled).copy()
    vif[~np.isfinite(vif)] = np.inf
    vif[spec.null_weight() > NULL_WEIGHT] = np.inf
    vif[dead] = np.inf
    values[dead] = 0.0
    return _Solution(values, cov_unit, rss, rank, svals, nulls, vif, [int(j) for j in np.flatnonzero(dead)])


def _combination_text(vec: np.ndarray, names: Sequence[str], units: dict[str, str]) -> str:
    order = np.argsort(-np.abs(vec))
    terms = []
    for j in order:
        if abs(vec[j]) < 1e-3:
            continue
        coef = vec[j] / vec[order[0]]
        sign = "-" if coef < 0 else "+"
        mag = f"{abs(coef):.3g}·" if not np.isclose(abs(coef), 1.0) else ""
        terms.append(f"{sign} {mag}{names[j]} [{units.get(names[j], '')}]")
    text = " ".join(terms)
    return text[2:] if text.startswith("+ ") else text


def _observability(svals: np.ndarray, n_obs: int) -> dict[str, float]:
    s = svals
    p = s.size
    if p == 0 or s[-1] <= 0:
        return {"O1": 0.0, "O2": 0.0, "O3": 0.0, "O4": 0.0, "O5": 0.0}
    return {
        "O1": float(np.exp(np.log(s).mean()) / math.sqrt(max(n_obs, 1))),
        "O2": float(s[-1] / s[0]),
        "O3": float(s[-1]),
        "O4": float(s[-1] ** 2 / s[0]),
        "O5": float(1.0 / (1.0 / s).sum()),
    }


def _result(problem: Problem, sol: _Solution, *, method: str, projection: str, loss: str, machine: str,
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
    combos = [
        f"{_combination_text(sol.null_vectors[:, j], names, problem.units)} is not identifiable"
        for j in range(sol.null_vectors.shape[1])
    ]
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
        observability=_observability(sol.svals, problem.n_obs), unidentifiable=combos, outlier_rows=outliers,
        residuals_um=resid, stages=stages or [], ball_mm=[float(x) for x in measurement.ball_mm],
        pivots_mm={k: [float(x) for x in v] for k, v in measurement.pivots_mm.items()},
        tool_mm=None if measurement.tool_mm is None else [float(x) for x in measurement.tool_mm],
        vif=sol.vif, unobserved=[names[j] for j in sol.unobserved],
    )


def _robust_rows(problem: Problem, loss: str, threshold: float) -> list[int]:
    """Rows flagged as outliers by a robust fit (0-based data-row indices)."""
    if problem.design is None or problem.data is None:
        raise IdentificationError("a robust loss needs the explicit design (too many points: use loss=linear)")
    rows = problem.rows
    a = problem.design[rows].reshape(-1, problem.design.shape[2])
    y = problem.data[rows].reshape(-1)
    first = _solve(problem.normal, problem.rhs, problem.yy)
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
    if loss != "linear":
        outliers = _robust_rows(problem, loss, outlier_threshold)
        if outliers:
            keep = np.setdiff1d(problem.rows, outliers)
            problem = build_problem(measurement, proj, with_zero=with_zero, extra=extra, rows=keep, explicit=True)
    if problem.n_obs < len(problem.names):
        raise IdentificationError(
            f"{problem.n_obs} observations cannot determine {len(problem.names)} parameters: measure more points"
        )
    sol = _solve(problem.normal, problem.rhs, problem.yy)
    if method == "gauss-newton":
        # Gauss–Newton: x1 = x0 + Δ with Δ from the linearised (scaled) normal equations, from x0 = 0.
        # The first-order model is linear in the parameters, so Δ at x1 is zero (checked) for every
        # parameter the data determine; along near-null directions (parameters reported as not
        # identifiable, infinite VIF) the second step is round-off amplified and is not checked.
        step = _solve(problem.normal, problem.rhs - problem.normal @ sol.values, problem.yy).values
        determined = np.isfinite(sol.vif)
        if np.abs(step[determined]).max(initial=0) > 1e-6 * max(1.0, np.abs(sol.values[determined]).max(initial=0)):
            raise IdentificationError("Gauss–Newton did not converge")  # pragma: no cover - linear model
        return _result(problem, sol, method=method, projection=proj.name, loss=loss, machine=measurement.machine,
                       measurement=measurement, outliers=outliers)
    return _double_differential(problem, sol, proj.name, loss, measurement, outliers, vif_max)


def _double_differential(problem: Problem, joint: _Solution, projection: str, loss: str, measurement: Measurement,
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
        sol = _solve(n_ff, rhs, problem.yy)
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


def format_result(result: IdentificationResult) -> str:
    """Human-readable table of an identification result."""
    lines = [f"machine {result.machine}   method {result.method}   projection {result.projection}   loss {result.loss}",
             f"rows {result.n_rows}  observations {result.n_obs}  rank {result.rank}/{len(result.parameters)}  "
             f"condition {result.condition:.3g}  residual RMS {result.rms_um:.3f} um  sigma {result.sigma_um:.3f} um",
             "", f"{'parameter':<12}{'value':>11}{'std':>10}   {'95% interval':<24}unit"]
    ci = result.ci95()
    for j, name in enumerate(result.parameters):
        u = result.units.get(name, "")
        if not np.isfinite(result.values[j]):
            lines.append(f"{name:<12}{'—':>11}{'—':>10}   {'not identifiable':<24}{u}")
            continue
        lines.append(f"{name:<12}{result.values[j]:>11.3f}{result.std[j]:>10.3f}   "
                     f"[{ci[j, 0]:8.3f}, {ci[j, 1]:8.3f}]      {u}")
    if result.unobserved:
        lines += ["", f"unobserved (no trace in these data): {', '.join(result.unobserved)}"]
    if result.unidentifiable:
        lines += ["", "not identifiable from these data:"] + [f"  {c}" for c in result.unidentifiable]
    if result.outlier_rows:
        lines += ["", f"outlier rows (0-based, reference = 0): {result.outlier_rows}"]
    if result.stages:
        lines += ["", "differentials:"]
        for s in result.stages:
            lines.append(f"  stage {s.index}: solved {len(s.solved)}, fixed {', '.join(s.fixed) or 'none'}")
    obs = ", ".join(f"{k}={v:.3g}" for k, v in result.observability.items())
    lines += ["", f"observability: {obs}"]
    return "\n".join(lines)
