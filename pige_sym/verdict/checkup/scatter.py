"""The run-to-run scatter of each PIGE, learned from the machine's runs and its fleet (hierarchical Bayes).

**Model.**  Run ``i`` of a machine measures PIGE ``p`` as ``x_i = μ_s + η_i + ε_i``: ``μ_s`` the level of its
*segment* (an entered correction starts a new one), ``η_i ~ N(0, τ²)`` how the machine itself moved since the other
runs (re-clamping, temperature: the *run-to-run scatter*, the same for a full calibration and a check-up), ``ε_i ~
N(0, u_i²)`` the run's own measurement error, ``u_i`` its standard error (a check-up's includes its held PIGEs'
error).  Every run that measured ``p`` counts, full calibrations and check-ups alike.

**Likelihood** of ``τ²`` (restricted: each segment's level integrated out under a flat prior), per series
(:class:`Series`: one PIGE of one machine)::

    log L(τ²) = −½ Σ_s [ Σ_i log v_i + log Σ_i w_i + Σ_i w_i (x_i − x̄_s)² ],   v_i = τ² + u_i²,  w_i = 1/v_i,

``x̄_s`` the weighted mean of segment ``s``; a segment of one run tells nothing about ``τ²``.  Computed on a grid of
``τ²`` spaced evenly in ``log τ²`` (:data:`GRID_STEP`) over the data's range.

**Prior** (the fleet): the PIGE's ``τ²`` is one draw of a population, ``τ² ~ Scaled-Inv-χ²(ν₀, s₀²)`` (a prior worth
``ν₀`` runs of scatter ``s₀``).  The population are the *units* (one PIGE of one machine) of the same unit [µm or
µrad] of every machine of the same structure in the history: the machine's other PIGEs and the fleet's.  ``ν₀`` and
``s₀²`` are not fixed but integrated over (hierarchical Bayes, a flat prior on ``log ν₀`` over
:data:`PRIOR_DOF` and on ``log s₀²`` over the grid): the population's units tell how alike they are.  Many alike
units put the weight on a large ``ν₀`` and the machine borrows their scatter (a new machine of a fleet has learned
limits from its first check-up); units that differ keep ``ν₀`` small, and each PIGE's own runs decide.  ``ν₀`` stops
at :data:`PRIOR_DOF`'s last value: the machine's own runs take over once it has as many degrees of freedom.  The
posterior of the target ``τ²`` is ``L_p(τ²)·∫ π(τ²|ν₀, s₀²) p(ν₀, s₀² | the other units) dν₀ ds₀²``: the full
hierarchical posterior (the other units' marginal likelihoods make the hyper-posterior; the target's own enters once).

**Used by** :mod:`~pige_sym.verdict.checkup.limits`: the posterior predictive distribution of the next run (a
mixture of normals over the grid).  The method and its measured false-alarm rate: docs/checkup.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np

#: Step of the grid of τ² in log τ² (16 points a decade).
GRID_STEP = math.log(10.0) / 16.0
#: The prior's degrees of freedom ν₀ integrated over (evenly in log ν₀).
PRIOR_DOF = (0.5, 0.8, 1.3, 2.0, 3.2, 5.0, 8.0, 12.6, 20.0, 31.6, 50.0, 79.4, 126.0, 200.0)
#: Every how many grid points a scale s₀² of the prior lies.
SCALE_EVERY = 3
#: The posterior's quantiles printed as the scatter's interval.
INTERVAL = (0.05, 0.95)


@dataclass
class Series:
    """One PIGE of one machine: the runs that measured it, in time order (in-control runs only).

    Attributes
    ----------
    machine_id, name : str
    values : ndarray, shape=(n,) [µm, µrad]
    variances : ndarray, shape=(n,)
        Each run's own squared standard error ``u_i²``.
    segments : ndarray, shape=(n,) of int
    kinds : list of str
        ``full`` or ``checkup`` per run.
    recent : ndarray, shape=(n,) of bool, optional
        The newest check-ups, left out while the population is worth enough without them
        (:data:`~pige_sym.verdict.checkup.reference.LAG`).
    """

    machine_id: str
    name: str
    values: np.ndarray
    variances: np.ndarray
    segments: np.ndarray
    kinds: list[str] = field(default_factory=list)
    recent: np.ndarray | None = None

    def settled(self) -> Series:
        """This series without its :attr:`recent` runs."""
        if self.recent is None or not self.recent.any():
            return self
        keep = ~self.recent
        return Series(self.machine_id, self.name, self.values[keep], self.variances[keep], self.segments[keep],
                      [k for k, r in zip(self.kinds, self.recent, strict=True) if not r])

    @cached_property
    def dof(self) -> int:
        """Degrees of freedom of the scatter: runs less segments (a segment of one run has none); counted once (a
        series is built whole and never changed, and the posteriors ask for it many times)."""
        return int(self.values.size - np.unique(self.segments).size) if self.values.size else 0


def log_likelihood(series: Series, tau2: np.ndarray) -> np.ndarray:
    """``log L(τ²)`` of ``series`` on the grid ``tau2`` (module docstring), shape=(G,)."""
    out = np.zeros(tau2.size)
    if series.dof == 0:
        return out
    order = np.argsort(series.segments, kind="stable")
    seg = series.segments[order]
    starts = np.flatnonzero(np.concatenate(([True], seg[1:] != seg[:-1])))
    x = series.values[order]
    counts = np.diff(np.append(starts, x.size))
    x = x - np.repeat(np.add.reduceat(x, starts) / counts, counts)
    v = tau2[:, None] + series.variances[order][None, :]
    w = 1.0 / v
    sw = np.add.reduceat(w, starts, axis=1)
    swx = np.add.reduceat(w * x, starts, axis=1)
    swxx = np.add.reduceat(w * x * x, starts, axis=1)
    out -= 0.5 * (np.log(v).sum(axis=1) + np.log(sw).sum(axis=1) + (swxx - swx**2 / sw).sum(axis=1))
    return out


def grid_for(series: list[Series]) -> np.ndarray:
    """The grid of τ² for a population (module docstring): from a thousandth of the smallest run variance to a
    thousand times the largest spread of a series, :data:`GRID_STEP` apart in log τ²."""
    variances = np.concatenate([s.variances for s in series if s.variances.size] or [np.ones(1)])
    spread = max([float(np.var(s.values)) for s in series if s.values.size > 1] + [float(variances.max())])
    low = max(float(np.min(variances[variances > 0], initial=spread)) * 1e-3, 1e-12)
    high = max(spread, low) * 1e3
    return low * np.exp(GRID_STEP * np.arange(int(math.ceil(math.log(high / low) / GRID_STEP)) + 1))


_KERNEL_REACH = 2000


@lru_cache(maxsize=1)
def _kernels() -> np.ndarray:
    """Per ν₀ the prior's density in ``d = log τ² − log s₀²`` on the grid's steps, ``exp(−ν₀/2·(d + e^{−d}))``
    up to a constant, shape=(ν₀, 2·reach + 1)."""
    d = GRID_STEP * np.arange(-_KERNEL_REACH, _KERNEL_REACH + 1)
    nu = np.array(PRIOR_DOF)[:, None]
    f = -0.5 * nu * (d[None, :] + np.exp(np.minimum(-d[None, :], 700.0)))
    return np.exp(f - f.max(axis=1, keepdims=True))


@lru_cache(maxsize=8)
def _prior(size: int) -> np.ndarray:
    """``π(τ²|ν₀, s₀²)`` on a grid of ``size`` points (probabilities, each row sums to 1), rows (ν₀, s₀²) with the
    scales every :data:`SCALE_EVERY` points away from the grid's ends, shape=(ν₀·S, G); read-only (kept per
    ``size``: a check-up and a chart ask again for the grids of the same sizes)."""
    scales = np.arange(2 * SCALE_EVERY, max(size - 2 * SCALE_EVERY, 2 * SCALE_EVERY + 1), SCALE_EVERY)
    offset = np.clip(np.arange(size)[None, :] - scales[:, None], -_KERNEL_REACH, _KERNEL_REACH) + _KERNEL_REACH
    p = _kernels()[:, offset].reshape(-1, size)
    p = p / np.maximum(p.sum(axis=1, keepdims=True), 1e-300)
    p.flags.writeable = False
    return p


@dataclass
class Posterior:
    """The posterior of one PIGE's run-to-run variance τ² on a grid.

    Attributes
    ----------
    tau2, weights : ndarray, shape=(G,)
        Grid [unit²] and posterior probabilities (sum 1).
    own_runs, own_dof : int
        The machine's own runs of this PIGE (in control) and the degrees of freedom they give.
    sibling_units : int
        The machine's other PIGEs in the population.
    fleet_machines, fleet_runs : int
        The other machines of its structure in the population, and their runs.
    pooled_units, pooled_dof : int
        The whole population besides this PIGE: units and degrees of freedom.
    prior_dof : float
        The posterior mean of ν₀ (what the prior is worth, in runs).
    """

    tau2: np.ndarray
    weights: np.ndarray
    own_runs: int
    own_dof: int
    sibling_units: int
    fleet_machines: int
    fleet_runs: int
    pooled_units: int
    pooled_dof: int
    prior_dof: float

    def quantile(self, q: float) -> float:
        """The ``q`` quantile of the scatter τ [unit]."""
        k = int(np.searchsorted(np.cumsum(self.weights), q))
        return float(math.sqrt(self.tau2[min(k, self.tau2.size - 1)]))

    @property
    def median(self) -> float:
        return self.quantile(0.5)

    def effective_dof(self, variance: float) -> float:
        """What the knowledge of a run's total variance ``τ² + variance`` is worth in degrees of freedom: ``2/Var(log
        σ²)`` (a scaled-inverse-χ² on ν degrees of freedom has ``Var(log σ²) ≈ 2/ν``)."""
        lv = np.log(self.tau2 + variance)
        mean = float(self.weights @ lv)
        var = float(self.weights @ (lv - mean) ** 2)
        return 2.0 / var if var > 0 else math.inf

    def source(self) -> str:
        """Where the scatter was learned (one clause)."""
        parts = [f"{self.own_runs} run{'s' if self.own_runs != 1 else ''} of its own ({self.own_dof} degree"
                 f"{'s' if self.own_dof != 1 else ''} of freedom)"]
        if self.sibling_units:
            parts.append(f"its {self.sibling_units} other PIGE{'s' if self.sibling_units != 1 else ''} of that unit")
        if self.fleet_machines:
            parts.append(f"{self.fleet_machines} machine{'s' if self.fleet_machines != 1 else ''} of its structure "
                         f"in this history ({self.fleet_runs} runs)")
        text = " and ".join([", ".join(parts[:-1]), parts[-1]] if len(parts) > 1 else parts)
        if self.pooled_units:
            text += f"; their prior is worth about {self.prior_dof:.0f} runs of its own"
        return text


def _runs(series: list[Series]) -> int:
    """The runs behind series (a run that measured several PIGEs counted once: the largest series per machine)."""
    most: dict[str, int] = {}
    for s in series:
        most[s.machine_id] = max(most.get(s.machine_id, 0), int(s.values.size))
    return sum(most.values())


def posteriors(targets: list[Series], population: list[Series]) -> dict[str, Posterior]:
    """The posterior of τ² of each target series (module docstring), by its name.

    Parameters
    ----------
    targets : list of Series
        The machine's series of the PIGEs judged (one unit each).
    population : list of Series
        Every unit of the same unit and structure: the targets, the machine's other PIGEs, the fleet's.
    """
    tau2 = grid_for(population)
    prior = _prior(tau2.size)  # (θ, G)
    informative = [s for s in population if s.dof > 0]
    logl = {id(s): log_likelihood(s, tau2) for s in informative}
    marginal = {}
    for k, v in logl.items():  # log Σ_g π(g|θ) L(g), θ = (ν₀, s₀²) flattened
        top = float(v.max())
        marginal[k] = np.log(np.maximum(prior @ np.exp(v - top), 1e-300)) + top
    total = sum(marginal.values()) if marginal else np.zeros(prior.shape[0])
    nu = np.repeat(np.array(PRIOR_DOF), prior.shape[0] // len(PRIOR_DOF))
    out = {}
    for t in targets:
        hyper = total - marginal.get(id(t), 0.0)
        hyper = np.exp(hyper - hyper.max())
        hyper /= hyper.sum()
        post = np.log(np.maximum(hyper @ prior, 1e-300)) + (logl[id(t)] if id(t) in logl else 0.0)
        w = np.exp(post - post.max())
        others = [s for s in informative if s is not t]
        fleet = [s for s in others if s.machine_id != t.machine_id]
        out[t.name] = Posterior(tau2, w / w.sum(), int(t.values.size), t.dof, len(others) - len(fleet),
                                len({s.machine_id for s in fleet}), _runs(fleet), len(others),
                                sum(s.dof for s in others), float(hyper @ nu))
    return out
