"""The scaled least-squares solve: singular values, rank, null space, observability.

Columns are scaled to unit norm; rank counts singular values with ``s_i/s_1 > RANK_RTOL``; the near-null
directions are those with ``s_i/s_1 <= NULL_RTOL``, and a parameter whose weight in them (the norm of its row in an
orthonormal basis of their span, which no choice of basis changes) exceeds ``NULL_WEIGHT`` is not individually
identifiable (:mod:`pige_sym.identification.least_squares` states the rules).  The near-null span is returned as
its canonical basis (:mod:`pige_sym.identification.canonical`), the same on every processor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pige_sym.constants import LOSSES as LOSSES
from pige_sym.constants import METHODS as METHODS
from pige_sym.errors import IdentificationError as IdentificationError
from pige_sym.identification.canonical import CanonicalBasis, canonical_basis, empty_basis, separation

#: Singular values at or below this fraction of the largest are round-off: not in the rank, not inverted.  From normal
#: equations a structural null shows as ~1e-8 (the guide's ``--projection x``: 8.6e-9), and as up to ~1e-6 when the
#: normal matrix differs in its last ~1e-12 (another BLAS, another summation order, a million rows): 1e-5 keeps
#: the rank the same on every processor (it was 1e-7, 10x above the first and below the second).
RANK_RTOL = 1e-5


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
    null_space: CanonicalBasis  # the near-null span, canonical, in parameter units
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
        """(P,) weight of each parameter in the near-null span: the norm of its row in the (orthonormal)
        near-null vectors, the same for any basis of the span (0 when there is none)."""
        if not self.near_null.any():
            return np.zeros(self.vectors.shape[0])
        return np.asarray(np.linalg.norm(self.vectors[:, self.near_null], axis=1))

    def null_space(self, scale: np.ndarray) -> CanonicalBasis:
        """The canonical basis of the near-null span in parameter units (``scale``: units per scaled unit)."""
        if not self.near_null.any():
            return empty_basis(self.vectors.shape[0])
        return canonical_basis(self.vectors[:, self.near_null], scale,
                               separation=separation(self.svals**2, self.near_null))


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


def scale_columns(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The normal matrix with its columns scaled to unit norm: (scaled (P, P), scale (P,) [parameter units per
    scaled unit], dead (P,) bool).  A zero or near-zero column (parameter not observed) is removed (its row and
    column 0, scale 1), never scaled up: scaling a ~1e-18 column to unit norm would turn round-off into a
    "value" of 1e17."""
    diag = np.sqrt(np.clip(np.diag(normal), 0, None))
    dead = diag <= ZERO_COLUMN_RTOL * max(float(diag.max(initial=0.0)), 1e-300)
    scale = 1.0 / np.where(dead, 1.0, diag)
    ns = normal * np.outer(scale, scale)
    ns[dead, :] = 0.0
    ns[:, dead] = 0.0
    return ns, scale, dead


def solve_scaled(normal: np.ndarray, rhs: np.ndarray, yy: float) -> Solution:
    ns, scale, dead = scale_columns(normal)
    rhs = np.where(dead, 0.0, rhs)
    spec = scaled_spectrum(ns)
    svals, rank, pinv_scaled = spec.svals, spec.rank, spec.pinv
    xs = pinv_scaled @ (rhs * scale)
    values = xs * scale
    cov_unit = pinv_scaled * np.outer(scale, scale)
    rss = max(float(yy - 2 * values @ rhs + values @ normal @ values), 0.0)
    vif = np.diag(pinv_scaled).copy()
    vif[~np.isfinite(vif)] = np.inf
    vif[spec.null_weight() > NULL_WEIGHT] = np.inf
    vif[dead] = np.inf
    values[dead] = 0.0
    return Solution(values, cov_unit, rss, rank, svals, spec.null_space(scale), vif,
                    [int(j) for j in np.flatnonzero(dead)])


def observability(svals: np.ndarray, n_obs: int) -> dict[str, float]:
    """The observability indices O1–O5 of the scaled singular values; 0 when one is round-off (at or below
    ``RANK_RTOL`` of the largest: its digits would be the processor's)."""
    s = np.asarray(svals, dtype=float)
    if s.size and s[0] > 0:
        s = np.where(s > RANK_RTOL * s[0], s, 0.0)
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
