"""How a direction-dependent trigger radius moves the fitted sphere centres (CONVENTIONS §7, docs/probe.md §5).

A touch probe trips after a pre-travel that depends on the probing direction: the three lobes of a
kinematic probe (``L_c·cos 3φ + L_s·sin 3φ`` for a horizontal move of azimuth φ, φ = 0 along +X) and a
different pre-travel for a vertical move (``V``).  A contact then lies at ``R_eff − pre`` from the centre
instead of ``R_eff``: a radial perturbation ``Δρ = −pre``.  The import's least-squares fit (every pose's
centre, one shared ``R_eff`` unless it is given) responds linearly; with the fit's Jacobian ``J`` (rows
``[n_kᵀ at pose i, 1]``, ``n_k`` the contact's unit normal) and its contact weights ``W``::

    [δc_1 … δc_n, δR] = (JᵀWJ)⁻¹ JᵀW Δρ

the fit's own Gauss–Newton solve (:func:`pige_sym.measurements.sphere_fit.linear_response`).
:func:`trigger_sensitivities` gives, per pose, the centre shift per µm of ``L_c``, ``L_s`` and ``V``:
shape ``(n, 3, 3)`` [µm/µm], the columns of the diagnosis' ``probe_trigger`` effect.  The move direction
is read from the contact: a normal within 18° of +Z is a vertical move onto the top, any other a
horizontal move towards the centre (azimuth of ``−n``), as pige's programs probe; a log of another
pattern gets sensitivities of that model.

With the same pattern at every pose the shift is one machine-frame vector and enters the deviation as
``(I − R_i)·v``, the pattern of axis-line offsets: the diagnosis then finds the effect undetermined.  On a
head machine the pattern and the lobes turn with the stylus (``stylus_rotations``): the shift is ``R_t,i·v``
in the machine frame and enters as ``(R_t,i − R_w,i)·v``, the pattern of a stylus offset (a ``tool`` error),
which the axis-line offsets of the head absorb in the same way.
Varying the pattern from pose to pose (``pige program --pattern alternate``) makes it visible.

File columns: ``trig_<p>_<x|y|z>`` for ``p`` in ``cos3``, ``sin3``, ``vert`` (9 columns, µm/µm).
"""

from __future__ import annotations

import numpy as np

from pige_sym.errors import FileFormatError
from pige_sym.measurements.measurement import Measurement, numeric_column
from pige_sym.measurements.sphere_fit import (
    Points,
    contact_weights,
    flatten,
    linear_response,
    pose_of_contact,
    stylus_normals,
    vertical_contacts,
)

PARTS = ("cos3", "sin3", "vert")
COLUMNS = tuple(f"trig_{p}_{a}" for p in PARTS for a in "xyz")


def _perturbations(normals: np.ndarray) -> np.ndarray:
    """Radial perturbation of each contact per unit ``L_c``, ``L_s``, ``V``: shape (m, 3) [µm/µm]."""
    vertical = vertical_contacts(normals)
    phi = np.arctan2(-normals[:, 1], -normals[:, 0])  # azimuth of the horizontal move towards the centre
    pre = np.column_stack([np.where(vertical, 0.0, np.cos(3 * phi)), np.where(vertical, 0.0, np.sin(3 * phi)),
                           vertical.astype(float)])
    return -pre


def trigger_sensitivities(points_mm: Points, centres_mm: np.ndarray, radius_fitted: bool,
                          moves: str = "normal", stylus_rotations: np.ndarray | None = None) -> np.ndarray:
    """Centre shift per unit lobing (cos, sin) and vertical pre-travel, shape=(n, 3, 3) [µm/µm].

    Parameters
    ----------
    points_mm : list of ndarray, shape=(m_i, 3) [mm], or (points (N, 3), starts (n + 1,))
        Each pose's contacts (stylus centres; :func:`~pige_sym.measurements.sphere_fit.flatten`).
    centres_mm : ndarray, shape=(n, 3) [mm]
        The fitted centres.
    radius_fitted : bool
        Whether the import fitted the shared effective radius (then it absorbs part of the pre-travel).
    moves : {"normal", "axes"}
        The fit's contact weights (:func:`~pige_sym.measurements.sphere_fit.fit_centres`).
    stylus_rotations : ndarray, shape=(n, 3, 3), optional
        Per pose, the stylus frame in the machine frame: on a head the lobes and the vertical pre-travel turn with
        the stylus (φ is measured about the stylus axis from the stylus frame's x, "vertical" is along its axis).

    Returns
    -------
    ndarray, shape=(n, 3, 3)
        ``[i, :, j]``: the shift of centre ``i`` per µm of part ``j`` (``cos3``, ``sin3``, ``vert``).
    """
    pts, starts = flatten(points_mm)
    v = pts - np.asarray(centres_mm)[pose_of_contact(starts)]
    normals = v / np.linalg.norm(v, axis=1, keepdims=True)
    weights = np.asarray(contact_weights(normals, moves, stylus_rotations, starts))
    local = np.asarray(stylus_normals(normals, stylus_rotations, starts))
    return linear_response(normals, weights, _perturbations(local), radius_fitted, starts)[0]


def sensitivity_columns(sens: np.ndarray) -> dict[str, np.ndarray]:
    """The file columns of :func:`trigger_sensitivities`, each shape=(n,) [µm/µm]."""
    return {f"trig_{p}_{a}": np.array(sens[:, i, j]) for j, p in enumerate(PARTS) for i, a in enumerate("xyz")}


def read_sensitivities(m: Measurement) -> np.ndarray | None:
    """The sensitivities stored in a measurement, shape=(n, 3, 3), or None when it has none.

    Raises
    ------
    FileFormatError
        Some of the columns only, or a value that is not a finite number.
    """
    columns = {c: numeric_column(m, c) for c in COLUMNS}
    present = [c for c, v in columns.items() if v is not None]
    if not present:
        return None
    if len(present) != len(COLUMNS):
        missing = ", ".join(c for c in COLUMNS if columns[c] is None)
        raise FileFormatError(m.path or "measurement", None, f"trigger sensitivity columns incomplete: add {missing} "
                              "(pige import-probe writes all nine) or remove them")
    out = np.zeros((m.n_rows, 3, 3))
    for j, p in enumerate(PARTS):
        for i, a in enumerate("xyz"):
            out[:, i, j] = columns[f"trig_{p}_{a}"]
    return out
