"""The trend of a PIGE over the check-ups, and when it will leave its tolerance.

**Which check-ups.**  During a drift episode (the new check-up is outside its control limits) the trend is fitted to
the run of consecutive flagged check-ups that ends with it: the drift, not the quiet days before it (a warm-up of an
hour checked every ten minutes after weeks of daily check-ups is on another time scale).  Otherwise to the
segment's check-ups (the last :data:`WINDOW`, at least three): a slow drift that has not yet left the limits.

**Fit** (robust: one bad check-up does not tilt it): the Theil–Sen line, slope ``b`` the median of the pairwise
slopes, level ``a`` the median of ``x_i − b·t_i``.  **Its uncertainty** comes from the run-to-run scatter the chart
learned (``s`` on ν degrees of freedom; provisional: the check-ups' own standard errors), not from the few points of
the window: ``SE(b) = s/√S_tt`` with ``S_tt = Σ(t_i − t̄)²`` (the least-squares slope's; Theil–Sen's is a few per cent
larger for normal scatter), the drift rate's interval ``b ± t_ν(0.95)·SE(b)`` at :data:`CONFIDENCE`.

**Shown.**  A drift is *shown* when its slope differs from zero at the check-up's own false-alarm level: ``|b| >
t_ν(1 − α'/2)·SE(b)`` with ``α' = α/m`` (``shown_alpha``; the chart's α over its ``m`` PIGEs): a machine that holds
still gets a forecast in at most ``α`` of its check-ups.  Only a shown drift is forecast.

**Forecast.**  The level follows the line ``ŷ(t) = ȳ + b(t − t̄)`` (``ȳ`` the line at the mean time); it leaves the
tolerance ``±L`` when ``ŷ`` crosses ``L`` on the side it drifts to.  The interval is the inverse of the line's band
``ŷ(t) ± q·s·√(1/n + (t − t̄)²/S_tt)`` (Fieller's): its earliest time is where the band's outer edge meets ``L``, its
latest where the inner edge does; when the drift is not shown at this confidence there is no latest time.  Coverage
measured on simulated drifts: docs/checkup.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.identification.distributions import t_quantile

CONFIDENCE = 0.90
MIN_POINTS = 2
#: Check-ups of a segment a quiet trend is fitted to (the newest).
WINDOW = 30


@dataclass
class Trend:
    """Drift of one PIGE [unit per hour] and its forecast (times in hours on the caller's clock).

    Attributes
    ----------
    rate, rate_low, rate_high, rate_std : float
        Theil–Sen slope, its interval at ``confidence`` and standard error [unit/h].
    level : float
        The line at ``t_now`` [unit].
    points : int
    episode : bool
        Fitted to a drift episode (the flagged check-ups) rather than the segment.
    leaves_at, leaves_low, leaves_high : float or None
        When the line leaves ``±limit`` (None: no limit, the drift is not shown, or it does not drift towards one);
        the interval's earliest and latest time (``leaves_high`` None: no latest time at this confidence) [h].
    shown : bool
        The drift is shown (module docstring): only then is it forecast.
    now : float
        ``t_now`` [h]: an earliest time at ``now`` means the line's band meets the tolerance already (the PIGE may
        be outside it now).
    """

    rate: float
    rate_low: float
    rate_high: float
    rate_std: float
    level: float
    points: int
    confidence: float
    episode: bool = False
    limit: float | None = None
    leaves_at: float | None = None
    leaves_low: float | None = None
    leaves_high: float | None = None
    shown: bool = False
    now: float = 0.0

    @property
    def reached(self) -> bool:
        """The forecast's band meets the tolerance at the check-up already (its earliest time is now)."""
        return self.leaves_low is not None and self.leaves_low <= self.now

    @property
    def significant(self) -> bool:
        """The drift's interval excludes zero."""
        return self.rate_low > 0 or self.rate_high < 0

    def to_dict(self) -> dict[str, Any]:
        return {"rate_per_h": self.rate, "rate_low": self.rate_low, "rate_high": self.rate_high,
                "rate_std": self.rate_std, "level": self.level, "points": self.points, "confidence": self.confidence,
                "significant": self.significant, "shown": self.shown, "episode": self.episode, "limit": self.limit,
                "leaves_at_h": self.leaves_at, "leaves_low_h": self.leaves_low, "leaves_high_h": self.leaves_high,
                "reached": self.reached}


def theil_sen(t: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(slope, level at t = 0) of the Theil–Sen line (module docstring); at least two distinct times."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    i, j = np.triu_indices(t.size, 1)
    dt = t[j] - t[i]
    keep = dt != 0
    if not keep.any():
        raise ValueError("a trend needs two distinct times")
    b = float(np.median((x[j] - x[i])[keep] / dt[keep]))
    return b, float(np.median(x - b * t))


def trend(t: np.ndarray, x: np.ndarray, t_now: float, limit: float | None = None, *, scale: float, dof: float,
          episode: bool = False, confidence: float = CONFIDENCE, shown_alpha: float | None = None) -> Trend | None:
    """The trend and forecast of one PIGE (module docstring).

    Parameters
    ----------
    t, x : ndarray, shape=(n,)
        Times [h] and values of the window's check-ups, the new one last.
    scale, dof : float
        Run-to-run standard deviation and its degrees of freedom.
    shown_alpha : float, optional
        The two-sided level at which the drift must be shown to be forecast (module docstring); default: the
        rate's interval excludes zero.

    Returns
    -------
    Trend or None
        None with fewer than :data:`MIN_POINTS` points or one time.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.size < MIN_POINTS or np.ptp(t) <= 0 or not (math.isfinite(scale) and scale > 0):
        return None
    b, a = theil_sen(t, x)
    t_bar = float(t.mean())
    s_tt = float(((t - t_bar) ** 2).sum())
    q = t_quantile(max(dof, 1.0), 0.5 + confidence / 2.0)
    se = scale / math.sqrt(s_tt)
    out = Trend(b, b - q * se, b + q * se, se, a + b * t_now, int(t.size), confidence, episode, limit, now=t_now)
    out.shown = (out.significant if shown_alpha is None else
                 abs(b) > t_quantile(max(dof, 1.0), 1.0 - shown_alpha / 2.0) * se)
    if limit is None or b == 0 or not out.shown:
        return out
    sign = 1.0 if b > 0 else -1.0
    y_bar = sign * (a + b * t_bar)  # the drift taken upwards
    slope = sign * b
    out.leaves_at = max(t_bar + (limit - y_bar) / slope, t_now)
    out.leaves_low, out.leaves_high = _fieller(y_bar, slope, limit, q * scale, t.size, s_tt, t_bar, t_now)
    return out


def _fieller(y_bar: float, b: float, limit: float, qs: float, n: int, s_tt: float, t_bar: float,
             t_now: float) -> tuple[float | None, float | None]:
    """Earliest and latest time the band ``y_bar + b·u ± qs·√(1/n + u²/S_tt)`` (u = t − t̄, b > 0) meets ``limit``.

    The roots of ``(L − ȳ − b·u)² = qs²(1/n + u²/S_tt)``: with the slope shown (``b² > qs²/S_tt``) both edges meet
    ``L``, the outer first; otherwise only the outer edge does (no latest time).  Times before ``t_now`` are
    ``t_now`` (already there).
    """
    d = limit - y_bar
    qa = b * b - qs * qs / s_tt
    qb = -2.0 * b * d
    qc = d * d - qs * qs / n
    reached = d <= qs / math.sqrt(n)  # the band at the mean time holds the limit already
    if qa > 0:
        root = math.sqrt(max(qb * qb - 4 * qa * qc, 0.0))
        lo, hi = (-qb - root) / (2 * qa), (-qb + root) / (2 * qa)
        return (t_now if reached else max(t_bar + lo, t_now)), max(t_bar + hi, t_now)
    if reached:
        return t_now, None
    if qa == 0:
        return max(t_bar + qc / (2 * b * d), t_now), None
    root = math.sqrt(qb * qb - 4 * qa * qc)  # qa < 0 < qc: real roots of opposite signs
    return max(t_bar + max((-qb - root) / (2 * qa), (-qb + root) / (2 * qa)), t_now), None
