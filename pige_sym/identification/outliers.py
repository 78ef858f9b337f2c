"""Outlier screen of the diagnosis: isolated rows only, judged against a given model.

A row is *flagged* when the norm of its residual (3 components) exceeds the
``threshold``-sigma two-sided normal level turned into a χ²₃ quantile, with the robust
noise level ``σ = 1.4826 · median |r|`` over all residual components.

Flagged rows that line up with a pose variable are *structure*, not outliers: at least
``CLUSTER_MIN`` flagged rows sharing one value of a rotary angle (and making up at least
half of the rows at that value), or a run of at least ``CLUSTER_MIN`` consecutive rows.
Such a cluster is signal: it stays in the data and becomes a candidate effect (an offset
of every row at that pose, :func:`pige_sym.diagnosis.diagnose` tests it like any other); only
the remaining isolated rows are outlier candidates.  When more than ``MAX_FRACTION`` of
the rows are flagged, the misfit is systematic and no row is treated as an outlier.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

CLUSTER_MIN = 3
MAX_FRACTION = 0.05
THRESHOLD = 4.0


@dataclass
class Cluster:
    """Flagged rows aligned with a pose variable.

    Attributes
    ----------
    rows : list of int
        The flagged rows.
    where : str
        The shared pose variable, e.g. ``A = -60 deg`` or ``consecutive rows 12-18``.
    pose_rows : list of int
        Every row with that pose variable (all rows at that angle, or the run).
    options : dict of str to float
        The pose as options of a ``pose_cluster`` effect (``axis``, ``deg`` or ``t_from_s``, ``t_to_s``).
    """

    rows: list[int]
    where: str
    pose_rows: list[int]
    options: dict[str, float]


def row_residuals(design: Callable[[np.ndarray], np.ndarray], w: np.ndarray, x: np.ndarray, data: np.ndarray,
                  rows: np.ndarray, chunk: int = 4000) -> np.ndarray:
    """Residuals of the model ``X·W·x`` on ``rows``, shape=(r, 3) [µm], evaluated in chunks."""
    beta = w @ x
    out = np.empty((rows.size, 3))
    for start in range(0, rows.size, chunk):
        r = rows[start: start + chunk]
        out[start: start + r.size] = data[r] - design(r) @ beta
    return out


def flag_rows(resid: np.ndarray, rows: np.ndarray, threshold: float = THRESHOLD) -> list[int]:
    """Rows whose residual norm is beyond the robust noise level (module docstring)."""
    if rows.size == 0:
        return []
    sigma = 1.4826 * float(np.median(np.abs(resid)))
    if sigma <= 0:
        return []
    from scipy.special import chdtri, ndtr

    limit = math.sqrt(chdtri(3, 2.0 - 2.0 * ndtr(threshold)))  # chi2.ppf(2Φ(t) − 1, 3)
    norms = np.sqrt((resid**2).sum(axis=1)) / sigma
    return [int(r) for r in rows[norms > limit]]


def split_clusters(flagged: list[int], angles_deg: np.ndarray, axes: tuple[str, ...], n_rows: int,
                   t_s: np.ndarray) -> tuple[list[int], list[Cluster]]:
    """Split flagged rows into isolated ones and clusters aligned with a pose variable.

    Parameters
    ----------
    flagged : list of int
    angles_deg : ndarray, shape=(n, k) [deg]
    axes : tuple of str
        Rotary axis names (column order).
    n_rows : int
        Rows in the measurement (the reference included).
    t_s : ndarray, shape=(n,) [s]
    """
    rows = np.array(sorted(flagged), dtype=int)
    in_cluster: set[int] = set()
    clusters: list[Cluster] = []
    for k, ax in enumerate(axes):
        vals = np.round(angles_deg[:, k], 6)
        for v in np.unique(vals[rows]) if rows.size else []:
            same = rows[vals[rows] == v]
            total = int((vals[1:] == v).sum())
            if same.size >= CLUSTER_MIN and same.size >= 0.5 * total and total < n_rows - 1:
                at = np.flatnonzero(vals == v)
                clusters.append(Cluster([int(r) for r in same], f"{ax} = {v:g} deg", [int(r) for r in at if r > 0],
                                        {"axis": float(k), "deg": float(v)}))
                in_cluster.update(int(r) for r in same)
    start = 0
    for i in range(1, rows.size + 1):
        if i == rows.size or rows[i] != rows[i - 1] + 1:
            run = rows[start:i]
            if run.size >= CLUSTER_MIN and not set(run.tolist()) <= in_cluster:
                members = [int(r) for r in run]
                clusters.append(Cluster(members, f"consecutive rows {run[0]}-{run[-1]}", members,
                                        {"t_from_s": float(t_s[run[0]]), "t_to_s": float(t_s[run[-1]])}))
                in_cluster.update(int(r) for r in run)
            start = i
    isolated = [int(r) for r in rows if int(r) not in in_cluster]
    if len(isolated) > MAX_FRACTION * max(n_rows - 1, 1) and len(isolated) > CLUSTER_MIN:
        return [], clusters
    return isolated, clusters
