"""The predicted tool-point error of a correction: draws of the parameters, the RMS each leaves.

:mod:`~pige_sym.compensation.weighing` states the rule: the RMS tool-point error left by entering ``c`` on a
machine whose parameters are x is ``√((x − c)ᵀ M (x − c))`` (M the error moments over the judged poses, (q, q)),
drawn for ``x ~ N(x̂, Σ)``: ``x − c = d + R z`` with ``d = x̂ − c``, z standard normal (``DRAWS`` of them, a fixed
seed) and R a square root of Σ, group by group of correlated values (:class:`~pige_sym.compensation.covariance.
BlockCovariance`).  Expanded,

    |x − c|²_M = dᵀ M d + 2 (R z)ᵀ M d + (R z)ᵀ M (R z),

the last term is the same for every correction judged on the same poses: it is computed once per weighing
(:class:`Draws`), and each prediction costs a product of the draws with one vector — linear in the number of values,
where the draws' quadratic form cost ``DRAWS·q²`` per prediction.  With maps, M is sparse (a map value moves the
tool point only at poses near its grid angle: :mod:`~pige_sym.compensation.map_moments`) and each draw's form costs
its non-zeros.  The draws are made in chunks from the seeded generator (the same numbers as all at once), so the
memory stays ``chunk·q``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.compensation.covariance import BlockCovariance, as_blocks

#: Draws of the parameters for the predicted error (fixed seed: the same file gives the same numbers).
DRAWS = 4000
#: Values drawn at once at most (rows × values): the memory of the draws.
CHUNK_VALUES = 1 << 20


@dataclass(frozen=True)
class ErrorPrediction:
    """Predicted RMS tool-point error over the judged poses [µm]: expected value and 95 % bound."""

    expected_um: float
    p95_um: float

    def to_dict(self) -> dict[str, float]:
        return {"expected": self.expected_um, "p95": self.p95_um}

    def text(self) -> str:
        if self.p95_um == self.expected_um:
            return f"{self.expected_um:.2f} um (if the values were exact: no uncertainty stated)"
        return f"{self.expected_um:.2f} um (95 % <= {self.p95_um:.2f})"


@dataclass
class Draws:
    """The draws of N(0, Σ) and their quadratic form over the moments, for any number of predictions (module
    docstring).

    Parameters
    ----------
    covariance : (q, q) ndarray or BlockCovariance
    moments : (q, q) ndarray or scipy sparse matrix
        ``M = Dᵀ D / n`` [µm² per unit²].
    seed : int
    """

    covariance: np.ndarray | BlockCovariance
    moments: Any
    seed: int = 0
    _blocks: BlockCovariance = field(init=False, repr=False)
    _roots: tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray] = field(init=False, repr=False)
    _form: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self._blocks = as_blocks(self.covariance)
        self._roots = self._blocks.roots()

    def _chunks(self) -> Iterator[tuple[slice, np.ndarray]]:
        """``(rows, R z)`` chunk by chunk: the same z as ``standard_normal((DRAWS, q))`` at once."""
        q = self._blocks.size
        rng = np.random.default_rng(self.seed)
        step = max(1, min(DRAWS, CHUNK_VALUES // max(q, 1)))
        roots, single_std = self._roots
        for start in range(0, DRAWS, step):
            rows = slice(start, min(start + step, DRAWS))
            z = rng.standard_normal((rows.stop - rows.start, q))
            w = np.empty_like(z)
            w[:, self._blocks.single] = z[:, self._blocks.single] * single_std
            for idx, root in roots:
                w[:, idx] = z[:, idx] @ root.T
            yield rows, w

    def form(self) -> np.ndarray:
        """``(R z)ᵀ M (R z)`` of every draw, shape=(DRAWS,) [µm²] (computed once)."""
        if self._form is None:
            out = np.empty(DRAWS)
            for rows, w in self._chunks():
                out[rows] = np.einsum("si,si->s", np.asarray(w @ self.moments), w)
            self._form = out
        return self._form

    def left(self, shift: np.ndarray) -> ErrorPrediction:
        """The RMS left by a correction that leaves ``shift = x̂ − c`` (q,) on average [µm, µrad]."""
        d = np.asarray(shift, dtype=float)
        md = np.asarray(self.moments @ d, dtype=float).reshape(-1)
        square = np.empty(DRAWS)
        form = self.form()
        for rows, w in self._chunks():
            square[rows] = float(d @ md) + 2.0 * (w @ md) + form[rows]
        rms = np.sqrt(np.clip(square, 0.0, None))
        return ErrorPrediction(float(rms.mean()), float(np.quantile(rms, 0.95)))
