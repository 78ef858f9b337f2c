"""Why a weighed value is entered as it is, in plain words (:func:`why_entered`), from the weighing's numbers:

- *entered as estimated*: the data show it many standard errors from 0;
- *entered in part*: the data show it only weakly (the share entered and its estimate ± standard error);
- *not entered*: the data do not show it beyond its uncertainty;
- *entered as a value other than its estimate* (more than it, or of the other sign): the data determine it together
  with values beside it (correlated) that are not entered, or only in part; with those as entered, the same data
  put it at the entered value.  The values beside it and their correlation are named.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pige_sym.compensation.covariance import BlockCovariance

#: A value beside another is named as the reason when their correlation is at least this.
CORRELATED = 0.3


def why_entered(i: int, names: Sequence[str], estimate: np.ndarray, covariance: np.ndarray | BlockCovariance,
                entered: np.ndarray, unit: str = "") -> str:
    """Why value ``i`` is entered as ``entered[i]`` (module docstring), in plain words.

    Parameters
    ----------
    i : int
    names : sequence of str
    estimate, entered : (q,) [µm, µrad]
    covariance : (q, q) or BlockCovariance
    unit : str
        Of value ``i``, for the text.
    """
    x, c = float(estimate[i]), float(entered[i])
    row = _row(covariance, i)
    std = math.sqrt(max(float(row[i]), 0.0))
    said = f"{x:+.4g} ± {std:.2g}{(' ' + unit) if unit else ''}"
    if c == 0.0:
        return f"not entered: the data do not show it beyond its uncertainty ({said})"
    share = c / x if x else math.inf
    if abs(share - 1.0) < 0.05:
        return "entered as estimated"
    if 0.0 < share < 1.0:
        return f"entered in part ({share:.0%} of the estimate): the data show it only weakly ({said})"
    beside = _weighed_down_beside(i, names, estimate, covariance, entered)
    partners = ", ".join(f"{names[j]} ({'not entered' if entered[j] == 0.0 else 'entered in part'}; correlation "
                         f"{rho:+.2f})" for j, rho in beside) or "the values beside it"
    own = "its estimate alone is within its uncertainty" if abs(x) < 2 * std else "its estimate"
    return (f"entered as {c:+.4g}, not as its estimate {said} ({own}): the data determine it together with "
            f"{partners}; with those as entered, the same data put it at {c:+.4g}")


def _row(covariance: np.ndarray | BlockCovariance, i: int) -> np.ndarray:
    """Row ``i`` of the covariance, shape=(q,)."""
    return covariance.row(i) if isinstance(covariance, BlockCovariance) else np.asarray(covariance, dtype=float)[i]


def _weighed_down_beside(i: int, names: Sequence[str], estimate: np.ndarray,
                         covariance: np.ndarray | BlockCovariance, entered: np.ndarray) -> list[tuple[int, float]]:
    """The values correlated with ``i`` (|ρ| ≥ :data:`CORRELATED`) that are not entered as estimated, strongest
    first, as (index, correlation)."""
    sd = np.sqrt(np.clip(np.asarray(covariance.diagonal(), dtype=float), 0.0, None))
    row = _row(covariance, i)
    out = []
    for j in range(len(names)):
        if j == i or sd[i] == 0 or sd[j] == 0 or row[j] == 0:
            continue
        rho = float(row[j] / (sd[i] * sd[j]))
        moved = entered[j] == 0.0 or abs(entered[j] - estimate[j]) > 0.05 * abs(estimate[j])
        if abs(rho) >= CORRELATED and moved:
            out.append((j, rho))
    return sorted(out, key=lambda t: -abs(t[1]))[:3]
