"""Compensation: commands that put the tool where the nominal program intended.

For a programmed pose (rotary angles θ, workpiece point x_W, tool direction v_W
from the nominal kinematics) and identified parameters p:

1. **Orientation (first order).**  The actual tool direction relative to the
   workpiece is ``v + ω(θ)×v`` with ``ω = orientation_jacobian(θ)·p`` [µrad].  The
   rotary angles are corrected by Δθ solving ``(∂v/∂θ)·Δθ = −ω×v`` in least squares
   (∂v/∂θ by central differences of the nominal ``tool_direction``).
2. **Position (exact to the model).**  At the corrected angles θ', the linear axes
   are commanded to ``L_nom(θ', x_W) − d_raw(θ', x_W)`` where d_raw is the un-zeroed
   ball-minus-nest offset of the tool point ``(jacobian + R_w·reference_jacobian)·p``:
   the tool point lands on x_W up to second order in the errors.

Programs in machine coordinates (``TRAFOOF``) give X/Y/Z of the tool point (the ball
centre of an R-test program); the intended workpiece point is found by inverting the
nominal kinematics (``linear_commands`` is affine in the point).  With ``TRAORI`` the
program holds workpiece coordinates; the compensated program stays in workpiece
coordinates: the point is shifted by ``−R_wᵀ·d_raw`` and the angles by Δθ.

Accepted diagnosis extensions (``pige diagnose --json``): an angular positioning
error (``angular_error_<AXIS>``, ``e(θ) = c·cos hθ + s·sin hθ``) or a reversal error
(``backlash_<AXIS>``, ``e = (b/2)·approach``) means the axis stands at ``θ + e`` when
θ is commanded, exactly what a zero-position error ``E<axis>0<axis> = e`` means
(CONVENTIONS §3).  They are compensated as a pose-dependent zero-position error
added to the parameters of each pose (the direction of approach follows the
program's sequence of rotary positions).  The other extensions are listed as not
compensated, with the reason: ``thermal_drift`` depends on when the program runs;
``wobble``/``radial_runout`` and linear-axis ``squareness`` belong in the
controller's own error-motion and squareness tables; ``setup_offset`` is not a
machine error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.compensation.parameters import AngleExtension, CompensationParameters, pose_parameters
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import approach_directions


def _affine_parts(fn: Any) -> tuple[np.ndarray, list[np.ndarray]]:
    """``fn(point)``, affine in the point: its value at the origin and its three slopes."""
    base = np.asarray(fn(np.zeros(3)))
    return base, [np.asarray(fn(e)) - base for e in np.eye(3)]


def raw_offset(kern: Any, angles_deg: np.ndarray, points_mm: np.ndarray, params: np.ndarray,
               pivots: dict | None, tool: Any) -> np.ndarray:
    """Un-zeroed tool-point minus workpiece-point error per pose, shape=(n, 3) [µm].

    ``params`` is one vector (P,) or one per pose (n, P).  Vectorised without forming the
    (n, 3, P) Jacobian: the deviation is ``basis(angles) @ coefficients(point) @ params`` and the
    coefficients are affine in the point, so they are applied to the parameters first (four
    coefficient tensors), then to the per-pose basis and points.
    """
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    pts = np.atleast_2d(np.asarray(points_mm, dtype=float))
    n = a.shape[0]
    if n == 0:
        return np.zeros((0, 3))
    per_pose = np.broadcast_to(params, (n, np.shape(params)[-1]))
    g0, g_slopes = _affine_parts(lambda x: kern.coefficients(x, pivots, tool))  # (nb, 3, P)
    r0, r_slopes = _affine_parts(lambda x: kern.reference_jacobian(x, pivots, tool))  # (3, P)
    b = kern.basis(a)  # (n, nb)
    if (per_pose == per_pose[0]).all():  # one parameter vector: contract it first
        p = per_pose[0]
        moving = b @ (g0 @ p) + sum(pts[:, k, None] * (b @ (g_slopes[k] @ p)) for k in range(3))
        fixed = r0 @ p + sum(pts[:, k, None] * (r_slopes[k] @ p)[None, :] for k in range(3))
    else:
        coef = np.einsum("jip,np->nji", g0, per_pose) + sum(
            pts[:, k, None, None] * np.einsum("jip,np->nji", g_slopes[k], per_pose) for k in range(3))
        moving = np.einsum("nj,nji->ni", b, coef)
        fixed = per_pose @ r0.T + sum(pts[:, k, None] * (per_pose @ r_slopes[k].T) for k in range(3))
    fixed = np.broadcast_to(fixed, (n, 3))
    return np.asarray(moving + np.einsum("nij,nj->ni", kern.workpiece_rotation(a), fixed))


def motion_offset(kern: Any, angles_deg: np.ndarray, points_mm: np.ndarray, motions: np.ndarray,
                  pivots: dict | None, tool: Any) -> np.ndarray:
    """Un-zeroed tool-point minus workpiece-point error of each pose's error motions ``motions`` (n, 6k),
    a different workpiece point per pose, shape=(n, 3) [µm] (``motion_jacobian`` is affine in the point)."""
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    pts = np.atleast_2d(np.asarray(points_mm, dtype=float))
    base, slopes = _affine_parts(lambda x: np.einsum("nim,nm->ni", kern.motion_jacobian(a, x, pivots, tool), motions))
    return np.asarray(base + sum(pts[:, j, None] * slopes[j] for j in range(3)))


def _linear_affine(kern: Any, angles_deg: np.ndarray, pivots: dict | None, tool: Any) -> tuple[np.ndarray, np.ndarray]:
    """RTCP commands as ``base + cols @ point``: base (n, 3) [mm], cols (n, 3, 3)."""
    base, slopes = _affine_parts(lambda x: kern.linear_commands(angles_deg, x, pivots, tool))
    return base, np.stack(slopes, axis=2)


def linear_commands_at(kern: Any, angles_deg: np.ndarray, points_mm: np.ndarray, pivots: dict | None,
                       tool: Any) -> np.ndarray:
    """Nominal RTCP X, Y, Z for a different workpiece point per pose, shape=(n, 3) [mm]."""
    base, cols = _linear_affine(kern, angles_deg, pivots, tool)
    return np.asarray(base + np.einsum("nij,nj->ni", cols, points_mm))


def workpiece_points(kern: Any, angles_deg: np.ndarray, xyz_mm: np.ndarray, pivots: dict | None,
                     tool: Any) -> np.ndarray:
    """Invert the nominal kinematics: workpiece points whose RTCP commands are ``xyz_mm``, shape=(n, 3)."""
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    base, cols = _linear_affine(kern, a, pivots, tool)
    return np.asarray(np.linalg.solve(cols, (np.asarray(xyz_mm, dtype=float) - base)[..., None])[..., 0])


@dataclass
class CompensatedPoses:
    """Original and compensated commands.

    ``orientation_limited`` (n,) marks poses near the orientation pole where (part of) the
    orientation correction was left out because it would have turned an axis by more than
    the limit; their position is still corrected.
    """

    angles_deg: np.ndarray
    xyz_mm: np.ndarray
    points_mm: np.ndarray
    new_angles_deg: np.ndarray
    new_xyz_mm: np.ndarray
    rtcp: bool | np.ndarray
    orientation_limited: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


def svd_3x2(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD of a stack of 3×2 matrices in closed form, like ``np.linalg.svd(m, full_matrices=False)``.

    Parameters
    ----------
    m : ndarray, shape=(n, 3, 2)

    Returns
    -------
    u : (n, 3, 2), sigma : (n, 2) descending, vt : (n, 2, 2)
        ``m = u * sigma @ vt``.  The larger singular value comes from the 2×2 Gram matrix, the
        smaller from ``|m0 × m1| / sigma_1`` (no cancellation near rank 1), the second left vector
        from ``n × u_1`` with its sign fixed by ``m v_2`` (accurate however small sigma_2 is).  A
        singular value 0 gets a zero left vector.
    """
    m0, m1 = m[:, :, 0], m[:, :, 1]
    a, d, b = np.einsum("ni,ni->n", m0, m0), np.einsum("ni,ni->n", m1, m1), np.einsum("ni,ni->n", m0, m1)
    normal = np.cross(m0, m1)
    area = np.linalg.norm(normal, axis=1)
    s1 = np.sqrt((a + d) / 2 + np.hypot((a - d) / 2, b))
    s2 = np.divide(area, s1, out=np.zeros_like(s1), where=s1 > 0)
    lam = s1**2
    first, second = np.stack([b, lam - a], axis=1), np.stack([lam - d, b], axis=1)
    v1 = np.where((np.linalg.norm(first, axis=1) >= np.linalg.norm(second, axis=1))[:, None], first, second)
    norm = np.linalg.norm(v1, axis=1)
    v1 = np.where(norm[:, None] > 0, v1 / np.where(norm > 0, norm, 1.0)[:, None], np.array([1.0, 0.0]))
    v2 = np.stack([-v1[:, 1], v1[:, 0]], axis=1)
    u1 = np.divide(np.einsum("nik,nk->ni", m, v1), s1[:, None], out=np.zeros_like(m0), where=s1[:, None] > 0)
    unit = np.divide(normal, area[:, None], out=np.zeros_like(normal), where=area[:, None] > 0)
    u2 = np.cross(unit, u1)
    u2 *= np.where(np.einsum("ni,ni->n", np.einsum("nik,nk->ni", m, v2), u2) < 0, -1.0, 1.0)[:, None]
    return np.stack([u1, u2], axis=2), np.stack([s1, s2], axis=1), np.stack([v1, v2], axis=1)


def orientation_steps(kern: Any, angles_deg: np.ndarray, params: np.ndarray,
                      max_step_deg: float | None = None,
                      motions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rotary-angle corrections Δθ (n, k) [deg] that cancel the orientation error to first order.

    Solves ``(∂v/∂θ)·Δθ = −ω×v`` per pose by SVD, ω from the parameters of each pose and, when given, the
    error motions of each pose ``motions`` (n, 6k) (:meth:`~pige_sym.model.error_motions.ErrorMaps.pose_motions`).
    With ``max_step_deg``, a singular direction whose step would exceed it (near the orientation pole, where
    ∂v/∂C → 0) is dropped; the second result (n,) marks the poses where that happened.
    """
    a = np.atleast_2d(angles_deg)
    n, k = a.shape
    v = kern.tool_direction(a)
    omega = np.einsum("nip,np->ni", kern.orientation_jacobian(a), params) * 1e-6
    if motions is not None:
        omega = omega + np.einsum("nim,nm->ni", kern.motion_orientation_jacobian(a), motions) * 1e-6
    target = -np.cross(omega, v)
    h = 1e-4
    dv = np.stack([(kern.tool_direction(a + h * e) - kern.tool_direction(a - h * e)) / (2 * h) for e in np.eye(k)],
                  axis=2)  # (n, 3, k) per degree
    u, sig, vt = svd_3x2(dv) if k == 2 else np.linalg.svd(dv, full_matrices=False)  # (n,3,k) (n,k) (n,k,k)
    coef = np.einsum("nik,ni->nk", u, target)
    safe = sig > 1e-9 * np.maximum(sig[:, :1], 1e-300)
    comp = np.where(safe, coef / np.where(safe, sig, 1.0), 0.0)  # step along each right singular vector
    limited = np.zeros(n, dtype=bool)
    step = np.einsum("nk,nkj->nj", comp, vt)
    if max_step_deg is not None:
        # drop the largest singular components until no axis turns by more than the limit
        for _ in range(k):
            over = np.abs(step).max(axis=1) > max_step_deg
            if not over.any():
                break
            limited |= over
            biggest = np.argmax(np.abs(comp), axis=1)
            comp[over, biggest[over]] = 0.0
            step = np.einsum("nk,nkj->nj", comp, vt)
    return step, limited


def compensate_poses(machine: str, values: dict[str, float], angles_deg: np.ndarray, xyz_mm: np.ndarray, *,
                     rtcp: bool | np.ndarray = False, pivots_mm: dict | None = None, tool_mm: Any = None,
                     extensions: list[AngleExtension] | tuple[()] = (),
                     approach: np.ndarray | None = None, max_angle_step_deg: float | None = None,
                     keep_turn: bool = False, error_maps: Any = None) -> CompensatedPoses:
    """Compensated commands for programmed poses (module docstring).

    Parameters
    ----------
    angles_deg : (n, k) [deg]
    xyz_mm : (n, 3) [mm]
        Machine positions of the tool point (``rtcp`` False) or workpiece coordinates (``rtcp`` True).
    rtcp : bool or (n,) bool
        Per pose when an array.
    extensions : list of AngleExtension
        Accepted angular-positioning / reversal errors to compensate too.
    approach : (n, k) of {−1, 0, +1}, optional
        Directions of approach (default: from the poses in order); used by backlash.
    max_angle_step_deg : float, optional
        Orientation-pole guard: no rotary axis is turned by more than this to correct the orientation
        (:func:`orientation_steps`).
    keep_turn : bool
        Leave a rotary command that the correction would move across a multiple of 360° (NC programs).
    error_maps : ErrorMaps, optional
        The rotary axes' error maps (CONVENTIONS §10) to compensate too, at the programmed angles.
    """
    kern = load_kernels(machine)
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    n = a.shape[0]
    p = pose_parameters(kern, values, a, extensions, approach)
    motions = error_maps.pose_motions(kern, a, approach) if error_maps is not None and n else None
    xyz = np.atleast_2d(np.asarray(xyz_mm, dtype=float))
    flags = np.broadcast_to(np.asarray(rtcp, dtype=bool), (n,))
    pts = xyz.copy()
    if (~flags).any():
        pts[~flags] = workpiece_points(kern, a[~flags], xyz[~flags], pivots_mm, tool_mm)
    new_a = a.copy()
    limited = np.zeros(n, dtype=bool)
    if kern.HAS_DIRECTION_SOLVER and n:
        step, limited = orientation_steps(kern, a, p, max_angle_step_deg, motions)
        if keep_turn:
            # never move a rotary command across a multiple of 360 deg: on a roll-over axis that can
            # mean a full turn of the table; the orientation of such a pose is left (reported as limited)
            crossing = np.floor((a + step) / 360.0) != np.floor(a / 360.0)
            step = np.where(crossing, 0.0, step)
            limited |= crossing.any(axis=1)
        new_a = a + step
    d_raw = raw_offset(kern, new_a, pts, p, pivots_mm, tool_mm) * 1e-3  # mm
    if motions is not None:
        d_raw = d_raw + motion_offset(kern, new_a, pts, motions, pivots_mm, tool_mm) * 1e-3
    new_xyz = np.empty_like(pts)
    if flags.any():
        rot = kern.workpiece_rotation(new_a[flags])
        new_xyz[flags] = pts[flags] - np.einsum("nji,nj->ni", rot, d_raw[flags])
    if (~flags).any():
        nominal = linear_commands_at(kern, new_a[~flags], pts[~flags], pivots_mm, tool_mm)
        new_xyz[~flags] = nominal - d_raw[~flags]
    return CompensatedPoses(a, xyz, pts, new_a, new_xyz, rtcp, limited)


def predicted_errors(params: CompensationParameters, angles_deg: np.ndarray, xyz_mm: np.ndarray,
                     rtcp: np.ndarray, cmd_angles_deg: np.ndarray, cmd_xyz_mm: np.ndarray,
                     approach: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Predicted errors of commanded poses on the machine described by ``params``.

    Parameters
    ----------
    angles_deg, xyz_mm : (n, k), (n, 3) [deg, mm]
        The poses as programmed (they define the intended point and tool direction).
    rtcp : (n,) bool
        Workpiece coordinates (True) or machine coordinates.
    cmd_angles_deg, cmd_xyz_mm : (n, k), (n, 3)
        The poses as commanded (the same, or compensated).
    approach : (n, k), optional
        Directions of approach (default: of ``angles_deg`` in order).

    Returns
    -------
    tool_point_um : (n,) [µm]
        |tool point − intended point|.
    orientation_urad : (n,) [µrad]
        |actual − intended tool direction| (NaN without a direction solver).
    """
    kern = load_kernels(params.machine)
    pivots = {k: np.asarray(v, dtype=float) for k, v in params.pivots_mm.items()} or None
    a0, a1 = np.atleast_2d(angles_deg), np.atleast_2d(cmd_angles_deg)
    pts = np.array(xyz_mm, dtype=float)
    machine_xyz = np.array(cmd_xyz_mm, dtype=float)
    if (~rtcp).any():
        pts[~rtcp] = workpiece_points(kern, a0[~rtcp], pts[~rtcp], pivots, params.tool_mm)
    if rtcp.any():
        machine_xyz[rtcp] = linear_commands_at(kern, a1[rtcp], machine_xyz[rtcp], pivots, params.tool_mm)
    approach = approach_directions(a0) if approach is None else approach
    maps = getattr(params, "error_maps", None)
    err = tool_point_error(params.machine, params.values, a1, machine_xyz, pts, pivots_mm=pivots,
                           tool_mm=params.tool_mm, extensions=params.extensions, approach=approach, error_maps=maps)
    orient = np.full(a0.shape[0], np.nan)
    if kern.HAS_DIRECTION_SOLVER and a0.shape[0]:
        p = pose_parameters(kern, params.values, a1, params.extensions, approach)
        v1 = kern.tool_direction(a1)
        omega = np.einsum("nip,np->ni", kern.orientation_jacobian(a1), p) * 1e-6
        if maps is not None:
            omega = omega + np.einsum("nim,nm->ni", kern.motion_orientation_jacobian(a1),
                                      maps.pose_motions(kern, a1, approach)) * 1e-6
        orient = np.linalg.norm(v1 + np.cross(omega, v1) - kern.tool_direction(a0), axis=1) * 1e6
    return np.linalg.norm(err, axis=1), orient


def tool_point_error(machine: str, values: dict[str, float], angles_deg: np.ndarray, xyz_mm: np.ndarray,
                     points_mm: np.ndarray, *, pivots_mm: dict | None = None, tool_mm: Any = None,
                     extensions: list[AngleExtension] | tuple[()] = (),
                     approach: np.ndarray | None = None, error_maps: Any = None) -> np.ndarray:
    """Tool point minus intended workpiece point on a machine with errors ``values``, shape=(n, 3) [µm].

    ``extensions`` are angle errors the machine also has, ``error_maps`` its error motions (CONVENTIONS §10),
    both evaluated at the commanded angles (``approach`` defaults to the directions of approach of the poses
    in order).
    """
    kern = load_kernels(machine)
    p = pose_parameters(kern, values, angles_deg, extensions, approach)
    nominal = linear_commands_at(kern, np.atleast_2d(angles_deg), np.atleast_2d(points_mm), pivots_mm, tool_mm)
    out = (xyz_mm - nominal) * 1e3 + raw_offset(kern, angles_deg, points_mm, p, pivots_mm, tool_mm)
    if error_maps is not None and np.atleast_2d(angles_deg).shape[0]:
        motions = error_maps.pose_motions(kern, angles_deg, approach)
        out = out + motion_offset(kern, angles_deg, points_mm, motions, pivots_mm, tool_mm)
    return out
