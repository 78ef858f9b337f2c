"""Control limits per PIGE learned from the machine's own check-ups: a Shewhart and an EWMA chart.

**The chart.**  Every check-up of a machine with the same poses and PIGEs (the plan's *signature*) is one point per
PIGE.  Points fall into *segments*: a segment starts at each full calibration and at each check-up run after the
controller was corrected (``pige checkup --corrected``); within a segment the machine is expected to hold its level.
A check-up the learned limits flagged once the scatter had :data:`TRUST_DOF` degrees of freedom leaves the centre, the
scatter and the EWMA (a drift must not widen the limits it is judged by); one flagged earlier stays (with few degrees
of freedom the scatter can come out small by chance, and dropping what it flags would keep it small and flag every
later check-up).  When a segment is closed by a correction or a new calibration (the assignable cause was found),
every check-up of it the learned limits flagged leaves the scatter: a corrected warm-up does not widen the limits of
the next weeks.

**Scatter.**  The run-to-run scatter of PIGE ``p`` is the pooled within-segment standard deviation of the earlier
in-control check-ups,

    ``s² = Σ_seg Σ_i (x_i − x̄_seg)² / ν``,   ``ν = Σ_seg (n_seg − 1)``,

so it holds everything that moves a PIGE from run to run at a constant level (the probing noise, re-clamping,
temperature), not only each run's own measurement noise, and a level change between segments does not inflate it.

**Shewhart test.**  The centre ``x̄`` is the mean of the current segment's ``n_c`` earlier in-control check-ups.  A
new value ``x`` is outside when ``|x − x̄| > t_ν(1 − α/(4m)) · s · √(1 + 1/n_c)``: ``x − x̄`` and ``s`` are
independent, so for a machine that holds still the chance is exactly ``α/(2m)`` (Student's t on ν degrees of freedom
is the small-sample correction).  Before the segment's first check-up the centre is the level it starts from (the
full calibration's value, or the previous value less the correction entered) with its own standard error ``u_c``;
the spread is then ``√(s² + max(u_c², s²))``.

**EWMA test** (a slow drift: a Shewhart chart sees a drift of one standard error per run only when it has built up to
three or four).  The segment's *recursive residuals* ``w_j = (x_j − x̄_{j−1})/√(1 + 1/(j−1))`` (each in-control
check-up against the mean of those before it, the new one included as the last) are independent ``N(0, σ²)`` for a
machine that holds still (Brown, Durbin & Evans 1975); their exponentially weighted mean ``Z_k = λ w_k + (1 − λ)
Z_{k−1}`` (``Z_0 = 0``, λ = :data:`LAMBDA`) is outside when ``|Z_k| > t_ν(1 − α/(4m)) · s · √(λ/(2 − λ)·(1 − (1 −
λ)^{2k}))``.

Both tests at ``α/(2m)`` for each of the ``m`` PIGEs (Bonferroni): the chance that a check-up of a drift-free machine
flags any PIGE is at most ``α`` (default 1 %; the EWMA's ``s`` shares points with ``Z``, so that rate is checked by
simulation: docs/checkup.md).

**Before the limits are learned** (ν < :data:`MIN_DOF`, i.e. fewer than ``MIN_DOF + 1`` check-ups with the same poses
since …): *provisional* limits from the runs' own standard errors, the Shewhart test alone: ``|x − x̄| > t_d(1 −
α/(2m))·√(u² + u_c²)`` (``u`` the run's standard error on ``d`` degrees of freedom, ``u_c`` the centre's).  They hold
the stated rate only when the machine's run-to-run scatter is its measurement noise; the verdict says
``provisional``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.identification.distributions import t_quantile

#: Family-wise false-alarm rate per check-up (all its PIGEs together).
ALPHA = 0.01
#: The rates ``--alpha`` may be: below 1e-6 a limit sits beyond 5 sigma even on a learned scatter (no drift short of
#: a crash is flagged, and the quantile leaves floating point near 1e-16), above 0.5 a still machine is flagged at
#: every other check-up.
ALPHA_RANGE = (1e-6, 0.5)
#: Degrees of freedom of the pooled scatter from which the learned limits replace the provisional ones.
MIN_DOF = 4
#: Degrees of freedom from which a check-up the learned limits flag leaves the chart (module docstring).
TRUST_DOF = 10
#: Weight of the newest recursive residual in the EWMA.
LAMBDA = 0.4
METHOD = ("per PIGE a Shewhart test of the value against the mean of the segment's earlier check-ups and an EWMA "
          f"(lambda {LAMBDA:g}) of the segment's recursive residuals, both scaled by the pooled within-segment "
          "standard deviation s on nu degrees of freedom, each at Student t_nu(1 - alpha/(4m)) (Bonferroni over the "
          "2m tests: at most alpha per check-up); provisional limits from the runs' own standard errors before nu = "
          f"{MIN_DOF}")


@dataclass
class Point:
    """One check-up value of one PIGE on the chart.

    Attributes
    ----------
    value, std : float [µm, µrad]
        Estimate and its standard error (the run's own).
    dof : int
        Degrees of freedom of ``std``.
    segment : int
    in_control : bool
        False when it leaves the chart (module docstring).
    flagged : bool
        The learned limits flagged it (it leaves the chart with its segment).
    """

    value: float
    std: float
    dof: int
    segment: int
    in_control: bool = True
    flagged: bool = False


@dataclass
class Start:
    """The level a segment starts from, the centre until the segment has check-ups of its own.

    ``std`` is the standard error of the difference it makes to a check-up's value besides the check-up's own noise:
    a full calibration's value and its held PIGEs' errors as they move the check-up's fit (``source = "full"``,
    :func:`~pige_sym.verdict.checkup.routine.start_std`), or the previous check-up's standard error (``corrected``).
    """

    value: float
    std: float
    source: str = "full"


@dataclass
class Limit:
    """The control limits of one PIGE for the next check-up.

    Attributes
    ----------
    centre : float
    half_width : float
        Shewhart: outside when ``|x − centre| > half_width``.
    scatter : float or None
        Pooled run-to-run standard deviation ``s`` (None while provisional).
    dof : int
        ν of the scatter (pooled; 0 when there is none).
    n_centre : int
        Points the centre averages.
    provisional : bool
        From the runs' own standard errors (module docstring).
    ewma, ewma_width : float or None
        The EWMA of the recursive residuals with the new value, and its limit (None: provisional, or no earlier
        check-up in the segment).
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
    ewma: float | None = None
    ewma_width: float | None = None
    z: float | None = None
    outside: bool | None = None

    def judge(self, value: float) -> Limit:
        """This limit with a value judged (``z``, ``outside``)."""
        z = (value - self.centre) / self.half_width if self.half_width > 0 else math.inf
        drift = self.ewma is not None and self.ewma_width is not None and abs(self.ewma) > self.ewma_width
        return Limit(self.centre, self.half_width, self.scatter, self.dof, self.n_centre, self.provisional,
                     self.ewma, self.ewma_width, float(z), bool(abs(z) > 1.0 or drift))

    @property
    def by(self) -> str:
        """Which test flagged the value: ``shewhart``, ``ewma``, both, or ``""``."""
        tests = ["shewhart"] * bool(self.z is not None and abs(self.z) > 1.0)
        tests += ["ewma"] * bool(self.ewma is not None and self.ewma_width and abs(self.ewma) > self.ewma_width)
        return "+".join(tests)

    def to_dict(self) -> dict[str, Any]:
        return {"centre": self.centre, "half_width": self.half_width, "scatter": self.scatter, "dof": self.dof,
                "n_centre": self.n_centre, "provisional": self.provisional, "ewma": self.ewma,
                "ewma_width": self.ewma_width, "z": self.z, "outside": self.outside, "by": self.by}


def pooled_scatter(points: list[Point]) -> tuple[float | None, int]:
    """``(s, ν)``: the pooled within-segment standard deviation of the in-control points (module docstring)."""
    groups: dict[int, list[float]] = {}
    for p in points:
        if p.in_control:
            groups.setdefault(p.segment, []).append(p.value)
    ss = sum(float(((np.array(v) - np.mean(v)) ** 2).sum()) for v in groups.values())
    dof = sum(len(v) - 1 for v in groups.values())
    return (math.sqrt(ss / dof) if dof > 0 else None), dof


def quantile(alpha: float, tests: int, dof: float) -> float:
    """``t_dof(1 − α/(2·tests))``, the two-sided Bonferroni critical value (normal for infinite ``dof``)."""
    return t_quantile(dof if math.isfinite(dof) else 1e12, 1.0 - alpha / (2.0 * tests))


def ewma_of(values: list[float], lam: float = LAMBDA) -> tuple[float, float] | None:
    """``(Z_k, √(λ/(2−λ)(1−(1−λ)^{2k})))`` of the recursive residuals of ``values`` (module docstring); None for
    fewer than two values."""
    if len(values) < 2:
        return None
    x = np.asarray(values, dtype=float)
    j = np.arange(1, x.size)
    means = np.cumsum(x)[:-1] / j
    w = (x[1:] - means) / np.sqrt(1.0 + 1.0 / j)
    z = 0.0
    for v in w:
        z = lam * float(v) + (1.0 - lam) * z
    k = w.size
    return z, math.sqrt(lam / (2.0 - lam) * (1.0 - (1.0 - lam) ** (2 * k)))


def control_limit(points: list[Point], segment: int, start: Start | None, *, value: float, run_std: float,
                  run_dof: int, m: int, alpha: float = ALPHA, min_dof: int = MIN_DOF) -> Limit | None:
    """The limits of one PIGE for a new check-up ``value`` of ``segment``, judged (module docstring).

    Parameters
    ----------
    points : list of Point
        Earlier check-ups with the same poses and PIGEs, in time order.
    segment : int
        The new check-up's segment.
    start : Start or None
        The segment's starting level (None: no centre until it has a check-up of its own).
    value : float
        The new check-up's value.
    run_std, run_dof : float, int
        The new check-up's own standard error and its degrees of freedom (provisional limits).
    m : int
        PIGEs judged in the check-up (Bonferroni).

    Returns
    -------
    Limit or None
        None when there is no centre yet (the first check-up of a segment without a starting level).
    """
    kept = [p for p in points if p.segment == segment and p.in_control]
    mine = [p.value for p in kept]
    if mine:
        centre, n_c = float(np.mean(mine)), len(mine)
        centre_var = float(np.mean([p.std**2 for p in kept])) / n_c
    elif start is not None:
        centre, n_c, centre_var = start.value, 1, start.std**2
    else:
        return None
    s, dof = pooled_scatter(points)
    if s is None or dof < min_dof:
        width = quantile(alpha, m, max(run_dof, 1)) * math.sqrt(run_std**2 + centre_var)
        return Limit(centre, width, None, dof, n_c, True).judge(value)
    q = quantile(alpha, 2 * m, dof)
    spread = s * math.sqrt(1.0 + 1.0 / n_c) if mine else math.sqrt(s**2 + max(centre_var, s**2))
    ew = ewma_of([*mine, value])
    return Limit(centre, q * spread, s, dof, n_c, False, None if ew is None else ew[0],
                 None if ew is None else q * s * ew[1]).judge(value)
