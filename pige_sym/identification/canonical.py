"""Canonical bases and combinations: one text for a subspace of parameters, on every processor.

A null space (the combinations the data do not determine, a candidate's removed directions, the motions a grid
angle does not see) has many bases, and which one an eigen-solver returns depends on the processor, the BLAS and
the last bits of the normal matrix.  Everything pige prints or writes about such a subspace goes through
:func:`canonical_basis` (the one basis the subspace determines) and :class:`Combination` (the one printer).

The canonical basis
-------------------
The reduced row-echelon form of the subspace with its pivots taken in the parameters' fixed order (the kernels'
``PARAMETERS``, then any extra column, as the caller lists them): basis vector ``i`` is the vector of the subspace
that is 1 on its pivot parameter ``p_i`` and 0 on the other pivots.  For given pivots it is unique for the subspace;
its sign and scale are fixed by the pivot.

*Units.* The pivots are chosen in the data's own scale, the columns scaled to unit norm as the solve scales them
(a unit of a scaled parameter moves the data by 1), so the choice does not depend on the parameters' units; the
coefficients are then given in parameter units, where the row-echelon form is the same for the subspace (the
coefficient of parameter ``k`` in the vector of pivot ``p`` is in [p]/[k]: ``EB0C [urad] - 0.08·EX0C [um]``
reads 0.08 µrad per µm).

*Pivots with a tolerance.* An exact row-echelon form takes as the next pivot the first parameter on which the part
of the subspace vanishing on the earlier pivots is not zero; in floating point "not zero" needs a threshold.  Here
a parameter is the next pivot when that part's weight on it (the norm of its row in an orthonormal basis, in the
data's scale) is at least :data:`PIVOT_RTOL` of the largest weight among it and the parameters after it.  A
parameter the subspace barely touches is so never a pivot (which would make every other coefficient huge and
ill-determined), and a tie between two parameters (a symmetric machine) is broken by their order, not by round-off.

*Tiny terms.* A term whose coefficient in the data's scale is below :data:`DROP_RTOL` of the largest of its vector
is 0: the 1e-3 rule the printers had, taken in the data's scale so that it does not depend on the units.

*Near-null directions.* The subspace is what the caller's tolerance chose (``NULL_RTOL``: singular values at or
below 1e-4 of the largest): the invariant subspace of those eigenvalues, not an exact null space.  Round-off moves
it by an angle of at most ``ROUNDOFF / separation`` (Davis–Kahan), ``separation`` the gap between the kept and the
near-null eigenvalues of the scaled normal matrix over its largest, and :data:`ROUNDOFF` (1e-12) the relative size
of the differences between processors, BLAS and summation orders in that matrix.

*Rounding to what is determined.* Each coefficient keeps at most :data:`SIGNIFICANT` significant digits, and no
digit that the round-off above could change by more than 1/:data:`MARGIN` of its unit (the bound of the angle
carried through ``B = Q·Q_p⁻¹``: ``|δB| ≤ θ·(1 + |B|)·|Q_p⁻¹|``).  The printer shows 3 significant digits of
these.  The text is then the same on every processor unless a number sits within round-off of a boundary: a
singular value at ``NULL_RTOL`` or ``RANK_RTOL``, a weight at :data:`PIVOT_RTOL`, a term at :data:`DROP_RTOL`, or
a coefficient at half a unit of its last kept digit.  With round-off of the assumed 1e-12 a kept digit changes
with a probability below 2/:data:`MARGIN` per coefficient, and the 3 printed digits (rounded from the kept ones)
about a thousand times less often; real differences between BLAS are nearer 1e-15.  An exact tie at such a
boundary (a coefficient exactly ``x.xxxxx5`` in its 7th digit, as exact dyadic data give) is not left to round-off:
a coefficient within its round-off (``delta``, at least :data:`ROUNDOFF` of itself) of half a unit of its last kept
digit is taken as that tie and rounded away from zero (:func:`rounded`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

#: A parameter becomes a pivot when its weight in the remaining subspace is at least this fraction of the largest.
PIVOT_RTOL = 0.3
#: A term below this fraction of its vector's largest (in the data's scale) is dropped.
DROP_RTOL = 1e-3
#: Relative size of the round-off differences between processors in a normal matrix.
ROUNDOFF = 1e-12
#: Most significant digits a coefficient keeps (the JSON); the text shows 3.
SIGNIFICANT = 6
#: A digit is kept only when round-off moves the coefficient by less than 1/MARGIN of its unit.
MARGIN = 1e4
#: Significant digits of a printed coefficient.
PRINTED = 3


@dataclass(frozen=True)
class Combination:
    """A linear combination of named parameters, canonical and rounded.

    Attributes
    ----------
    terms : tuple of (str, float)
        ``(name, coefficient)`` in the printed order: a basis vector's pivot first (coefficient 1), then the
        others by decreasing magnitude (ties in the parameters' order); coefficients in parameter units.
    """

    terms: tuple[tuple[str, float], ...]

    def text(self, units: Mapping[str, str] | None = None) -> str:
        """``EX0C [um] - 12.5·EB0C [urad]``: each coefficient's :func:`magnitude`, no ``1·``, units in brackets
        where ``units`` names them; ``0`` for an empty combination."""
        parts = []
        for name, c in self.terms:
            mag = magnitude(c)
            unit = f" [{units[name]}]" if units is not None and name in units else ""
            parts.append(("- " if c < 0 else "+ ") + ("" if mag == "1" else f"{mag}·") + name + unit)
        text = " ".join(parts)
        return text[2:] if text.startswith("+ ") else "-" + text[2:] if text.startswith("- ") else text or "0"

    def as_dict(self) -> dict[str, float]:
        """``{name: coefficient}`` in the printed order (the JSON form)."""
        return dict(self.terms)

    def names(self) -> list[str]:
        return [n for n, _ in self.terms]


@dataclass(frozen=True)
class CanonicalBasis:
    """The canonical basis of a subspace of parameters (module docstring).

    Attributes
    ----------
    coefficients : ndarray, shape=(P, r)
        Basis vectors as columns, in parameter units, rounded; ``coefficients[pivots[i], i] == 1`` and 0 on the
        other pivots; dropped terms exactly 0.
    pivots : tuple of int
        The pivot parameter of each vector, increasing.
    """

    coefficients: np.ndarray
    pivots: tuple[int, ...]

    @property
    def dimension(self) -> int:
        return len(self.pivots)

    def involved(self) -> np.ndarray:
        """(P,) bool: the parameters with a non-zero coefficient in some basis vector."""
        return np.asarray((self.coefficients != 0).any(axis=1))

    def combinations(self, names: Sequence[str]) -> list[Combination]:
        """One :class:`Combination` per basis vector, in pivot order."""
        out = []
        for i, piv in enumerate(self.pivots):
            col = self.coefficients[:, i]
            rest = sorted((int(k) for k in np.flatnonzero(col) if k != piv), key=lambda k: (-abs(col[k]), k))
            out.append(Combination(tuple((names[k], float(col[k])) for k in [piv, *rest])))
        return out


def magnitude(c: float) -> str:
    """``|c|`` to :data:`PRINTED` significant digits, without an exponent or trailing zeros (``12.5``, ``0.08``,
    ``1230``)."""
    m = float(f"{abs(c):.{PRINTED}g}")
    if m == 0:
        return "0"
    text = f"{m:.{max(0, PRINTED - 1 - math.floor(math.log10(m)))}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def empty_basis(p: int) -> CanonicalBasis:
    """The basis of the zero subspace of ``p`` parameters."""
    return CanonicalBasis(np.zeros((p, 0)), ())


def canonical_basis(vectors: np.ndarray, scale: np.ndarray | None = None, *,
                    separation: float = 1.0) -> CanonicalBasis:
    """The canonical basis of the subspace spanned by ``scale[:, None] * vectors`` (module docstring).

    Parameters
    ----------
    vectors : ndarray, shape=(P, r)
        Any basis of the subspace in the data's scale (the scaled problem's coordinates), full column rank.
    scale : ndarray, shape=(P,), optional
        Parameter units per scaled unit (``1/column norm``; 1 for a column without trace); ones by default.
    separation : float
        Gap between the kept and the near-null eigenvalues of the scaled normal matrix over its largest
        (1 for a subspace known exactly); bounds the round-off of the subspace.
    """
    v = np.asarray(vectors, dtype=float)
    p = v.shape[0]
    scale = np.ones(p) if scale is None else np.asarray(scale, dtype=float)
    if v.ndim != 2 or v.shape[1] == 0:
        return empty_basis(p)
    u, s, _ = np.linalg.svd(v, full_matrices=False)
    q = u[:, s > 1e-9 * s[0]] if s.size and s[0] > 0 else u[:, :0]
    pivots = _pivots(q)
    qp_inv = np.linalg.inv(q[pivots])
    b = q @ qp_inv  # (P, r): identity on the pivot rows
    b[pivots] = np.eye(len(pivots))
    b[np.abs(b) < DROP_RTOL * np.abs(b).max(axis=0)] = 0.0
    theta = min(ROUNDOFF / max(separation, 1e-300), 1.0)  # the angle round-off may turn the subspace by [rad]
    delta = theta * (1.0 + np.linalg.norm(b, 2)) * np.linalg.norm(qp_inv, 2)
    ratio = scale[:, None] / scale[pivots][None, :]  # (P, r): parameter units of row k per unit of the pivot
    coef = b * ratio
    out = np.array([[0.0 if c == 0 else rounded(c, d) for c, d in zip(row, drow, strict=True)]
                    for row, drow in zip(coef, delta * ratio, strict=True)]).reshape(coef.shape)
    out[pivots, range(len(pivots))] = 1.0
    return CanonicalBasis(out, tuple(pivots))


def _pivots(q: np.ndarray) -> list[int]:
    """Pivot rows of an orthonormal basis ``q`` (P, r), in order (module docstring: pivots with a tolerance)."""
    pivots: list[int] = []
    rest = q
    for j in range(q.shape[0]):
        if rest.shape[1] == 0:
            break
        weight = np.linalg.norm(rest, axis=1)
        if weight[j] <= 0 or weight[j] < PIVOT_RTOL * weight[j:].max():
            continue
        pivots.append(j)
        h = rest[j] / weight[j]  # the direction of ``rest`` that carries row j; keep its complement
        _, _, vt = np.linalg.svd(h[None, :])
        rest = rest @ vt[1:].T  # (P, r' - 1), orthonormal, 0 on row j
    return pivots


def rounded(c: float, delta: float = 0.0) -> float:
    """``c`` to :data:`SIGNIFICANT` significant digits and no digit that ``delta`` (its round-off) could change by
    more than 1/:data:`MARGIN` of a unit; 0 when no digit is determined."""
    if c == 0 or not math.isfinite(c):
        return 0.0
    decimals = SIGNIFICANT - 1 - math.floor(math.log10(abs(c)))
    if delta > 0:
        decimals = min(decimals, -math.ceil(math.log10(delta * MARGIN)))
    units = abs(c) * 10.0 ** decimals  # |c| in units of its last kept digit
    tie = math.floor(units) + 0.5
    if abs(units - tie) <= max(delta, ROUNDOFF * abs(c)) * 10.0 ** decimals:  # a tie, up to round-off
        return float(round(math.copysign(math.ceil(tie) * 10.0 ** -decimals, c), max(decimals, 0) + 1))
    return float(round(c, decimals))


def combination(vector: np.ndarray, names: Sequence[str]) -> Combination:
    """A vector that is not a basis vector (e.g. the PIGEs that absorb a removed direction) as a
    :class:`Combination`: its own coefficients rounded to :data:`SIGNIFICANT` digits, terms below
    :data:`DROP_RTOL` of the largest dropped, largest first (ties in the parameters' order)."""
    vec = np.asarray(vector, dtype=float)
    big = float(np.abs(vec).max(initial=0.0))
    if big == 0 or not math.isfinite(big):
        return Combination(())
    keep = [k for k in range(vec.size) if abs(vec[k]) >= DROP_RTOL * big]
    coef = {k: rounded(float(vec[k])) for k in keep}
    order = sorted(keep, key=lambda k: (-abs(coef[k]), k))
    return Combination(tuple((names[k], coef[k]) for k in order))


def separation(eigenvalues: np.ndarray, near_null: np.ndarray) -> float:
    """``(smallest kept − largest near-null) / largest`` of a scaled normal matrix's eigenvalues (``w = s²``);
    1 when nothing is kept or nothing is near-null."""
    w = np.clip(np.asarray(eigenvalues, dtype=float), 0.0, None)
    null = np.asarray(near_null, dtype=bool)
    if not null.any() or null.all() or w.max(initial=0.0) <= 0:
        return 1.0
    return float((w[~null].min() - w[null].max()) / w.max())
