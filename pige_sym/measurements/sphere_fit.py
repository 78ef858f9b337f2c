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
do not span three directions (``s_min/s_max`` of ``Gᵢ`` below :data:`MIN_SPREAD`), or whose contacts lie on
one plane, line or point, is *degenerate*: its centre is not determined.

Every step works on all poses at once (the contacts flat, ``starts`` marking where each pose begins; sums per
pose by ``np.add.reduceat``, 3×3 and 4×4 solves batched), so the cost is linear in the contacts with a small
constant: a 200,000-pose log fits in seconds (benchmarks/bench_scale.py).  :func:`fit_own_radius` fits each pose
with its own radius, for the import's screen of faulty contacts.
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
#: Smallest ratio of the point scatter's smallest to largest eigenvalue of a pose (flat: plane, line, point).
MIN_SCATTER = 1e-10

Points = list[np.ndarray] | tuple[np.ndarray, np.ndarray]


def flatten(points_mm: Points) -> tuple[np.ndarray, np.ndarray]:
    """Contacts of every pose as ``(points (N, 3), starts (n + 1,))``: pose ``i`` is ``points[starts[i]:starts[i+1]]``.

    A list of per-pose arrays is concatenated; a ``(points, starts)`` pair is returned as it is.
    """
    if isinstance(points_mm, tuple):
        pts, starts = points_mm
        return np.asarray(pts, dtype=float), np.asarray(starts, dtype=np.int64)
    arrays = [np.asarray(p, dtype=float).reshape(-1, 3) for p in points_mm]
    starts = np.zeros(len(arrays) + 1, dtype=np.int64)
    np.cumsum([len(a) for a in arrays], out=starts[1:])
    return (np.concatenate(arrays) if arrays else np.zeros((0, 3))), starts


def pose_of_contact(starts: np.ndarray) -> np.ndarray:
    """The pose index of every contact, shape=(N,)."""
    return np.repeat(np.arange(len(starts) - 1), np.diff(starts))


def pose_sums(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sum of ``values`` (N, ...) over the contacts of each pose, shape=(n, ...) (every pose has contacts)."""
    counts = np.diff(starts)
    if counts.size and (counts == counts[0]).all():  # the usual log: one pattern, a reshape instead of reduceat
        return values.reshape(counts.size, int(counts[0]), *values.shape[1:]).sum(axis=1)
    return np.add.reduceat(values, starts[:-1], axis=0)


def pose_grams(a: np.ndarray, b: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``Σ a_k b_kᵀ`` over the contacts of each pose, shape=(n, p, q) for ``a`` (N, p) and ``b`` (N, q)."""
    counts = np.diff(starts)
    if counts.size and (counts == counts[0]).all():
        n, m = counts.size, int(counts[0])
        return np.einsum("nki,nkj->nij", a.reshape(n, m, -1), b.reshape(n, m, -1))
    return np.add.reduceat(a[:, :, None] * b[:, None, :], starts[:-1], axis=0)


def inverse3(m: np.ndarray) -> np.ndarray:
    """Inverses of a stack of 3×3 matrices (n, 3, 3) by their adjugates (much faster than a batched LU for 3×3)."""
    a = m.reshape(-1, 3, 3)
    adj = np.empty_like(a)
    for i in range(3):
        for j in range(3):
            r0, r1 = [k for k in range(3) if k != j]
            c0, c1 = [k for k in range(3) if k != i]
            adj[:, i, j] = (-1) ** (i + j) * (a[:, r0, c0] * a[:, r1, c1] - a[:, r0, c1] * a[:, r1, c0])
    det = np.einsum("ni,ni->n", a[:, 0, :], adj[:, :, 0])
    return (adj / det[:, None, None]).reshape(m.shape)


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


def stylus_normals(normals: np.ndarray | list[np.ndarray], stylus_rotations: np.ndarray | None,
                   starts: np.ndarray | None = None) -> np.ndarray | list[np.ndarray]:
    """The contact normals of every pose in its stylus frame, ``R_tᵀ n`` (unchanged without rotations).

    Parameters
    ----------
    normals : ndarray, shape=(N, 3), with ``starts``; or list of ndarray, shape=(m_i, 3)
        Machine frame.
    stylus_rotations : ndarray, shape=(n, 3, 3), or None
        The nominal tool rotation of every pose (the stylus frame into M); None: the stylus does not turn.
    starts : ndarray, shape=(n + 1,), optional
        Where each pose's contacts begin in flat ``normals``.
    """
    if stylus_rotations is None:
        return normals
    if isinstance(normals, list):
        return [g @ r for g, r in zip(normals, stylus_rotations, strict=True)]
    assert starts is not None
    return np.einsum("nj,njk->nk", normals, stylus_rotations[pose_of_contact(starts)])


def contact_weights(normals: np.ndarray | list[np.ndarray], moves: str, stylus_rotations: np.ndarray | None = None,
                    starts: np.ndarray | None = None) -> np.ndarray | list[np.ndarray]:
    """``1/κ²`` of every contact of every pose (module docstring), moves read in the stylus frame."""
    local = stylus_normals(normals, stylus_rotations, starts)
    if isinstance(local, list):
        return [1.0 / move_cosines(g, moves) ** 2 for g in local]
    return 1.0 / move_cosines(local, moves) ** 2


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
    residual_flat_um : ndarray, shape=(N,)
        The contacts' radial residuals ``|x − c| − R_eff`` [µm], pose after pose.
    starts : ndarray, shape=(n + 1,)
        Where each pose's contacts begin.
    dof : int
    """

    centres_mm: np.ndarray
    covariance_um2: np.ndarray
    radius_mm: float
    radius_fitted: bool
    sigma_um: float
    residual_flat_um: np.ndarray
    starts: np.ndarray
    dof: int

    @property
    def residuals_um(self) -> list[np.ndarray]:
        """Per pose, the contacts' radial residuals [µm]."""
        return np.split(self.residual_flat_um, self.starts[1:-1])

    @property
    def pose_rms_um(self) -> np.ndarray:
        """Per pose, the RMS of its contacts' radial residuals, shape=(n,) [µm]."""
        return np.sqrt(pose_sums(self.residual_flat_um**2, self.starts) / np.diff(self.starts))


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
    pts = np.asarray(points_mm, dtype=float)
    centres, radii, _ = _algebraic(pts, np.array([0, len(pts)]))
    return centres[0], float(radii[0])


def _algebraic(pts: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pose's algebraic centre and radius, and its scatter ratio ``λ_min/λ_max`` (0: flat).

    With centred points ``x̃`` (Σ x̃ = 0) the normal equations of ``|x̃|² = 2c·x̃ + k`` split:
    ``c = S⁻¹ Σ x̃|x̃|² / 2`` with the scatter ``S = Σ x̃x̃ᵀ``, ``k = Σ|x̃|²/m``.
    """
    counts = np.diff(starts)
    pose = pose_of_contact(starts)
    mean = pose_sums(pts, starts) / counts[:, None]
    xc = pts - mean[pose]
    scatter = pose_grams(xc, xc, starts)
    lam = np.linalg.eigvalsh(scatter)
    ratio = np.where(lam[:, 2] > 0, lam[:, 0] / np.where(lam[:, 2] > 0, lam[:, 2], 1.0), 0.0)
    ok = ratio > MIN_SCATTER
    sq = (xc**2).sum(axis=1)
    rhs = pose_sums(xc * sq[:, None], starts) / 2.0
    safe = np.where(ok[:, None, None], scatter, np.eye(3))
    centre = np.linalg.solve(safe, rhs[:, :, None])[:, :, 0]
    k = pose_sums(sq, starts) / counts
    radius = np.sqrt(np.clip(k + (centre**2).sum(axis=1), 0.0, None))
    return centre + mean, radius, np.where(ok, ratio, 0.0)


def contact_spread(points_mm: np.ndarray, centre_mm: np.ndarray) -> float:
    """``s_min / s_max`` of the unit normals of a pose's contacts (0: the centre is not determined)."""
    pts = np.asarray(points_mm, dtype=float)
    return float(_spreads(pts, np.array([0, len(pts)]), np.asarray(centre_mm, dtype=float)[None, :])[0])


def _spreads(pts: np.ndarray, starts: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """``s_min / s_max`` of every pose's unit normals, shape=(n,) (0 where a contact sits on the centre)."""
    v = pts - centres[pose_of_contact(starts)]
    length = np.linalg.norm(v, axis=1)
    bad = pose_sums((~(length > 0)).astype(np.int64), starts) > 0
    g = v / np.where(length > 0, length, 1.0)[:, None]
    lam = np.clip(np.linalg.eigvalsh(pose_grams(g, g, starts)), 0.0, None)
    spread = np.sqrt(lam[:, 0] / np.where(lam[:, 2] > 0, lam[:, 2], 1.0))
    return np.where(bad | ~(lam[:, 2] > 0), 0.0, spread)


def _unit_normals(pts: np.ndarray, starts: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N, 3) of every contact from its pose's centre, and the distances (N,) [mm]."""
    v = pts - centres[pose_of_contact(starts)]
    dist = np.linalg.norm(v, axis=1)
    return v / dist[:, None], dist


def _check_poses(pts: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Algebraic centres and radii, or InputError naming the first pose without a determined centre."""
    counts = np.diff(starts)
    few = np.flatnonzero(counts < MIN_CONTACTS)
    if few.size:
        i = int(few[0])
        raise InputError(f"pose {i}: {counts[i]} contacts; a sphere centre needs at least {MIN_CONTACTS}")
    if not np.isfinite(pts).all():
        i = int(pose_of_contact(starts)[np.flatnonzero(~np.isfinite(pts).all(axis=1))[0]])
        raise InputError(f"pose {i}: a contact is not a finite point")
    centres, radii, scatter = _algebraic(pts, starts)
    spread = np.where(scatter > 0, _spreads(pts, starts, centres), 0.0)
    bad = np.flatnonzero(~(spread >= MIN_SPREAD))
    if bad.size:
        i = int(bad[0])
        what = ("its contacts lie on one plane, line or point" if scatter[i] == 0 else
                f"normals spread {spread[i]:.3f} < {MIN_SPREAD}: contacts must not lie on one circle or line")
        raise InputError(f"pose {i}: degenerate contact pattern ({what}); probe it from more directions")
    return centres, radii


def fit_centres(points_mm: Points, *, radius_mm: float | None = None, iterations: int = 20,
                moves: str = "normal", stylus_rotations: np.ndarray | None = None) -> SphereFit:
    """Fit every pose's centre (and one shared effective radius unless given).

    Parameters
    ----------
    points_mm : list of ndarray, each shape=(k_i, 3) [mm], or (points (N, 3), starts (n + 1,))
        Stylus-tip centres at contact, per pose, k_i ≥ 4 (:func:`flatten`).
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
    pts, starts = flatten(points_mm)
    centres, radii = _check_poses(pts, starts)
    fitted = radius_mm is None
    radius = float(np.median(radii)) if radius_mm is None else float(radius_mm)
    weights = np.asarray(contact_weights(_unit_normals(pts, starts, centres)[0], moves, stylus_rotations, starts))
    for _ in range(iterations):
        normals, dist = _unit_normals(pts, starts, centres)
        steps, d_r = linear_response(normals, weights, (dist - radius)[:, None], fitted, starts)
        centres = centres + steps[:, :, 0]
        radius += float(d_r[0])
        if max(float(np.abs(steps).max()), abs(float(d_r[0]))) < 1e-10:
            break
    return _finish(pts, starts, centres, radius, fitted, weights)


def linear_response(normals: np.ndarray | list[np.ndarray], weights: np.ndarray | list[np.ndarray],
                    radial: np.ndarray | list[np.ndarray], radius_fitted: bool,
                    starts: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares response of the centres (and the shared radius) to radial misfits.

    Solves ``min Σ w (ρ − n·δc_i − δR)²`` for all poses at once with the shared radius eliminated (Schur
    complement), O(N): the Gauss–Newton step of :func:`fit_centres` (``ρ`` its residuals) and the centres'
    response to any radial perturbation (:mod:`~pige_sym.measurements.probe_trigger`).

    Parameters
    ----------
    normals, weights : ndarray, shapes (N, 3) and (N,), with ``starts``; or lists of per-pose arrays
        The contacts' unit normals and weights.
    radial : ndarray, shape=(N, k), or list of ndarray, shape=(m_i, k)
        ``k`` radial misfits of each contact.
    radius_fitted : bool
        Whether the shared radius moves too (else ``δR = 0``).
    starts : ndarray, shape=(n + 1,), optional
        Where each pose begins in the flat arrays (not with lists).

    Returns
    -------
    centres : ndarray, shape=(n, 3, k)
    radius : ndarray, shape=(k,)
    """
    if isinstance(normals, list):
        g, starts = flatten(normals)
        w = np.concatenate(weights) if isinstance(weights, list) else np.asarray(weights)
        rho = np.concatenate(radial) if isinstance(radial, list) else np.asarray(radial)
    else:
        assert starts is not None
        g, w, rho = normals, np.asarray(weights), np.asarray(radial)
    gw = g * w[:, None]
    inv = inverse3(pose_grams(gw, g, starts))  # (n, 3, 3)
    h_cr = pose_sums(gw, starts)  # (n, 3)
    g_c = pose_grams(gw, rho, starts)  # (n, 3, k)
    inv_h = np.einsum("nij,nj->ni", inv, h_cr)
    d_r = np.zeros(rho.shape[1])
    if radius_fitted:
        h_rr = float(w.sum() - np.einsum("ni,ni->", h_cr, inv_h))
        g_r = w @ rho - np.einsum("ni,nik->k", inv_h, g_c)
        if h_rr > 0:
            d_r = g_r / h_rr
    return np.einsum("nij,njk->nik", inv, g_c - h_cr[:, :, None] * d_r[None, None, :]), d_r


def fit_own_radius(points_mm: Points, *, moves: str = "normal", stylus_rotations: np.ndarray | None = None,
                   iterations: int = 20, start: SphereFit | None = None) -> np.ndarray:
    """Radial residuals [µm] of every contact against the best sphere through its own pose's contacts (a radius
    per pose), shape=(N,); zero for poses of :data:`MIN_CONTACTS` contacts (no redundancy).

    The poses must be valid (:func:`fit_centres` checks them).  ``start``: the shared-radius fit of the same
    contacts, a start one or two Gauss–Newton steps from the answer (default: the algebraic solution).
    """
    pts, starts = flatten(points_mm)
    if start is None:
        centres, radii, _ = _algebraic(pts, starts)
    else:
        centres, radii = start.centres_mm.copy(), np.full(len(starts) - 1, start.radius_mm)
    weights = np.asarray(contact_weights(_unit_normals(pts, starts, centres)[0], moves, stylus_rotations, starts))
    pose = pose_of_contact(starts)
    for _ in range(iterations):
        normals, dist = _unit_normals(pts, starts, centres)
        rows = np.concatenate([normals, np.ones((len(pts), 1))], axis=1)  # d(ρ)/d(c, R) = −(n, 1)
        rw = rows * weights[:, None]
        step = np.linalg.solve(pose_grams(rw, rows, starts),
                               pose_sums(rw * (dist - radii[pose])[:, None], starts)[:, :, None])[:, :, 0]
        centres, radii = centres + step[:, :3], radii + step[:, 3]
        if float(np.abs(step).max()) < 1e-10:
            break
    _, dist = _unit_normals(pts, starts, centres)
    out = (dist - radii[pose]) * 1e3
    out[np.diff(starts)[pose] <= MIN_CONTACTS] = 0.0
    return out


def _finish(pts: np.ndarray, starts: np.ndarray, centres: np.ndarray, radius: float, fitted: bool,
            weights: np.ndarray) -> SphereFit:
    normals, dist = _unit_normals(pts, starts, centres)
    residuals = (dist - radius) * 1e3
    dof = len(pts) - 3 * (len(starts) - 1) - (1 if fitted else 0)
    rss = float((weights * residuals**2).sum())
    sigma = float(np.sqrt(rss / dof)) if dof > 0 else float("nan")
    gw = normals * weights[:, None]
    cov = inverse3(pose_grams(gw, normals, starts)) * (sigma**2 if dof > 0 else np.nan)
    return SphereFit(centres, cov, radius, fitted, sigma, residuals, starts, dof)
