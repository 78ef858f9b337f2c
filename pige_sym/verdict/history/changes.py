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


def _welch(va: Any, vb: Any, na: Any, nb: Any) -> Any:
    """Welch–Satterthwaite degrees of freedom of ``va + vb`` (arrays, element by element)."""
    num = (va + vb) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = np.where(va > 0, va**2 / np.maximum(na, 1), 0.0) + np.where(vb > 0, vb**2 / np.maximum(nb, 1), 0.0)
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.maximum(na + nb, 1))


def _joint(d: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T², rank) of changes d (k, m) with covariances (k, m, m), on scaled parameters: k comparisons of m parameters
    at once (one stacked eigen-decomposition), shapes (k,)."""
    s = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    scaled = cov / (s[:, :, None] * s[:, None, :])
    w, v = np.linalg.eigh(scaled)
    keep = w > 1e-10 * np.maximum(w.max(axis=1, initial=-np.inf), 1e-300)[:, None]
    proj = np.einsum("kij,ki->kj", v, d / s)
    terms = np.where(keep, proj**2 / np.where(keep, w, 1.0), 0.0)
    return terms.sum(axis=1), keep.sum(axis=1)


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
    return compare_pairs([(a, b, from_run, to_run)], alpha=alpha)[0]


def compare_consecutive(runs: list[Any], *, alpha: float = ALPHA) -> list[Comparison]:
    """Each run compared with the one before it (runs with an ``id``, in order): :func:`compare_runs` of every
    consecutive pair, their numbers computed together (a history of 10,000 runs in one pass)."""
    return compare_pairs([(a, b, a.id, b.id) for a, b in zip(runs, runs[1:], strict=False)], alpha=alpha)


def compare_pairs(pairs: list[tuple[Estimate, Estimate, int | None, int | None]], *, alpha: float = ALPHA,
                  ) -> list[Comparison]:
    """:func:`compare_runs` of each ``(a, b, from_run, to_run)``, computed together: the pairs whose runs have the same
    parameters and test the same ones (a history's check-ups) as arrays — one stacked eigen-decomposition for their
    joint statistics, one call of the F and t tail probabilities each."""
    groups: dict[tuple[tuple[str, ...], tuple[str, ...]], list[int]] = {}
    for k, (a, b, _, _) in enumerate(pairs):
        groups.setdefault((tuple(a.parameters), tuple(b.parameters)), []).append(k)
    effects: dict[int, list[str] | None] = {}
    for a, b, _, _ in pairs:
        for run in (a, b):
            if id(run) not in effects:
                effects[id(run)] = _effect_ids(run)
    out: list[Comparison | None] = [None] * len(pairs)
    for (names_a, names_b), ks in groups.items():
        in_a = {p: i for i, p in enumerate(names_a)}
        in_b = {p: j for j, p in enumerate(names_b)}
        names = list(names_a) + [p for p in names_b if p not in in_a]
        common = [p for p in names if p in in_a and p in in_b]
        ia, ib = np.array([in_a[p] for p in common], dtype=int), np.array([in_b[p] for p in common], dtype=int)
        xa = np.array([np.asarray(pairs[k][0].values, dtype=float)[ia] for k in ks]).reshape(len(ks), ia.size)
        xb = np.array([np.asarray(pairs[k][1].values, dtype=float)[ib] for k in ks]).reshape(len(ks), ib.size)
        ca = np.array([np.asarray(pairs[k][0].covariance, dtype=float) for k in ks])
        cb = np.array([np.asarray(pairs[k][1].covariance, dtype=float) for k in ks])
        va, vb = ca[:, ia, ia], cb[:, ib, ib]
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(va) & (va >= 0) & np.isfinite(vb) & (vb >= 0) & np.isfinite(xa) & np.isfinite(xb)
                  & (va + vb > 0))
        patterns: dict[bytes, list[int]] = {}
        for row in range(len(ks)):
            patterns.setdefault(ok[row].tobytes(), []).append(row)
        for listed in patterns.values():
            rows = np.array(listed, dtype=int)
            sel = np.flatnonzero(ok[rows[0]])
            tested = [common[c] for c in sel]
            ja, jb = ia[sel], ib[sel]
            d = xb[np.ix_(rows, sel)] - xa[np.ix_(rows, sel)]
            cov = ca[rows][:, ja[:, None], ja[None, :]] + cb[rows][:, jb[:, None], jb[None, :]]
            numbers = _tests(d, cov, va[np.ix_(rows, sel)], vb[np.ix_(rows, sel)],
                             [(int(pairs[ks[r]][0].dof), int(pairs[ks[r]][1].dof)) for r in rows])
            by_row = {key: v.tolist() for key, v in numbers.items()}  # Python numbers, row by row
            set_a, set_b = set(names_a), set(names_b)
            for n, r in enumerate(rows.tolist()):
                a, b, from_run, to_run = pairs[ks[r]]
                out[ks[r]] = _comparison(names, tested, set_a, set_b, a.units, b.units,
                                         (effects[id(a)], effects[id(b)]), from_run, to_run, alpha,
                                         {key: v[n] for key, v in by_row.items()})
    return [c for c in out if c is not None]


def _tests(d: np.ndarray, cov: np.ndarray, va: np.ndarray, vb: np.ndarray, nu: list[tuple[int, int]],
           ) -> dict[str, np.ndarray]:
    """The numbers of k comparisons of the same m tested parameters: ``d`` (k, m) the changes, ``cov`` (k, m, m) their
    covariances, ``va``, ``vb`` (k, m) each run's variances, ``nu`` each pair's degrees of freedom."""
    from scipy.special import fdtrc, stdtr  # F and Student t (scipy.stats' without its ~1 s import; here, not at the
    # package's import: pige checkup reads the history without them)

    k, m = d.shape
    nus = np.array(nu, dtype=float).reshape(k, 2)
    if m == 0:
        return {"stat": np.full(k, np.nan), "rank": np.zeros(k, dtype=int), "p_joint": np.full(k, np.nan),
                "d": d, "std": d, "z": d, "p": d, "nu": nus}
    stat, rank = _joint(d, cov)
    r = np.maximum(rank, 1)
    p_joint = fdtrc(r, np.maximum(nus.min(axis=1), 1), stat / r)  # T² >= 0: stats.f.sf
    std = np.sqrt(va + vb)
    z = d / std
    p_each = 2 * stdtr(_welch(va, vb, nus[:, :1], nus[:, 1:]), -np.abs(z))  # = 2 stats.t.sf(|z|, ν)
    return {"stat": stat, "rank": rank, "p_joint": p_joint, "d": d, "std": std, "z": z, "p": p_each, "nu": nus}


def _comparison(names: list[str], tested: list[str], in_a: set[str], in_b: set[str], units_a: dict[str, str],
                units_b: dict[str, str], effects: tuple[list[str] | None, list[str] | None], from_run: int | None,
                to_run: int | None, alpha: float, numbers: dict[str, Any]) -> Comparison:
    """One pair's :class:`Comparison` from its numbers (a row of :func:`_tests`)."""
    nu = (int(numbers["nu"][0]), int(numbers["nu"][1]))
    p_joint = float(numbers["p_joint"]) if tested else None
    joint = p_joint is not None and p_joint <= alpha
    out = Comparison(from_run, to_run, TEST, alpha, len(tested), int(numbers["rank"]),
                     float(numbers["stat"]) if tested else None, nu, p_joint, joint)
    effects_a, effects_b = effects
    if effects_a is not None and effects_b is not None and effects_a != effects_b:
        out.notes.append(f"the runs were fitted with different effects ({', '.join(effects_a) or 'none'} vs "
                         f"{', '.join(effects_b) or 'none'}): a PIGE change may partly reflect the model")
    m = max(len(tested), 1)
    position = {p: k for k, p in enumerate(tested)}
    for p in names:
        unit = units_a.get(p) or units_b.get(p, "")
        if p not in position:
            why = "not determined in both runs" if p in in_a and p in in_b else \
                "estimated in one run only (different model)"
            out.changes.append(Change(p, unit, from_run, to_run, None, None, None, None, None, why))
            continue
        k = position[p]
        p_val = float(numbers["p"][k])
        sig = joint and p_val <= alpha / m
        out.changes.append(Change(p, unit, from_run, to_run, float(numbers["d"][k]), float(numbers["std"][k]),
                                  float(numbers["z"][k]), p_val, sig,
                                  "" if sig or not joint else "within noise at the Bonferroni level"))
    return out
