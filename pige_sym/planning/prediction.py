"""Predicted precision of an R-test before it is run: design, covariance, criteria and gradients.

Model
-----
Row i of a test (i = 1 … N; row 0 is the reference pose and carries no information)
observes ``y_i = D·J(θ_i)·p + e_i`` with ``J = basis(θ) @ G(ball)`` from the generated
kernels, D the excitation projection (m × 3, CONVENTIONS §5) and white noise of standard
deviation σ per observed component.  The normal matrix is
``N = Σ_i w_i A_iᵀA_i`` (``A_i = D·J(θ_i)``, w_i the number of times the pose is
measured) and the predicted covariance is ``σ²·N⁺``, with the rank, near-null and
identifiability rules of :mod:`pige_sym.identification.least_squares` (unit-norm column scaling,
``RANK_RTOL``, ``NULL_RTOL``, ``NULL_WEIGHT``): a parameter with weight in a near-null
direction is *undetermined* and gets no standard error; so is one whose column is below
``UNOBSERVED_RTOL`` (1e-9) times the largest column (round-off, e.g. the A-axis errors when
A never moves).  These are exactly the standard
errors ``pige identify`` reports for data with noise σ (tests check it).

Criteria (smaller is better), over the determined parameters j
---------------------------------------------------------------
``worst``  the largest standard error ``max_j σ·√C_jj`` [µm or µrad]; optimised through
           the smooth maximum ``(Σ_j s_j^q)^(1/q)`` (q = 16, at most 8^(1/16) = 14 % above
           the maximum for 8 parameters), reported exactly;
``A``      A-optimality, the total variance ``Σ_j C_jj`` (µm² and µrad² added, as 1 µm and
           1 µrad are treated alike everywhere in pige_sym);
``D``      D-optimality, ``log det`` of the covariance of the estimable parameters,
           reported as the geometric-mean standard error ``σ·det(C)^(1/2r)``.

Gradient with respect to the angles: ``df = tr(F·dN)`` with ``F = ∂f/∂N`` in closed form
(``F = −C·W·C`` for ``worst`` and ``A``, ``−C/r`` for ``D``) and the derivative of each row's
basis by central differences of that row alone, so one gradient costs a few basis
evaluations instead of one criterion evaluation per variable.

Estimable subspace: when a parameter combination cannot be determined by any pose within
the limits (structural), the criterion is taken on the complement ``T`` of that null space:
``C = T (TᵀNT)⁻¹ Tᵀ``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.spectrum import NULL_RTOL, NULL_WEIGHT, scaled_spectrum
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import missing_tool
from pige_sym.model.projection import Projection, parse_projection

CRITERIA = ("worst", "A", "D")
SMOOTH_MAX_POWER = 16.0
UNOBSERVED_RTOL = 1e-9  # a column this much smaller than the largest is round-off: the parameter is not observed
SINGULAR = 1e6  # criterion value of a design that cannot determine the estimable parameters
_DIFF_STEP_DEG = 1e-3


@dataclass
class Setup:
    """What a test is planned or graded for (everything but the poses).

    Attributes
    ----------
    machine : str
        Canonical machine code.
    ball_mm : ndarray, shape=(3,) [mm]
    tool_mm : ndarray, shape=(3,) [mm] or None
    pivots_mm : dict of str to ndarray, shape=(3,) [mm]
    noise_um : float
        Sensor noise per observed component [µm].
    projection : Projection
    with_zero : bool
        Also plan for the zero-position errors.
    """

    machine: str
    ball_mm: np.ndarray
    tool_mm: np.ndarray | None = None
    pivots_mm: dict[str, np.ndarray] | None = None
    noise_um: float = 0.25
    projection: Projection | None = None
    with_zero: bool = False

    def __post_init__(self) -> None:
        kern = load_kernels(self.machine)
        self._kernels = kern
        self._coef: dict[bytes, np.ndarray] = {}
        self.machine = kern.MACHINE_CODE
        self.ball_mm = np.asarray(self.ball_mm, dtype=float)
        if self.ball_mm.shape != (3,) or not np.isfinite(self.ball_mm).all():
            raise InputError(f"ball position must be three finite numbers, got {self.ball_mm!r}")
        if self.tool_mm is not None:
            self.tool_mm = np.asarray(self.tool_mm, dtype=float)
        why = missing_tool(kern.MACHINE_CODE, self.tool_mm)
        if why:
            raise InputError(why)
        if not (math.isfinite(self.noise_um) and self.noise_um > 0):
            raise InputError(f"noise must be a finite number > 0 um, got {self.noise_um!r}")
        if self.projection is None:
            self.projection = parse_projection("xyz")

    @property
    def kernels(self) -> Any:
        return self._kernels

    @property
    def names(self) -> list[str]:
        """Parameters planned for: the PIGEs (and the zero-position errors with ``with_zero``)."""
        kern = self.kernels
        return list(kern.LOCATION_PARAMETERS) + (list(kern.ZERO_PARAMETERS) if self.with_zero else [])

    @property
    def units(self) -> dict[str, str]:
        return {n: self.kernels.UNITS[n] for n in self.names}

    def with_ball(self, ball_mm: np.ndarray) -> Setup:
        """The same set-up with the ball elsewhere (shares the kernels and the coefficient cache)."""
        ball = np.asarray(ball_mm, dtype=float)
        if np.array_equal(ball, self.ball_mm):
            return self
        other = copy.copy(self)
        other.ball_mm = ball
        return other


def projected_coefficients(setup: Setup, ball_mm: np.ndarray | None = None) -> np.ndarray:
    """Coefficients of the projected design, shape=(K, m, P): ``A_i = basis_i @ coefficients``."""
    ball = setup.ball_mm if ball_mm is None else np.asarray(ball_mm, dtype=float)
    key = ball.tobytes()
    if key not in setup._coef:
        kern = setup.kernels
        idx = [kern.PARAMETERS.index(n) for n in setup.names]
        g = np.asarray(kern.coefficients(ball, setup.pivots_mm or None, setup.tool_mm))[:, :, idx]
        assert setup.projection is not None
        if len(setup._coef) > 64:
            setup._coef.clear()
        setup._coef[key] = np.einsum("mi,kip->kmp", setup.projection.directions, g)
    return setup._coef[key]


def design_rows(setup: Setup, angles_deg: np.ndarray, coef: np.ndarray | None = None) -> np.ndarray:
    """Projected design of every row, shape=(n, m, P) [µm per parameter unit]."""
    coef = projected_coefficients(setup) if coef is None else coef
    b = np.asarray(setup.kernels.basis(np.atleast_2d(angles_deg)))
    return np.einsum("nk,kmp->nmp", b, coef)


def normal_matrix(rows: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
    """``AᵀA`` of design rows (n, m, P), optionally with extra columns (n, m, q) appended."""
    a = rows if extra is None else np.concatenate([rows, extra], axis=2)
    flat = a.reshape(-1, a.shape[2])
    return flat.T @ flat


@dataclass
class Prediction:
    """Predicted standard errors of a test.

    Attributes
    ----------
    names : list of str
    units : dict of str to str
    std : ndarray, shape=(P,)
        Predicted standard errors [µm or µrad]; NaN where undetermined.
    covariance : ndarray, shape=(P, P)
        ``σ²·N⁺`` (meaningful for the determined parameters only).
    determined : ndarray of bool, shape=(P,)
    undetermined : list of str
        Names of the parameters that get no value.
    rank : int
    condition : float
        Scaled condition number (inf when rank-deficient), as ``pige identify`` reports it.
    n_obs : int
    """

    names: list[str]
    units: dict[str, str]
    std: np.ndarray
    covariance: np.ndarray
    determined: np.ndarray
    undetermined: list[str]
    rank: int
    condition: float
    n_obs: int

    @property
    def worst(self) -> float:
        """Largest standard error of a determined parameter (inf when none is)."""
        finite = self.std[self.determined]
        return float(finite.max()) if finite.size else math.inf

    def criterion(self, name: str) -> float:
        """Value of a criterion (module docstring), inf when a parameter is undetermined."""
        if self.undetermined:
            return math.inf
        if name == "worst":
            return self.worst
        if name == "A":
            return float(np.trace(self.covariance))
        if name == "D":
            sign, logdet = np.linalg.slogdet(self.covariance)
            return float(math.exp(logdet / (2 * len(self.names)))) if sign > 0 else math.inf
        raise InputError(f"unknown criterion {name!r}: use {', '.join(CRITERIA)}")

    def std_dict(self) -> dict[str, float | None]:
        """Name -> standard error, None where undetermined (never a number for those)."""
        return {n: (float(s) if d else None) for n, s, d in zip(self.names, self.std, self.determined, strict=True)}


def _drop_unobserved(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero the rows/columns of parameters whose column norm is round-off; returns (normal, column norms)."""
    diag = np.sqrt(np.clip(np.diag(normal), 0, None))
    unobserved = diag <= UNOBSERVED_RTOL * diag.max(initial=0.0)
    if unobserved.any():
        normal = normal.copy()
        normal[unobserved, :] = 0.0
        normal[:, unobserved] = 0.0
        diag = np.where(unobserved, 0.0, diag)
    return normal, diag


def predict_from_normal(normal: np.ndarray, names: Sequence[str], units: dict[str, str], noise_um: float,
                        n_obs: int) -> Prediction:
    """Prediction from a normal matrix with the identification's rank and null rules."""
    p = normal.shape[0]
    normal, diag = _drop_unobserved(normal)
    scale = 1.0 / np.where(diag > 0, diag, 1.0)
    spec = scaled_spectrum(normal * np.outer(scale, scale))
    rank = spec.rank
    cov = spec.pinv * np.outer(scale, scale) * noise_um**2
    determined = (diag > 0) & (spec.null_weight() <= NULL_WEIGHT)
    std = np.where(determined, np.sqrt(np.clip(np.diag(cov), 0, None)), np.nan)
    cond = float(spec.smax / spec.svals[rank - 1]) if rank == p and rank > 0 else math.inf
    undetermined = [names[j] for j in range(p) if not determined[j]]
    return Prediction(list(names), dict(units), std, cov, determined, undetermined, rank, cond, n_obs)


def predict(setup: Setup, angles_deg: np.ndarray, *, extra: np.ndarray | None = None,
            extra_names: Sequence[str] = (), extra_units: dict[str, str] | None = None) -> Prediction:
    """Predicted standard errors of a test with these poses (row 0, the reference, is skipped).

    Parameters
    ----------
    setup : Setup
    angles_deg : ndarray, shape=(n, k) [deg]
    extra : ndarray, shape=(n, m, q), optional
        Projected extra model columns (effects estimated jointly), all rows.
    """
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    if angles.shape[0] < 2:
        raise InputError("a test needs at least one pose after the reference pose")
    rows = design_rows(setup, angles[1:])
    ex = None if extra is None else extra[1:]
    names = setup.names + list(extra_names)
    units = setup.units | dict(extra_units or {})
    return predict_from_normal(normal_matrix(rows, ex), names, units, setup.noise_um, rows.shape[0] * rows.shape[1])


@dataclass
class Estimable:
    """The estimable subspace of a problem and which parameters the criterion covers.

    Attributes
    ----------
    basis : ndarray, shape=(P, r)
        ``T``: the criterion's covariance is ``T (TᵀNT)⁻¹ Tᵀ``.
    covered : ndarray of bool, shape=(P,)
        Parameters whose standard error enters the criterion (the structurally determined ones).
    """

    basis: np.ndarray
    covered: np.ndarray

    @classmethod
    def from_rich_design(cls, normal: np.ndarray) -> Estimable:
        """Estimable subspace of a design that visits the whole admissible region."""
        normal, diag = _drop_unobserved(normal)
        scale = 1.0 / np.where(diag > 0, diag, 1.0)
        w, v = np.linalg.eigh(normal * np.outer(scale, scale))
        smax = math.sqrt(max(w.max(initial=0.0), 0.0)) or 1.0
        null = np.sqrt(np.clip(w, 0, None)) <= NULL_RTOL * smax
        covered = diag > 0
        if null.any():
            covered &= np.linalg.norm(v[:, null], axis=1) <= NULL_WEIGHT  # weight in the null span, any basis
        return cls(scale[:, None] * v[:, ~null], covered)

    @classmethod
    def full(cls, p: int) -> Estimable:
        return cls(np.eye(p), np.ones(p, dtype=bool))


def criterion_and_dn(normal: np.ndarray, est: Estimable, criterion: str, noise_um: float, *,
                     gradient: bool = True) -> tuple[float, np.ndarray]:
    """Smooth criterion value (log scale) and ``F = ∂f/∂N`` (P × P) for a normal matrix.

    A design that cannot determine the estimable parameters returns ``SINGULAR`` and ``F = 0``.
    With ``gradient=False`` only the value is computed (``F`` is returned as zeros).
    """
    t = est.basis
    m = t.T @ normal @ t
    try:
        chol = np.linalg.cholesky(m)
        minv = np.linalg.inv(m)
    except np.linalg.LinAlgError:
        return SINGULAR, np.zeros_like(normal)
    if not np.isfinite(minv).all():
        return SINGULAR, np.zeros_like(normal)
    r = t.shape[1]
    if criterion == "D":
        value = -float(np.log(np.diag(chol)).sum()) / r + math.log(noise_um)
        return value, (-(t @ minv @ t.T) / (2 * r) if gradient else np.zeros_like(normal))
    if criterion not in ("A", "worst"):
        raise InputError(f"unknown criterion {criterion!r}: use {', '.join(CRITERIA)}")
    c = t @ minv @ t.T if gradient else None
    d = np.clip(np.diag(c) if c is not None else np.einsum("ij,jk,ik->i", t, minv, t), 1e-300, None)
    cov_idx = np.flatnonzero(est.covered)
    w = np.zeros(d.shape[0])
    if criterion == "A":
        total = float(d[cov_idx].sum())
        value = math.log(total * noise_um**2)
        w[cov_idx] = 1.0 / total
    else:
        q = SMOOTH_MAX_POWER
        logs = 0.5 * np.log(d[cov_idx]) + math.log(noise_um)
        top = logs.max()
        e = np.exp(q * (logs - top))
        value = top + math.log(e.sum()) / q
        w[cov_idx] = e / e.sum() / (2 * d[cov_idx])
    return value, (-(c * w) @ c if c is not None else np.zeros_like(normal))


def criterion_values(normals: np.ndarray, est: Estimable, criterion: str, noise_um: float) -> np.ndarray:
    """:func:`criterion_and_dn`'s value for a stack of normal matrices (S, P, P), shape=(S,).

    One batched Cholesky factorisation and inverse; when one of the matrices is not
    positive definite the stack is evaluated one by one (so the values are the same).
    """
    t = est.basis
    m = t.T @ normals @ t
    try:
        chol = np.linalg.cholesky(m)
        minv = np.linalg.inv(m)
    except np.linalg.LinAlgError:
        return np.array([criterion_and_dn(n, est, criterion, noise_um, gradient=False)[0] for n in normals])
    r = t.shape[1]
    if criterion == "D":
        values = -np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1) / r + math.log(noise_um)
    elif criterion in ("A", "worst"):
        d = np.clip(np.einsum("ij,sjk,ik->si", t, minv, t), 1e-300, None)[:, est.covered]
        if criterion == "A":
            values = np.log(d.sum(axis=1) * noise_um**2)
        else:
            logs = 0.5 * np.log(d) + math.log(noise_um)
            top = logs.max(axis=1)
            values = top + np.log(np.exp(SMOOTH_MAX_POWER * (logs - top[:, None])).sum(axis=1)) / SMOOTH_MAX_POWER
    else:
        raise InputError(f"unknown criterion {criterion!r}: use {', '.join(CRITERIA)}")
    return np.where(np.isfinite(minv).all(axis=(1, 2)), values, SINGULAR)


def basis_derivatives(setup: Setup, angles_deg: np.ndarray) -> np.ndarray:
    """Derivative of each row's basis with respect to each axis angle, shape=(k, n, K) [per deg]."""
    kern = setup.kernels
    out = []
    for a in range(angles_deg.shape[1]):
        step = np.zeros(angles_deg.shape[1])
        step[a] = _DIFF_STEP_DEG
        out.append((np.asarray(kern.basis(angles_deg + step)) - np.asarray(kern.basis(angles_deg - step)))
                   / (2 * _DIFF_STEP_DEG))
    return np.array(out)


def criterion_gradient(setup: Setup, angles_deg: np.ndarray, coef: np.ndarray, est: Estimable, criterion: str,
                       weights: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """Criterion of poses (no reference row) and its gradient with respect to their angles, shape=(n, k)."""
    b = np.asarray(setup.kernels.basis(angles_deg))
    a = np.einsum("nk,kmp->nmp", b, coef)
    wts = np.ones(angles_deg.shape[0]) if weights is None else weights
    flat = (a * np.sqrt(wts)[:, None, None]).reshape(-1, a.shape[2])
    value, f = criterion_and_dn(flat.T @ flat, est, criterion, setup.noise_um)
    if value >= SINGULAR:
        return value, np.zeros_like(angles_deg)
    af = np.einsum("nmp,pq->nmq", a, f)
    grad = np.empty_like(angles_deg)
    for k, db in enumerate(basis_derivatives(setup, angles_deg)):
        da = np.einsum("nk,kmp->nmp", db, coef)
        grad[:, k] = 2.0 * wts * np.einsum("nmq,nmq->n", af, da)
    return value, grad
