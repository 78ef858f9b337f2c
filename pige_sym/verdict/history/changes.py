"""Change of each parameter between two runs and whether it is real (not noise).

Both runs carry an estimate ``x`` [µm, µrad] with covariance ``C`` (``σ²(AᵀA)⁻¹`` with σ
estimated on ``ν`` degrees of freedom).  The runs are independent, so the change
``d = x_b − x_a`` has covariance ``C_a + C_b``.

Test (named ``TEST`` in every output), on the parameters determined in both runs (m of them):

1. *joint Wald test*: ``T² = dᵀ (C_a + C_b)⁺ d`` on the scaled parameters, rank r; ``T²/r``
   against ``F(r, min(ν_a, ν_b))`` (σ is estimated, so F rather than χ²; taking the smaller
   ν is conservative).  The runs differ when ``p <= α``;
2. *follow-up per parameter*, only when the joint test rejects: ``z = d_i / √(C_a,ii + C_b,ii)``,
   two-sided Student t with Welch–Satterthwaite degrees of freedom, at ``α/m`` (Bonferroni).

A parameter is ``significant`` only when both steps reject.  Flagged parameters are a subset
of the Bonferroni-flagged ones and exist only when the joint test rejects, so the chance that
a comparison of two runs of an unchanged machine flags any parameter is at most α
(default 1 %).  A parameter undetermined in either run is not tested (``significant`` None).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

ALPHA = 0.01
TEST = ("joint Wald test T² = dᵀ(Ca+Cb)⁺d vs F(r, min ν), then per-parameter two-sided t "
        "(Welch–Satterthwaite ν) at α/m (Bonferroni), family-wise false-alarm rate ≤ α")


class Estimate(Protocol):
    """What :func:`compare_runs` needs of a run (an IdentificationResult or a RunRecord)."""

    parameters: list[str]
    values: np.ndarray
    covariance: np.ndarray
    dof: int
    units: dict[str, str]


@dataclass
class Change:
    """Change of one parameter from one run to the next [its unit]."""

    parameter: str
    unit: str
    from_run: int | None
    to_run: int | None
    change: float | None
    std: float | None
    z: float | None
    p_value: float | None
    significant: bool | None
    reason: str = ""


@dataclass
class Comparison:
    """Joint test and per-parameter changes between two runs."""

    from_run: int | None
    to_run: int | None
    test: str
    alpha: float
    n_tested: int
    rank: int
    statistic: float | None
    dof: tuple[int, int]
    p_value: float | None
    significant: bool
    changes: list[Change] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        return json_ready({**asdict(self), "changes": [asdict(c) for c in self.changes]})


def _welch(va: float, vb: float, na: int, nb: int) -> float:
    num = (va + vb) ** 2
    den = (va**2 / max(na, 1) if va > 0 else 0.0) + (vb**2 / max(nb, 1) if vb > 0 else 0.0)
    return num / den if den > 0 else float(max(na + nb, 1))


def _joint(d: np.ndarray, cov: np.ndarray) -> tuple[float, int]:
    """(T², rank) of change d (m,) with covariance (m, m), on scaled parameters."""
    s = np.sqrt(np.diag(cov))
    scaled = cov / np.outer(s, s)
    w, v = np.linalg.eigh(scaled)
    keep = w > 1e-10 * max(float(w.max()), 1e-300)
    proj = v[:, keep].T @ (d / s)
    return float((proj**2 / w[keep]).sum()), int(keep.sum())


def _effect_ids(run: Any) -> list[str] | None:
    """Accepted effect ids of a stored run (None for a bare estimate)."""
    effects = getattr(run, "effects", None)
    if effects is None:
        return None
    return sorted(str(f.get("effect")) for f in effects if f.get("effect") != "outliers")


def compare_runs(a: Estimate, b: Estimate, *, alpha: float = ALPHA, from_run: int | None = None,
                 to_run: int | None = None) -> Comparison:
    """Compare run ``b`` with the earlier run ``a`` (module docstring).

    Returns
    -------
    Comparison
        ``changes`` in the parameter order of ``a`` (then parameters only ``b`` has).
    """
    from scipy.special import fdtrc, stdtr  # F and Student t (scipy.stats' without its ~1 s import; here, not at the
    # package's import: pige checkup reads the history without them)

    names = list(a.parameters) + [p for p in b.parameters if p not in a.parameters]
    tested: list[str] = []
    for p in names:
        if p in a.parameters and p in b.parameters:
            i, j = a.parameters.index(p), b.parameters.index(p)
            if all(math.isfinite(float(x)) and float(x) >= 0 for x in (a.covariance[i, i], b.covariance[j, j])) \
                    and math.isfinite(float(a.values[i])) and math.isfinite(float(b.values[j])) \
                    and a.covariance[i, i] + b.covariance[j, j] > 0:
                tested.append(p)
    ia = [a.parameters.index(p) for p in tested]
    ib = [b.parameters.index(p) for p in tested]
    d = np.asarray(b.values, dtype=float)[ib] - np.asarray(a.values, dtype=float)[ia]
    cov = np.asarray(a.covariance, dtype=float)[np.ix_(ia, ia)] + np.asarray(b.covariance, dtype=float)[np.ix_(ib, ib)]
    nu = (int(a.dof), int(b.dof))
    stat, rank, p_joint = None, 0, None
    if tested:
        stat, rank = _joint(d, cov)
        p_joint = float(fdtrc(max(rank, 1), max(min(nu), 1), stat / max(rank, 1)))  # T² >= 0: stats.f.sf
    joint = p_joint is not None and p_joint <= alpha
    out = Comparison(from_run, to_run, TEST, alpha, len(tested), rank, stat, nu, p_joint, joint)
    effects_a, effects_b = _effect_ids(a), _effect_ids(b)
    if effects_a is not None and effects_b is not None and effects_a != effects_b:
        out.notes.append(f"the runs were fitted with different effects ({', '.join(effects_a) or 'none'} vs "
                         f"{', '.join(effects_b) or 'none'}): a PIGE change may partly reflect the model")
    m = max(len(tested), 1)
    for p in names:
        unit = a.units.get(p) or b.units.get(p, "")
        if p not in tested:
            why = "not determined in both runs" if p in a.parameters and p in b.parameters else \
                "estimated in one run only (different model)"
            out.changes.append(Change(p, unit, from_run, to_run, None, None, None, None, None, why))
            continue
        k = tested.index(p)
        va, vb = float(a.covariance[ia[k], ia[k]]), float(b.covariance[ib[k], ib[k]])
        std = math.sqrt(va + vb)
        z = float(d[k]) / std
        p_val = float(2 * stdtr(_welch(va, vb, nu[0], nu[1]), -abs(z)))  # = 2 stats.t.sf(|z|, ν)
        sig = joint and p_val <= alpha / m
        out.changes.append(Change(p, unit, from_run, to_run, float(d[k]), std, z, p_val, sig,
                                  "" if sig or not joint else "within noise at the Bonferroni level"))
    return out
