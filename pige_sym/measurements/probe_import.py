"""From a probe log to a measurement file every command reads (CONVENTIONS §7).

Steps: contacts grouped by pose (:func:`~pige_sym.measurements.probe_log.group_poses`); the stylus-centre
offset along the spindle axis added (``stylus_offset_mm``: where the tool length is set to the ball's
bottom, the centre is ``r`` higher); sphere centres fitted (:mod:`~pige_sym.measurements.sphere_fit`,
one effective radius for all poses unless given); a contact whose radial residual exceeds
``max(OUTLIER_SIGMAS·σ, OUTLIER_FLOOR_UM)`` is refused with its line (a contact far off the sphere is a
probing fault, not data); then the deviation of every pose

    ``d(θ) = −e(θ) = −(c(θ) − c_nom(θ))``, ``c_nom(θ) = pivot + R_w(θ)(c(0) − pivot)``  [µm, machine axes]

which is what an R-test would read with the ball at ``c(0)``: every command then uses the R-test model
unchanged.  On a head or mixed machine (CONVENTIONS §7, "Head and mixed machines") the log holds the linear
axes, where the stylus centre would be with the head at its reference pose; the nominal stylus centre at the
pose is ``X + h(θ)``, ``h = (R_t(θ) − I)·tool`` with ``tool`` the stylus centre from the last tool-side pivot
(``tool_mm``, the R-test's ``--tool``; the rotary axis lines meet at ``pivot``, so the head's own pivot drops
out), the sphere is fitted to those, and the deviation is the same expression: ``e = −d`` with ``d`` the R-test
deviation of a ball at ``c(0)`` and a tool at ``tool`` (exact when the table has no rotary axis, first order
otherwise).  The probing moves turn with the head: the contact weights and trigger sensitivities are read in
each pose's stylus frame.

The file is ``pige-rtest 1`` with ``instrument: sphere-probe`` and, per row, the covariance of the pose's
centre (``cov_xx_um2 … cov_zz_um2``); the identification uses them, and row 0's, since the
error of ``c(0)`` enters every pose through ``c_nom`` (:mod:`pige_sym.identification.instruments`).
Columns: ``t_s`` is the pose's order (a probe log holds no time), the angles, ``dx_um dy_um dz_um``,
``n_samples`` (contacts) and ``sd_um`` (RMS radial residual of the pose), the fitted centre ``cx_mm cy_mm
cz_mm``, the first log line of the pose, the six covariance entries, and the centre's response to a
direction-dependent trigger radius (``trig_…``, :mod:`~pige_sym.measurements.probe_trigger`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import FileFormatError, InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.axis_sense import to_conventions
from pige_sym.measurements.measurement import Measurement, missing_tool
from pige_sym.measurements.probe_head import head_offsets
from pige_sym.measurements.probe_log import ProbeLog, group_poses, read_probe_log
from pige_sym.measurements.probe_trigger import sensitivity_columns, trigger_sensitivities
from pige_sym.measurements.sphere_fit import MIN_CONTACTS, SphereFit, fit_centres

INSTRUMENT = "sphere-probe"
COV_COLUMNS = ("cov_xx_um2", "cov_xy_um2", "cov_xz_um2", "cov_yy_um2", "cov_yz_um2", "cov_zz_um2")
CENTRE_COLUMNS = ("cx_mm", "cy_mm", "cz_mm")
OUTLIER_SIGMAS = 8.0
OUTLIER_FLOOR_UM = 20.0
#: Header items of the probing program kept in the measurement's metadata (as ``program_<key>``).
PROGRAM_KEYS = ("dialect", "kinematics_codes", "stylus_tool", "stylus_length_mm", "work_offset", "window_mm")


@dataclass(frozen=True)
class ProbeImport:
    """How to turn a log into a measurement.

    Attributes
    ----------
    machine : str
    pivot_mm : (3,) [mm]
        Nominal rotary centre (intersection of the axis lines) in the log's coordinates.
    sphere_radius_mm, stylus_radius_mm : float [mm]
    radius_mm : float or None [mm]
        Calibrated effective radius; None fits one from the data.
    stylus_offset_mm : float [mm]
        Stylus centre above the controlled point along the spindle axis.
    units : {"mm", "inch"}
    tool_mm : (3,) [mm] or None
        Head and mixed machines: the stylus centre from the nominal pivot of the last tool-side axis at the
        reference pose (CONVENTIONS §7, the R-test's ``--tool``); required there, refused on a table machine.
    moves : {"axes", "normal"}
        How the contacts were probed: along machine axes (pige's programs; the trigger scatter along the
        move weighs less on an inclined surface) or along the surface normal
        (:func:`~pige_sym.measurements.sphere_fit.fit_centres`).
    pivots_mm : dict of str to (3,) [mm] or None
        Table machines: the nominal pivot of each rotary axis (lines that need not meet, as in LinuxCNC's trt
        configurations); None: every line through ``pivot_mm``.
    axis_sense : dict of str to int
        Axes the controller commands in the reverse of CONVENTIONS' sense: the log's angles are θ_cmd.
    kinematics : {"identity", "tcp"}
        The controller's kinematics during probing: ``identity`` logs the linear axes; ``tcp`` logs work
        coordinates, mapped back through the nominal kinematics the controller held (pivots, ``axis_sense``).
    program : dict of str to str
        What the probing program's header stated (kept in the measurement's metadata).
    """

    machine: str
    pivot_mm: tuple[float, float, float]
    sphere_radius_mm: float
    stylus_radius_mm: float
    radius_mm: float | None = None
    stylus_offset_mm: float = 0.0
    units: str = "mm"
    moves: str = "axes"
    tool_mm: tuple[float, float, float] | None = None
    pivots_mm: dict[str, tuple[float, float, float]] | None = None
    axis_sense: dict[str, int] = field(default_factory=dict)
    kinematics: str = "identity"
    program: dict[str, str] = field(default_factory=dict)

    def pivots(self) -> dict[str, np.ndarray] | np.ndarray:
        """Per-axis pivots (a dict) or the one intersection (an array) [mm]."""
        if self.pivots_mm is None:
            return np.asarray(self.pivot_mm, dtype=float)
        return {a: np.asarray(v, dtype=float) for a, v in self.pivots_mm.items()}


def _pose_points(log: ProbeLog, groups: list[np.ndarray], offset_mm: float, head_mm: np.ndarray) -> list[np.ndarray]:
    """Nominal stylus-tip centres of every pose: the logged point, the stylus offset, the head's turn ``h_i``."""
    pts = []
    for g, h in zip(groups, head_mm, strict=True):
        if len(g) < MIN_CONTACTS:
            lines = ", ".join(str(x) for x in log.lines[g])
            raise FileFormatError(log.path, int(log.lines[g[0]]), f"a pose with {len(g)} contacts (lines {lines}); "
                                                                   f"a sphere centre needs {MIN_CONTACTS}")
        pts.append(log.xyz_mm[g] + (np.array([0.0, 0.0, offset_mm]) + h))
    return pts


def _fit(log: ProbeLog, groups: list[np.ndarray], pts: list[np.ndarray], radius: float | None,
         moves: str, frames: np.ndarray | None) -> SphereFit:
    try:
        fit = fit_centres(pts, radius_mm=radius, moves=moves, stylus_rotations=frames)
    except InputError as exc:
        i = int(str(exc).split(":")[0].split()[-1]) if str(exc).startswith("pose ") else 0
        raise FileFormatError(log.path, int(log.lines[groups[i][0]]), str(exc)) from None
    # each pose against the best sphere through its own contacts (own radius: a fault cannot leak into the
    # other poses through the shared one); the worst contact is named from the shared-radius fit
    own = [fit_centres([p], moves=moves, stylus_rotations=None if frames is None else frames[i:i + 1]).residuals_um[0]
           if len(p) > MIN_CONTACTS else np.zeros(len(p)) for i, p in enumerate(pts)]
    pooled = np.concatenate(own)
    robust = 1.4826 * float(np.median(np.abs(pooled[pooled != 0]))) if (pooled != 0).any() else 0.0
    limit = max(OUTLIER_SIGMAS * robust, OUTLIER_FLOOR_UM)
    for g, res, shared in zip(groups, own, fit.residuals_um, strict=True):
        if np.abs(res).max() > limit or np.abs(shared).max() > 3 * limit:
            worst = np.argsort(-np.abs(shared))[:2]
            which = ", ".join(f"line {log.lines[g[j]]} {shared[j]:+.1f} um" for j in worst)
            raise FileFormatError(log.path, int(log.lines[g[0]]), f"the pose at lines {log.lines[g[0]]}-"
                                  f"{log.lines[g[-1]]} is {np.abs(res).max():.1f} um off the best sphere through its "
                                  f"own contacts (limit {limit:.1f} um; largest off the fitted sphere: {which}): a "
                                  "probing fault (chip, missed trigger) or a wrong pose; re-probe the pose")
    return fit


def probe_measurement(log: ProbeLog, spec: ProbeImport) -> Measurement:
    """The measurement of a probe log (module docstring)."""
    kern = load_kernels(spec.machine)
    check_tool(kern, spec.tool_mm)
    if (spec.pivots_mm is not None or spec.kinematics == "tcp") and kern.TOOL_ROTARY:
        raise InputError(f"{kern.MACHINE_CODE}: a pivot per axis and logs in TCP kinematics are read for table "
                         "machines; give one --pivot x,y,z and a log probed with RTCP off")
    groups = group_poses(log)
    angles = to_conventions(np.array([log.angles_deg[g[0]] for g in groups]), spec.axis_sense, kern.ROTARY_AXES)
    if np.abs(angles[0]).max() > 1e-9:
        raise FileFormatError(log.path, int(log.lines[0]), "the first pose must be the reference pose (every rotary "
                                                            "angle 0): c_nom is the motion of its centre")
    head, frames = head_offsets(kern, angles, spec.tool_mm)
    pts = _pose_points(log, groups, spec.stylus_offset_mm, head)
    if spec.kinematics == "tcp":
        pts = [_machine_points(kern, p, theta, spec) for p, theta in zip(pts, angles, strict=True)]
    fit = _fit(log, groups, pts, spec.radius_mm, spec.moves, frames)
    nominal = _nominal_centres(kern, angles, fit.centres_mm[0], spec.pivots())
    deviation = -(fit.centres_mm - nominal) * 1e3
    deviation[0] = 0.0
    m = _measurement(kern, log, spec, groups, angles, fit, deviation)
    m.extra_columns |= sensitivity_columns(trigger_sensitivities(pts, fit.centres_mm, fit.radius_fitted, spec.moves,
                                                                 frames))
    return m


def _nominal_centres(kern: Any, angles: np.ndarray, centre0: np.ndarray,
                     pivots: dict[str, np.ndarray] | np.ndarray) -> np.ndarray:
    """``c_nom(θ)``: the nominal motion of ``c(0)``, shape=(n, 3) [mm] (one pivot, or one per axis on a table)."""
    if isinstance(pivots, dict):
        return np.asarray(kern.linear_commands(angles, centre0, pivots, None))
    return pivots + np.einsum("nij,j->ni", kern.workpiece_rotation(angles), centre0 - pivots)


def _machine_points(kern: Any, work_mm: np.ndarray, theta: np.ndarray, spec: ProbeImport) -> np.ndarray:
    """Contacts logged in TCP kinematics (work coordinates) as the controller's nominal machine positions [mm]."""
    return np.array([_nominal_centres(kern, theta[None], p, spec.pivots())[0] for p in work_mm])


def check_tool(kern: Any, tool_mm: Any) -> None:
    """A head machine needs ``--tool``; a table machine must not get one (one-line InputError)."""
    why = missing_tool(kern.MACHINE_CODE, tool_mm)
    if why:
        raise InputError(why + " (CONVENTIONS §7: the stylus turns with the head)")
    if tool_mm is not None and not kern.TOOL_ROTARY:
        raise InputError(f"--tool: {kern.MACHINE_CODE} has no tool-side rotary axis, the stylus does not turn; "
                         "leave --tool out (the stylus centre is the controlled point, --stylus-offset)")


def _measurement(kern: Any, log: ProbeLog, spec: ProbeImport, groups: list[np.ndarray], angles: np.ndarray,
                 fit: SphereFit, deviation: np.ndarray) -> Measurement:
    n = len(groups)
    cov = fit.covariance_um2
    iu = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    extra = {c: [repr(float(v)) for v in fit.centres_mm[:, k]] for k, c in enumerate(CENTRE_COLUMNS)}
    extra["log_line"] = [str(int(log.lines[g[0]])) for g in groups]
    extra |= {c: [repr(float(v)) for v in cov[:, i, j]] for c, (i, j) in zip(COV_COLUMNS, iu, strict=True)}
    sd = np.array([float(np.sqrt(np.mean(r**2))) for r in fit.residuals_um])
    meta = {
        "instrument": INSTRUMENT,
        "measurand": "d = -(c - c_nom): sphere centre c(theta) against the nominal motion of c(0) (CONVENTIONS 7)",
        "probe_log": os.path.basename(log.path), "probe_format": log.format,
        **({"pivot_mm": ", ".join(repr(float(v)) for v in spec.pivot_mm)} if spec.pivots_mm is None else {}),
        "sphere_radius_mm": repr(spec.sphere_radius_mm), "stylus_radius_mm": repr(spec.stylus_radius_mm),
        "r_eff_mm": f"{float(fit.radius_mm)!r} ({'fitted' if fit.radius_fitted else 'given'})",
        "contact_sigma_um": repr(float(fit.sigma_um)), "probing_moves": spec.moves, "source": "pige import-probe",
        "probe_kinematics": spec.kinematics,
        **{f"program_{k}": v for k, v in spec.program.items() if k in PROGRAM_KEYS},
    }
    if spec.tool_mm is not None:
        meta["stylus_frame"] = f"turns with the head ({', '.join(kern.TOOL_ROTARY)}): probing moves read in it"
    if spec.pivots_mm is None:
        ball, pivots = fit.centres_mm[0] - np.asarray(spec.pivot_mm), {}
    else:
        ball, pivots = fit.centres_mm[0], {a: np.asarray(v, dtype=float) for a, v in spec.pivots_mm.items()}
    return Measurement(
        machine=str(kern.MACHINE_CODE), ball_mm=ball, pivots_mm=pivots, axis_sense=dict(spec.axis_sense),
        tool_mm=None if spec.tool_mm is None else np.asarray(spec.tool_mm, dtype=float),
        t_s=np.arange(n, dtype=float), angles_deg=angles, deviation_um=deviation, rotary_axes=log.rotary_axes,
        frame="machine", trajectory=f"sphere probing, {n} poses, {log.format} log",
        optional={"n_samples": np.array([len(g) for g in groups], dtype=float), "sd_um": sd},
        extra_columns=extra, metadata=meta,
    )


def import_probe_log(path: str | os.PathLike[str], fmt: str, spec: ProbeImport) -> Measurement:
    """Read a probe log and return its measurement (:func:`probe_measurement`)."""
    kern = load_kernels(spec.machine)
    return probe_measurement(read_probe_log(path, fmt, tuple(kern.ROTARY_AXES), units=spec.units), spec)


def row_covariances(m: Measurement) -> np.ndarray:
    """The per-row centre covariances of a probe measurement, shape=(n, 3, 3) [µm²] (strictly read).

    Raises
    ------
    FileFormatError
        A missing, non-numeric or non-positive-definite covariance (names the row).
    """
    missing = [c for c in COV_COLUMNS if c not in m.extra_columns]
    if missing:
        raise FileFormatError(m.metadata.get("probe_log", "<measurement>"), None,
                              f"instrument {INSTRUMENT} needs the columns {', '.join(COV_COLUMNS)} "
                              "(written by pige import-probe)")
    from pige_sym.options import strict_float

    cov = np.zeros((m.n_rows, 3, 3))
    iu = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    for c, (i, j) in zip(COV_COLUMNS, iu, strict=True):
        for r, text in enumerate(m.extra_columns[c]):
            v = strict_float(str(text))
            if v is None:
                raise FileFormatError("<measurement>", None, f"row {r}: {c} {text!r} is not a number")
            cov[r, i, j] = cov[r, j, i] = v
    bad = [r for r in range(m.n_rows) if np.linalg.eigvalsh(cov[r]).min() <= 0]
    if bad:
        raise FileFormatError("<measurement>", None, f"row {bad[0]}: the centre covariance is not positive definite")
    return cov
