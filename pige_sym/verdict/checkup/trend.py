"""The trend of a PIGE over the check-ups, and when it will leave its tolerance.

**Fit** (robust: one bad check-up does not tilt it): the Theil–Sen line through the points ``(t_i, x_i)`` of the
current segment (since the last full calibration or correction): the slope ``b`` is the median of the pairwise
slopes, the level ``a`` the median of ``x_i − b·t_i``.  **Drift rate interval**: Sen's distribution-free
interval of the slope at :data:`CONFIDENCE` (the ranks ``(N ∓ z·σ_S)/2`` of the ``N`` sorted pairwise slopes,
``σ_S² = n(n−1)(2n+5)/18`` the variance of Kendall's S; the same as ``scipy.stats.theilslopes``); its half-width
over ``z`` is quoted as the rate's standard error.

**Forecast.**  The level follows the line; it leaves the tolerance ``±L`` when the line crosses ``L`` in the
direction of the drift.  The interval comes from the band of lines through the pivot ``(t̃, x̃)`` (the median time
and the line there) with every slope of the interval and the pivot moved by ``±δ``, ``δ = z·√(π/2)·σ̂/√n`` (σ̂ =
1.4826·MAD of the residuals; √(π/2): a median's standard error): the earliest crossing is the band's outer edge,
the latest its inner edge; when the slope interval reaches zero (a drift not shown at this confidence) there is no
latest time.  Needs :data:`MIN_POINTS` points.  docs/checkup.md gives the measured coverage of the interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import ndtri  # normal quantile (scipy.stats' without its import time)

CONFIDENCE = 0.90
MIN_POINTS = 4


@dataclass
class Trend:
    """Drift of one PIGE [unit per hour] and its forecast (times in hours on the caller's clock).

    Attributes
    ----------
    rate, rate_low, rate_high, rate_std : float
        Theil–Sen slope, its interval at ``confidence`` and the interval's half-width over z [unit/h].
    level : float
        The line at ``t_now`` [unit].
    points : int
    leaves_at, leaves_low, leaves_high : float or None
        When the line leaves ``±limit`` (None: not in the direction it drifts, or no limit); the interval's
        earliest and latest time (``leaves_high`` None: the drift is not shown, no latest time) [h].
    """

    rate: float
    rate_low: float
    rate_high: float
    rate_std: float
    level: float
    points: int
    confidence: float
    limit: float | None = None
    leaves_at: float | None = None
    leaves_low: float | None = None
    leaves_high: float | None = None

    @property
    def significant(self) -> bool:
        """The drift's interval excludes zero."""
        return self.rate_low > 0 or self.rate_high < 0

    def to_dict(self) -> dict[str, Any]:
        return {"rate_per_h": self.rate, "rate_low": self.rate_low, "rate_high": self.rate_high,
                "rate_std": self.rate_std, "level": self.level, "points": self.points, "confidence": self.confidence,
                "significant": self.significant, "limit": self.limit, "leaves_at_h": self.leaves_at,
                "leaves_low_h": self.leaves_low, "leaves_high_h": self.leaves_high}


def theil_sen(t: np.ndarray, x: np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float, float, float]:
    """(slope, level at t = 0, slope low, slope high) of the Theil–Sen line with Sen's interval (module docstring).

    Parameters
    ----------
    t, x : ndarray, shape=(n,)
        Times [h] and values; at least two distinct times.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    i, j = np.triu_indices(t.size, 1)
    dt = t[j] - t[i]
    keep = dt != 0
    slopes = np.sort((x[j] - x[i])[keep] / dt[keep])
    if slopes.size == 0:
        raise ValueError("a trend needs two distinct times")
    b = float(np.median(slopes))
    a = float(np.median(x - b * t))
    n, nt = t.size, slopes.size
    z = float(ndtri(0.5 + confidence / 2.0))
    sigma = math.sqrt(n * (n - 1) * (2 * n + 5) / 18.0)
    low = slopes[max(int(round((nt - z * sigma) / 2.0)) - 1, 0)]
    high = slopes[min(int(round((nt + z * sigma) / 2.0)), nt - 1)]
    return b, a, float(low), float(high)


def trend(t: np.ndarray, x: np.ndarray, t_now: float, limit: float | None = None, *,
          confidence: float = CONFIDENCE) -> Trend | None:
    """The trend and forecast of one PIGE (module docstring); None with fewer than :data:`MIN_POINTS` points."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.size < MIN_POINTS or np.ptp(t) <= 0:
        return None
    b, a, low, high = theil_sen(t, x, confidence)
    z = float(ndtri(0.5 + confidence / 2.0))
    out = Trend(b, low, high, (high - low) / (2 * z), a + b * t_now, int(t.size), confidence, limit)
    if limit is None or b == 0:
        return out
    sign = 1.0 if b > 0 else -1.0
    resid = x - (a + b * t)
    robust = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
    delta = z * math.sqrt(math.pi / 2) * robust / math.sqrt(t.size)
    pivot_t = float(np.median(t))
    pivot_x = sign * (a + b * pivot_t)  # the drift taken upwards
    fast, slow = (high, low) if sign > 0 else (-low, -high)
    out.leaves_at = _crossing(pivot_t, pivot_x, sign * b, limit, t_now)
    out.leaves_low = _crossing(pivot_t, pivot_x + delta, fast, limit, t_now)
    out.leaves_high = _crossing(pivot_t, pivot_x - delta, slow, limit, t_now) if slow > 0 else None
    return out


def _crossing(pivot_t: float, pivot_x: float, slope: float, limit: float, t_now: float) -> float | None:
    """When ``pivot_x + slope·(t − pivot_t)`` reaches ``limit`` (not before ``t_now``); None for a slope ≤ 0."""
    if slope <= 0:
        return None
    return max(pivot_t + (limit - pivot_x) / slope, t_now) if pivot_x < limit else t_now
