"""What the diagnosis does differently for instruments other than the R-test.

- :func:`screen_scale`: probe rows differ in precision (the contact pattern, the stand hiding contacts, the
  pattern turning with a head); the search and its outlier screen fit every row brought to one scale with its
  own covariance ``Σ_i``.
- :func:`reference_prior`: the rows are independent given the reference centre's error ``u`` (``d_i`` gains
  ``R_w,i·u``): the search holds ``u`` as a nuisance of every model (three columns after the PIGEs,
  :data:`~pige_sym.diagnosis.candidates.REFERENCE_NUISANCE`) with its prior ``N(0, Σ_0)`` (the reference pose's
  own fit) as a pseudo-observation; the PIGE fit of the search is then the generalised least squares of the
  identification.  Without it a head machine's search (where ``u`` is not an axis-line offset) named
  drifts and error motions in 25–60 % of noise-only logs.
- :func:`coupled_estimate`, :func:`couple_final`: the final model (PIGEs and accepted effects) solved again by
  generalised least squares with the probe rows' full covariance (the reference centre's error in every row,
  :mod:`pige_sym.identification.instruments`), so the reported standard errors are honest.
- :func:`instrument_notes`: what the search does not model about the instrument (the rows' correlation
  through the reference pose; a direction-dependent trigger radius that one contact pattern hides).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from pige_sym.diagnosis.candidates import Layout
from pige_sym.diagnosis.results import Finding
from pige_sym.diagnosis.selection import Model
from pige_sym.diagnosis.thermal import drift_derivative
from pige_sym.identification.instruments import instrument, whitened_rows
from pige_sym.identification.normal_sums import NormalSums
from pige_sym.identification.result import IdentificationResult
from pige_sym.identification.spectrum import solve_scaled
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement


def screen_scale(m: Measurement) -> np.ndarray:
    """Per probe row, ``s̄·Σ_i^{-1/2}`` with ``Σ_i`` the covariance of its centre and ``s̄`` the median of their
    RMS σ: rows of unequal precision brought to one scale, so the search's least squares and the outlier screen's
    robust noise level fit every row.  Shape (n, 3, 3); row 0 holds the scale of the reference centre's
    error (:func:`reference_prior`)."""
    from pige_sym.measurements.probe_import import row_covariances

    vals, vecs = np.linalg.eigh(row_covariances(m))
    scale = float(np.median(np.sqrt(vals[1:].mean(axis=1))))
    return np.asarray(scale * (vecs / np.sqrt(vals)[:, None, :]) @ np.transpose(vecs, (0, 2, 1)))


def reference_prior(sums: NormalSums, first: int, scale0: np.ndarray) -> None:
    """Add the prior ``u ~ N(0, Σ_0)`` of the reference centre's error to the search's normal equations.

    A pseudo-observation ``0 = u`` weighted like the rows (``scale0 = s̄·Σ_0^{-1/2}``) on the nuisance columns
    ``first … first + 2``, shared by every fold (a held-out fit keeps it) and counted as no observation.
    """
    a = np.zeros((3, sums.gram.shape[1]))
    a[:, first:first + 3] = scale0
    sums.gram += (a.T @ a) / sums.gram.shape[0]


def coupled_estimate(m: Measurement, design: np.ndarray, rows: np.ndarray,
                     transform: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The model's coefficients by generalised least squares on a probe file's correlated rows.

    Parameters
    ----------
    m : Measurement
        A probe import (machine frame).
    design : ndarray, shape=(n, 3, K)
        The final model's columns on every row (row 0 unused) [µm per coefficient].
    rows : ndarray of int
        The rows fitted (outliers left out).
    transform : ndarray, shape=(P + Σq, K)
        Coefficients to PIGEs and catalogue parameters.

    Returns
    -------
    values : (P + Σq,), covariance : (P + Σq, P + Σq), identifiable : (P + Σq,) bool, sigma2 : float
        In PIGE and catalogue units; ``sigma2`` is the whitened residual variance.
    """
    rot = load_kernels(m.machine).workpiece_rotation(m.angles_deg)
    a, y = whitened_rows(m, design, m.deviation_um, rot, rows)
    sol = solve_scaled(a.T @ a, a.T @ y, float(y @ y))
    sigma2 = sol.rss / max(y.size - sol.rank, 1)
    determined = np.isfinite(sol.vif)
    ident = np.abs(transform[:, ~determined]).sum(axis=1) == 0
    return transform @ sol.values, transform @ sol.cov_unit @ transform.T * sigma2, ident, sigma2


def couple_final(m: Measurement, layout: Layout, model: Model, design: Callable[[np.ndarray], np.ndarray],
                 transform: np.ndarray, result: IdentificationResult, outliers: list[int]) -> None:
    """Replace the diagnosis' final estimate of a probe file by :func:`coupled_estimate` (in place).

    ``design``: the raw super-design rows of the model's candidates; ``transform``: model coefficients to PIGEs and
    catalogue parameters.  An interpolated drift's τ is estimated too: its column ∂/∂ln τ carries τ's uncertainty
    into the others.  The reference centre's error is in the rows' covariance here, not a column.
    """
    skip = set(outliers)
    rows = np.array([r for r in range(1, m.n_rows) if r not in skip], dtype=int)
    full = design(rows)
    taus = [full @ drift_derivative(layout, model, i) for i, c in enumerate(model.cands) if c.mix is not None]
    p, q = len(layout.pige), len(layout.nuisance)
    keep = np.r_[0:p, p + q:model.w.shape[1]]
    cols = np.zeros((m.n_rows, 3, keep.size + len(taus)))
    cols[rows] = np.concatenate([(full @ model.w)[:, :, keep], *(t[:, :, None] for t in taus)], axis=2)
    transform = np.hstack([transform[:, keep], np.zeros((transform.shape[0], len(taus)))])
    values, cov, ident, sigma2 = coupled_estimate(m, cols, rows, transform)
    ident &= result.identifiable
    result.values = np.where(ident, values, np.nan)
    result.covariance = cov
    result.std = np.where(ident, np.sqrt(np.clip(np.diag(cov), 0, None)), np.nan)
    result.identifiable = ident
    result.sigma_um = math.sqrt(sigma2)


def instrument_notes(m: Measurement, findings: list[Finding]) -> list[str]:
    """What the search did not model about an instrument other than the R-test (its rows are correlated)."""
    kind = instrument(m)
    if kind == "rtest":
        return []
    blind = (" A probe whose trigger radius depends on the direction biases the axis-line offsets; with one contact "
             "pattern at every pose nothing in the residuals shows it (docs/probe.md): calibrate the probe per "
             "direction, or probe with pige program --pattern alternate so the diagnosis can fit it."
             if kind == "sphere-probe" and not any(f.effect == "probe_trigger" for f in findings) else "")
    kern = load_kernels(m.machine)
    if kind == "sphere-probe" and kern.TOOL_ROTARY:
        blind += (" A stylus centre that is not where --tool says (a bent stylus, a wrong tool length) moves every "
                  "centre by (R_t - I)·Δ: exactly the offsets of the head's axis lines "
                  f"({', '.join(_head_offsets(kern))}), so nothing in the residuals shows it either: calibrate the "
                  "stylus (length and offset) before probing.")
    search = (f"{kind}: the search fits every row at its own precision, with the reference centre's error as a "
              "nuisance of known covariance (the rows' correlation)")
    if not findings:
        return [f"{search}; the final estimate is the identification with the reference pose's correlation "
                "(standard errors from it)." + blind]
    return [f"{search}; the final fit (PIGEs and the accepted effects) is solved again with the reference pose's "
            "correlation and the drift time constants' uncertainty, so its standard errors are honest." + blind]


def _head_offsets(kern: Any) -> list[str]:
    """The position errors of the tool-side axes (what a stylus offset turns into)."""
    return [p for p in kern.LOCATION_PARAMETERS if p[-1] in "".join(kern.TOOL_ROTARY) and p[1] in "XYZ"]
