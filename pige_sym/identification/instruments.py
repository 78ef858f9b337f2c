"""Instruments other than the R-test: their observations, weights and correlations in the least squares.

Sphere probe (CONVENTIONS §7; file written by :mod:`pige_sym.measurements.probe_import`)
----------------------------------------------------------------------------------------
Row ``i`` holds ``d_i = −(c_i − pivot − R_i(c_0 − pivot))`` with ``R_i`` the nominal workpiece rotation.  The
measured centres carry errors ``δc_i`` of covariance ``Σ_i`` (the sphere fit), so

    ``d_i = J_i p + R_i δc_0 − δc_i``,   ``Cov(d_i, d_j) = δ_ij Σ_i + R_i Σ_0 R_jᵀ``  (i, j ≥ 1)

The reference centre's error enters every row, turned by the pose: the rows are correlated, and an
ordinary fit would understate the standard errors of the location errors (``(I − R_i)·δc_0`` looks exactly
like an axis-line offset).  The problem is solved by generalised least squares on the full covariance
``C = D + S Σ_0 Sᵀ`` (``D`` block-diagonal with the ``Σ_i``, ``S`` the stacked ``R_i``), scaled to a mean variance
of 1, without ever forming the ``3r × 3r`` matrix: a whitening ``W`` with ``WᵀW = C⁻¹`` is applied in O(r),

    ``W = (I + V Vᵀ)^(-1/2) B``,   ``B = blockdiag(L_i⁻¹)`` (``Σ_i = L_i L_iᵀ``),   ``V = B S L_0`` (3r × 3),
    ``(I + V Vᵀ)^(-1/2) = I + V P diag(((1 + λ)^(-1/2) − 1)/λ) Pᵀ Vᵀ``  with ``VᵀV = P diag(λ) Pᵀ`` (3 × 3),

so ``WᵀW = (B⁻¹B⁻ᵀ + S Σ_0 Sᵀ)⁻¹ = C⁻¹``: the same normal equations as a dense Cholesky whitening (checked to
1e-9 relative in the tests), in time and memory linear in the rows.  σ is estimated from the whitened
residuals as usual, so the reported σ is the typical per-component scatter [µm] and the standard errors
follow the data.  Only the full 3-D projection is meaningful (the centre is a 3-D point); robust losses are
not available (the rows are correlated).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pige_sym.errors import InputError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.probe_import import INSTRUMENT, row_covariances


def instrument(m: Measurement) -> str:
    """The instrument a measurement comes from (``rtest`` unless its metadata says otherwise)."""
    return m.metadata.get("instrument", "rtest")


def probe_covariance(m: Measurement, rotations: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Covariance of the stacked deviations of ``rows``, shape=(3r, 3r) [µm²] (module docstring).

    Dense, for checks on small files: the fit itself never forms it (:func:`whitened_rows`).
    """
    cov = row_covariances(m)
    stack = rotations[rows].reshape(3 * rows.size, 3)  # the R_i stacked
    big = stack @ cov[0] @ stack.T
    for k, i in enumerate(rows):
        big[3 * k:3 * k + 3, 3 * k:3 * k + 3] += cov[i]
    return big


def whitened_normal(m: Measurement, design: np.ndarray, data: np.ndarray, rotations: np.ndarray,
                    rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Normal equations of the generalised least squares of a probe measurement.

    Parameters
    ----------
    m : Measurement
    design : ndarray, shape=(n, 3, P)
        All rows, machine frame [µm per µm or µrad].
    data : ndarray, shape=(n, 3) [µm]
    rotations : ndarray, shape=(n, 3, 3)
        Nominal workpiece rotation of every row.
    rows : ndarray of int
        Rows fitted (not the reference row).

    Returns
    -------
    normal : (P, P), rhs : (P,), yy : float
        ``AᵀC⁻¹A``, ``AᵀC⁻¹y``, ``yᵀC⁻¹y`` with ``C`` scaled to a mean variance of 1.
    """
    if instrument(m) != INSTRUMENT:
        raise InputError(f"not a {INSTRUMENT} measurement")
    if 0 in set(rows.tolist()):
        raise InputError("the reference row of a probe measurement is not an observation (it defines c_nom)")
    a, y = whitened_rows(m, design, data, rotations, rows)
    return a.T @ a, a.T @ y, float(y @ y)


def whitened_rows(m: Measurement, design: np.ndarray, data: np.ndarray, rotations: np.ndarray,
                  rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``WA`` (3r, P) and ``Wy`` (3r,) of a probe measurement, ``WᵀW = C⁻¹`` with ``C`` scaled to a mean variance
    of 1, in O(r) (module docstring)."""
    cov = row_covariances(m)
    whiten = _whitening(cov[rows], cov[0], rotations[rows])
    return whiten(design[rows]), whiten(data[rows][:, :, None])[:, 0]


def _whitening(sigma: np.ndarray, sigma0: np.ndarray, rotations: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``X ↦ W X`` for stacked rows ``X`` of shape (r, 3, k), returning (3r, k) (module docstring).

    Parameters
    ----------
    sigma : ndarray, shape=(r, 3, 3) [µm²]
        Covariance of each row's own centre.
    sigma0 : ndarray, shape=(3, 3) [µm²]
        Covariance of the reference centre.
    rotations : ndarray, shape=(r, 3, 3)
        ``R_i`` of each row.
    """
    shared = np.einsum("rij,jk,rlk->ril", rotations, sigma0, rotations)  # R_i Σ_0 R_iᵀ
    scale = float(np.mean(np.trace(sigma, axis1=1, axis2=2) + np.trace(shared, axis1=1, axis2=2))) / 3.0
    chol = np.linalg.cholesky(sigma / scale)  # (r, 3, 3): Σ_i = L_i L_iᵀ
    inv_chol = np.linalg.inv(chol)
    lever = np.linalg.cholesky(sigma0 / scale)
    v = np.einsum("rij,rjk,kl->ril", inv_chol, rotations, lever).reshape(-1, 3)  # V = B S L_0, (3r, 3)
    lam, vecs = np.linalg.eigh(v.T @ v)
    lam = np.clip(lam, 0.0, None)
    factor = np.where(lam > 1e-300, np.expm1(-0.5 * np.log1p(lam)) / np.where(lam > 1e-300, lam, 1.0), -0.5)
    core = (vecs * factor) @ vecs.T  # P diag(((1 + λ)^-1/2 − 1)/λ) Pᵀ

    def apply(x: np.ndarray) -> np.ndarray:
        y = np.einsum("rij,rjk->rik", inv_chol, x).reshape(-1, x.shape[2])  # B X
        return y + v @ (core @ (v.T @ y))

    return apply
