"""The scaled least-squares solve: singular values, rank, null space, observability.

Columns are scaled to unit norm; rank counts singular values with ``s_i/s_1 > RANK_RTOL``; a parameter
with weight beyond ``NULL_RTOL`` in a near-null direction is not individually identifiable
(:mod:`pige_sym.identification.least_squares` states the rules).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pige_sym.constants import LOSSES as LOSSES
from pige_sym.constants import METHODS as METHODS
from pige_sym.errors import IdentificationError as IdentificationError

RANK_RTOL = 1e-7


NULL_RTOL = 1e-4


NULL_WEIGHT = 1e-3


ZERO_COLUMN_RTOL = 1e-9


@dataclass
class Solution:
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


def solve_scaled(normal: np.ndarray, rhs: np.ndarray, yy: float) -> Solution:
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
    return Solution(values, cov_unit, rss, rank, svals, nulls, vif, [int(j) for j in np.flatnonzero(dead)])


def combination_text(vec: np.ndarray, names: Sequence[str], units: dict[str, str]) -> str:
    order = np.argsort(-np.abs(vec))
    lead = float(vec[order[0]])
    terms = []
    for j in order[np.abs(vec[order]) >= 1e-3].tolist():
        coef = float(vec[j]) / lead
        sign = "-" if coef < 0 else "+"
        mag = f"{abs(coef):.3g}·" if abs(abs(coef) - 1.0) > 1e-8 + 1e-5 else ""  # np.isclose's tolerances
        terms.append(f"{sign} {mag}{names[j]} [{units.get(names[j], '')}]")
    text = " ".join(terms)
    return text[2:] if text.startswith("+ ") else text


def observability(svals: np.ndarray, n_obs: int) -> dict[str, float]:
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
