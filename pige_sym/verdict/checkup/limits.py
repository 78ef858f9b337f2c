"""Control limits per PIGE for the next run: the posterior predictive of the run-to-run scatter, two tests.

**What a new check-up is compared with.**  The runs of the current *segment* (an entered correction starts a new
one; the full calibrations are in it as well as the check-ups), in time order, in control (a check-up the learned
limits flagged once they were worth :data:`TRUST_DOF` degrees of freedom leaves them: a drift must not widen the
limits it is judged by; those of a segment closed by a correction leave it too).  A segment started by a correction
begins with the previous run less the correction entered (its *start*), as the first of its runs.  Run ``i`` has
value ``x_i`` and variance ``τ² + u_i²`` (:mod:`~pige_sym.verdict.checkup.scatter`): its own standard error ``u_i``
and the machine's run-to-run scatter ``τ``, whose posterior (from the machine's history and its fleet) is a set of
weights ``w_g`` on a grid ``τ_g²``.

**Shewhart test** (a jump).  The centre ``x̄ = Σ a_i x_i`` is the segment's weighted mean at the posterior median
``τ̂²`` (``a_i ∝ 1/(τ̂² + u_i²)``).  For a machine that holds still, ``x − x̄`` given ``τ²`` is normal with variance
``v(τ²) = τ² + u² + Σ a_i² (τ² + u_i²)`` (``u`` the new run's standard error); over the posterior it is the mixture
``Σ_g w_g N(0, v(τ_g²))``, the *posterior predictive*.  The new value is outside when ``|x − x̄| > h``, ``h`` the
mixture's two-sided point at the Shewhart test's share ``β_S = SHEWHART_SHARE·α/m``: ``Σ_g w_g P(|N(0, v_g)| > h) =
β_S``.  With a vague prior and equal ``u_i`` this is close to the Student-t limit ``t_ν(1 − β_S/2)·s·√(1 + 1/n)``;
with the fleet's prior it is narrower, as the prior is worth runs.

**EWMA test** (a slow drift: a Shewhart test sees a drift of one standard deviation per run only once it has built
up).  Given ``τ²``, the segment's *innovations* ``e_j = (x_j − x̄_{<j})/√(v_j + Var x̄_{<j})`` (each run against the
weighted mean of those before it, the new one last) are independent ``N(0, 1)`` for a machine that holds still (the
recursive residuals of Brown, Durbin & Evans 1975); their exponentially weighted mean ``Z_k = λ e_k + (1 − λ) Z_{k−1}``
(λ = :data:`LAMBDA`) has variance ``V_k = λ/(2 − λ)·(1 − (1 − λ)^{2k})``.  Its posterior p-value ``Σ_g w_g P(|N(0,
V_k)| > |Z_k(τ_g²)|)`` below the rest of the PIGE's share, ``β_E = (1 − SHEWHART_SHARE)·α/m``, flags the value.

The two tests of each of the ``m`` PIGEs at ``β_S + β_E = α/m`` (Bonferroni): the chance that a check-up of a
drift-free machine flags any PIGE is at most ``α`` (default 1 %; measured by simulation: docs/checkup.md).

**Provisional limits.**  While neither the machine nor its fleet has two runs of a PIGE in one segment
(:data:`MIN_DOF` degrees of freedom over the population), nothing is known of ``τ``: the Shewhart test alone, against
the runs' own standard errors, ``|x − x̄| > t_d(1 − α/(2m))·√(u² + Var x̄)`` (``τ = 0``, ``d`` the run's degrees of
freedom); the verdict says ``provisional``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.identification.distributions import normal_quantile, t_quantile
from pige_sym.verdict.checkup.scatter import INTERVAL, Posterior

#: Family-wise false-alarm rate per check-up (all its PIGEs together).
ALPHA = 0.01
#: The rates ``--alpha`` may be: below 1e-6 a limit sits beyond 5 sigma even on a learned scatter (no drift short of
#: a crash is flagged, and the quantile leaves floating point near 1e-16), above 0.5 a still machine is flagged at
#: every other check-up.
ALPHA_RANGE = (1e-6, 0.5)
#: Degrees of freedom of the population below which the limits are provisional (module docstring).
MIN_DOF = 1
#: What the posterior of a PIGE's scatter must be worth (degrees of freedom) for a check-up it flags to leave the
#: centre and the scatter (module docstring).
TRUST_DOF = 10
#: Weight of the newest innovation in the EWMA.
LAMBDA = 0.4
#: The Shewhart test's share of a PIGE's α/m; the EWMA's is the rest (a drift of one standard deviation per run,
#: which the EWMA sees first, was flagged within five runs in 81.5 % of the cases with this share, 65 % with half).
SHEWHART_SHARE = 0.2
#: Innovations the EWMA sums (the older ones weigh less than 0.6^60 ≈ 5e-14).
EWMA_MEMORY = 60
METHOD = ("per PIGE a Shewhart test of the value against the weighted mean of its segment's runs (full calibrations "
          f"and check-ups) and an EWMA (lambda {LAMBDA:g}) of the segment's innovations, both from the posterior "
          "predictive of the run-to-run scatter (learned from every run of the machine and, through a hierarchical "
          f"prior, from its other PIGEs and the machine's fleet), at {SHEWHART_SHARE:g} and {1 - SHEWHART_SHARE:g} of "
          "alpha/m (Bonferroni over the m PIGEs: at most alpha per check-up)")


@dataclass
class Limit:
    """The control limits of one PIGE for the next check-up, judged.

    Attributes
    ----------
    centre : float
    half_width : float
        Shewhart: outside when ``|x − centre| > half_width``.
    scatter : float or None
        The run-to-run scatter τ (posterior median; None while provisional) [unit].
    scatter_low, scatter_high : float or None
        Its 90 % posterior interval.
    dof : int
        What the posterior is worth in degrees of freedom (:meth:`~.scatter.Posterior.effective_dof`); 0 while
        provisional.
    n_centre : int
        Runs the centre averages.
    provisional : bool
        From the runs' own standard errors (module docstring).
    source : str
        Where the limits were learned.
    ewma : float or None
        The EWMA of the standardized innovations (at the posterior median), with the new value.
    p_shewhart, p_ewma : float or None
        The tests' posterior p-values (the Shewhart's is below its share exactly when ``|z| > 1``).
    alpha_test : float
        The EWMA's level, ``(1 − SHEWHART_SHARE)·α/m``.
    z : float or None
        ``(x − centre)/half_width``: ±1 at the Shewhart limits.
    outside : bool or None
        Outside the Shewhart or the EWMA limits.
    """

    centre: float
    half_width: float
    scatter: float | None
    dof: int
    n_centre: int
    provisional: bool
    source: str = ""
    scatter_low: float | None = None
    scatter_high: float | None = None
    ewma: float | None = None
    p_shewhart: float | None = None
    p_ewma: float | None = None
    alpha_test: float = ALPHA * (1.0 - SHEWHART_SHARE)
    z: float | None = None
    outside: bool | None = None

    @property
    def by(self) -> str:
        """Which test flagged the value: ``shewhart``, ``ewma``, both, or ``""``."""
        tests = ["shewhart"] * bool(self.z is not None and abs(self.z) > 1.0)
        tests += ["ewma"] * bool(self.p_ewma is not None and self.p_ewma < self.alpha_test)
        return "+".join(tests)

    def to_dict(self) -> dict[str, Any]:
        return {"centre": self.centre, "half_width": self.half_width, "scatter": self.scatter,
                "scatter_low": self.scatter_low, "scatter_high": self.scatter_high, "dof": self.dof,
                "n_centre": self.n_centre, "provisional": self.provisional, "source": self.source,
                "ewma": self.ewma, "p_shewhart": self.p_shewhart, "p_ewma": self.p_ewma,
                "alpha_test": self.alpha_test, "z": self.z, "outside": self.outside, "by": self.by}


def _tail(x: np.ndarray) -> np.ndarray:
    """``P(|N(0, 1)| > x) = erfc(x/√2)`` elementwise, ``x ≥ 0``, to a relative 1.2e-7 (Chebyshev fit of Press et al.,
    *Numerical Recipes* §6.2, ``erfcc``: no scipy on the check-up's path)."""
    z = np.abs(np.asarray(x, dtype=float)) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.5 * z)
    poly = -z * z - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (
        -0.18628806 + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))))
    return t * np.exp(poly)


def mixture_point(weights: np.ndarray, variances: np.ndarray, tail: float) -> float:
    """``h`` with ``Σ_g w_g P(|N(0, v_g)| > h) = tail``: the bracket between the normal points of the smallest and
    the largest ``v_g`` narrowed sixteenfold six times (to a relative 1e-7 of its width in log h)."""
    sd = np.sqrt(variances)
    z = normal_quantile(1.0 - tail / 2.0)
    low, high = math.log(z * float(sd.min())), math.log(z * float(sd.max()))
    for _ in range(6):
        if high - low < 1e-12:
            break
        h = np.linspace(low, high, 17)
        p = weights @ _tail(np.exp(h)[None, :] / sd[:, None])
        k = int(np.clip(np.searchsorted(-p, -tail), 1, 16))  # p falls with h: the first point at or below tail
        low, high = float(h[k - 1]), float(h[k])
    return math.exp(0.5 * (low + high))


def innovations(values: np.ndarray, variances: np.ndarray, tau2: np.ndarray) -> np.ndarray:
    """The standardized innovations of a segment's runs for each ``τ²`` of the grid (module docstring), shape=(G,
    n − 1): run ``j`` against the weighted mean of runs ``0 … j − 1``."""
    v = tau2[:, None] + variances[None, :]
    w = 1.0 / v
    cw = np.cumsum(w, axis=1)[:, :-1]
    mean = np.cumsum(w * values[None, :], axis=1)[:, :-1] / cw
    return (values[None, 1:] - mean) / np.sqrt(v[:, 1:] + 1.0 / cw)


def ewma_of(e: np.ndarray, lam: float = LAMBDA) -> tuple[np.ndarray, float]:
    """``(Z_k, V_k)`` of innovations ``e`` (shape (G, k), the newest last; module docstring)."""
    k = e.shape[1]
    used = e[:, -EWMA_MEMORY:]
    weights = lam * (1.0 - lam) ** np.arange(used.shape[1])[::-1]
    return used @ weights, lam / (2.0 - lam) * (1.0 - (1.0 - lam) ** (2 * k))


def provisional_limit(values: np.ndarray, variances: np.ndarray, *, value: float, variance: float, run_dof: int,
                      m: int, alpha: float) -> Limit:
    """The provisional limits (module docstring): ``τ = 0``."""
    w = 1.0 / variances
    centre = float(w @ values / w.sum())
    width = t_quantile(max(run_dof, 1), 1.0 - alpha / (2.0 * m)) * math.sqrt(variance + 1.0 / float(w.sum()))
    z = (value - centre) / width
    return Limit(centre, width, None, 0, int(values.size), True, "the runs' own standard errors (the run-to-run "
                 "scatter is not known yet)", alpha_test=alpha / (2.0 * m), z=z, outside=bool(abs(z) > 1.0))


def control_limit(values: np.ndarray, variances: np.ndarray, post: Posterior | None, *, value: float,
                  variance: float, run_dof: int, m: int, alpha: float = ALPHA) -> Limit | None:
    """The limits of one PIGE for a new check-up ``value``, judged (module docstring).

    Parameters
    ----------
    values, variances : ndarray, shape=(n,)
        The segment's runs in control, in time order (its start first when it has one), and their own variances.
    post : Posterior or None
        The posterior of the PIGE's run-to-run variance (None: provisional limits).
    value, variance : float
        The new check-up's value and its own variance.
    run_dof : int
        Degrees of freedom of the new check-up's standard error (provisional limits).
    m : int
        PIGEs judged in the check-up (Bonferroni).

    Returns
    -------
    Limit or None
        None when the segment has no run yet (nothing to compare with).
    """
    if values.size == 0:
        return None
    if post is None:
        return provisional_limit(values, variances, value=value, variance=variance, run_dof=run_dof, m=m,
                                 alpha=alpha)
    tail_s, tail_e = alpha / m * SHEWHART_SHARE, alpha / m * (1.0 - SHEWHART_SHARE)
    tau2, w = post.tau2, post.weights
    a = 1.0 / (post.median**2 + variances)
    a /= a.sum()
    centre = float(a @ values)
    predictive = tau2 + variance + (a**2) @ (tau2[None, :] + variances[:, None])
    half = mixture_point(w, predictive, tail_s)
    d = value - centre
    p_s = float(w @ _tail(abs(d) / np.sqrt(predictive)))
    e = innovations(np.append(values, value), np.append(variances, variance), tau2)
    z_ewma, v_ewma = ewma_of(e)
    p_e = float(w @ _tail(np.abs(z_ewma) / math.sqrt(v_ewma)))
    k = int(np.searchsorted(np.cumsum(w), 0.5))
    dof = post.effective_dof(variance)
    return Limit(centre, half, post.median, int(min(dof, 1e6)), int(values.size), False, post.source(),
                 post.quantile(INTERVAL[0]), post.quantile(INTERVAL[1]), float(z_ewma[min(k, z_ewma.size - 1)]),
                 p_s, p_e, tail_e, d / half, bool(p_s < tail_s or p_e < tail_e))
