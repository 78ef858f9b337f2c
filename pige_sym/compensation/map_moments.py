"""The error moments of a correction with maps: sparse, because each map value acts only near its grid angle.

:func:`~pige_sym.compensation.weighing.error_moments` forms ``M = Dᵀ D / n`` over the judged poses, D (3n, q) the
tool-point error per unit of each value.  A map value's column is its motion's column (the kernels'
``motion_jacobian`` at the pose's point) times its hat function (:meth:`~pige_sym.model.error_motions.MapGrid.hat`):
at any pose only two grid angles of each mapped axis act, so D holds, per row, the PIGEs' and effects' columns and
two values per map — whatever the grid's step.  D and M are built sparse (``scipy.sparse``): the cost follows the
poses and the values, where the dense (3n, q) matrix and its q² products made 800 map values cost a minute.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def map_design(params: Any, kern: Any, poses: Any, pivots: dict | None) -> tuple[list[str], Any]:
    """The map values' columns of D: their names (:meth:`~pige_sym.model.error_motions.ErrorMaps.values`) and the
    tool-point error per unit value (3n, V) as a ``scipy.sparse.csr_array`` [µm per µm or µrad], rows pose by pose
    (x, y, z)."""
    from scipy.sparse import csr_array

    a, pts = poses.angles_deg, poses.points_mm
    n = a.shape[0]
    names, weights, comps = params.error_maps.value_weights(kern, a, poses.approach)  # (n, V) sparse
    if not names or n == 0:
        return names, csr_array((3 * n, len(names)))
    base = kern.motion_jacobian(a, np.zeros(3), pivots, params.tool_mm)
    per_point = base + sum(pts[:, j, None, None] * (kern.motion_jacobian(a, e, pivots, params.tool_mm) - base)
                           for j, e in enumerate(np.eye(3)))  # (n, 3, 6k) the motion columns at each pose's point
    coo = weights.tocoo()
    pose, value = coo.row, coo.col
    data = per_point[pose, :, comps[value]] * coo.data[:, None]  # (nnz, 3)
    rows = (3 * pose[:, None] + np.arange(3)[None, :]).reshape(-1)
    cols = np.repeat(value, 3)
    from scipy.sparse import coo_array

    return names, coo_array((data.reshape(-1), (rows, cols)), shape=(3 * n, len(names))).tocsr()


def sparse_moments(dense_part: np.ndarray, dense_names: list[str], map_part: Any, map_names: list[str],
                   names: list[str], n: int) -> Any:
    """``M = Dᵀ D / n`` (q, q) as a ``scipy.sparse.csr_array`` in the order of ``names``: ``dense_part`` (3n, p) the
    columns of ``dense_names``, ``map_part`` (3n, V) those of ``map_names``."""
    from scipy.sparse import csr_array, hstack

    d = hstack([csr_array(dense_part), map_part], format="csr")
    order = {name: k for k, name in enumerate(dense_names + map_names)}
    d = d[:, [order[name] for name in names]]
    return csr_array((d.T @ d) / max(n, 1))
