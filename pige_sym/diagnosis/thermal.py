"""The time constant τ of a drift between grid points (step 5 of :mod:`pige_sym.diagnosis.diagnose`).

Drifts: ``thermal_drift`` (machine frame) and ``table_drift`` (the nest or sphere creeping on the
table), each on the layout's τ grid.  The drift columns at any τ are interpolated from the accumulated
sums at the three nearest grid points (quadratic Lagrange weights in ln τ, exact linear combinations);
τ minimises the RSS and its standard error comes from the Gauss–Newton covariance with the ∂/∂ln τ
column.  Each drift of the model is refined in turn.
"""

from __future__ import annotations

import math

import numpy as np

from pige_sym.diagnosis.candidates import (
    Candidate,
    Layout,
)
from pige_sym.diagnosis.selection import Model, Selector
from pige_sym.identification.normal_sums import fit
from pige_sym.model.effects import DRIFT_KINDS, EffectSpec


def _tau_weights(layout: Layout, log_tau: float) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Quadratic Lagrange weights (and their d/d ln τ) of the 3 τ-grid points around ``log_tau``."""
    s = np.log(layout.tau_grid_s)
    g = int(np.clip(np.searchsorted(s, log_tau) - 1, 0, len(s) - 3))
    idx = [g, g + 1, g + 2]
    pts = s[idx]
    w, dw = np.zeros(3), np.zeros(3)
    for i in range(3):
        o = [pts[j] for j in range(3) if j != i]
        den = (pts[i] - o[0]) * (pts[i] - o[1])
        w[i] = (log_tau - o[0]) * (log_tau - o[1]) / den
        dw[i] = (2 * log_tau - o[0] - o[1]) / den
    return idx, w, dw


def _drift_at(layout: Layout, kind: str, log_tau: float, derivative: bool = False) -> np.ndarray:
    idx, w, dw = _tau_weights(layout, log_tau)
    mix = np.zeros((layout.n_columns, 3))
    for i, g in enumerate(idx):
        for j, col in enumerate(layout.drift_cols[kind][g]):
            mix[col, j] += dw[i] if derivative else w[i]
    return mix


def drift_derivative(layout: Layout, model: Model, i: int) -> np.ndarray:
    """The super-design combination ``∂(v·drift columns)/∂ln τ`` of the model's i-th (interpolated) drift, (C,)."""
    c = model.cands[i]
    v = model.reductions[i].basis @ model.fit.values[model.blocks[i]]
    return _drift_at(layout, c.spec.kind, math.log(float(c.spec.options["tau_s"])), derivative=True) @ v


def refine_tau(selector: Selector, model: Model) -> tuple[Model, dict[str, float]]:
    """Replace each grid drift by the interpolated τ of least RSS; returns the model and the std of τ [s] by kind."""
    stds: dict[str, float] = {}
    for kind in [c.spec.kind for c in model.cands if c.spec.kind in DRIFT_KINDS]:
        model, stds[kind] = _refine_one(selector, model, kind)
    return model, stds


def _refine_one(selector: Selector, model: Model, kind: str) -> tuple[Model, float]:
    """:func:`refine_tau` for the drift of one kind."""
    layout = selector.layout
    i = next(k for k, c in enumerate(model.cands) if c.spec.kind == kind)
    if len(layout.tau_grid_s) < 3:
        return model, float("nan")
    old = model.cands[i]
    s = np.log(layout.tau_grid_s)

    def cand(log_tau: float) -> Candidate:
        spec = EffectSpec(kind, {"tau_s": float(np.exp(log_tau))})
        return Candidate(spec, old.key, old.cols, 1, _drift_at(layout, kind, log_tau))

    def with_tau(log_tau: float) -> Model:
        return selector.model(model.cands[:i] + [cand(log_tau)] + model.cands[i + 1:])

    g = int(np.argmin(np.abs(s - math.log(float(old.spec.options["tau_s"])))))
    lo, hi = s[max(g - 1, 0)], s[min(g + 1, len(s) - 1)]
    from scipy.optimize import minimize_scalar

    opt = minimize_scalar(lambda x: with_tau(x).fit.rss, bounds=(lo, hi), method="bounded", options={"xatol": 1e-4})
    best = with_tau(float(opt.x))
    if best.fit.rss > model.fit.rss:
        best, opt.x = model, math.log(float(old.spec.options["tau_s"]))
    # Gauss–Newton covariance with the ∂/∂ln τ column: v · ∂(drift columns)/∂ln τ
    block = best.blocks[i]
    red = best.reductions[i]
    v = red.basis @ best.fit.values[block]
    dcol = _drift_at(layout, kind, float(opt.x), derivative=True) @ v
    aug = fit(selector.sums, np.concatenate([best.w, dcol[:, None]], axis=1), heldout=False)
    tau = float(np.exp(opt.x))
    std_tau = tau * float(aug.std[-1]) if np.isfinite(aug.vif[-1]) else float("nan")
    best.fit.cov_unit = aug.cov_unit[:-1, :-1] * (aug.sigma2 / best.fit.sigma2 if best.fit.sigma2 > 0 else 1.0)
    return best, std_tau
