"""What a map fit (:mod:`~pige_sym.identification.maps`) says about its PIGEs and how its values covary.

**The PIGEs given the maps.** The joint fit has many more unknowns than the PIGEs (the maps' values, the left-out
functions, the values the per-angle test holds); its own rank and condition count them all, and the held values
make it singular by design.  What a reader of ``rank`` and ``condition`` asks is how well the PIGEs and
zero-position errors are determined with the maps fitted beside them.  That is the Schur complement of the other
unknowns in the normal matrix, ``S = (Σ_pp / s²)⁻¹`` (the inverse of the PIGEs' block of the unit covariance; s² the
fit's variance factor), column-scaled as the fit scales its columns (by each PIGE column's norm over the whitened
rows of every file): its singular values give the condition and the observability indices of
:func:`~pige_sym.identification.spectrum.observability`, and ``rank`` counts the PIGEs and zero-position errors with
a value.  What the maps take of a PIGE column shows as a smaller singular value than the PIGE fit alone has.

**The covariance of PIGEs and map values** (:func:`value_covariance`): the reported values are linear in the fitted
unknowns — a PIGE is its column, a map value at grid angle g is ``q_g · z`` of its motion (§10 projection), φ± is
φ ± r/2 — so their covariance is ``T Σ Tᵀ`` over the fit's covariance Σ.  It is written to ``--json`` when it has at
most :data:`MAX_COVARIANCE_NAMES` rows (else the PIGEs' alone), named ``<axis>:<motion>@<angle>`` (``C:EXC@30``), so
``pige compensate`` weighs the correlations of PIGEs and maps.  Its diagonal is the square of the printed standard
errors exactly (the correlations are scaled by them, as :meth:`~pige_sym.identification.result.IdentificationResult.
covariance_dict` does).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pige_sym.identification.spectrum import observability

#: The most rows of the covariance written with the maps (a 30° AC map: 140 rows; a 15° one: 250).
MAX_COVARIANCE_NAMES = 400


def pige_statistics(joint: Any, blocks: list[Any], sigmas: list[float], fitted: int,
                    n_names: int) -> tuple[int, float, dict[str, float], np.ndarray]:
    """(rank, condition, observability, singular values) of the PIGEs and zero-position errors given the maps
    (module docstring); ``fitted``: the fit's first columns that are PIGEs or zero-position errors, ``n_names``:
    how many the machine has (the rank counts those with a value)."""
    r = joint.result
    det = [j for j in range(fitted) if math.isfinite(float(r.values[j]))]
    n_obs = int(r.n_obs)
    if not det:
        return 0, math.inf, observability(np.zeros(0), n_obs), np.zeros(0)
    cov_unit = np.asarray(r.covariance, dtype=float)[np.ix_(det, det)] / max(joint.variance_factor, 1e-300)
    schur = np.linalg.pinv(cov_unit, hermitian=True)
    norms = np.zeros(len(det))
    for b, s in zip(blocks, sigmas, strict=True):
        norms += np.sum((b.design[:, det] / s) ** 2, axis=0)
    scale = 1.0 / np.sqrt(np.where(norms > 0, norms, 1.0))
    w = np.linalg.eigvalsh(schur * np.outer(scale, scale))[::-1]
    svals = np.sqrt(np.clip(w, 0.0, None))
    cond = float(svals[0] / svals[-1]) if svals[-1] > 0 else math.inf
    rank = min(len(det), n_names)
    return rank, cond, observability(svals, n_obs), svals


def value_covariance(result: Any, layout: Any, groups: dict[str, Any], maps: dict[str, Any],
                     names: list[str], fitted: list[int]) -> tuple[list[str], np.ndarray] | None:
    """The covariance of every determined PIGE, zero-position error and map value (module docstring), or None with
    more than :data:`MAX_COVARIANCE_NAMES` of them."""
    cov = np.asarray(result.covariance, dtype=float)
    n = cov.shape[0]
    rows: list[np.ndarray] = []
    labels: list[str] = []
    stds: list[float] = []
    for k, j in enumerate(fitted):
        if math.isfinite(float(result.values[k])):
            rows.append(np.eye(n)[k])
            labels.append(names[j])
            stds.append(float(result.std[k]))
    for ax, grid in layout.grids.items():
        m = maps[ax]
        per_node: dict[str, dict[int, np.ndarray]] = {}
        for motion in layout.motions[ax]:
            gr = groups[motion.name]
            per_node[motion.name] = {}
            for r_i, g in enumerate(gr["nodes"]):
                if gr["columns"] and math.isfinite(float(m.value[motion.name][g])):
                    row = np.zeros(n)
                    row[gr["columns"]] = gr["q"][r_i]
                    per_node[motion.name][g] = row
        for name in m.value:
            if name.endswith(("+", "-")):
                mean, rev = per_node.get(name[:-1], {}), per_node.get(name[:-1] + ":reversal", {})
                sign = 0.5 if name.endswith("+") else -0.5
                nodes = {g: mean[g] + sign * rev[g] for g in mean if g in rev}
            else:
                nodes = per_node.get(name, {})
            for g, row in sorted(nodes.items()):
                if math.isfinite(float(m.value[name][g])) and math.isfinite(float(m.std[name][g])):
                    rows.append(row)
                    labels.append(f"{ax}:{name}@{grid.angles_deg[g]:g}")
                    stds.append(float(m.std[name][g]))
    if len(labels) > MAX_COVARIANCE_NAMES or not labels:
        return None
    t = np.array(rows)
    c = t @ np.nan_to_num(cov) @ t.T
    root = np.sqrt(np.clip(np.diag(c), 1e-300, None))
    corr = np.clip(0.5 * (c + c.T) / np.outer(root, root), -1.0, 1.0)
    np.fill_diagonal(corr, 1.0)
    sd = np.array(stds)
    return labels, corr * np.outer(sd, sd)
