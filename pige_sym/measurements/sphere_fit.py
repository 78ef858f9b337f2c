"""Least-squares sphere centres from touch-probe contacts (CONVENTIONS §7).

Model: contact ``j`` of pose ``i`` (stylus-tip centre ``x_ij`` [mm]) lies at the effective radius
``R_eff`` from the pose's sphere centre ``c_i``: ``|x_ij − c_i| = R_eff + κ_ij·ε_ij`` with independent
contact errors ``ε`` of one standard deviation σ.  ``moves="normal"``: the probe moves along the surface
normal, ``κ = 1``.  ``moves="axes"`` (pige's programs): the probe's trigger scatter lies along its move,
a machine axis — vertical onto the top (a normal within 18° of +Z), horizontal towards the centre
otherwise — so the radial error is ``κ = |cos(move, normal)|`` times it (0.64 on a 50° ring) and each
contact is weighted by ``1/κ²``.  On a head machine the moves turn with the head: "vertical" is along the
stylus axis and "horizontal" across it, read in each pose's stylus frame (``stylus_rotations``).

:func:`fit_centres` solves every pose's centre and, unless it is given, one ``R_eff`` shared by all poses
(the same sphere and stylus: a radius per pose would leave a four-contact pose without redundancy),
by Gauss–Newton from the algebraic (linear) solution of each pose.  σ is pooled over all contacts
(``Σ(r/κ)² / (N − 3n − 1)``); the covariance of each centre is ``σ² (GᵢᵀWᵢGᵢ)⁻¹`` with ``Gᵢ`` the unit
normals of its contacts and ``Wᵢ = diag(1/κ²)``, the conditional covariance given ``R_eff`` (the radius
error moves every centre along the mean normal of its pattern; with the same pattern at every pose that
is nearly a common offset, which the identification's reference coupling absorbs).  A pose whose normals
do not span three directions (``s_min/s_max`` of ``Gᵢ`` below :data:`MIN_SPREAD`) is *degenerate*: its
centre is not determined.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pige_sym.errors import InputError

#: Smallest ratio of the smallest to the largest singular value of a pose's contact normals.
MIN_SPREAD = 0.1
MIN_CONTACTS = 4
VERTICAL_COS = float(np.cos(np.radians(18.0)))  # a normal within 18 deg of +Z: a vertical move onto the top
MOVES = ("axes", "normal")


def vertical_contacts(normals: np.ndarray) -> np.ndarray:
    """Which contacts were probed by a vertical move (pige's programs), shape=(m,) bool."""
    return np.asarray(normals[:, 2] > VERTICAL_COS)


def move_cosines(normals: np.ndarray, moves: str) -> np.ndarray:
    """``κ``: the radial share of an error along the probing move, shape=(m,) (module docstring).

    ``normals`` are in the stylus frame (the machine frame on a table machine; turned with the head on a
    head machine: :func:`stylus_normals`).
    """
    if moves == "normal":
        return np.ones(len(normals))
    if moves != "axes":
        raise InputError(f"moves {moves!r}: use {' or '.join(MOVES)}")
    horizontal = np.sqrt(normals[:, 0] ** 2 + normals[:, 1] ** 2)
    return np.where(vertical_contacts(normals), normals[:, 2], horizontal)


def stylus_normals(normals: list[np.ndarray], stylus_rotations: np.ndarray | None) -> list[np.ndarray]:
    """The contact normals of every pose in its stylus frame, ``R_tᵀ n`` (unchanged without rotations).

    Parameters
    ----------
    normals : list of ndarray, shape=(m_i, 3)
        Machine frame.
    stylus_rotations : ndarray, shape=(n, 3, 3), or None
        The nominal tool rotation of every pose (the stylus frame into M); None: the stylus does not turn.
    """
    if stylus_rotations is None:
        return normals
    return [g @ r for g, r in zip(normals, stylus_rotations, strict=True)]


def contact_weights(normals: list[np.ndarray], moves: str, stylus_rotations: np.ndarray | None = None
                    ) -> list[np.ndarray]:
    """``1/κ²`` of every contact of every pose (module docstring), moves read in the stylus frame."""
    return [1.0 / move_cosines(g, moves) ** 2 for g in stylus_normals(normals, stylus_rotations)]


@dataclass
class SphereFit:
    """Sphere centres of every pose.

    Attributes
    ----------
    centres_mm : ndarray, shape=(n, 3) [mm]
    covariance_um2 : ndarray, shape=(n, 3, 3) [µm²]
        Covariance of each centre (pooled σ, the pose's contact geometry).
    radius_mm : float
        Effective radius ``R + r − pre-travel`` (fitted, or as given).
    radius_fitted : bool
    sigma_um : float
        Pooled contact standard deviation [µm], along the probing move (``moves="axes"``) or the normal
        (NaN without redundancy).
    residuals_um : list of ndarray
        Per pose, the contacts' radial residuals ``|x − c| − R_eff`` [µm].
    dof : int
    """

    centres_mm: np.ndarray
    covariance_um2: np.ndarray
    radius_mm: float
    radius_fitted: bool
    sigma_um: float
    residuals_um: list[np.ndarray]
    dof: int


def algebraic_centre(points_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the sphere through ≥ 4 points, linear least squares on ``|x|² = 2c·x + k``.

    Parameters
    ----------
    points_mm : ndarray, shape=(k, 3) [mm]

    Returns
    -------
    centre_mm : ndarray, shape=(3,) [mm]
    radius_mm : float
    """
    x = np.asarray(points_mm, dtype=float)
    mean = x.mean(axis=0)
    xc = x - mean  # centred for conditioning
    a = np.column_stack([2 * xc, np.ones(len(xc))])
    sol, *_ = np.linalg.lstsq(a, (xc**2).sum(axis=1), rcond=None)
    centre = sol[:3]
    return centre + mean, float(np.sqrt(max(sol[3] + centre @ centre, 0.0)))


def contact_spread(points_mm: np.ndarray, centre_mm: np.ndarray) -> float:
    """``s_min / s_max`` of the unit normals of a pose's contacts (0: the centre is not determined)."""
    n = np.asarray(points_mm, dtype=float) - centre_mm
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    s = np.linalg.svd(n, compute_uv=False)
    return float(s[-1] / s[0]) if s.size == 3 and s[0] > 0 else 0.0


def _normals(points: list[np.ndarray], centres: np.ndarray) -> list[np.ndarray]:
    out = []
    for x, c in zip(points, centres, strict=True):
        v = x - c
        out.append(v / np.linalg.norm(v, axis=1, keepdims=True))
    return out


def fit_centres(points_mm: list[np.ndarray], *, radius_mm: float | None = None, iterations: int = 20,
                moves: str = "normal", stylus_rotations: np.ndarray | None = None) -> SphereFit:
    """Fit every pose's centre (and one shared effective radius unless given).

    Parameters
    ----------
    points_mm : list of ndarray, each shape=(k_i, 3) [mm]
        Stylus-tip centres at contact, per pose, k_i ≥ 4.
    radius_mm : float, optional
        The effective radius when known (calibrated on a ring or sphere); fitted otherwise.
    iterations : int
        Gauss–Newton iterations at most (converges in 2–3 from the algebraic start).
    moves : {"normal", "axes"}
        Direction of the probing moves, which sets each contact's weight (module docstring).
    stylus_rotations : ndarray, shape=(n, 3, 3), optional
        Per pose, the stylus frame in the machine frame (a head turns it): ``moves="axes"`` then means along
        the stylus axis onto its pole and across it elsewhere.  Default: the machine frame.

    Returns
    -------
    SphereFit

    Raises
    ------
    InputError
        A pose with fewer than four contacts or a degenerate contact pattern (its index in the message).
    """
    pts = [np.asarray(p, dtype=float) for p in points_mm]
    for i, p in enumerate(pts):
        if p.ndim != 2 or p.shape[0] < MIN_CONTACTS or p.shape[1] != 3:
            raise InputError(f"pose {i}: {p.shape[0] if p.ndim == 2 else 0} contacts; a sphere centre needs at "
                             f"least {MIN_CONTACTS}")
    starts = [algebraic_centre(p) for p in pts]
    centres = np.array([c for c, _ in starts])
    for i, p in enumerate(pts):
        spread = contact_spread(p, centres[i])
        if spread < MIN_SPREAD:
            raise InputError(f"pose {i}: degenerate contact pattern (normals spread {spread:.3f} < {MIN_SPREAD}: "
                             "contacts must not lie on one circle or line); probe it from more directions")
    fitted = radius_mm is None
    radius = float(np.median([r for _, r in starts])) if radius_mm is None else float(radius_mm)
    weights = contact_weights(_normals(pts, centres), moves, stylus_rotations)
    for _ in range(iterations):
        centres, radius, step = _gauss_newton_step(pts, centres, radius, fitted, weights)
        if step < 1e-10:
            break
    return _finish(pts, centres, radius, fitted, weights)


def linear_response(normals: list[np.ndarray], weights: list[np.ndarray], radial: list[np.ndarray],
                    radius_fitted: bool) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares response of the centres (and the shared radius) to radial misfits.

    Solves ``min Σ w (ρ − n·δc_i − δR)²`` pose by pose with the shared radius eliminated (Schur complement),
    O(n): the Gauss–Newton step of :func:`fit_centres` (``ρ`` its residuals) and the centres' response to
    any radial perturbation (:mod:`~pige_sym.measurements.probe_trigger`).

    Parameters
    ----------
    normals, weights : list of ndarray, shapes (m_i, 3) and (m_i,)
        Per pose, the contacts' unit normals and weights.
    radial : list of ndarray, shape=(m_i, k)
        Per pose, ``k`` radial misfits of each contact.
    radius_fitted : bool
        Whether the shared radius moves too (else ``δR = 0``).

    Returns
    -------
    centres : ndarray, shape=(n, 3, k)
    radius : ndarray, shape=(k,)
    """
    blocks = []
    h_rr, g_r = 0.0, np.zeros(radial[0].shape[1])
    for g, w, rho in zip(normals, weights, radial, strict=True):
        gw = g * w[:, None]
        inv = np.linalg.inv(gw.T @ g)
        h_cr, g_c = gw.sum(axis=0), gw.T @ rho
        blocks.append((inv, h_cr, g_c))
        if radius_fitted:
            h_rr += w.sum() - h_cr @ inv @ h_cr
            g_r = g_r + w @ rho - h_cr @ inv @ g_c
    d_r = g_r / h_rr if radius_fitted and h_rr > 0 else np.zeros_like(g_r)
    return np.array([inv @ (g_c - np.outer(h_cr, d_r)) for inv, h_cr, g_c in blocks]), d_r


def _gauss_newton_step(pts: list[np.ndarray], centres: np.ndarray, radius: float, fitted: bool,
                       weights: list[np.ndarray]) -> tuple[np.ndarray, float, float]:
    """One weighted Gauss–Newton step (:func:`linear_response` of the residuals ``|x − c| − R``)."""
    residuals = [(np.linalg.norm(x - c, axis=1) - radius)[:, None] for x, c in zip(pts, centres, strict=True)]
    steps, d_r = linear_response(_normals(pts, centres), weights, residuals, fitted)
    new = centres + steps[:, :, 0]
    step = max(float(np.abs(steps).max()), abs(float(d_r[0])))
    return new, radius + float(d_r[0]), step


def _finish(pts: list[np.ndarray], centres: np.ndarray, radius: float, fitted: bool,
            weights: list[np.ndarray]) -> SphereFit:
    normals = _normals(pts, centres)
    residuals = [(np.linalg.norm(x - c, axis=1) - radius) * 1e3 for x, c in zip(pts, centres, strict=True)]
    n_contacts = sum(len(r) for r in residuals)
    dof = n_contacts - 3 * len(pts) - (1 if fitted else 0)
    rss = float(sum((w * r**2).sum() for r, w in zip(residuals, weights, strict=True)))
    sigma = float(np.sqrt(rss / dof)) if dof > 0 else float("nan")
    cov = np.array([np.linalg.inv((g * w[:, None]).T @ g) for g, w in zip(normals, weights, strict=True)]) * (
        sigma**2 if dof > 0 else np.nan)
    return SphereFit(centres, cov, radius, fitted, sigma, residuals, dof)
