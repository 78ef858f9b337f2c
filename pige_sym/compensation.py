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

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.constants import CONTROLLER_STYLES as CONTROLLER_STYLES
from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.effects import EffectSpec
from pige_sym.errors import CompensationError as CompensationError
from pige_sym.errors import FileFormatError, InputError
from pige_sym.kernels import load_kernels
from pige_sym.trajectories import approach_directions

COMPENSABLE_KINDS = ("angular_error", "backlash")
NOT_COMPENSATED_WHY = {
    "thermal_drift": "time-dependent (depends on when the program runs)",
    "wobble": "an error motion: enter it in the controller's rotary-axis error tables",
    "radial_runout": "an error motion: enter it in the controller's rotary-axis error tables",
    "squareness": "a linear-axis error: enter it in the controller's squareness compensation",
    "setup_offset": "a set-up error of the test, not of the machine",
}


@dataclass
class AngleExtension:
    """An accepted extension acting as a pose-dependent zero-position error of a rotary axis.

    Attributes
    ----------
    spec : EffectSpec
        ``angular_error_<AXIS>`` or ``backlash_<AXIS>`` with its options (harmonic).
    params : dict of str to float
        Fitted values [µrad] by parameter name (``cos_urad``, ``sin_urad`` or ``b_urad``).
    """

    spec: EffectSpec
    params: dict[str, float]

    def zero_error_urad(self, angles_deg: np.ndarray, rotary_axes: tuple[str, ...],
                        approach: np.ndarray) -> np.ndarray:
        """Angle error of the axis at each pose, shape=(n,) [µrad].

        Parameters
        ----------
        angles_deg : shape=(n, k) [deg]
        rotary_axes : names of the columns of ``angles_deg``
        approach : shape=(n, k) of {−1, 0, +1}
            Direction of approach of each axis (:func:`~pige_sym.trajectories.approach_directions`).
        """
        k = rotary_axes.index(self.spec.axis)
        if self.spec.kind == "angular_error":
            h = self.spec.harmonic
            theta = np.radians(angles_deg[:, k])
            return self.params["cos_urad"] * np.cos(h * theta) + self.params["sin_urad"] * np.sin(h * theta)
        return 0.5 * self.params["b_urad"] * approach[:, k]


@dataclass
class CompensationParameters:
    """Parameters read from an identify/diagnose JSON result.

    Attributes
    ----------
    machine : str
    values : dict of str to float
        PIGEs and zero-position errors [µm, µrad].
    units : dict of str to str
    tool_mm : list of float or None
    pivots_mm : dict of str to list of float
    source : str
        Where the values come from (file name).
    ignored : list of str
        Names (and reasons) of what is not compensated.
    extensions : list of AngleExtension
        Accepted extensions that are compensated (module docstring).
    """

    machine: str
    values: dict[str, float]
    units: dict[str, str]
    tool_mm: list[float] | None
    pivots_mm: dict[str, list[float]]
    source: str
    ignored: list[str]
    extensions: list[AngleExtension] = field(default_factory=list)


def load_parameters(path: str | os.PathLike[str], machine: str | None = None, *,
                    allow_missing: bool = False) -> CompensationParameters:
    """Read ``pige identify --json`` / ``pige diagnose --json`` output, validated by :mod:`pige_sym.schema`.

    A PIGE without a value (not identifiable, or missing) is refused unless ``allow_missing``;
    then it is set to 0 and named in ``ignored``.  ``machine`` (``--machine`` or the program's
    header) must agree with the file's machine.
    """
    from pige_sym.schema import read_params_file

    doc = read_params_file(path, machine=machine, allow_missing=allow_missing)
    kern = load_kernels(doc.machine)
    ignored = [f"{k} (no value in the file: set to 0 by --allow-missing)" for k in doc.set_to_zero]
    extensions, skipped = _extensions({"findings": doc.findings}, doc.path, tuple(kern.ROTARY_AXES))
    ignored += [f"{effect} ({why})" for effect, why in skipped.items()]
    described = {e.spec.id for e in extensions} | set(skipped)
    ignored += [f"{name} (no finding describes it)" for name in doc.effect_values
                if name.split(".", 1)[0] not in described]
    tool = None if doc.tool_mm is None else list(doc.tool_mm)
    pivots = {a: list(v) for a, v in doc.pivots_mm.items()}
    return CompensationParameters(kern.MACHINE_CODE, dict(doc.pige), dict(doc.units), tool, pivots, doc.path,
                                  ignored, extensions)


_HEADER_MACHINE = re.compile(r"machine\s*[:=]\s*(\S+)", re.IGNORECASE)
_GENERATED_TITLE = re.compile(r",\s*(\S+\(\w+\)\w*),\s*ball\b")


def program_machine(text: str) -> str | None:
    """The machine an NC program's leading comments name (``machine: CODE``, or a ``pige program`` title)."""
    head = text.lstrip("\ufeff").splitlines()[:8]
    comments = [ln for ln in head if ln.lstrip().startswith((";", "("))]
    for line in comments:
        m = _HEADER_MACHINE.search(line)
        if m:
            return m.group(1).rstrip(")")
    if any("generated by pige_sym" in ln for ln in comments):
        for line in comments:
            m = _GENERATED_TITLE.search(line)
            if m:
                return m.group(1)
    return None


def _extensions(data: dict[str, Any], path: str,
                rotary_axes: tuple[str, ...]) -> tuple[list[AngleExtension], dict[str, str]]:
    """Compensable accepted findings of a ``pige diagnose --json`` result, and the others with the reason."""
    findings = data.get("findings", [])
    if not isinstance(findings, list):
        raise FileFormatError(path, None, '"findings" must be a list')
    for f in findings:
        if not isinstance(f, dict) or not isinstance(f.get("effect"), str) or not isinstance(f.get("params"), dict):
            raise FileFormatError(path, None, 'each finding needs "effect" and "params"')
    try:
        return angle_extensions(findings, rotary_axes)
    except InputError as exc:
        raise FileFormatError(path, None, str(exc)) from None


def angle_extensions(records: Any, rotary_axes: tuple[str, ...]) -> tuple[list[AngleExtension], dict[str, str]]:
    """Split effect records into compensable angle extensions and the rest (with the reason).

    Parameters
    ----------
    records : iterable of dict
        Either findings (``{"effect", "options", "params"}``, as ``pige diagnose --json``
        prints them) or flat simulator records (``{"effect": id, option: value, param:
        value}``, as in a ``*.truth.json`` sidecar).
    rotary_axes : tuple of str

    Returns
    -------
    extensions : list of AngleExtension
    not_compensated : dict of str to str
        Every other effect id with the reason it is not compensated.

    Raises
    ------
    InputError
        A record names an axis the machine does not have or lacks a parameter.
    """
    from pige_sym.effects import OPTION_KEYS

    out: list[AngleExtension] = []
    skipped: dict[str, str] = {}
    for rec in records:
        if "params" in rec:
            options, values = dict(rec.get("options") or {}), dict(rec["params"])
        else:
            options = {k: v for k, v in rec.items() if k in OPTION_KEYS}
            values = {k: v for k, v in rec.items() if k != "effect" and k not in OPTION_KEYS}
        spec = EffectSpec(str(rec["effect"]), options)
        if spec.kind not in COMPENSABLE_KINDS:
            skipped[spec.id] = NOT_COMPENSATED_WHY.get(spec.kind, "not compensable")
            continue
        if spec.axis not in rotary_axes:
            raise InputError(f"effect {spec.id}: {spec.axis} is not a rotary axis of the machine")
        params = {}
        for name in spec.param_names:
            v = values.get(name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise InputError(f"effect {spec.id}: {name} must be a finite number")
            params[name] = float(v)
        out.append(AngleExtension(spec, params))
    return out, skipped


def pose_parameters(kern: Any, values: dict[str, float], angles_deg: np.ndarray,
                    extensions: list[AngleExtension] | tuple[()] = (),
                    approach: np.ndarray | None = None) -> np.ndarray:
    """Parameter vector of every pose, shape=(n, P) [µm, µrad]: the values plus the extensions' zero errors.

    ``approach`` (n, k) defaults to the directions of approach of the poses in order.
    """
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    out = np.tile(_param_vector(kern, values), (a.shape[0], 1))
    if extensions:
        appr = approach_directions(a) if approach is None else np.atleast_2d(approach)
        axes = tuple(kern.ROTARY_AXES)
        for ext in extensions:
            ax = ext.spec.axis
            out[:, kern.PARAMETERS.index(f"E{ax[0]}0{ax}")] += ext.zero_error_urad(a, axes, appr)
    return out


def _param_vector(kern: Any, values: dict[str, float]) -> np.ndarray:
    return np.array([values.get(n, 0.0) for n in kern.PARAMETERS])


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
                      max_step_deg: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rotary-angle corrections Δθ (n, k) [deg] that cancel the orientation error to first order.

    Solves ``(∂v/∂θ)·Δθ = −ω×v`` per pose by SVD.  With ``max_step_deg``, a singular
    direction whose step would exceed it (near the orientation pole, where ∂v/∂C → 0) is
    dropped; the second result (n,) marks the poses where that happened.
    """
    a = np.atleast_2d(angles_deg)
    n, k = a.shape
    v = kern.tool_direction(a)
    omega = np.einsum("nip,np->ni", kern.orientation_jacobian(a), params) * 1e-6
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
                     keep_turn: bool = False) -> CompensatedPoses:
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
    """
    kern = load_kernels(machine)
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    n = a.shape[0]
    p = pose_parameters(kern, values, a, extensions, approach)
    xyz = np.atleast_2d(np.asarray(xyz_mm, dtype=float))
    flags = np.broadcast_to(np.asarray(rtcp, dtype=bool), (n,))
    pts = xyz.copy()
    if (~flags).any():
        pts[~flags] = workpiece_points(kern, a[~flags], xyz[~flags], pivots_mm, tool_mm)
    new_a = a.copy()
    limited = np.zeros(n, dtype=bool)
    if kern.HAS_DIRECTION_SOLVER and n:
        step, limited = orientation_steps(kern, a, p, max_angle_step_deg)
        if keep_turn:
            # never move a rotary command across a multiple of 360 deg: on a roll-over axis that can
            # mean a full turn of the table; the orientation of such a pose is left (reported as limited)
            crossing = np.floor((a + step) / 360.0) != np.floor(a / 360.0)
            step = np.where(crossing, 0.0, step)
            limited |= crossing.any(axis=1)
        new_a = a + step
    d_raw = raw_offset(kern, new_a, pts, p, pivots_mm, tool_mm) * 1e-3  # mm
    new_xyz = np.empty_like(pts)
    if flags.any():
        rot = kern.workpiece_rotation(new_a[flags])
        new_xyz[flags] = pts[flags] - np.einsum("nji,nj->ni", rot, d_raw[flags])
    if (~flags).any():
        nominal = linear_commands_at(kern, new_a[~flags], pts[~flags], pivots_mm, tool_mm)
        new_xyz[~flags] = nominal - d_raw[~flags]
    return CompensatedPoses(a, xyz, pts, new_a, new_xyz, rtcp, limited)


def compensate_program(program_text: str, params: CompensationParameters, *, path: str = "<program>",
                       dialect: str | None = None, pass_through: bool = False, **guards: Any) -> str:
    """Compensated program text, in the program's own dialect (:mod:`pige_sym.nc.compensate`).

    ``guards``: ``max_change_mm``, ``max_change_deg``, ``rtcp_on``, ``rtcp_off``, ``header``.
    """
    from pige_sym.nc.compensate import compensate_nc

    return compensate_nc(program_text, params, path=path, dialect=dialect, pass_through=pass_through,
                         **guards).text


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
    err = tool_point_error(params.machine, params.values, a1, machine_xyz, pts, pivots_mm=pivots,
                           tool_mm=params.tool_mm, extensions=params.extensions, approach=approach)
    orient = np.full(a0.shape[0], np.nan)
    if kern.HAS_DIRECTION_SOLVER and a0.shape[0]:
        p = pose_parameters(kern, params.values, a1, params.extensions, approach)
        v1 = kern.tool_direction(a1)
        omega = np.einsum("nip,np->ni", kern.orientation_jacobian(a1), p) * 1e-6
        orient = np.linalg.norm(v1 + np.cross(omega, v1) - kern.tool_direction(a0), axis=1) * 1e6
    return np.linalg.norm(err, axis=1), orient


def controller_corrections(params: CompensationParameters) -> list[dict[str, Any]]:
    """Corrected axis lines: per rotary axis the pivot point [mm] and unit direction, machine frame."""
    kern = load_kernels(params.machine)
    out = []
    pos_idx = {"A": (1, 2), "B": (0, 2), "C": (0, 1)}
    for ax in kern.ROTARY_AXES:
        names = [n for n in kern.LOCATION_PARAMETERS if n.endswith("0" + ax)]
        vals = [params.values.get(n, 0.0) for n in names]
        d = "ABC".index(ax[0])
        u = np.eye(3)[d]
        pivot = np.asarray(params.pivots_mm.get(ax, [0.0, 0.0, 0.0]), dtype=float).copy()
        i1, i2 = pos_idx[ax[0]]
        pivot[i1] += vals[0] * 1e-3
        pivot[i2] += vals[1] * 1e-3
        eps = np.zeros(3)
        eps[i1], eps[i2] = vals[2] * 1e-6, vals[3] * 1e-6
        direction = u + np.cross(eps, u)
        direction /= np.linalg.norm(direction)
        zero = params.values.get(f"E{ax[0]}0{ax}", 0.0)
        side = "workpiece" if ax in kern.WORKPIECE_ROTARY else "tool"
        nominal = np.asarray(params.pivots_mm.get(ax, [0.0, 0.0, 0.0]), dtype=float)
        out.append({"axis": ax, "side": side, "pivot_mm": pivot.tolist(), "direction": direction.tolist(),
                    "zero_offset_deg": float(np.degrees(zero * 1e-6)),
                    "pivot_delta_mm": (pivot - nominal).tolist(), "direction_delta": (direction - u).tolist()})
    return out


NOT_VERIFIED = "NOT verified on a controller: check every value against the machine's documentation"


def format_controller(params: CompensationParameters, style: str = "table", *, carrier: int = 1) -> str:
    """The corrections as deltas to the machine's current kinematic description.

    Styles (units, signs and mappings in docs/controller-corrections.md): ``table`` (corrected
    axis lines, machine frame), ``siemens`` (``$TC_CARR`` *fine offsets* of swivel data record
    ``carrier``), ``heidenhain`` (kinematics-table deltas), ``fanuc`` (rotation-axis centre and
    direction deltas), ``linuxcnc`` (``trtkins`` rot-point / offset deltas).
    """
    rows = controller_corrections(params)
    if style == "table":
        lines = [f"corrected kinematic chain of {params.machine} (machine frame, reference pose)",
                 f"{'axis':<5}{'side':<11}{'pivot x,y,z [mm]':<36}{'direction':<40}zero [deg]"]
        for r in rows:
            piv = ", ".join(f"{x:.6f}" for x in r["pivot_mm"])
            dirs = ", ".join(f"{x:.9f}" for x in r["direction"])
            lines.append(f"{r['axis']:<5}{r['side']:<11}{piv:<36}{dirs:<40}{r['zero_offset_deg']:.7f}")
        return "\n".join(lines)
    if style not in CONTROLLER_STYLES:
        raise InputError(f"unknown controller style {style!r}: use {', '.join(CONTROLLER_STYLES)}")
    if not isinstance(carrier, int) or carrier < 1:
        raise InputError("--carrier must be a positive integer")
    kern = load_kernels(params.machine)
    chain = [a.name for a in reversed(kern_axes(params.machine, "workpiece"))] + kern_axes_names(params.machine)
    by = {r["axis"]: r for r in rows}
    first, second = by[chain[0]], by[chain[1]]
    head = [f"corrections for {kern.MACHINE_CODE} as DELTAS to the current kinematic description "
            f"(axis 1 = {chain[0]}, axis 2 = {chain[1]}); parameters from {params.source}", NOT_VERIFIED]
    body = {"siemens": _siemens_fine, "heidenhain": _heidenhain, "fanuc": _fanuc,
            "linuxcnc": _linuxcnc}[style](first, second, carrier)
    orient = [f"{r['axis']}: direction change ({', '.join(f'{x:+.9f}' for x in r['direction_delta'])})"
              for r in (first, second) if np.abs(r["direction_delta"]).max() > 0]
    comment = "; " if style == "siemens" else "# " if style == "linuxcnc" else ""
    if orient:
        body.append(comment + "axis-direction changes (not expressible as offsets; enter only where the controller "
                    "has an axis-direction entry): " + "; ".join(orient))
    return "\n".join([comment + h for h in head] + body)


def _siemens_fine(first: dict, second: dict, carrier: int) -> list[str]:
    d1, d2 = np.array(first["pivot_delta_mm"]), np.array(second["pivot_delta_mm"])
    vec = {44: d1, 55: d2 - d1, 58: -d2}  # fine offsets of l2 ($TC_CARR4..6), l3 (15..17), l4 (18..20)
    out = []
    for start, v in sorted(vec.items()):
        out += [f"$TC_CARR{start + k}[{carrier}]=$TC_CARR{start + k}[{carrier}]{_signed(v[k], 6)}" for k in range(3)]
    out.append(f"$TC_CARR64[{carrier}]=$TC_CARR64[{carrier}]{_signed(first['zero_offset_deg'], 7)}")
    out.append(f"$TC_CARR65[{carrier}]=$TC_CARR65[{carrier}]{_signed(second['zero_offset_deg'], 7)}")
    return out


def _signed(value: float, decimals: int) -> str:
    """``+0.012000`` / ``-0.009000`` (no ``-0.000000``)."""
    return f"{round(float(value), decimals) + 0.0:+.{decimals}f}"


def _heidenhain(first: dict, second: dict, carrier: int) -> list[str]:
    out = ["kinematics table: add to the transformation that places each rotary axis (mm, deg)"]
    for r in (first, second):
        d = r["pivot_delta_mm"]
        out.append(f"  {r['axis']}: X {d[0]:+.6f}  Y {d[1]:+.6f}  Z {d[2]:+.6f} mm   "
                   f"zero (axis datum) {r['zero_offset_deg']:+.7f} deg")
    return out


def _fanuc(first: dict, second: dict, carrier: int) -> list[str]:
    out = ["tool centre point parameters: add to the rotation-axis centre / offset entries (mm, deg)"]
    for r in (first, second):
        d = r["pivot_delta_mm"]
        out.append(f"  {r['axis']}: centre dX {d[0]:+.6f}  dY {d[1]:+.6f}  dZ {d[2]:+.6f} mm   "
                   f"angle offset {r['zero_offset_deg']:+.7f} deg")
    return out


def _linuxcnc(first: dict, second: dict, carrier: int) -> list[str]:
    tilt, rot = np.array(first["pivot_delta_mm"]), np.array(second["pivot_delta_mm"])
    if first["axis"][0] == "C":
        tilt, rot = rot, tilt
    off = rot - tilt
    out = ["# trtkins: add to the HAL parameters (mm, machine frame, + = towards + of the machine axis)"]
    out += [f"setp trtkins.{c}-rot-point [{tilt[k]:+.6f}]" for k, c in enumerate("xyz")]
    out += [f"setp trtkins.{c}-offset [{off[k]:+.6f}]" for k, c in enumerate("xyz")]
    out.append(f"# rotary zero offsets [deg]: {first['axis']} {first['zero_offset_deg']:+.7f}, "
               f"{second['axis']} {second['zero_offset_deg']:+.7f} (home offsets of the joints)")
    return out


def kern_axes(machine: str, side: str) -> list[Any]:
    from pige_sym.codegen.machine_code import parse_machine_code

    st = parse_machine_code(machine)
    axes = st.workpiece_axes if side == "workpiece" else st.tool_axes
    return [a for a in axes if a.kind == "rotary"]


def kern_axes_names(machine: str) -> list[str]:
    return [a.name for a in kern_axes(machine, "tool")]


def read_program(path: str | os.PathLike[str]) -> str:
    """Read a program keeping its line endings exactly."""
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return fh.read()
    except FileNotFoundError:
        raise FileFormatError(str(path), None, "program not found") from None
    except UnicodeDecodeError as exc:
        raise FileFormatError(str(path), None, f"not a UTF-8 text file ({exc.reason})") from None


@dataclass
class CompensationStudyRow:
    """Before/after on one test program."""

    trajectory: str
    rmse_before_um: float
    rmse_after_um: float
    reduction: float
    predicted_after_um: float
    command_change_rmse_mm: float
    before_um: np.ndarray
    after_um: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {"trajectory": self.trajectory, "rmse_before_um": self.rmse_before_um,
                "rmse_after_um": self.rmse_after_um, "reduction": self.reduction,
                "predicted_after_um": self.predicted_after_um,
                "command_change_rmse_mm": self.command_change_rmse_mm}


def tool_point_error(machine: str, values: dict[str, float], angles_deg: np.ndarray, xyz_mm: np.ndarray,
                     points_mm: np.ndarray, *, pivots_mm: dict | None = None, tool_mm: Any = None,
                     extensions: list[AngleExtension] | tuple[()] = (),
                     approach: np.ndarray | None = None) -> np.ndarray:
    """Tool point minus intended workpiece point on a machine with errors ``values``, shape=(n, 3) [µm].

    ``extensions`` are angle errors the machine also has (evaluated at the commanded angles;
    ``approach`` defaults to the directions of approach of the poses in order).
    """
    kern = load_kernels(machine)
    p = pose_parameters(kern, values, angles_deg, extensions, approach)
    nominal = linear_commands_at(kern, np.atleast_2d(angles_deg), np.atleast_2d(points_mm), pivots_mm, tool_mm)
    return (xyz_mm - nominal) * 1e3 + raw_offset(kern, angles_deg, points_mm, p, pivots_mm, tool_mm)


def compensation_study(machine: str, trajectories: list[Any], *, truth: dict[str, float],
                       identified: dict[str, float], covariance: np.ndarray | None = None,
                       ball_mm: Any = DEFAULT_BALL_MM, tool_mm: Any = None,
                       pivots_mm: dict | None = None, truth_extensions: list[AngleExtension] | tuple[()] = (),
                       extensions: list[AngleExtension] | tuple[()] = ()) -> list[CompensationStudyRow]:
    """Run each test program uncompensated and compensated on a machine with the true errors.

    ``predicted_after_um`` is the RMSE expected from the identification covariance
    alone: ``sqrt(trace(J Σ Jᵀ)/n)`` over the program's poses.  ``pivots_mm`` are the
    nominal pivots of the rotary axes (default: all at the origin).  ``truth_extensions``
    are angle errors the simulated machine has too; ``extensions`` those compensated.
    """
    kern = load_kernels(machine)
    ball = np.asarray(ball_mm, dtype=float)
    rows = []
    for tr in trajectories:
        a = tr.angles_deg
        pts = np.tile(ball, (a.shape[0], 1))
        xyz = kern.linear_commands(a, ball, pivots_mm, tool_mm)
        approach = approach_directions(a)
        comp = compensate_poses(machine, identified, a, xyz, pivots_mm=pivots_mm, tool_mm=tool_mm,
                                extensions=extensions, approach=approach)
        before = tool_point_error(machine, truth, a, xyz, pts, pivots_mm=pivots_mm, tool_mm=tool_mm,
                                  extensions=truth_extensions, approach=approach)
        after = tool_point_error(machine, truth, comp.new_angles_deg, comp.new_xyz_mm, pts, pivots_mm=pivots_mm,
                                 tool_mm=tool_mm, extensions=truth_extensions, approach=approach)
        rms_b = float(np.sqrt((before**2).sum(axis=1).mean()))
        rms_a = float(np.sqrt((after**2).sum(axis=1).mean()))
        pred = float("nan")
        if covariance is not None:
            jac = kern.jacobian(a, None, ball, pivots_mm, tool_mm)[:, :, : covariance.shape[0]]
            rot = kern.workpiece_rotation(a)
            ref = kern.reference_jacobian(ball, pivots_mm, tool_mm)[:, : covariance.shape[0]]
            jac = jac + np.einsum("nij,jp->nip", rot, ref)
            pred = float(np.sqrt(np.einsum("nip,pq,niq->", jac, covariance, jac) / a.shape[0]))
        change = float(np.sqrt(((comp.new_xyz_mm - xyz) ** 2).sum(axis=1).mean()))
        rows.append(CompensationStudyRow(tr.description, rms_b, rms_a, 1 - rms_a / rms_b if rms_b else 0.0, pred,
                                         change, before, after))
    return rows


def plot_compensation(rows: list[CompensationStudyRow], out_dir: str | Path) -> list[str]:
    """Deviation per point before/after (paper Figures 9 and 10 style); returns PNG paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, r in enumerate(rows):
        fig, axs = plt.subplots(1, 2, figsize=(10, 3.6))
        idx = np.arange(r.before_um.shape[0])
        for k, c in enumerate("xyz"):
            axs[0].plot(idx, r.before_um[:, k], "-", label=f"{c} before")
            axs[0].plot(idx, r.after_um[:, k], "--", label=f"{c} after")
        axs[0].set_xlabel("point")
        axs[0].set_ylabel("tool point error [µm]")
        axs[0].legend(fontsize=7, ncol=2)
        axs[1].plot(idx, np.linalg.norm(r.before_um, axis=1), "o-", label=f"before, RMSE {r.rmse_before_um:.2f} µm")
        axs[1].plot(idx, np.linalg.norm(r.after_um, axis=1), "s-", label=f"after, RMSE {r.rmse_after_um:.2f} µm")
        axs[1].set_xlabel("point")
        axs[1].set_ylabel("|error| [µm]")
        axs[1].legend(fontsize=8)
        fig.suptitle(r.trajectory, fontsize=9)
        fig.tight_layout()
        paths.append(str(out / f"compensation_{i}.png"))
        fig.savefig(paths[-1], dpi=90)
        plt.close(fig)
    return paths
