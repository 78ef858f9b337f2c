"""Student's t quantile and the chi-square tail, without ``scipy.special``'s import time.

``pige checkup`` answers in under a second with a long history (issue 42); importing ``scipy.special`` (its array-API
backends) takes a third of that on its own.  The check-up needs three numbers, computed here with the standard
methods and checked against ``scipy.special`` in ``tests/test_checkup.py`` (the t quantile to 1e-7 relative over
dof 1 to 1e8 and tail probabilities down to 1e-7, the chi-square tail to 1e-12):

- the regularized incomplete beta ``I_x(a, b)`` by its continued fraction (modified Lentz; Press et al., *Numerical
  Recipes*, §6.4), hence Student's t distribution ``P(T ≤ t) = 1 − I_{ν/(ν+t²)}(ν/2, 1/2)/2`` for t ≥ 0;
- the t quantile by Newton steps on that distribution from the normal quantile (``statistics.NormalDist``), with a
  bisection bracket so that it cannot leave the root;
- the regularized upper incomplete gamma ``Q(a, x)`` (series below ``a + 1``, continued fraction above), hence the
  chi-square tail ``P(χ²_k > x) = Q(k/2, x/2)``.
"""

from __future__ import annotations

import math
from functools import lru_cache
from statistics import NormalDist

_EPS = 1e-15
_TINY = 1e-300


def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the incomplete beta (modified Lentz)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    h = d
    for m in range(1, 10000):
        m2 = 2 * m
        for aa in (m * (b - m) * x / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
            d = 1.0 + aa * d
            d = 1.0 / (d if abs(d) > _TINY else _TINY)
            c = 1.0 + aa / c
            c = c if abs(c) > _TINY else _TINY
            h *= d * c
        if abs(d * c - 1.0) < _EPS:
            return h
    return h  # pragma: no cover - converges within a few hundred terms for the arguments used here


def betainc(a: float, b: float, x: float) -> float:
    """The regularized incomplete beta function ``I_x(a, b)``, ``0 ≤ x ≤ 1``."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def t_sf(dof: float, t: float) -> float:
    """``P(T > t)`` for Student's t on ``dof`` degrees of freedom."""
    tail = 0.5 * betainc(dof / 2.0, 0.5, dof / (dof + t * t))
    return tail if t >= 0 else 1.0 - tail


@lru_cache(maxsize=4096)
def t_quantile(dof: float, p: float) -> float:
    """The ``p`` quantile of Student's t on ``dof`` degrees of freedom (``0 < p < 1``); kept per ``(dof, p)`` (a
    chart asks for the same few quantiles at every check-up, each a few hundred continued-fraction terms)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"probability {p} outside (0, 1)")
    if p < 0.5:
        return -t_quantile(dof, 1.0 - p)
    if dof > 1e7:
        return NormalDist().inv_cdf(p)
    target = 1.0 - p
    lo, hi = 0.0, 1.0
    while t_sf(dof, hi) > target:
        lo, hi = hi, 2.0 * hi
    x = min(max(NormalDist().inv_cdf(p), lo), hi)
    for _ in range(200):
        f = t_sf(dof, x) - target
        if f > 0:
            lo = x
        else:
            hi = x
        pdf = math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2) - 0.5 * math.log(dof * math.pi)
                       - (dof + 1) / 2 * math.log1p(x * x / dof))
        step = f / pdf if pdf > 0 else 0.0
        if abs(step) <= 1e-13 * max(1.0, abs(x)) or hi - lo <= 1e-13 * max(1.0, abs(x)):
            return x + step
        new = x + step
        x = new if lo < new < hi else 0.5 * (lo + hi)
    return x


def gammaincc(a: float, x: float) -> float:
    """The regularized upper incomplete gamma function ``Q(a, x)``."""
    if x <= 0.0:
        return 1.0
    log_front = -x + a * math.log(x) - math.lgamma(a)
    if x < a + 1.0:  # series for P
        term = total = 1.0 / a
        ap = a
        for _ in range(100000):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * _EPS:
                break
        return max(0.0, 1.0 - total * math.exp(log_front))
    b = x + 1.0 - a  # continued fraction for Q (modified Lentz)
    c, d = 1.0 / _TINY, 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = b + an / c
        c = c if abs(c) > _TINY else _TINY
        h *= d * c
        if abs(d * c - 1.0) < _EPS:
            break
    return math.exp(log_front) * h


def chi2_sf(k: float, x: float) -> float:
    """``P(χ²_k > x)``."""
    return gammaincc(k / 2.0, x / 2.0)


def normal_quantile(p: float) -> float:
    """The ``p`` quantile of the standard normal distribution."""
    return NormalDist().inv_cdf(p)
