"""Model selection for the diagnosis: forward steps, swaps and backward elimination.

A *model* is the PIGEs plus an ordered list of candidates, each reduced to its
identifiable part jointly with everything before it (:func:`pige_sym.diagnosis.candidates.reduce_candidate`).
Every model is fitted on the accumulated normal equations (:mod:`pige_sym.identification.normal_sums`)
and scored by ``BIC = N ln(RSS/N) + k ln N`` (k = rank + non-linear parameters such as
τ) and by its k-fold held-out RMS.

An extension is *supported* when, against the model without it,
``ΔBIC ≤ delta_bic_max`` (−10: very strong evidence), the nested F-test p-value is
below ``p_max`` and the held-out RMS drops by at least ``min_heldout_gain``.  No VIF
cutoff: harmonics 1–4 compete on BIC and held-out error, and the VIF and inflated
standard errors are reported.

1. **Forward**: add the supported candidate with the lowest ΔBIC (at most one per key:
   the harmonics of an effect are separate keys, the τ grid of the drift one key); an
   tie (ΔBIC within ``TIE_BIC``) goes to the candidate with fewer catalogue parameters.  Candidates that
   replace a finding almost as well (BIC gap < 10) are reported with it as alternatives.
2. **Swap**: replace an accepted candidate by a pooled one while that lowers the BIC
   by more than ``SWAP_MARGIN``, so an early proxy cannot block the true effect.
3. **Backward**: every accepted candidate must still be supported against the final
   model without it; the weakest one that is not is dropped, and steps 2–3 repeat.
4. **Exact best subset** (when the model has at most ``BEST_SUBSET_MAX`` = 3 effects):
   the pool is the model's candidates plus the best variant of every other key whose
   ΔBIC against some model of the forward path reached ``delta_bic_max`` (at most
   ``BEST_SUBSET_POOL`` = 10 keys; a drift of the model enters at its interpolated τ,
   ``refine``).  Every subset of up to three distinct keys is fitted without its held-out
   error and ranked by BIC; the least-BIC one in which every effect is supported against
   the same subset without it replaces the greedy model if that lowers the BIC by more
   than ``SWAP_MARGIN`` (only those are fitted in full), and steps 1–3 continue from it.
   The fitted span of a subset does not depend on the order of its reductions (a removed
   direction is already in the span), so subsets are built in pool order and share their
   cached prefixes: at most 175 small fits.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pige_sym.diagnosis.candidates import Candidate, Layout, Reduction, reduce_candidate
from pige_sym.identification.normal_sums import LinearFit, NormalSums, fit

SWAP_MARGIN = 2.0
TIE_BIC = 0.5
MAX_EFFECTS = 6
BEST_SUBSET_MAX = 3  # exact search over every subset of up to this many effects
BEST_SUBSET_POOL = 10  # screened candidates (distinct keys) entering it


@dataclass
class Model:
    """PIGEs plus reduced candidates, fitted.

    Attributes
    ----------
    cands : list of Candidate
    reductions : list of Reduction
    w : ndarray, shape=(C, K)
        Model columns as combinations of super-design columns.
    names : list of str
        Names of the K model columns.
    blocks : list of slice
        Model columns of each candidate.
    fit : LinearFit
    """

    cands: list[Candidate]
    reductions: list[Reduction]
    w: np.ndarray
    names: list[str]
    blocks: list[slice]
    fit: LinearFit
    _pinv: np.ndarray | None = field(default=None, repr=False)

    def pinv(self, sums: NormalSums) -> np.ndarray:
        """``(WᵀGW)⁺`` of the model (cached), shape=(K, K)."""
        if self._pinv is None:
            self._pinv = np.linalg.pinv(self.w.T @ sums.total_gram @ self.w, rcond=1e-12, hermitian=True)
        return self._pinv

    @property
    def extra(self) -> int:
        """Non-linear parameters of the model (τ), counted in the BIC."""
        return sum(c.extra_params for c in self.cands)

    @property
    def bic(self) -> float:
        """BIC of the fit, non-linear parameters included."""
        return self.fit.bic(self.extra)

    @property
    def keys(self) -> list[str]:
        """Selection keys of the candidates in the model."""
        return [c.key for c in self.cands]


@dataclass
class Comparison:
    """Evidence for a model against a nested one."""

    delta_bic: float
    f_statistic: float
    p_value: float
    heldout_gain: float

    def supported(self, delta_bic_max: float, p_max: float, min_gain: float) -> bool:
        """True when all three tests pass (module docstring)."""
        return self.delta_bic <= delta_bic_max and self.p_value <= p_max and self.heldout_gain >= min_gain


def shortfall(cmp: Comparison, delta_bic_max: float, p_max: float, min_gain: float) -> str:
    """Why a candidate was not accepted, in words, with each test's value and its threshold (ΔBIC ``(ΔBIC …)``
    kept in the text: the rejection list reads it back)."""
    bic = (f"the BIC rises by {cmp.delta_bic:.1f} with it" if cmp.delta_bic > 0 else
           f"the BIC falls by only {-cmp.delta_bic:.1f} with it")
    return (f"{bic} (ΔBIC {cmp.delta_bic:.1f}, accepted at {delta_bic_max:g} or less), the F test gives "
            f"p = {cmp.p_value:.2g} (accepted at {p_max:g} or less), the held-out RMS "
            f"{'shrinks' if cmp.heldout_gain >= 0 else 'grows'} by {abs(cmp.heldout_gain):.1%} (accepted when it "
            f"shrinks by {min_gain:.0%} or more)")


def compare(small: Model, big: Model) -> Comparison:
    """ΔBIC, F-test and held-out gain of ``big`` over the nested ``small``."""
    return compare_fits(small.fit, big.fit, small.extra, big.extra)


def compare_fits(a: LinearFit, b: LinearFit, extra_a: int = 0, extra_b: int = 0) -> Comparison:
    """ΔBIC, F-test and held-out gain of fit ``b`` over the nested fit ``a`` (extra: non-linear parameters)."""
    q = max(b.rank - a.rank, 1)
    dof = max(b.n_obs - b.rank, 1)
    f_stat = ((a.rss - b.rss) / q) / (b.rss / dof) if b.rss > 0 else float("inf")
    from scipy.special import fdtrc  # F survival function (scipy.stats.f.sf without its import cost)

    p_val = float(fdtrc(q, dof, f_stat)) if math.isfinite(f_stat) else 0.0
    gain = 1.0 - b.heldout_rms / a.heldout_rms if a.heldout_rms > 0 else 0.0
    return Comparison(b.bic(extra_b) - a.bic(extra_a), f_stat, p_val, gain)


@dataclass
class Selector:
    """Builds, caches and compares models on one set of normal equations."""

    sums: NormalSums
    layout: Layout
    cache: dict[tuple[str, ...], Model] = field(default_factory=dict)
    quick_cache: dict[tuple[str, ...], Model] = field(default_factory=dict)

    def model(self, cands: list[Candidate], heldout: bool = True) -> Model:
        """The fitted model of the PIGEs plus ``cands`` (each reduced against those before it).

        With ``heldout=False`` the k-fold held-out RMS is not computed (NaN; values, RSS,
        rank and BIC are the same): a cheaper model for ranking by BIC only.
        """
        key = tuple(c.label for c in cands)
        if key in self.cache:
            return self.cache[key]
        if not heldout and key in self.quick_cache:
            return self.quick_cache[key]
        if not cands:
            p = self.layout.base  # the PIGEs and the nuisance every model holds
            w = np.eye(self.layout.n_columns)[:, :p]
            model = Model([], [], w, list(self.layout.pige) + list(self.layout.nuisance), [],
                          fit(self.sums, w, heldout=heldout))
        else:
            base = self.model(cands[:-1], heldout=False)  # prefixes are cached: one reduction per new model
            c = cands[-1]
            units = dict(self.layout.units)
            red = reduce_candidate(self.sums.total_gram, base.w, c, base.names, units, base.pinv(self.sums))
            emb = c.embedding(self.layout.n_columns) @ red.basis
            k = base.w.shape[1]
            w = np.concatenate([base.w, emb], axis=1)
            model = Model(list(cands), base.reductions + [red], w, base.names + [f"{c.label}#{j}" for j in
                                                                                   range(emb.shape[1])],
                          base.blocks + [slice(k, k + emb.shape[1])], fit(self.sums, w, heldout=heldout))
        (self.cache if heldout else self.quick_cache)[key] = model
        return model

    def forward(self, current: Model, pool: list[Candidate], progress: Callable[[int], None] | None = None
                ) -> tuple[list[tuple[Candidate, Model, Comparison]], list[tuple[Candidate, Reduction]]]:
        """Every pooled candidate added to ``current``: the scored ones (best first) and the fully confounded ones."""
        scored, confounded = [], []
        for c in pool:
            if c.key in current.keys:
                continue
            big = self.model(current.cands + [c])
            red = big.reductions[-1]
            if red.basis.shape[1] == 0:
                confounded.append((c, red))
            else:
                scored.append((c, big, compare(current, big)))
            if progress is not None:
                progress(1)
        scored.sort(key=lambda t: t[2].delta_bic)
        # ties (the same fitted subspace, e.g. backlash and a harmonic of a tilt axis seen at three
        # angles) go to the effect with fewer catalogue parameters
        tied = [t for t in scored if scored and t[2].delta_bic <= scored[0][2].delta_bic + TIE_BIC]
        if tied:
            simplest = min(tied, key=lambda t: len(t[0].cols))
            scored.remove(simplest)
            scored.insert(0, simplest)
        return scored, confounded

    def swap(self, current: Model, pool: list[Candidate]) -> Model:
        """Replace accepted candidates by pooled ones while the BIC drops by more than ``SWAP_MARGIN``."""
        for _ in range(4 * len(pool) + 1):
            best = current
            for i, old in enumerate(current.cands):
                others = {c.key for j, c in enumerate(current.cands) if j != i}
                for c in pool:
                    if c.key in others or c.label == old.label:
                        continue
                    trial = self.model(current.cands[:i] + current.cands[i + 1:] + [c])
                    if trial.reductions[-1].basis.shape[1] and trial.bic < best.bic - SWAP_MARGIN:
                        best = trial
            if best is current:
                return current
            current = best
        return current

    def without(self, current: Model, i: int) -> Model:
        """``current`` without its i-th candidate."""
        return self.model(current.cands[:i] + current.cands[i + 1:])

    def backward(self, current: Model, delta_bic_max: float, p_max: float, min_gain: float) -> Model:
        """Drop the weakest accepted candidate that the final model no longer supports, repeatedly."""
        while current.cands:
            worst, worst_dbic = None, -math.inf
            for i in range(len(current.cands)):
                cmp = compare(self.without(current, i), current)
                if not cmp.supported(delta_bic_max, p_max, min_gain) and cmp.delta_bic > worst_dbic:
                    worst, worst_dbic = i, cmp.delta_bic
            if worst is None:
                return current
            current = self.without(current, worst)
        return current


def best_subset(selector: Selector, pool: list[Candidate], *, below: float, delta_bic_max: float, p_max: float,
                min_gain: float, max_effects: int = BEST_SUBSET_MAX,
                progress: Callable[[int], None] | None = None) -> Model | None:
    """The least-BIC model with a BIC under ``below`` over every subset of up to ``max_effects`` pooled
    candidates (distinct keys) in which every effect earns its place (supported against the same
    subset without it); None when there is none.

    Subsets are fitted in pool order, so every prefix is a cached model; the order of the
    reductions does not change the fitted span (module docstring).  They are ranked by BIC
    alone (no held-out error: cheaper); only those under ``below`` are fitted in full and
    checked, best first.
    """
    ranked: list[Model] = []
    for k in range(1, min(max_effects, len(pool)) + 1):
        for combo in itertools.combinations(pool, k):
            if len({c.key for c in combo}) < k:
                continue
            model = selector.model(list(combo), heldout=False)
            if model.bic < below and all(r.basis.shape[1] for r in model.reductions):  # none wholly confounded
                ranked.append(model)
            if progress is not None:
                progress(1)
    for quick in sorted(ranked, key=lambda m: m.bic):
        model = selector.model(quick.cands)
        if all(compare(selector.without(model, i), model).supported(delta_bic_max, p_max, min_gain)
               for i in range(len(model.cands))):
            return model
    return None


def _screened(best_dbic: dict[str, tuple[float, Candidate]], current: Model, delta_bic_max: float
              ) -> list[Candidate]:
    """The best-subset pool: the current model's candidates, then the best variant of every other key
    whose ΔBIC against some model of the forward path passed ``delta_bic_max``, strongest first,
    ``BEST_SUBSET_POOL`` keys in all."""
    pool = list(current.cands)
    others = sorted((v for k, v in best_dbic.items() if k not in current.keys and v[0] <= delta_bic_max),
                    key=lambda v: v[0])
    pool += [c for _, c in others[: max(BEST_SUBSET_POOL - len(pool), 0)]]
    return pool


def _grow(selector: Selector, current: Model, pool: list[Candidate], reasons: dict[str, str],
          best_dbic: dict[str, tuple[float, Candidate]], crit: tuple[float, float, float],
          progress: Callable[[int], None] | None) -> Model:
    """Forward steps, each followed by swaps and backward elimination, while an addition is supported."""
    for _ in range(MAX_EFFECTS):
        if len(current.cands) >= MAX_EFFECTS:
            break
        scored, confounded = selector.forward(current, pool, progress)
        for c, red in confounded:
            reasons[c.label] = "unidentifiable with the PIGEs: " + "; ".join(red.removed)
        for c, _, cmp in scored:
            reasons[c.label] = "not supported: " + shortfall(cmp, *crit)
            if cmp.delta_bic < best_dbic.get(c.key, (math.inf, c))[0]:
                best_dbic[c.key] = (cmp.delta_bic, c)
        if not scored or not scored[0][2].supported(*crit):
            break
        current = selector.swap(scored[0][1], pool)
        current = selector.backward(current, *crit)
    return current


def select(selector: Selector, pool: list[Candidate], *, delta_bic_max: float, p_max: float, min_gain: float,
           progress: Callable[[int], None] | None = None, refine: Callable[[Selector, Model], Model] | None = None
           ) -> tuple[Model, dict[str, str]]:
    """Forward + swap + backward selection, then the exact best-subset check (module docstring).

    ``refine`` (e.g. the interpolated τ of a thermal drift) is applied to the greedy model
    before the exact search, so that subsets compete against its best non-linear fit: a
    drift at a τ-grid point leaves a misfit that other effects could otherwise absorb.

    Returns
    -------
    Model
        The final model.
    dict of str to str
        Why each candidate that is not in the final model was left out, by candidate label.
    """
    crit = (delta_bic_max, p_max, min_gain)
    reasons: dict[str, str] = {}
    best_dbic: dict[str, tuple[float, Candidate]] = {}
    current = _grow(selector, selector.model([]), pool, reasons, best_dbic, crit, progress)
    current = selector.backward(selector.swap(current, pool), *crit)
    if len(current.cands) <= BEST_SUBSET_MAX:
        if refine is not None:
            current = refine(selector, current)
        exact = best_subset(selector, _screened(best_dbic, current, delta_bic_max), below=current.bic - SWAP_MARGIN,
                            delta_bic_max=delta_bic_max, p_max=p_max, min_gain=min_gain, progress=progress)
        if exact is not None:  # a better combination than the greedy path found
            current = _grow(selector, exact, pool, reasons, best_dbic, crit, progress)
            current = selector.backward(selector.swap(current, pool), *crit)
    for c in current.cands:
        reasons.pop(c.label, None)
    return current, reasons
