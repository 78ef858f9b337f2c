"""The covariance of what compensation weighs, as blocks: groups of correlated values and values correlated with none.

A parameter file states the PIGEs' and effects' covariance (or their standard errors), and each map value's standard
error alone (the file holds no covariance of a map): what :mod:`~pige_sym.compensation.weighing` weighs is
block-diagonal — a few dense groups and, with maps, hundreds or thousands of values on their own.  Held as blocks,
every operation on it (the prior's variances, the entered values, the draws of the prediction) costs what its groups
cost: linear in the map values, where the dense q × q matrix cost q² to store and q³ to solve.

:func:`correlated_groups` finds the groups of a dense matrix (connected through non-zero covariances, as
``scipy.sparse.csgraph.connected_components`` does, without its import on ``pige checkup``'s path).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def correlated_groups(cov: np.ndarray) -> list[np.ndarray]:
    """Index groups of the estimates that are correlated (connected through non-zero covariances), each sorted,
    in the order of their first index (``scipy.sparse.csgraph.connected_components``' groups, without its 0.4 s
    import on ``pige checkup``'s path: the matrices here are a few dozen rows)."""
    linked = np.abs(cov) > 0
    linked |= linked.T
    seen = np.zeros(len(cov), dtype=bool)
    groups = []
    for start in range(len(cov)):
        if seen[start]:
            continue
        member = np.zeros(len(cov), dtype=bool)
        member[start] = True
        while True:
            grown = member | linked[member].any(axis=0)
            if (grown == member).all():
                break
            member = grown
        seen |= member
        groups.append(np.flatnonzero(member))
    return groups


@dataclass(frozen=True)
class BlockCovariance:
    """A block-diagonal covariance (q, q) [µm², µrad², µm·µrad].

    Attributes
    ----------
    size : int
        q.
    groups : tuple of (ndarray (g,) of int, ndarray (g, g))
        Each group of two or more correlated values: its indices (sorted) and its block.
    single : ndarray (s,) of int
        The values correlated with no other.
    variance : ndarray (s,)
        Their variances.
    """

    size: int
    groups: tuple[tuple[np.ndarray, np.ndarray], ...]
    single: np.ndarray
    variance: np.ndarray

    @classmethod
    def from_dense(cls, cov: np.ndarray) -> BlockCovariance:
        """The blocks of a dense covariance (:func:`correlated_groups`)."""
        cov = np.asarray(cov, dtype=float)
        found = correlated_groups(cov)
        single = np.array([int(g[0]) for g in found if g.size == 1], dtype=int)
        groups = tuple((g, cov[np.ix_(g, g)]) for g in found if g.size > 1)
        return cls(len(cov), groups, single, cov[single, single].copy())

    @classmethod
    def with_singles(cls, dense: BlockCovariance, at: np.ndarray, single: np.ndarray, variance: np.ndarray,
                     size: int) -> BlockCovariance:
        """``dense`` placed at the indices ``at`` of a covariance of ``size`` values, beside ``single`` values of
        ``variance`` correlated with none."""
        at = np.asarray(at, dtype=int)
        groups = tuple((at[idx], block) for idx, block in dense.groups)
        return cls(size, groups, np.concatenate([at[dense.single], np.asarray(single, dtype=int)]),
                   np.concatenate([dense.variance, np.asarray(variance, dtype=float)]))

    def diagonal(self) -> np.ndarray:
        """The variances, shape=(q,)."""
        out = np.zeros(self.size)
        out[self.single] = self.variance
        for idx, block in self.groups:
            out[idx] = np.diag(block)
        return out

    def row(self, i: int) -> np.ndarray:
        """Row ``i`` of the matrix, shape=(q,) (the covariances of value ``i`` with every value)."""
        out = np.zeros(self.size)
        at = np.flatnonzero(self.single == i)
        if at.size:
            out[i] = self.variance[at[0]]
            return out
        for idx, block in self.groups:
            k = np.flatnonzero(idx == i)
            if k.size:
                out[idx] = block[k[0]]
        return out

    def toarray(self) -> np.ndarray:
        """The dense matrix (q, q) (for small q: a check, a report)."""
        out = np.zeros((self.size, self.size))
        out[self.single, self.single] = self.variance
        for idx, block in self.groups:
            out[np.ix_(idx, idx)] = block
        return out

    def positive_definite(self) -> bool:
        """Whether the whole matrix is positive definite (a Cholesky factor of every group, every single variance
        > 0)."""
        if not (self.variance > 0).all():
            return False
        try:
            for _, block in self.groups:
                np.linalg.cholesky(block)
        except np.linalg.LinAlgError:
            return False
        return True

    def ridged(self, ridge: float) -> BlockCovariance:
        """The same with ``ridge`` of each variance added to it (the diagonal times ``1 + ridge``)."""
        groups = tuple((idx, block + np.diag(ridge * np.diag(block))) for idx, block in self.groups)
        return BlockCovariance(self.size, groups, self.single, self.variance + ridge * self.variance)

    def solve_shifted(self, shift: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """``(Σ + diag(shift))⁻¹ rhs`` for a vector ``rhs`` (q,), block by block."""
        out = np.empty(self.size)
        out[self.single] = rhs[self.single] / (self.variance + shift[self.single])
        for idx, block in self.groups:
            out[idx] = np.linalg.solve(block + np.diag(shift[idx]), rhs[idx])
        return out

    def roots(self) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
        """A square root per group ``V √Λ`` (``block = V Λ Vᵀ``, eigenvalues clipped at 0) and the singles' standard
        deviations: a draw of N(0, Σ) is ``R z`` group by group with z standard normal."""
        out = []
        for idx, block in self.groups:
            vals, vecs = np.linalg.eigh(block)
            out.append((idx, vecs * np.sqrt(np.clip(vals, 0.0, None))))
        return out, np.sqrt(np.clip(self.variance, 0.0, None))


def as_blocks(covariance: np.ndarray | BlockCovariance) -> BlockCovariance:
    """``covariance`` as blocks (a dense matrix split into its correlated groups)."""
    return covariance if isinstance(covariance, BlockCovariance) else BlockCovariance.from_dense(covariance)
