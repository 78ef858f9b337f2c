"""Forms of the symbolic model the emitter prints: the trigonometric basis of a matrix and the
closed-form inverse of the tool direction.

:func:`trig_basis` splits a matrix of polynomials in ``(cos θ_i, sin θ_i)`` into monomials and coefficient
matrices (``jacobian = basis @ coefficients``); :func:`direction_solver` solves the tool direction for the two
rotary angles when the structure allows a closed form.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import sympy as sp

from pige_sym.codegen.symbolic import SymbolicModel


@dataclass
class TrigBasis:
    """Decomposition ``M(θ, g) = Σ_k basis_k(θ) · C_k(g)`` of a matrix of polynomials.

    Attributes
    ----------
    monomials : list of tuple of int
        Exponents ``(a_1, b_1, a_2, b_2, …)`` of ``c_1^a_1 s_1^b_1 …`` per basis column.
    coefficients : list of sympy.Matrix
        One coefficient matrix (same shape as M) per monomial.
    """

    monomials: list[tuple[int, ...]]
    coefficients: list[sp.Matrix]


def trig_basis(matrix: sp.Matrix, pairs: list[tuple[sp.Symbol, sp.Symbol]]) -> TrigBasis:
    """Split a matrix of trig polynomials into monomials and coefficient matrices."""
    gens = [g for pair in pairs for g in pair]
    table: dict[tuple[int, ...], sp.Matrix] = {}
    for i, j in itertools.product(range(matrix.rows), range(matrix.cols)):
        expr = matrix[i, j]
        if expr == 0:
            continue
        poly = sp.Poly(expr, *gens)
        for monom, coeff in poly.terms():
            m = table.setdefault(tuple(monom), sp.zeros(matrix.rows, matrix.cols))
            m[i, j] += coeff
    monomials = sorted(table, key=lambda m: (sum(m), tuple(-x for x in m)))
    return TrigBasis(monomials=monomials, coefficients=[table[m] for m in monomials])


@dataclass
class DirectionSolver:
    """Closed-form inverse of the tool direction for two rotary axes.

    ``tool_direction[primary_component] = a cos θ_p + b sin θ_p + g`` depends on the
    primary axis only; the other two components are linear in
    ``(cos θ_s, sin θ_s)`` with coefficients depending on θ_p.
    """

    primary: int  # index into rotary axes
    secondary: int
    primary_component: int
    a: sp.Expr
    b: sp.Expr
    g: sp.Expr
    other_components: tuple[int, int]
    # rows: component -> (coef of cos θ_s, coef of sin θ_s, constant), in (c_p, s_p)
    rows: list[tuple[sp.Expr, sp.Expr, sp.Expr]]


def direction_solver(model: SymbolicModel) -> DirectionSolver | None:
    """Derive the closed-form tool-direction inverse, or None when there is none.

    Only machines with exactly two rotary axes whose tool direction has one
    component that depends on one axis alone (all ISO orthogonal 5-axis
    structures) get one.
    """
    if len(model.rotary) != 2:
        return None
    pairs = model.trig_pairs
    v = model.tool_direction
    for comp in range(3):
        for p_idx in range(2):
            s_idx = 1 - p_idx
            cs, ss = pairs[s_idx]
            cp, sp_ = pairs[p_idx]
            if v[comp].has(cs) or v[comp].has(ss) or not (v[comp].has(cp) or v[comp].has(sp_)):
                continue
            poly = sp.Poly(v[comp], cp, sp_)
            if poly.total_degree() > 1:
                continue
            a = poly.coeff_monomial(cp)
            b = poly.coeff_monomial(sp_)
            g = poly.coeff_monomial(1)
            others = tuple(c for c in range(3) if c != comp)
            rows = []
            for oc in others:
                q = sp.Poly(v[oc], cs, ss)
                if q.total_degree() > 1:
                    break
                rows.append((q.coeff_monomial(cs), q.coeff_monomial(ss), q.coeff_monomial(1)))
            else:
                return DirectionSolver(
                    primary=p_idx, secondary=s_idx, primary_component=comp, a=a, b=b, g=g,
                    other_components=(others[0], others[1]), rows=rows,
                )
    return None
