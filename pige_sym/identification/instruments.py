"""Instruments other than the R-test: their observations, weights and correlations in the least squares.

Sphere probe (CONVENTIONS §7; file written by :mod:`pige_sym.measurements.probe_import`)
----------------------------------------------------------------------------------------
Row ``i`` holds ``d_i = −(c_i − pivot − R_i(c_0 − pivot))`` with ``R_i`` the nominal workpiece rotation.  The
measured centres carry errors ``δc_i`` of covariance ``Σ_i`` (the sphere fit), so

    ``d_i = J_i p + R_i δc_0 − δc_i``,   ``Cov(d_i, d_j) = δ_ij Σ_i + R_i Σ_0 R_jᵀ``  (i, j ≥ 1)

The reference centre's error enters every row, turned by the pose: the rows are correlated, and an
ordinary fit would understate the standard errors of the location errors (``(I − R_i)·δc_0`` looks exactly
like an axis-line offset).  The problem is solved by generalised least squares on the full covariance
``C`` (dense, 3(n−1) square: Cholesky ``C = L Lᵀ`` of ``C`` scaled to a mean variance of 1, then the
ordinary machinery on ``L⁻¹A``, ``L⁻¹y``); σ is estimated from the whitened residuals as usual, so the
reported σ is the typical per-component scatter [µm] and the standard errors follow the data.
Only the full 3-D projection is meaningful (the centre is a 3-D point); robust losses are not available
(the rows are correlated).
"""

from __future__ import annotations

import numpy as np

from pige_sym.errors import InputError
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.probe_import import INSTRUMENT, row_covariances


def instrument(m: Measurement) -> str:
    """The instrument a measurement comes from (``rtest`` unless its metadata says otherwise)."""
    return m.metadata.get("instrument", "rtest")


def probe_covariance(m: Measurement, rotations: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Covariance of the stacked deviations of ``rows``, shape=(3r, 3r) [µm²] (module docstring)."""
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
    """``L⁻¹A`` (3r, P) and ``L⁻¹y`` (3r,) of a probe measurement, ``C = L Lᵀ`` scaled to a mean variance of 1."""
    cov = probe_covariance(m, rotations, rows)
    cov /= float(np.mean(np.diag(cov)))
    chol = np.linalg.cholesky(cov)
    from scipy.linalg import solve_triangular

    a = solve_triangular(chol, design[rows].reshape(-1, design.shape[2]), lower=True)
    y = solve_triangular(chol, data[rows].reshape(-1), lower=True)
    return a, y
