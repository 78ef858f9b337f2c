"""Control limits per PIGE learned from the machine's own check-ups (a Shewhart chart of individual values).

**The chart.**  Every check-up of a machine with the same poses and PIGEs (the plan's *signature*) is one point per
PIGE.  Points fall into *segments*: a segment starts at each full calibration and at each check-up run after the
controller was corrected (``pige checkup --corrected``); within a segment the machine is expected to hold its level.

**Scatter.**  The run-to-run scatter of PIGE ``p`` is the pooled within-segment standard deviation of the in-control
check-ups (those inside their limits when they were judged),

    ``s² = Σ_seg Σ_i (x_i − x̄_seg)² / ν``,   ``ν = Σ_seg (n_seg − 1)``,

so it holds everything that moves a PIGE from run to run at a constant level (the probing noise, re-clamping,
temperature), not only each run's own measurement noise, and a level change between segments does not inflate it.

**Limits.**  The centre ``x̄`` is the mean of the current segment's ``n_c`` in-control check-ups (before the first:
the level the segment starts from, counted as one point: the full calibration's value, or the previous value less
the correction entered).  A new value ``x`` is outside its limits when

    ``|x − x̄| > t_ν(1 − α/(2m)) · s · √(1 + 1/n_c)``

with Student's t on ν degrees of freedom (the small-sample correction: ``x − x̄`` and ``s`` are independent, so
for a machine that holds still the chance is exactly ``α/m`` per PIGE) and ``m`` the check-up's PIGEs
(Bonferroni): the chance that a check-up of a drift-free machine flags any PIGE is at most ``α`` (default 1 %).

**Before the limits are learned** (ν < :data:`MIN_DOF`, i.e. fewer than ``MIN_DOF + 1`` in-control check-ups with
the same poses): *provisional* limits from the runs' own standard errors, ``|x − x̄| > t_d(1 − α/(2m))·√(u² +
u_c²)`` (``u`` the run's standard error on ``d`` degrees of freedom, ``u_c`` the centre's).  They hold the stated
rate only when the machine's run-to-run scatter is its measurement noise; the verdict says ``provisional``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import stdtrit  # Student t quantile (scipy.stats' without its import time)

#: Family-wise false-alarm rate per check-up (all its PIGEs together).
ALPHA = 0.01
#: Degrees of freedom of the pooled scatter from which the learned limits replace the provisional ones.
MIN_DOF = 4
METHOD = ("Shewhart chart of individual values per PIGE: centre = mean of the segment's in-control check-ups, "
          "scatter = pooled within-segment standard deviation on nu degrees of freedom, limit = "
          "t_nu(1 - alpha/(2m)) * s * sqrt(1 + 1/n_c) (Bonferroni over the m PIGEs: at most alpha per check-up)")


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
        Inside its limits when judged (only those enter the scatter and the centre).
    """

    value: float
    std: float
    dof: int
    segment: int
    in_control: bool = True


@dataclass
class Start:
    """The level a segment starts from, counted as one point until the segment has check-ups of its own."""

    value: float
    std: float


@dataclass
class Limit:
    """The control limits of one PIGE for the next check-up.

    Attributes
    ----------
    centre : float
    half_width : float
        Outside when ``|x − centre| > half_width``.
    scatter : float or None
        Pooled run-to-run standard deviation ``s`` (None while provisional).
    dof : int
        ν of the scatter (pooled; 0 when there is none).
    n_centre : int
        Points the centre averages.
    provisional : bool
        From the runs' own standard errors (module docstring).
    """

    centre: float
    half_width: float
    scatter: float | None
    dof: int
    n_centre: int
    provisional: bool
    z: float | None = None
    outside: bool | None = None

    def judge(self, value: float) -> Limit:
        """This limit with a value judged: ``z`` in half-widths' units (±1 at the limits) and whether it is outside."""
        z = (value - self.centre) / self.half_width if self.half_width > 0 else math.inf
        return Limit(self.centre, self.half_width, self.scatter, self.dof, self.n_centre, self.provisional,
                     float(z), bool(abs(z) > 1.0))

    def to_dict(self) -> dict[str, Any]:
        return {"centre": self.centre, "half_width": self.half_width, "scatter": self.scatter, "dof": self.dof,
                "n_centre": self.n_centre, "provisional": self.provisional, "z": self.z, "outside": self.outside}


def pooled_scatter(points: list[Point]) -> tuple[float | None, int]:
    """``(s, ν)``: the pooled within-segment standard deviation of the in-control points (module docstring)."""
    groups: dict[int, list[float]] = {}
    for p in points:
        if p.in_control:
            groups.setdefault(p.segment, []).append(p.value)
    ss = sum(float(((np.array(v) - np.mean(v)) ** 2).sum()) for v in groups.values())
    dof = sum(len(v) - 1 for v in groups.values())
    return (math.sqrt(ss / dof) if dof > 0 else None), dof


def quantile(alpha: float, m: int, dof: float) -> float:
    """``t_dof(1 − α/(2m))``, the two-sided Bonferroni critical value (normal for infinite ``dof``)."""
    return float(stdtrit(dof if math.isfinite(dof) else 1e12, 1.0 - alpha / (2.0 * m)))


def control_limit(points: list[Point], segment: int, start: Start | None, *, run_std: float, run_dof: int,
                  m: int, alpha: float = ALPHA, min_dof: int = MIN_DOF) -> Limit | None:
    """The limits of one PIGE for a new check-up of ``segment`` (module docstring).

    Parameters
    ----------
    points : list of Point
        Earlier check-ups with the same poses and PIGEs, in time order.
    segment : int
        The new check-up's segment.
    start : Start or None
        The segment's starting level (None: no centre until it has a check-up of its own).
    run_std, run_dof : float, int
        The new check-up's own standard error and its degrees of freedom (provisional limits).
    m : int
        PIGEs judged in the check-up (Bonferroni).

    Returns
    -------
    Limit or None
        None when there is no centre yet (the first check-up of a segment without a starting level).
    """
    mine = [p for p in points if p.segment == segment and p.in_control]
    if mine:
        centre = float(np.mean([p.value for p in mine]))
        n_c = len(mine)
        centre_var = float(np.mean([p.std**2 for p in mine])) / n_c
    elif start is not None:
        centre, n_c, centre_var = start.value, 1, start.std**2
    else:
        return None
    s, dof = pooled_scatter(points)
    if s is not None and dof >= min_dof:
        return Limit(centre, quantile(alpha, m, dof) * s * math.sqrt(1.0 + 1.0 / n_c), s, dof, n_c, False)
    width = quantile(alpha, m, max(run_dof, 1)) * math.sqrt(run_std**2 + centre_var)
    return Limit(centre, width, None, dof, n_c, True)


@dataclass
class ChartSummary:
    """What the limits of a check-up rest on, for the reader."""

    method: str = METHOD
    alpha: float = ALPHA
    min_dof: int = MIN_DOF
    notes: list[str] = field(default_factory=list)
