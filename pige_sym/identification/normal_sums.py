"""Normal equations of a design accumulated in row chunks, split into cross-validation folds.

For a design ``X`` (rows × C, three observations per row) and data ``y`` the sums
``XᵀX``, ``Xᵀy``, ``yᵀy`` and the observation count are accumulated per fold; a fold is
a fixed pseudo-random subset of rows (seeded, so results are reproducible).  Every
least-squares fit of a model ``X·W`` (W: C × K) then needs only ``WᵀGW`` and ``WᵀXᵀy``,
and the k-fold held-out error of a fit is exact from the per-fold sums: fit on
``G − G_f``, evaluate ``yᵀy_f − 2x·r_f + x·G_f·x`` on fold f.  Memory is O(k·C²) and a
chunk's design, whatever the number of rows.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pige_sym.identification.canonical import CanonicalBasis, canonical_basis, empty_basis, separation

N_FOLDS = 5
CHUNK_ROWS = 10000
RANK_RTOL = 1e-5  # as :data:`pige_sym.identification.spectrum.RANK_RTOL`: above the normal matrix's round-off
NULL_RTOL = 1e-4
NULL_WEIGHT = 0.05


@dataclass
class NormalSums:
    """Per-fold normal equations.

    Attributes
    ----------
    gram : ndarray, shape=(F, C, C)
    rhs : ndarray, shape=(F, C)
    yy : ndarray, shape=(F,)
    n_obs : ndarray, shape=(F,)
    """

    gram: np.ndarray
    rhs: np.ndarray
    yy: np.ndarray
    n_obs: np.ndarray

    @property
    def total_gram(self) -> np.ndarray:
        """``XᵀX`` over all folds, shape=(C, C)."""
        return np.asarray(self.gram.sum(axis=0))

    @property
    def total_rhs(self) -> np.ndarray:
        """``Xᵀy`` over all folds, shape=(C,)."""
        return np.asarray(self.rhs.sum(axis=0))

    @property
    def n(self) -> int:
        """Number of observations."""
        return int(self.n_obs.sum())

    def add_rows(self, x: np.ndarray, y: np.ndarray, folds: np.ndarray, sign: float = 1.0) -> None:
        """Add (sign=+1) or remove (−1) rows: x (r, 3, C), y (r, 3), folds (r,).

        Rows sorted by fold are sliced without copies (``accumulate`` evaluates them so).
        """
        bounds = np.flatnonzero(np.diff(folds)) + 1
        sorted_folds = bool(np.all(np.diff(folds) >= 0))
        groups = np.split(np.arange(folds.size), bounds) if sorted_folds else \
            [np.flatnonzero(folds == f) for f in np.unique(folds)]
        for idx in groups:
            f = int(folds[idx[0]])
            sel = slice(int(idx[0]), int(idx[-1]) + 1) if sorted_folds else idx
            a = x[sel].reshape(-1, x.shape[2])
            b = y[sel].reshape(-1)
            self.gram[f] += sign * (a.T @ a)
            self.rhs[f] += sign * (a.T @ b)
            self.yy[f] += sign * float(b @ b)
            self.n_obs[f] += int(sign) * b.size


def extend(sums: NormalSums, n_new: int, x: np.ndarray, y: np.ndarray, folds: np.ndarray) -> NormalSums:
    """Append ``n_new`` columns that are zero outside the given rows.

    Parameters
    ----------
    x : ndarray, shape=(r, 3, C + n_new)
        Full design rows (old and new columns) of every row where a new column is non-zero.
    y : ndarray, shape=(r, 3)
    folds : ndarray, shape=(r,)
    """
    f_n, c = sums.gram.shape[0], sums.gram.shape[1]
    out = NormalSums(np.zeros((f_n, c + n_new, c + n_new)), np.zeros((f_n, c + n_new)), sums.yy.copy(),
                     sums.n_obs.copy())
    out.gram[:, :c, :c], out.rhs[:, :c] = sums.gram, sums.rhs
    for f in np.unique(folds):
        sel = folds == f
        a = x[sel].reshape(-1, x.shape[2])
        b = y[sel].reshape(-1)
        delta = a.T @ a
        delta[:c, :c] = 0.0  # already counted
        out.gram[f] += delta
        out.rhs[f, c:] += a[:, c:].T @ b
    return out


def fold_of_rows(n_rows: int, n_folds: int = N_FOLDS, seed: int = 0) -> np.ndarray:
    """Fold index of every row, shape=(n,) (row 0, the reference, gets −1)."""
    folds = np.random.default_rng(seed).integers(0, n_folds, size=n_rows)
    folds[0] = -1
    return folds


def accumulate(design: Callable[[np.ndarray], np.ndarray], data: np.ndarray, rows: np.ndarray, folds: np.ndarray,
               n_columns: int, n_folds: int = N_FOLDS, chunk: int = CHUNK_ROWS) -> NormalSums:
    """Accumulate the normal equations over ``rows`` in chunks.

    Parameters
    ----------
    design : callable
        ``design(rows) -> (r, 3, C)`` design rows.
    data : ndarray, shape=(n, 3) [µm]
    rows : ndarray of int
    folds : ndarray of int, shape=(n,)
    """
    sums = NormalSums(np.zeros((n_folds, n_columns, n_columns)), np.zeros((n_folds, n_columns)),
                      np.zeros(n_folds), np.zeros(n_folds, dtype=int))
    for start in range(0, rows.size, chunk):
        r = rows[start: start + chunk]
        r = r[np.argsort(folds[r], kind="stable")]  # each fold's rows contiguous: no copies
        sums.add_rows(design(r), data[r], folds[r])
    return sums


@dataclass
class LinearFit:
    """A least-squares fit on normal equations.

    Attributes
    ----------
    values : ndarray, shape=(K,)
    cov_unit : ndarray, shape=(K, K)
        ``(WᵀGW)⁺`` (multiply by σ² for the covariance).
    rss : float [µm²]
    rank : int
    n_obs : int
    heldout_rms : float [µm]
        k-fold cross-validated RMS of the observations.
    vif : ndarray, shape=(K,)
        Variance inflation per model column; ``inf`` where undetermined (weight in a
        near-null direction, or a column without trace).
    svals : ndarray, shape=(K,)
        Singular values of the column-scaled design.
    null_space : CanonicalBasis
        The near-null span (parameter units), its canonical basis (:mod:`pige_sym.identification.canonical`).
    """

    values: np.ndarray
    cov_unit: np.ndarray
    rss: float
    rank: int
    n_obs: int
    heldout_rms: float
    vif: np.ndarray
    svals: np.ndarray
    null_space: CanonicalBasis

    @property
    def sigma2(self) -> float:
        """Residual variance ``RSS/(N − rank)`` [µm²]."""
        dof = self.n_obs - self.rank
        return self.rss / dof if dof > 0 else float("nan")

    @property
    def std(self) -> np.ndarray:
        """Standard errors of the coefficients, shape=(K,)."""
        return np.sqrt(np.clip(np.diag(self.cov_unit) * self.sigma2, 0, None))

    def bic(self, extra_params: int = 0) -> float:
        """``N ln(RSS/N) + k ln N`` with k = rank + extra (non-linear) parameters."""
        n = max(self.n_obs, 1)
        return n * math.log(max(self.rss, 1e-300) / n) + (self.rank + extra_params) * math.log(n)


def _solve(g: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, np.ndarray, np.ndarray,
                                                  CanonicalBasis]:
    d = np.sqrt(np.clip(np.diag(g), 0, None))
    dmax = float(d.max()) if d.size else 0.0
    s = np.where(d > 1e-12 * max(dmax, 1e-300), 1.0 / np.where(d > 0, d, 1.0), 0.0)
    gs = g * np.outer(s, s)
    w, v = np.linalg.eigh((gs + gs.T) / 2)
    w = np.clip(w, 0, None)[::-1]
    v = v[:, ::-1]
    wmax = float(w[0]) if w.size and w[0] > 0 else 1.0
    keep = w > RANK_RTOL**2 * wmax
    inv = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    pinv_s = (v * inv) @ v.T
    x = s * (pinv_s @ (s * r))
    vif = np.diag(pinv_s).copy()
    near_null = w <= NULL_RTOL**2 * wmax
    if near_null.any():  # a parameter with weight in the near-null span (its row's norm: any basis) is not determined
        vif[np.linalg.norm(v[:, near_null], axis=1) > NULL_WEIGHT] = np.inf
    vif[s == 0] = np.inf
    nulls = (canonical_basis(v[:, near_null], np.where(s > 0, s, 1.0), separation=separation(w, near_null))
             if near_null.any() else empty_basis(g.shape[0]))
    return x, pinv_s * np.outer(s, s), int(keep.sum()), vif, np.sqrt(w), nulls


def _solve_folds(g: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Minimum-norm solutions of a stack of normal equations g (F, K, K), r (F, K) at once, shape=(F, K)."""
    d = np.sqrt(np.clip(np.einsum("fkk->fk", g), 0, None))
    dmax = d.max(axis=1, keepdims=True)
    s = np.where(d > 1e-12 * np.maximum(dmax, 1e-300), 1.0 / np.where(d > 0, d, 1.0), 0.0)
    gs = g * s[:, :, None] * s[:, None, :]
    w, v = np.linalg.eigh((gs + np.swapaxes(gs, 1, 2)) / 2)
    wmax = np.maximum(w.max(axis=1, keepdims=True), 1e-300)
    keep = w > RANK_RTOL**2 * wmax
    inv = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    proj = np.einsum("fkj,fk->fj", v, s * r)  # Vᵀ(s·r)
    return np.asarray(s * np.einsum("fkj,fj->fk", v, inv * proj))


def fit(sums: NormalSums, w: np.ndarray, heldout: bool = True) -> LinearFit:
    """Least-squares fit of the model ``X·W`` (W: C × K) with its k-fold held-out RMS."""
    if heldout:
        gf = w.T @ sums.gram @ w
        rf = sums.rhs @ w  # (F, K)
        g, r = gf.sum(axis=0), rf.sum(axis=0)
    else:  # the totals only
        g, r = w.T @ sums.total_gram @ w, sums.total_rhs @ w
    yy = float(sums.yy.sum())
    x, cov, rank, vif, svals, nulls = _solve(g, r)
    rss = max(yy - 2 * float(x @ r) + float(x @ g @ x), 0.0)
    held = float("nan")
    if heldout:
        xf = _solve_folds(g[None] - gf, r[None] - rf)  # fit without fold f, for every f
        err = sums.yy - 2 * np.einsum("fk,fk->f", xf, rf) + np.einsum("fk,fkl,fl->f", xf, gf, xf)
        held = math.sqrt(float(np.clip(err, 0, None).sum()) / max(sums.n, 1))
    return LinearFit(x, cov, rss, rank, sums.n, held, vif, svals, nulls)
