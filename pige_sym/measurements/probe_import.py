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
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.errors import FileFormatError, InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.axis_sense import to_conventions
from pige_sym.measurements.measurement import PROBE_COLUMNS, Measurement, missing_tool, numeric_column
from pige_sym.measurements.probe_checks import (
    SETUP_FLAGS,
    check_contact_sigma,
    check_deviations,
    check_far_contacts,
    check_options,
    check_pose_count,
    check_radius,
    check_reference,
    check_repeated_contacts,
)
from pige_sym.measurements.probe_head import head_offsets
from pige_sym.measurements.probe_log import ProbeLog, pose_starts, read_probe_log
from pige_sym.measurements.probe_trigger import sensitivity_columns, trigger_sensitivities
from pige_sym.measurements.sphere_fit import (
    MIN_CONTACTS,
    SphereFit,
    fit_centres,
    fit_own_radius,
)

INSTRUMENT = "sphere-probe"
CENTRE_COLUMNS = PROBE_COLUMNS[:3]
COV_COLUMNS = PROBE_COLUMNS[3:9]
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))  # the entries COV_COLUMNS hold
OUTLIER_SIGMAS = 8.0
OUTLIER_FLOOR_UM = 20.0
#: Header items of the probing program kept in the measurement's metadata (as ``program_<key>``).
PROGRAM_KEYS = ("dialect", "kinematics_codes", "stylus_tool", "stylus_length_mm", "work_offset", "window_mm",
                "checkup", "machine_id")


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
    sphere_mm : (3,) [mm] or None
        Where the program put the sphere at the reference pose (``--sphere`` or the program's header): the
        fitted reference centre must be near it (:mod:`~pige_sym.measurements.probe_checks`).
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
    sphere_mm: tuple[float, float, float] | None = None

    def pivots(self) -> dict[str, np.ndarray] | np.ndarray:
        """Per-axis pivots (a dict) or the one intersection (an array) [mm]."""
        if self.pivots_mm is None:
            return np.asarray(self.pivot_mm, dtype=float)
        return {a: np.asarray(v, dtype=float) for a, v in self.pivots_mm.items()}


def _pose_points(log: ProbeLog, starts: np.ndarray, offset_mm: float, head_mm: np.ndarray) -> np.ndarray:
    """Nominal stylus-tip centres of every contact (N, 3) [mm]: the logged point, the stylus offset, the head's turn
    ``h_i`` of its pose."""
    counts = np.diff(starts)
    few = np.flatnonzero(counts < MIN_CONTACTS)
    if few.size:
        i = int(few[0])
        lines = ", ".join(str(x) for x in log.lines[starts[i]:starts[i + 1]])
        raise FileFormatError(log.path, int(log.lines[starts[i]]), f"a pose with {counts[i]} contacts (lines "
                                                                    f"{lines}); a sphere centre needs {MIN_CONTACTS}")
    return log.xyz_mm + np.array([0.0, 0.0, offset_mm]) + np.repeat(head_mm, counts, axis=0)


def _fit(log: ProbeLog, starts: np.ndarray, pts: np.ndarray, spec: ProbeImport, frames: np.ndarray | None) -> SphereFit:
    """The shared-radius fit of the import (``--radius`` when given), after the checks on the contacts and the radius.

    The radius the contacts lie on comes first, from the fit with a free radius: a given radius far from it (25 mm
    for a 14.2 mm sphere) is refused before a fit with it is tried, which has no meaning and can fail outright.
    """
    free = _fit_centres(log, starts, pts, None, spec, frames)
    # each pose against the best sphere through its own contacts (own radius: a fault cannot leak into the
    # other poses through the shared one); the worst contact is named from the shared-radius fit
    own = fit_own_radius((pts, starts), moves=spec.moves, stylus_rotations=frames, start=free)
    robust = 1.4826 * float(np.median(np.abs(own[own != 0]))) if (own != 0).any() else 0.0
    limit = max(OUTLIER_SIGMAS * robust, OUTLIER_FLOOR_UM)
    check_contact_sigma(log.path, robust)
    check_radius(log.path, int(log.lines[0]), free.radius_mm, spec.radius_mm,
                 spec.sphere_radius_mm + spec.stylus_radius_mm, limit)
    fit = free if spec.radius_mm is None else _fit_centres(log, starts, pts, spec.radius_mm, spec, frames)
    own_max = np.maximum.reduceat(np.abs(own), starts[:-1])
    shared_max = np.maximum.reduceat(np.abs(fit.residual_flat_um), starts[:-1])
    bad = np.flatnonzero((own_max > limit) | (shared_max > 3 * limit))
    if bad.size:
        i = int(bad[0])
        first, last = int(starts[i]), int(starts[i + 1])
        shared = fit.residual_flat_um[first:last]
        worst = np.argsort(-np.abs(shared))[:2]
        which = ", ".join(f"line {log.lines[first + j]} {shared[j]:+.1f} um" for j in worst)
        raise FileFormatError(log.path, int(log.lines[first]), f"the pose at lines {log.lines[first]}-"
                              f"{log.lines[last - 1]} is {own_max[i]:.1f} um off the best sphere through its "
                              f"own contacts (limit {limit:.1f} um; largest off the fitted sphere: {which}): a "
                              "probing fault (chip, missed trigger) or a wrong pose; re-probe the pose")
    return fit


def _fit_centres(log: ProbeLog, starts: np.ndarray, pts: np.ndarray, radius_mm: float | None, spec: ProbeImport,
                 frames: np.ndarray | None) -> SphereFit:
    """:func:`~pige_sym.measurements.sphere_fit.fit_centres`, its refusals located at the pose's first line."""
    try:
        return fit_centres((pts, starts), radius_mm=radius_mm, moves=spec.moves, stylus_rotations=frames)
    except InputError as exc:
        i = int(str(exc).split(":")[0].split()[-1]) if str(exc).startswith("pose ") else 0
        raise FileFormatError(log.path, int(log.lines[starts[i]]), str(exc)) from None


def probe_measurement(log: ProbeLog, spec: ProbeImport) -> Measurement:
    """The measurement of a probe log (module docstring)."""
    kern = load_kernels(spec.machine)
    check_tool(kern, spec.tool_mm)
    if kern.TOOL_ROTARY and (spec.kinematics == "tcp" or not _head_lines_meet(kern, spec.pivots_mm)):
        raise InputError(f"{kern.MACHINE_CODE}: a head's probe log is read with RTCP off and the lines of its "
                         f"tool-side axes ({', '.join(kern.TOOL_ROTARY)}) through one pivot (give them the same "
                         "--pivot, or one --pivot x,y,z)")
    check_options(spec.stylus_offset_mm)
    starts = pose_starts(log)
    check_repeated_contacts(log.path, log.xyz_mm, log.angles_deg, log.lines, starts)
    fitted = spec.program.get("checkup", "").split(",") if spec.program.get("checkup") else kern.LOCATION_PARAMETERS
    check_pose_count(log.path, len(starts) - 1, len(fitted), int(log.lines[-1]))
    angles = to_conventions(log.angles_deg[starts[:-1]], spec.axis_sense, kern.ROTARY_AXES)
    if np.abs(angles[0]).max() > 1e-9:
        raise FileFormatError(log.path, int(log.lines[0]), "the first pose must be the reference pose (every rotary "
                                                            "angle 0): c_nom is the motion of its centre")
    head, frames = head_offsets(kern, angles, spec.tool_mm)
    pts = _pose_points(log, starts, spec.stylus_offset_mm, head)
    if spec.kinematics == "tcp":
        pts = _machine_points(kern, pts, starts, angles, spec)
    check_far_contacts(log.path, pts, starts, log.lines, spec.sphere_radius_mm + spec.stylus_radius_mm)
    fit = _fit(log, starts, pts, spec, frames)
    check_reference(log.path, int(log.lines[0]), fit.centres_mm[0], spec.sphere_mm,
                    "the program's header (sphere_mm)" if spec.program else "--sphere")
    nominal = _nominal_centres(kern, angles, fit.centres_mm[0], spec.pivots(), spec.tool_mm, head)
    deviation = -(fit.centres_mm - nominal) * 1e3
    deviation[0] = 0.0
    check_deviations(log.path, deviation, log.lines[starts[:-1]])
    m = _measurement(kern, log, spec, starts, angles, fit, deviation)
    m.optional |= sensitivity_columns(trigger_sensitivities((pts, starts), fit.centres_mm, fit.radius_fitted,
                                                            spec.moves, frames))
    return m


def _head_lines_meet(kern: Any, pivots: dict[str, Any] | None) -> bool:
    """Whether the tool-side axis lines go through one pivot (then ``h = (R_t − I)·tool``)."""
    if pivots is None:
        return True
    heads = [np.asarray(pivots[a], dtype=float) for a in kern.TOOL_ROTARY]
    return all(np.allclose(p, heads[0], rtol=0.0, atol=1e-9) for p in heads)


def _nominal_centres(kern: Any, angles: np.ndarray, centre0: np.ndarray, pivots: dict[str, np.ndarray] | np.ndarray,
                     tool_mm: Any = None, head_mm: np.ndarray | None = None) -> np.ndarray:
    """``c_nom(θ)``: the nominal motion of ``c(0)``, shape=(n, 3) [mm] (one pivot, or one per axis).

    With a pivot per axis it is the kernels' RTCP command of a tool point at ``c(0)``; on a head that command
    also undoes the head's turn, ``−h``, which is added back (``head_mm``).
    """
    if isinstance(pivots, dict):
        lin = np.asarray(kern.linear_commands(angles, centre0, pivots, tool_mm))
        return lin if head_mm is None or tool_mm is None else lin + head_mm
    return pivots + np.einsum("nij,j->ni", kern.workpiece_rotation(angles), centre0 - pivots)


def _machine_points(kern: Any, work_mm: np.ndarray, starts: np.ndarray, angles: np.ndarray,
                    spec: ProbeImport) -> np.ndarray:
    """Contacts logged in TCP kinematics (work coordinates) as the controller's nominal machine positions [mm].

    The nominal motion of a point is affine in the point: it is evaluated at the origin and the three unit
    points once per pose and applied to every contact of the pose.
    """
    pivots = spec.pivots()
    origin = _nominal_centres(kern, angles, np.zeros(3), pivots)
    columns = np.stack([_nominal_centres(kern, angles, e, pivots) - origin for e in np.eye(3)], axis=2)  # (n, 3, 3)
    pose = np.repeat(np.arange(len(angles)), np.diff(starts))
    return np.einsum("nij,nj->ni", columns[pose], work_mm) + origin[pose]


def check_tool(kern: Any, tool_mm: Any) -> None:
    """A head machine needs ``--tool``; a table machine must not get one (one-line InputError)."""
    why = missing_tool(kern.MACHINE_CODE, tool_mm)
    if why:
        raise InputError(why + " (CONVENTIONS §7: the stylus turns with the head)")
    if tool_mm is not None and not kern.TOOL_ROTARY:
        raise InputError(f"--tool: {kern.MACHINE_CODE} has no tool-side rotary axis, the stylus does not turn; "
                         "leave --tool out (the stylus centre is the controlled point, --stylus-offset)")


def _measurement(kern: Any, log: ProbeLog, spec: ProbeImport, starts: np.ndarray, angles: np.ndarray,
                 fit: SphereFit, deviation: np.ndarray) -> Measurement:
    n = len(starts) - 1
    cov = fit.covariance_um2
    numbers = {c: np.array(fit.centres_mm[:, k]) for k, c in enumerate(CENTRE_COLUMNS)}
    numbers |= covariance_columns(cov)
    extra = {"log_line": list(map(str, log.lines[starts[:-1]].tolist()))}
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
        optional={"n_samples": np.diff(starts).astype(float), "sd_um": fit.pose_rms_um, **numbers},
        extra_columns=extra, metadata=meta,
    )


def import_probe_log(path: str | os.PathLike[str], fmt: str, spec: ProbeImport) -> Measurement:
    """Read a probe log and return its measurement (:func:`probe_measurement`)."""
    kern = load_kernels(spec.machine)
    return probe_measurement(read_probe_log(path, fmt, tuple(kern.ROTARY_AXES), units=spec.units), spec)


def covariance_columns(cov: np.ndarray) -> dict[str, np.ndarray]:
    """The per-row centre covariances (n, 3, 3) [µm²] as the file's columns ``cov_xx_um2 … cov_zz_um2``."""
    return {c: np.array(cov[:, i, j]) for c, (i, j) in zip(COV_COLUMNS, _UPPER, strict=True)}


def row_covariances(m: Measurement) -> np.ndarray:
    """The per-row centre covariances of a probe measurement, shape=(n, 3, 3) [µm²] (strictly read).

    Raises
    ------
    FileFormatError
        A missing, non-numeric or non-positive-definite covariance (names the row).
    """
    where = m.path or m.metadata.get("probe_log", "<measurement>")
    columns = [numeric_column(m, c) for c in COV_COLUMNS]
    if any(c is None for c in columns):
        raise FileFormatError(where, None, f"instrument {INSTRUMENT} needs the columns {', '.join(COV_COLUMNS)} "
                              "(written by pige import-probe)")
    cov = np.zeros((m.n_rows, 3, 3))
    for values, (i, j) in zip(columns, _UPPER, strict=True):
        cov[:, i, j] = cov[:, j, i] = values
    bad = np.flatnonzero(~(np.linalg.eigvalsh(cov)[:, 0] > 0))
    if bad.size:
        raise FileFormatError(where, None, f"row {int(bad[0]) + 1}: the centre covariance is not positive definite")
    return cov


def verify_written(out: Path | str, m: Measurement) -> Any:
    """A check for :func:`~pige_sym.measurements.rtest_writer.write_measurement` of ``m``: the written file must pass
    the reader's validation (:func:`~pige_sym.measurements.rtest.check_as_read`: its header read back, its rows
    checked as read) and the covariances their check; the import is refused with the reader's reason otherwise,
    and nothing is written."""
    def verify(tmp: Path) -> None:
        from pige_sym.measurements.rtest import check_as_read

        try:
            check_as_read(tmp, m)
            row_covariances(m)
        except FileFormatError as exc:
            where = f"line {exc.line}: " if exc.line is not None else ""
            raise InputError(f"{out}: not written: pige's reader refuses what import-probe would write ({where}"
                             f"{exc.problem}); check {SETUP_FLAGS}") from None

    return verify
