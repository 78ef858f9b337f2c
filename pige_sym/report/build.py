"""Self-contained HTML calibration report of one or more R-test measurements (``pige report``).

Pipeline
--------
1. :func:`gather_report` reads every measurement file (and a ``<stem>.truth.json``
   sidecar beside it, when present) and computes everything the report shows into a
   :class:`ReportData`: the identification with both methods (Gauss–Newton and the
   double-differential scheme), the diagnosis, the compensation before/after on the
   measured trajectory (and on an NC program when one is given), and, on request,
   the projection study and the Sobol indices on the measured trajectory.
2. :func:`write_report` draws the figures (matplotlib, Agg backend) into
   ``DIR/<label>/*.png`` and writes ``DIR/report.html`` with every PNG embedded as a
   base64 ``data:`` URI and the CSS inline: the page loads nothing from anywhere.
3. :func:`render_html` is pure: ``ReportData`` (with its figures) in, HTML text out.
   Every piece of text goes through :func:`html.escape`.

Choices made here
-----------------
- *Deviation plots (ISO 10791-6 / R-test style).*  Per measurement: the deviation
  components dx, dy, dz [µm] in the machine frame against the point index, above the
  commanded rotary angles [deg] against the same index; and, when one rotary axis
  turns through at least 180° (cone-frustum, stepped sweeps), a polar plot of each
  component against that axis' angle, drawn about a nominal circle (radius offset,
  radial scale in µm).  The PIGE model of the primary identification is overlaid
  when every parameter was determined.
- *Compensation before/after.*  With a truth sidecar, the simulated machine carries
  the true parameters (PIGEs and zero-position errors; effects listed in the sidecar
  are not simulated and this is said); without one, the machine is assumed to carry
  exactly the identified errors, so "after" only shows what the compensation
  algorithm itself leaves and the report says the before/after is model-predicted.
  Parameters without a value are compensated as 0 and listed.
- *Primary method.*  ``method`` (default Gauss–Newton) selects the estimate used for
  the model overlay and the compensation: ``gauss-newton``, ``double-differential``,
  or ``diagnosis`` (the PIGEs of the diagnosis' final fit, estimated jointly with the
  accepted extensions, which are not compensated).  Both identification methods are
  always tabulated.
- *Studies* run on the measured trajectory, ball and tool (pivots at their defaults),
  the projection study with the Gauss–Newton fit's σ as the simulated noise.
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pige_sym import __version__
from pige_sym.compensation import (
    AngleExtension,
    CompensationParameters,
    CompensationStudyRow,
    angle_extensions,
    compensate_poses,
    compensate_program,
    compensation_study,
    plot_compensation,
    read_program,
    tool_point_error,
)
from pige_sym.diagnosis import DiagnosisResult, diagnose, residual_plots
from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import atomic_write_text, json_ready
from pige_sym.identification import METHODS, IdentificationError, IdentificationResult, identify
from pige_sym.io import Measurement, read_measurement
from pige_sym.kernels import load_kernels
from pige_sym.nc.program import parse_program, poses_from_program
from pige_sym.simulator import normalise_parameter_name
from pige_sym.studies import ProjectionStudy, SobolStudy, projection_study, sobol_study
from pige_sym.trajectories import Trajectory, approach_directions

STUDIES = ("projection", "sobol")
PRIMARY_METHODS = (*METHODS, "diagnosis")
UNIT_TEXT = {"um": "µm", "urad": "µrad", "s": "s", "count": "count"}


# ---------------------------------------------------------------------------------------------
# data


@dataclass
class ReportFigure:
    """A PNG written for the report.

    Attributes
    ----------
    key : str
        What it shows (``deviation``, ``polar``, ``identification``, ``residual``,
        ``compensation``, ``sobol``).
    path : Path
        The PNG file.
    caption : str
        Plain text (escaped when rendered).
    """

    key: str
    path: Path
    caption: str


@dataclass
class Truth:
    """Known parameters of a simulated measurement (``<stem>.truth.json``).

    Attributes
    ----------
    path : Path
    values : dict of str to float
        Parameter name to value [µm or µrad]; parameters absent from the file are 0.
    notes : list of str
        What the sidecar holds that the report does not simulate (effects, outliers).
    extensions : list of AngleExtension
        Angle errors of the sidecar's effects (angular positioning, backlash) that the
        before/after simulates on the true machine.
    """

    path: Path
    values: dict[str, float]
    notes: list[str] = field(default_factory=list)
    extensions: list[AngleExtension] = field(default_factory=list)


@dataclass
class MeasurementReport:
    """Everything the report shows about one measurement file.

    Attributes
    ----------
    path : Path
        The file as given.
    label : str
        Its directory name under the output directory (unique, file-system safe).
    measurement : Measurement
    machine : str
        Canonical machine code.
    identification : dict of str to IdentificationResult
        One result per method (``gauss-newton``, ``double-differential``).
    primary_method : {"gauss-newton", "double-differential", "diagnosis"}
        The estimate that drives the model overlay and the compensation.
    diagnosis : DiagnosisResult or None
        None when the diagnosis failed on these data (``diagnosis_error`` says why).
    compensation : list of CompensationStudyRow
        The measured trajectory first, then the NC program's poses when one is given.
    compensation_basis : {"truth", "model"}
        Whether "before" is simulated with the truth sidecar or with the identified model.
    not_compensated : list of str
        Parameters without a value, compensated as 0.
    extensions : list of AngleExtension
        Accepted diagnosis extensions compensated with the PIGEs (primary method ``diagnosis``).
    extensions_not_compensated : list of str
        Accepted extensions that are not compensated, with the reason.
    truth : Truth or None
    model_um : ndarray, shape=(n, 3) [µm] or None
        PIGE-model deviation of the primary estimate in the machine frame (None when a
        parameter is undetermined).
    compensated_program_text : str or None
        The NC program compensated with the primary estimate.
    compensated_program : Path or None
        Where :func:`write_report` wrote it (beside the figures).
    projection : ProjectionStudy or None
    sobol : SobolStudy or None
    figures : list of ReportFigure
    notes : list of str
    """

    path: Path
    label: str
    measurement: Measurement
    machine: str
    identification: dict[str, IdentificationResult]
    primary_method: str
    diagnosis: DiagnosisResult | None
    compensation: list[CompensationStudyRow]
    compensation_basis: str
    not_compensated: list[str]
    extensions: list[AngleExtension] = field(default_factory=list)
    extensions_not_compensated: list[str] = field(default_factory=list)
    truth: Truth | None = None
    diagnosis_error: str | None = None
    model_um: np.ndarray | None = None
    compensated_program_text: str | None = None
    compensated_program: Path | None = None
    projection: ProjectionStudy | None = None
    projection_noise_um: float | None = None
    sobol: SobolStudy | None = None
    figures: list[ReportFigure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def primary(self) -> IdentificationResult:
        """The result whose estimate is compensated (may hold extension parameters: diagnosis)."""
        if self.primary_method == "diagnosis" and self.diagnosis is not None:
            return self.diagnosis.final
        return self.identification[self.primary_method]

    def estimate(self) -> tuple[dict[str, float], list[str], np.ndarray | None]:
        """The primary estimate restricted to the machine's parameters.

        Returns
        -------
        values : dict of str to float
            Parameter to value [µm, µrad]; 0 where there is no value.
        missing : list of str
            Parameters without a value.
        covariance : ndarray, shape=(P, P) or None
            Their covariance (kernel parameter order); None when a value is missing.
        """
        res = self.primary
        params = set(load_kernels(self.machine).PARAMETERS)
        idx = [j for j, n in enumerate(res.parameters) if n in params]
        values = {res.parameters[j]: float(res.values[j]) for j in idx}
        missing = [k for k, v in values.items() if not math.isfinite(v)]
        cov = None if missing or res.covariance.shape[0] < len(idx) else res.covariance[np.ix_(idx, idx)]
        return {k: (v if math.isfinite(v) else 0.0) for k, v in values.items()}, missing, cov

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (non-finite numbers become ``None``)."""
        out: dict[str, Any] = {
            "file": str(self.path),
            "label": self.label,
            "machine": self.machine,
            "primary_method": self.primary_method,
            "identification": {k: v.to_dict() for k, v in self.identification.items()},
            "diagnosis": None if self.diagnosis is None else self.diagnosis.to_dict(),
            "diagnosis_error": self.diagnosis_error,
            "compensation": {"basis": self.compensation_basis, "not_compensated": self.not_compensated,
                             "rows": [r.to_dict() for r in self.compensation],
                             "program": None if self.compensated_program is None else str(self.compensated_program)},
            "truth": None if self.truth is None else {"file": str(self.truth.path), "pige": self.truth.values},
            "projection": None if self.projection is None else self.projection.to_dict(),
            "sobol": None if self.sobol is None else self.sobol.to_dict(),
            "figures": [str(f.path) for f in self.figures],
            "notes": self.notes,
        }
        return json_ready(out)


@dataclass
class ReportData:
    """All the content of a report, before rendering.

    Attributes
    ----------
    measurements : list of MeasurementReport
    studies : tuple of str
        Studies requested (subset of ``projection``, ``sobol``).
    program : Path or None
        NC program compensated for every measurement.
    settings : dict of str to str
        Options the report was built with (shown in the header).
    created : str
        UTC time stamp (ISO 8601).
    html_path : Path or None
        Set by :func:`write_report`.
    """

    measurements: list[MeasurementReport]
    studies: tuple[str, ...] = ()
    program: Path | None = None
    settings: dict[str, str] = field(default_factory=dict)
    created: str = ""
    html_path: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        return json_ready({
            "report": None if self.html_path is None else str(self.html_path),
            "created": self.created, "version": __version__, "settings": self.settings,
            "studies": list(self.studies), "program": None if self.program is None else str(self.program),
            "measurements": [m.to_dict() for m in self.measurements],
        })


def parse_studies(text: str | Iterable[str] | None) -> tuple[str, ...]:
    """Study names from ``projection,sobol`` (or an iterable); unknown names raise InputError."""
    if text is None:
        return ()
    items = text.split(",") if isinstance(text, str) else list(text)
    out: list[str] = []
    for item in (s.strip().lower() for s in items):
        if not item:
            continue
        if item not in STUDIES:
            raise InputError(f"--study: unknown study {item!r}: use {', '.join(STUDIES)}")
        if item not in out:
            out.append(item)
    return tuple(out)


def read_truth(csv_path: str | os.PathLike[str], machine: str) -> Truth | None:
    """The truth sidecar ``<stem>.truth.json`` beside a measurement, or None when there is none.

    Accepts the sidecar of ``pige simulate`` and of the reference datasets (a ``pige``
    object of name: value, letter O accepted for the digit zero).

    Raises
    ------
    FileFormatError
        The sidecar exists but is not valid JSON, has no ``pige`` object, names a
        parameter the machine does not have, or another machine.
    """
    p = Path(csv_path)
    tp = p.with_name(p.stem + ".truth.json")
    if not tp.is_file():
        return None
    try:
        data = json.loads(tp.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise FileFormatError(str(tp), exc.lineno, f"not valid JSON: {exc.msg}") from None
    except UnicodeDecodeError as exc:
        raise FileFormatError(str(tp), None, f"not a UTF-8 text file ({exc.reason})") from None
    if not isinstance(data, dict) or not isinstance(data.get("pige"), dict):
        raise FileFormatError(str(tp), None, 'expected a JSON object with a "pige" object of name: value')
    kern = load_kernels(machine)
    if isinstance(data.get("machine"), str) and load_kernels(data["machine"]).MACHINE_CODE != kern.MACHINE_CODE:
        raise FileFormatError(str(tp), None, f"truth is for machine {data['machine']}, the measurement for "
                              f"{kern.MACHINE_CODE}")
    values: dict[str, float] = dict.fromkeys(kern.PARAMETERS, 0.0)
    for name, v in data["pige"].items():
        key = normalise_parameter_name(str(name))
        if key not in kern.PARAMETERS:
            raise FileFormatError(str(tp), None, f"parameter {name!r} does not belong to {kern.MACHINE_CODE}")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise FileFormatError(str(tp), None, f"parameter {name}: {v!r} is not a finite number")
        values[key] = float(v)
    notes = []
    effects = data.get("effects") or []
    records = [e for e in effects if isinstance(e, dict) and isinstance(e.get("effect"), str)]
    try:
        extensions, skipped = angle_extensions(records, tuple(kern.ROTARY_AXES))
    except InputError as exc:
        raise FileFormatError(str(tp), None, str(exc)) from None
    names = list(skipped)
    names += [str(e.get("name", e)) if isinstance(e, dict) else str(e) for e in effects if e not in records]
    if isinstance(data.get("effect"), str) and data["effect"] not in ("", "none"):
        names.append(data["effect"])
    if names:
        simulated = "true PIGEs" + (" and angle errors" if extensions else "")
        notes.append(f"the truth sidecar also lists effect(s) {', '.join(names)}: the before/after simulates the "
                     f"{simulated} only")
    return Truth(tp, values, notes, extensions)


# ---------------------------------------------------------------------------------------------
# gathering


def _labels(paths: Sequence[Path]) -> list[str]:
    out: list[str] = []
    for p in paths:
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", p.stem) or "measurement"
        label, k = base, 2
        while label in out:
            label, k = f"{base}-{k}", k + 1
        out.append(label)
    return out


def _measured_trajectory(m: Measurement) -> Trajectory:
    desc = m.trajectory or "measured angles"
    return Trajectory("measured", tuple(m.rotary_axes), m.angles_deg, m.t_s, desc)


def program_before_after(machine: str, truth: dict[str, float], identified: dict[str, float], angles_deg: np.ndarray,
                         xyz_mm: np.ndarray, rtcp: Sequence[bool], *, description: str,
                         pivots_mm: dict | None = None, tool_mm: Any = None,
                         covariance: np.ndarray | None = None,
                         truth_extensions: list[AngleExtension] | tuple[()] = (),
                         extensions: list[AngleExtension] | tuple[()] = ()) -> CompensationStudyRow:
    """Before/after tool-point error of an NC program's poses on a machine with errors ``truth``.

    Parameters
    ----------
    machine : str
    truth, identified : dict of str to float
        Parameters of the simulated machine and of the compensation [µm, µrad].
    angles_deg : ndarray, shape=(m, k) [deg]
    xyz_mm : ndarray, shape=(m, 3) [mm]
        Machine positions of the tool point (``TRAFOOF`` poses) or workpiece
        coordinates (``TRAORI`` poses), as programmed.
    rtcp : sequence of bool, length m
    description : str
    pivots_mm : dict axis -> (3,) [mm], optional
    tool_mm : (3,) [mm], optional
    covariance : ndarray, shape=(P, P), optional
        Identification covariance (kernel parameter order); gives ``predicted_after_um``.

    Returns
    -------
    CompensationStudyRow
        Errors per pose, shape=(m, 3) [µm], before and after.
    """
    kern = load_kernels(machine)
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    xyz = np.atleast_2d(np.asarray(xyz_mm, dtype=float))
    flags = np.asarray(rtcp, dtype=bool)
    n = a.shape[0]
    approach = approach_directions(a)
    pts = np.empty((n, 3))
    cmd_before = np.empty((n, 3))
    cmd_after = np.empty((n, 3))
    new_a = np.empty_like(a)
    for flag in (False, True):
        sel = np.flatnonzero(flags == flag)
        if sel.size == 0:
            continue
        comp = compensate_poses(machine, identified, a[sel], xyz[sel], rtcp=flag, pivots_mm=pivots_mm,
                                tool_mm=tool_mm, extensions=extensions, approach=approach[sel])
        pts[sel] = comp.points_mm
        new_a[sel] = comp.new_angles_deg
        if flag:  # the controller turns workpiece coordinates into machine positions nominally
            for j, row in enumerate(sel):
                cmd_before[row] = kern.linear_commands(a[row : row + 1], xyz[row], pivots_mm, tool_mm)[0]
                cmd_after[row] = kern.linear_commands(comp.new_angles_deg[j : j + 1], comp.new_xyz_mm[j], pivots_mm,
                                                    tool_mm)[0]
        else:
            cmd_before[sel] = xyz[sel]
            cmd_after[sel] = comp.new_xyz_mm
    before = tool_point_error(machine, truth, a, cmd_before, pts, pivots_mm=pivots_mm, tool_mm=tool_mm,
                              extensions=truth_extensions, approach=approach)
    after = tool_point_error(machine, truth, new_a, cmd_after, pts, pivots_mm=pivots_mm, tool_mm=tool_mm,
                             extensions=truth_extensions, approach=approach)
    rms_b = float(np.sqrt((before**2).sum(axis=1).mean()))
    rms_a = float(np.sqrt((after**2).sum(axis=1).mean()))
    pred = float("nan")
    if covariance is not None:
        q = covariance.shape[0]
        rot = kern.workpiece_rotation(a)
        total = 0.0
        for i in range(n):
            jac = kern.jacobian(a[i : i + 1], None, pts[i], pivots_mm, tool_mm)[0, :, :q]
            jac = jac + rot[i] @ kern.reference_jacobian(pts[i], pivots_mm, tool_mm)[:, :q]
            total += float(np.einsum("ip,pq,iq->", jac, covariance, jac))
        pred = math.sqrt(total / n)
    change = float(np.sqrt(((cmd_after - cmd_before) ** 2).sum(axis=1).mean()))
    return CompensationStudyRow(description, rms_b, rms_a, 1 - rms_a / rms_b if rms_b else 0.0, pred, change,
                                before, after)


def gather_report(measurement_paths: Sequence[str | os.PathLike[str]], *, studies: Iterable[str] = (),
                  program: str | os.PathLike[str] | None = None, method: str = "gauss-newton",
                  projection: str = "xyz", with_zero: bool = False, presets: int = 50, sobol_samples: int = 2048,
                  seed: int = 0, progress: bool = False) -> ReportData:
    """Compute everything a report shows (no files written).

    Parameters
    ----------
    measurement_paths : sequence of path-like
        ``pige-rtest 1`` files; all are read (and their truth sidecars checked) before
        any computation, so a bad file fails fast.
    studies : iterable of {"projection", "sobol"}
    program : path-like, optional
        An 840D-style NC program compensated with each measurement's estimate.
    method : {"gauss-newton", "double-differential", "diagnosis"}
        Primary estimate (module docstring).
    projection : str
        Excitation projection of the identification tables (the diagnosis uses xyz).
    with_zero : bool
        Also estimate the zero-position errors.
    presets : int
        Random presets of the projection study.
    sobol_samples : int
        Base sample size of the Sobol study (power of 2).
    seed : int
    progress : bool
        Show a tqdm progress bar on stderr.

    Returns
    -------
    ReportData

    Raises
    ------
    PigeError
        Bad input (file format, truth sidecar, program, option); the message names it.
    """
    if method not in PRIMARY_METHODS:
        raise InputError(f"unknown method {method!r}: use {', '.join(PRIMARY_METHODS)}")
    study_set = parse_studies(studies)
    if presets < 1:
        raise InputError("--presets must be at least 1")
    if sobol_samples < 2 or sobol_samples & (sobol_samples - 1):
        raise InputError(f"--samples must be a power of 2, got {sobol_samples}")
    paths = [Path(p) for p in measurement_paths]
    if not paths:
        raise InputError("give at least one measurement file")
    loaded = []
    for p in paths:
        m = read_measurement(p)
        loaded.append((p, m, read_truth(p, m.machine)))
    program_text = read_program(program) if program is not None else None
    labels = _labels(paths)
    steps_per_file = 4 + len(study_set) + (program is not None)
    reports: list[MeasurementReport] = []
    with tqdm(total=steps_per_file * len(paths), desc="report", unit="step", disable=not progress) as bar:
        for (p, m, truth), label in zip(loaded, labels, strict=True):
            bar.set_postfix_str(f"{p.name}: identification")
            results = {meth: identify(m, method=meth, projection=projection, with_zero=with_zero) for meth in METHODS}
            bar.update(1)
            bar.set_postfix_str(f"{p.name}: diagnosis")
            diag: DiagnosisResult | None = None
            diag_error = None
            try:
                diag = diagnose(m)
            except IdentificationError as exc:  # the data are fine; one candidate fit is not: report it, go on
                diag_error = str(exc)
            bar.update(1)
            primary = method if diag is not None or method != "diagnosis" else "gauss-newton"
            rep = _compensation(p, label, m, truth, results, diag, primary, bar)
            if diag_error is not None:
                rep.diagnosis_error = diag_error
                rep.notes.append(f"the diagnosis failed on these data ({diag_error})"
                                 + ("; the Gauss–Newton estimate is compensated instead" if primary != method
                                    else ""))
            if program_text is not None and program is not None:
                bar.set_postfix_str(f"{p.name}: program")
                _program(rep, Path(program), program_text)
                bar.update(1)
            kern = load_kernels(m.machine)
            traj = _measured_trajectory(m)
            if m.pivots_mm and study_set:
                rep.notes.append("the studies place the rotary-axis pivots at the origin (the file gives pivots)")
            if "projection" in study_set:
                bar.set_postfix_str(f"{p.name}: projection study")
                sigma = results["gauss-newton"].sigma_um
                noise = sigma if math.isfinite(sigma) and sigma > 0 else 0.25
                rep.projection = projection_study(kern.MACHINE_CODE, traj, presets=presets, noise_um=noise, seed=seed,
                                                  ball_mm=m.ball_mm, tool_mm=m.tool_mm, progress=False)
                rep.projection_noise_um = noise
                bar.update(1)
            if "sobol" in study_set:
                bar.set_postfix_str(f"{p.name}: Sobol indices")
                rep.sobol = sobol_study(kern.MACHINE_CODE, traj, n=sobol_samples, ball_mm=m.ball_mm,
                                        tool_mm=m.tool_mm, seed=seed)
                bar.update(1)
            bar.update(1)  # the figures are drawn by write_report; keep the step count honest
            reports.append(rep)
    settings = {"primary method": method, "projection": projection, "zero-position errors": str(with_zero),
                "studies": ", ".join(study_set) or "none"}
    if "projection" in study_set:
        settings["projection-study presets"] = str(presets)
    if "sobol" in study_set:
        settings["Sobol samples"] = str(sobol_samples)
    created = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    return ReportData(reports, study_set, None if program is None else Path(program), settings, created)


def _compensation(p: Path, label: str, m: Measurement, truth: Truth | None,
                  results: dict[str, IdentificationResult], diag: DiagnosisResult | None, method: str,
                  bar: Any) -> MeasurementReport:
    """Before/after on the measured trajectory with the primary estimate."""
    bar.set_postfix_str(f"{p.name}: compensation")
    kern = load_kernels(m.machine)
    rep = MeasurementReport(
        path=p, label=label, measurement=m, machine=kern.MACHINE_CODE, identification=results,
        primary_method=method, diagnosis=diag, compensation=[], compensation_basis="truth" if truth else "model",
        not_compensated=[], truth=truth,
    )
    identified, rep.not_compensated, covariance = rep.estimate()
    if method == "diagnosis" and diag is not None:
        rep.extensions, skipped = angle_extensions([f.to_dict() for f in diag.findings], tuple(kern.ROTARY_AXES))
        rep.extensions_not_compensated = [f"{effect} ({why})" for effect, why in skipped.items()]
    machine_values = truth.values if truth is not None else identified
    # the model-predicted machine carries what was identified, extensions included
    machine_extensions = truth.extensions if truth is not None else rep.extensions
    pivots = m.pivots_mm or None
    rep.compensation = compensation_study(kern.MACHINE_CODE, [_measured_trajectory(m)], truth=machine_values,
                                          identified=identified, covariance=covariance, ball_mm=m.ball_mm,
                                          tool_mm=m.tool_mm, pivots_mm=pivots, truth_extensions=machine_extensions,
                                          extensions=rep.extensions)
    if not rep.not_compensated:
        vec = np.array([identified.get(n, 0.0) for n in kern.PARAMETERS])
        rep.model_um = kern.deviation(m.angles_deg, vec, m.ball_mm, pivots, m.tool_mm)
    if truth is not None:
        rep.notes += truth.notes
    bar.update(1)
    return rep


def _program(rep: MeasurementReport, program: Path, text: str) -> None:
    """Compensate the NC program with the primary estimate; before/after on its poses."""
    m = rep.measurement
    kern = load_kernels(m.machine)
    prog = parse_program(text, path=str(program), rotary_axes=tuple(kern.ROTARY_AXES))
    angles, xyz, rtcp, _lines = poses_from_program(prog)
    if angles.shape[0] == 0:
        raise InputError(f"{program}: no pose with every axis programmed (X, Y, Z, {', '.join(kern.ROTARY_AXES)})")
    res = rep.primary
    identified, _missing, covariance = rep.estimate()
    machine_values = rep.truth.values if rep.truth is not None else identified
    machine_extensions = rep.truth.extensions if rep.truth is not None else rep.extensions
    pivots = m.pivots_mm or None
    row = program_before_after(rep.machine, machine_values, identified, angles, xyz, rtcp,
                               description=f"NC program {program.name} ({angles.shape[0]} poses)", pivots_mm=pivots,
                               tool_mm=m.tool_mm, covariance=covariance, truth_extensions=machine_extensions,
                               extensions=rep.extensions)
    rep.compensation.append(row)
    params = CompensationParameters(
        machine=rep.machine, values=identified, units={k: res.units.get(k, "") for k in identified},
        tool_mm=None if m.tool_mm is None else [float(x) for x in m.tool_mm],
        pivots_mm={k: [float(x) for x in v] for k, v in m.pivots_mm.items()},
        source=f"{rep.path.name} ({rep.primary_method})",
        ignored=list(rep.not_compensated) + list(rep.extensions_not_compensated), extensions=list(rep.extensions),
    )
    rep.compensated_program_text = compensate_program(text, params, path=str(program))


# ---------------------------------------------------------------------------------------------
# figures


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    fig.savefig(path, dpi=90)
    _pyplot().close(fig)
    return path


def deviation_figure(m: Measurement, model_um: np.ndarray | None) -> Any:
    """Deviation components against the point index above the commanded angles.

    Parameters
    ----------
    m : Measurement
    model_um : ndarray, shape=(n, 3) [µm] or None
        PIGE-model deviation (machine frame) to overlay.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    dev = m.deviation_machine_um()
    idx = np.arange(m.n_rows)
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(9, 5.6), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    colors = ("tab:blue", "tab:orange", "tab:green")
    for k, c in enumerate("xyz"):
        ax0.plot(idx, dev[:, k], "o-", ms=3.5, lw=1, color=colors[k], label=f"d{c} measured")
        if model_um is not None:
            ax0.plot(idx, model_um[:, k], "--", lw=1, color=colors[k], alpha=0.8, label=f"d{c} PIGE model")
    ax0.axhline(0, color="k", lw=0.6)
    ax0.set_ylabel("deviation ball − nest [µm]")
    ax0.set_title("R-test deviation, machine frame" + (" (converted from the table frame)" if m.frame == "table"
                                                       else ""), fontsize=10)
    ax0.legend(fontsize=7, ncol=3 if model_um is None else 2, loc="best")
    ax0.grid(alpha=0.3)
    for k, a in enumerate(m.rotary_axes):
        ax1.plot(idx, m.angles_deg[:, k], ".-", lw=1, label=f"{a}")
    ax1.set_xlabel("measurement point (0 = reference pose)")
    ax1.set_ylabel("commanded angle [deg]")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def polar_axis(m: Measurement) -> int | None:
    """Index of the rotary axis that turns through at least 180° (the largest span), or None."""
    spans = np.ptp(m.angles_deg, axis=0)
    k = int(np.argmax(spans))
    return k if spans[k] >= 180.0 else None


def polar_figure(m: Measurement, model_um: np.ndarray | None, axis_index: int) -> Any:
    """Deviation components magnified about a nominal circle against one rotary angle.

    The radius is ``R0 + d`` [µm] with ``R0`` a round offset larger than the largest
    deviation; the dashed circle is zero deviation and the radial ticks read in µm of
    deviation.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    dev = m.deviation_machine_um()
    theta = np.radians(m.angles_deg[:, axis_index])
    peak = float(np.abs(dev).max())
    if model_um is not None:
        peak = max(peak, float(np.abs(model_um).max()))
    step = _nice_step(peak if peak > 0 else 1.0)
    r0 = 2 * step * math.ceil(peak / step if peak > 0 else 1.0)
    fig, axs = plt.subplots(1, 3, figsize=(11, 4), subplot_kw={"projection": "polar"})
    circle = np.linspace(0, 2 * np.pi, 361)
    ticks = np.arange(-r0 / 2, r0 / 2 + step / 2, step)
    ticks = ticks[(ticks >= -r0 + 1e-12)]
    colors = ("tab:blue", "tab:orange", "tab:green")
    for k, (ax, c) in enumerate(zip(axs, "xyz", strict=True)):
        ax.plot(circle, np.full_like(circle, r0), "k--", lw=0.8)
        ax.plot(theta, r0 + dev[:, k], "o-", ms=3, lw=1, color=colors[k], label="measured")
        if model_um is not None:
            ax.plot(theta, r0 + model_um[:, k], "-", lw=0.8, color="0.3", alpha=0.8, label="PIGE model")
        ax.set_rlim(0, r0 + r0 / 2 + step / 2)
        ax.set_rticks(r0 + ticks)
        ax.set_yticklabels([f"{t:+g}" for t in ticks], fontsize=7)
        ax.set_title(f"d{c} [µm] vs {m.rotary_axes[axis_index]} [deg]", fontsize=10)
        ax.tick_params(axis="x", labelsize=7)
        if k == 0:
            ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(-0.25, -0.15))
    fig.suptitle(f"deviation about the nominal circle (dashed = 0 µm, ring step {step:g} µm)", fontsize=10)
    fig.tight_layout()
    return fig


def _nice_step(x: float) -> float:
    """A 1-2-5 step near x/2."""
    target = x / 2
    exp = math.floor(math.log10(target))
    for mult in (1, 2, 5, 10):
        if mult * 10**exp >= target:
            return float(mult * 10**exp)
    return float(10 ** (exp + 1))  # pragma: no cover


def identification_figure(results: dict[str, IdentificationResult], truth: Truth | None) -> Any:
    """Estimates with 95 % intervals per parameter and method; truth as crosses; no bar where undetermined.

    Two panels: position errors [µm], orientation and zero-position errors [µrad].

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    from matplotlib.transforms import blended_transform_factory

    first = next(iter(results.values()))
    groups = [("position errors", "um"), ("orientation / zero-position errors", "urad")]
    fig, axs = plt.subplots(1, 2, figsize=(11, 3.8))
    markers = {"gauss-newton": ("o", "tab:blue"), "double-differential": ("s", "tab:purple")}
    for ax, (title, unit) in zip(axs, groups, strict=True):
        names = [n for n in first.parameters if first.units.get(n) == unit and "." not in n]
        x = np.arange(len(names))
        for i, (meth, res) in enumerate(results.items()):
            ci = res.ci95()
            mk, col = markers.get(meth, ("^", "tab:gray"))
            off = (i - (len(results) - 1) / 2) * 0.22
            for j, name in enumerate(names):
                q = res.parameters.index(name)
                v = res.values[q]
                if math.isfinite(v):
                    ax.errorbar(x[j] + off, v, yerr=[[v - ci[q, 0]], [ci[q, 1] - v]], fmt=mk, color=col, ms=5,
                                capsize=3, label=meth if j == 0 else None)
                else:  # no value: a label at mid-height (axes coordinates), never a number
                    ax.text(x[j] + off, 0.5, "not identifiable", transform=blended_transform_factory(
                        ax.transData, ax.transAxes), fontsize=6.5, color="crimson", ha="center", va="center",
                        rotation=90)
        if truth is not None:
            ax.plot(x, [truth.values.get(n, 0.0) for n in names], "x", color="crimson", ms=8, mew=2, label="truth")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x)
        ax.set_xticklabels(names)
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.set_ylabel(f"value [{UNIT_TEXT.get(unit, unit)}]")
        ax.set_title(f"{title} (95 % intervals)", fontsize=10)
        ax.grid(alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        if handles:
            ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def sobol_figure(study: SobolStudy) -> Any:
    """Total Sobol indices per parameter, one bar group per projection.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.6))
    n_proj = len(study.projections)
    x = np.arange(len(study.parameters))
    width = 0.8 / max(n_proj, 1)
    for i, proj in enumerate(study.projections):
        ax.bar(x + (i - (n_proj - 1) / 2) * width, study.total_order[i], width, label=f"{proj} (total)")
    ax.set_xticks(x)
    ax.set_xticklabels(study.parameters)
    ax.set_ylabel("total Sobol index [-]")
    ax.set_title("sensitivity of the mean-square projected deviation to each PIGE", fontsize=10)
    ax.legend(fontsize=7, ncol=n_proj)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    return fig


def draw_figures(rep: MeasurementReport, out_dir: Path) -> list[ReportFigure]:
    """Write every PNG of one measurement into ``out_dir`` (created); returns them in page order."""
    out_dir.mkdir(parents=True, exist_ok=True)
    m = rep.measurement
    figs: list[ReportFigure] = []
    overlay = "; dashed: PIGE model of the " + rep.primary_method + " estimate" if rep.model_um is not None else (
        "; no model overlay: a parameter is undetermined")
    figs.append(ReportFigure("deviation", _save(deviation_figure(m, rep.model_um), out_dir / "deviation.png"),
                             f"Deviation ball − nest per measurement point [µm], machine frame, with the commanded "
                             f"rotary angles [deg]{overlay}."))
    k = polar_axis(m)
    if k is not None:
        figs.append(ReportFigure("polar", _save(polar_figure(m, rep.model_um, k), out_dir / "deviation_polar.png"),
                                 f"Deviation components against the {m.rotary_axes[k]} angle, magnified about a "
                                 f"nominal circle (dashed line = zero deviation; radial labels in µm)."))
    figs.append(ReportFigure("identification", _save(identification_figure(rep.identification, rep.truth),
                                                     out_dir / "identification.png"),
                             "Identified PIGEs with 95 % confidence intervals, both methods"
                             + ("; red crosses: truth from the sidecar." if rep.truth is not None else ".")))
    paths: list[str] = []
    if rep.diagnosis is not None:
        try:
            paths = residual_plots(m, rep.diagnosis, out_dir)
        except InputError:
            paths = []
    captions = {"residual_time": "Residual of the PIGE fit against time [µm] (thermal drift shows as a trend).",
                "residual_rows": "Residual norm per row (red: outliers) and its autocorrelation in time.",
                "residual_approach": "Tangential residual by direction of approach (backlash shows as a split)."}
    for path in paths:
        stem = Path(path).stem
        cap = captions.get(stem, f"Residual of the PIGE fit in the radial / tangential / axial frame of axis "
                                 f"{stem.removeprefix('residual_')} [µm] against its angle (harmonics show at their "
                                 "order).")
        figs.append(ReportFigure("residual", Path(path), cap))
    basis = ("simulated with the true parameters of the sidecar" if rep.compensation_basis == "truth" else
             "model-predicted: the machine is assumed to carry exactly the identified errors")
    for path, row in zip(plot_compensation(rep.compensation, out_dir), rep.compensation, strict=True):
        figs.append(ReportFigure("compensation", Path(path),
                                 f"Tool-point error before and after compensation [µm], {row.trajectory} ({basis})."))
    if rep.sobol is not None:
        figs.append(ReportFigure("sobol", _save(sobol_figure(rep.sobol), out_dir / "sobol.png"),
                                 "Total Sobol indices of the mean-square projected deviation, per projection."))
    return figs


def write_report(data: ReportData, out_dir: str | os.PathLike[str]) -> Path:
    """Draw the figures, write the compensated programs and ``out_dir/report.html``; returns the HTML path."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    for rep in data.measurements:
        sub = out / rep.label
        rep.figures = draw_figures(rep, sub)
        text = rep.compensated_program_text
        if text is not None and data.program is not None:
            target = sub / f"{data.program.stem}_compensated{data.program.suffix or '.mpf'}"
            with open(target, "w", encoding="utf-8", newline="") as fh:
                fh.write(text)
            rep.compensated_program = target
    html_path = out / "report.html"
    atomic_write_text(html_path, render_html(data, base=out))
    data.html_path = html_path
    return html_path


def build_report(measurement_paths: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str], *,
                 studies: Iterable[str] = (), program: str | os.PathLike[str] | None = None,
                 method: str = "gauss-newton", projection: str = "xyz", with_zero: bool = False,
                 presets: int = 50, sobol_samples: int = 2048, seed: int = 0, progress: bool = False) -> Path:
    """Build the report of measurement files into ``out_dir``; returns the path of ``report.html``.

    Parameters are those of :func:`gather_report`; PNGs are kept in ``out_dir/<label>/``.
    """
    data = gather_report(measurement_paths, studies=studies, program=program, method=method, projection=projection,
                         with_zero=with_zero, presets=presets, sobol_samples=sobol_samples, seed=seed,
                         progress=progress)
    return write_report(data, out_dir)


# ---------------------------------------------------------------------------------------------
# HTML

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:0;color:#1d232a;
background:#f6f7f9;line-height:1.4}
header,main,footer{max-width:1150px;margin:0 auto;padding:0 18px}
header{padding-top:18px}
h1{font-size:1.6em;margin:.2em 0}
h2{font-size:1.3em;border-bottom:2px solid #2b6cb0;padding-bottom:3px;margin-top:1.6em}
h3{font-size:1.08em;margin:1.2em 0 .4em;color:#2b4a6f}
section.measurement{background:#fff;border:1px solid #d9dee5;border-radius:6px;padding:6px 18px 18px;margin:18px 0}
table{border-collapse:collapse;margin:.4em 0 .8em;font-size:.86em}
th,td{border:1px solid #d0d6de;padding:3px 7px;text-align:left;vertical-align:top}
th{background:#eef2f7}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr.unid td{background:#fde8e8}
span.unid,.bad{color:#b00020;font-weight:600}
.ok{color:#1b7f3a;font-weight:600}
.note{background:#fff8e1;border-left:4px solid #f0b400;padding:6px 10px;margin:.6em 0;font-size:.92em}
figure{margin:.8em 0}
.figrow{display:flex;flex-wrap:wrap;gap:0 14px}
.figrow figure{flex:1 1 480px;max-width:100%}
figure img{max-width:100%;height:auto;border:1px solid #e2e6ea}
figcaption{font-size:.85em;color:#4a5563}
nav a{margin-right:12px}
.nw{white-space:nowrap}
code{background:#eef2f7;padding:0 3px;border-radius:3px}
ul.verdict li{margin:.25em 0}
footer{font-size:.8em;color:#5c6670;padding-bottom:30px}
"""


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _u(unit: str) -> str:
    return UNIT_TEXT.get(unit, unit)


def _f(x: float | None, fmt: str = ".3f", none: str = "—") -> str:
    if x is None:
        return none
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return none
    if math.isnan(xf):
        return none
    if math.isinf(xf):
        return "∞" if xf > 0 else "−∞"
    return format(xf, fmt)


def _table(head: Sequence[str], rows: Iterable[Sequence[str]], *, row_classes: Sequence[str] | None = None,
           num_cols: Iterable[int] = ()) -> str:
    """An HTML table; ``head`` is escaped, cells are already HTML."""
    nums = set(num_cols)
    out = ["<table>", "<thead><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr></thead>", "<tbody>"]
    for i, row in enumerate(rows):
        cls = row_classes[i] if row_classes and row_classes[i] else ""
        attr = f' class="{_e(cls)}"' if cls else ""
        cells = "".join(f'<td class="num">{c}</td>' if j in nums else f"<td>{c}</td>" for j, c in enumerate(row))
        out.append(f"<tr{attr}>{cells}</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _kv(items: Iterable[tuple[str, str]]) -> str:
    """Two-column key/value table; keys escaped, values already HTML."""
    return "<table>" + "".join(f"<tr><th>{_e(k)}</th><td>{v}</td></tr>" for k, v in items) + "</table>"


def _img(fig: ReportFigure, base: Path | None) -> str:
    data = base64.b64encode(fig.path.read_bytes()).decode("ascii")
    shown = fig.path.relative_to(base) if base is not None and fig.path.is_relative_to(base) else fig.path
    return (f'<figure data-figure="{_e(fig.key)}"><img src="data:image/png;base64,{data}" '
            f'alt="{_e(fig.caption)}"><figcaption>{_e(fig.caption)} <span class="file">({_e(shown)})</span>'
            "</figcaption></figure>")


def _figs(rep: MeasurementReport, key: str, base: Path | None) -> str:
    return "\n".join(_img(f, base) for f in rep.figures if f.key == key)


def _summary_html(rep: MeasurementReport) -> str:
    m = rep.measurement
    kern = load_kernels(m.machine)
    dev = m.deviation_machine_um()
    norms = np.linalg.norm(dev, axis=1)
    side = {a: ("workpiece side" if a in kern.WORKPIECE_ROTARY else "tool side") for a in kern.ROTARY_AXES}
    axes = ", ".join(f"{a} ({side[a]}, {_f(m.angles_deg[:, k].min(), '.1f')} … {_f(m.angles_deg[:, k].max(), '.1f')}°)"
                     for k, a in enumerate(m.rotary_axes))
    items = [
        ("file", f"<code>{_e(rep.path)}</code>"),
        ("machine", f"<code>{_e(rep.machine)}</code>" + (f" (written as <code>{_e(m.machine)}</code>)"
                                                         if m.machine != rep.machine else "")),
        ("rotary axes", _e(axes)),
        ("ball at the reference pose", _e(", ".join(_f(x, "g") for x in m.ball_mm) + " mm")),
    ]
    if m.tool_mm is not None:
        items.append(("tool (ball from the last tool-side pivot)", _e(", ".join(_f(x, "g") for x in m.tool_mm)
                                                                      + " mm")))
    for ax, pv in m.pivots_mm.items():
        items.append((f"nominal pivot of {ax}", _e(", ".join(_f(x, "g") for x in pv) + " mm")))
    items += [
        ("trajectory", _e(m.trajectory or "not stated in the file")),
        ("points", _e(f"{m.n_rows} rows (the reference pose and {m.n_rows - 1} measured points) over "
                      f"{_f(m.t_s[-1] - m.t_s[0], '.0f')} s")),
        ("frame of the deviations", _e(m.frame)),
        ("largest deviation", _e(f"|d| max {_f(norms.max())} µm; per component max |dx| {_f(np.abs(dev[:, 0]).max())}"
                                 f", |dy| {_f(np.abs(dev[:, 1]).max())}, |dz| {_f(np.abs(dev[:, 2]).max())} µm")),
        ("RMS of |d| over the points", _e(f"{_f(math.sqrt(float((norms[1:] ** 2).mean())) if m.n_rows > 1 else 0.0)}"
                                          " µm")),
    ]
    if "source" in m.metadata:
        items.append(("source", _e(m.metadata["source"])))
    extra = [c for c in m.optional] + list(m.extra_columns)
    if extra:
        items.append(("other columns", _e(", ".join(extra))))
    items.append(("truth sidecar", _e(rep.truth.path) if rep.truth is not None else "none (real measurement or "
                                                                                     "truth unknown)"))
    return _kv(items)


def _status(res: IdentificationResult, j: int) -> tuple[str, bool]:
    """(HTML status, flagged) of parameter j."""
    if not bool(res.identifiable[j]):
        return '<span class="unid">NOT IDENTIFIABLE — no value</span>', True
    if not math.isfinite(res.values[j]):
        return '<span class="unid">not fixed by any differential — no value</span>', True
    return '<span class="ok">identified</span>', False


def _identification_html(rep: MeasurementReport) -> str:
    gn = rep.identification["gauss-newton"]
    dd = rep.identification["double-differential"]
    truth = rep.truth
    ci = gn.ci95()
    ci_dd = dd.ci95()
    fixed_at = {p: s.index for s in dd.stages for p in s.fixed}
    head = ["parameter", "unit", "Gauss–Newton value", "std", "95 % interval", "VIF", "status (GN)",
            "double-diff. value", "std", "95 % interval", "fixed at stage", "status (DD)"]
    if truth is not None:
        head += ["truth", "error (GN)", "|error| / std"]
    rows, classes = [], []
    for j, name in enumerate(gn.parameters):
        u = _u(gn.units.get(name, ""))
        st_gn, bad_gn = _status(gn, j)
        jd = dd.parameters.index(name)
        st_dd, bad_dd = _status(dd, jd)
        vif = gn.vif[j] if gn.vif is not None else float("nan")
        if bad_gn:
            cells_gn = ["not identifiable", "—", "—", _f(vif, ".3g")]
        else:
            cells_gn = [_f(gn.values[j]), _f(gn.std[j]), f"[{_f(ci[j, 0])}, {_f(ci[j, 1])}]", _f(vif, ".3g")]
        if bad_dd:
            cells_dd = ["no value", "—", "—", _e(fixed_at.get(name, "—"))]
        else:
            cells_dd = [_f(dd.values[jd]), _f(dd.std[jd]), f"[{_f(ci_dd[jd, 0])}, {_f(ci_dd[jd, 1])}]",
                        _e(fixed_at.get(name, "—"))]
        row = [f"<b>{_e(name)}</b>", _e(u), *cells_gn, st_gn, *cells_dd, st_dd]
        if truth is not None:
            t = truth.values.get(name, 0.0)
            if bad_gn:
                row += [_f(t), "—", "—"]
            else:
                err = gn.values[j] - t
                ratio = abs(err) / gn.std[j] if gn.std[j] > 0 else float("inf")
                row += [_f(t), _f(err, "+.3f"), _f(ratio, ".2f")]
        rows.append(row)
        classes.append("unid" if (bad_gn or bad_dd) else "")
    num_cols = [2, 3, 4, 5, 7, 8, 9, 10] + ([12, 13, 14] if truth is not None else [])
    parts = [_table(head, rows, row_classes=classes, num_cols=num_cols)]
    n_bad = int((~gn.identifiable).sum())
    if n_bad:
        parts.append(f'<p class="note"><span class="unid">{n_bad} parameter(s) are not identifiable from these data'
                     "</span>: no value is reported for them and they are compensated as 0.</p>")
    obs = ", ".join(f"{k} = {_f(v, '.3g')}" for k, v in gn.observability.items())
    facts = [
        ("projection / loss", _e(f"{gn.projection} / {gn.loss}")),
        ("rank", _e(f"{gn.rank} of {len(gn.parameters)}") + ("" if gn.rank == len(gn.parameters)
                                                            else ' <span class="unid">(rank-deficient)</span>')),
        ("condition number (scaled)", _e(_f(gn.condition, ".4g"))),
        ("residual RMS / σ", _e(f"{_f(gn.rms_um, '.4f')} µm / {_f(gn.sigma_um, '.4f')} µm "
                                f"({gn.n_obs} observations, {gn.dof} degrees of freedom)")),
        ("observability indices", _e(obs) + " <small>(O1 Borm–Menq, O2 Driels–Pathre, O3 Nahvi, O4 noise "
                                            "amplification, O5 Sun–Hollerbach; scaled columns)</small>"),
        ("singular values (scaled)", _e(", ".join(_f(s, ".3g") for s in gn.singular_values))),
    ]
    if gn.outlier_rows:
        facts.append(("outlier rows", _e(gn.outlier_rows)))
    parts.append(_kv(facts))
    parts.append("<h4>Unidentifiable combinations</h4>")
    if gn.unidentifiable:
        parts.append('<ul class="combos">' + "".join(f'<li><span class="unid">{_e(c)}</span></li>'
                                                       for c in gn.unidentifiable) + "</ul>")
    else:
        parts.append("<p>None: every parameter combination is determined by the data.</p>")
    parts.append("<h4>Stages of the double-differential scheme</h4>")
    parts.append(_stages_html(dd))
    return "\n".join(parts)


def _stages_html(dd: IdentificationResult) -> str:
    if not dd.stages:
        return "<p>No stage.</p>"
    head = ["stage", "solved", "rank", "condition", "fixed at this stage", "values ± std (VIF)"]
    rows = []
    for s in dd.stages:
        vals = []
        for p in s.solved:
            u = _u(dd.units.get(p, ""))
            std = s.std.get(p)
            if std is None or not math.isfinite(s.vif.get(p, float("inf"))):
                vals.append(f'{_e(p)}: <span class="unid">not identifiable at this stage</span>')
            else:
                mark = "<b>" if p in s.fixed else ""
                end = "</b>" if p in s.fixed else ""
                vals.append(f"{mark}{_e(p)} = {_f(s.values[p])} ± {_f(std)} {_e(u)} (VIF {_f(s.vif[p], '.3g')})"
                            f"{end}")
        rows.append([_e(s.index), _e(len(s.solved)), _e(f"{s.rank}/{len(s.solved)}"), _e(_f(s.condition, ".4g")),
                     _e(", ".join(s.fixed) or "none"), "<br>".join(vals)])
    return _table(head, rows, num_cols=[0, 1, 3]) + (
        "<p><small>A parameter is fixed when it is individually identifiable and its variance inflation factor is "
        "at most 10; fixed parameters (bold) are substituted and the rest re-solved.</small></p>")


def _final_html(res: IdentificationResult) -> str:
    head = ["parameter", "value", "std", "unit", "status"]
    rows, classes = [], []
    for j, name in enumerate(res.parameters):
        st, bad = _status(res, j)
        rows.append([_e(name), "not identifiable" if bad else _f(res.values[j]), "—" if bad else _f(res.std[j]),
                     _e(_u(res.units.get(name, ""))), st])
        classes.append("unid" if bad else "")
    return _table(head, rows, row_classes=classes, num_cols=[1, 2])


def _diagnosis_html(rep: MeasurementReport, base: Path | None) -> str:
    d = rep.diagnosis
    if d is None:
        return (f'<p class="note"><span class="bad">The diagnosis failed on these data: {_e(rep.diagnosis_error)}'
                "</span>. The identification above does not depend on it.</p>")
    parts = [_kv([
        ("baseline PIGE fit", _e(f"residual RMS {_f(d.baseline_rms_um, '.4f')} µm, held-out RMS "
                                 f"{_f(d.baseline_heldout_rms_um, '.4f')} µm, BIC {_f(d.baseline_bic, '.1f')}")),
        ("outlier rows", _e(d.outlier_rows or "none")),
    ])]
    parts.append("<h4>Verdict</h4>")
    if d.findings:
        parts.append('<ul class="verdict">' + "".join(f"<li>{_e(f.sentence())}</li>" for f in d.findings) + "</ul>")
    else:
        parts.append(f"<p>{_e(d.verdict())}</p>")
    parts.append("<h4>Findings</h4>")
    if d.findings:
        head = ["effect", "parameters ± std", "ΔBIC", "F / p", "RMS before → after [µm]",
                "held-out RMS before → after [µm]", "explained", "PIGE shifts", "evidence"]
        rows = []
        for f in d.findings:
            opts = "".join(f" {k}={v:g}" for k, v in f.options.items())
            params = "<br>".join(f"{_e(k)} = {_f(v, '.4g')} ± {_f(f.std.get(k), '.2g')} {_e(_u(f.units.get(k, '')))}"
                                 for k, v in f.params.items())
            shifts = sorted(f.pige_shift.items(), key=lambda kv: -abs(kv[1]))
            shift_txt = "<br>".join(f'<span class="nw">{_e(k)} {_f(v, "+.3g")} {_e(_u(d.final.units.get(k, "")))}'
                                    "</span>" for k, v in shifts[:4] if abs(v) > 0) or "—"
            rows.append([f"<b>{_e(f.effect)}</b>{_e(opts)}", params, _f(f.delta_bic, ".1f"),
                         f"{_f(f.f_statistic, '.3g')} / {_f(f.p_value, '.2g')}",
                         f"{_f(f.rms_um_before, '.4f')} → {_f(f.rms_um_after, '.4f')}",
                         f"{_f(f.heldout_rms_um_before, '.4f')} → {_f(f.heldout_rms_um_after, '.4f')}",
                         _f(f.explained * 100 if math.isfinite(f.explained) else float("nan"), ".0f") + " %",
                         shift_txt, _e(f.evidence)])
        parts.append(_table(head, rows, num_cols=[2, 3, 4, 5, 6]))
        parts.append("<h4>Final estimates with the accepted extensions</h4>")
        parts.append(_final_html(d.final))
        if rep.extensions:
            ids = ", ".join(e.spec.id for e in rep.extensions)
            parts.append(f"<p><small>Compensated with the PIGEs: {_e(ids)} (pose-dependent zero errors).</small></p>")
        for why in rep.extensions_not_compensated:
            parts.append(f"<p><small>Not compensated: {_e(why)}.</small></p>")
        if not rep.extensions and not rep.extensions_not_compensated:
            parts.append("<p><small>Accepted extensions are compensated only when the report's method is "
                         "<code>diagnosis</code>.</small></p>")
    else:
        parts.append("<p>No finding: the PIGE model explains the data down to the noise.</p>")
    parts.append("<h4>Rejected candidates</h4>")
    if d.rejected:
        rows = [[_e(r.effect), _e(" ".join(f"{k}={v:g}" for k, v in r.options.items()) or "—"), _e(r.reason),
                 _f(r.delta_bic, ".1f"), _f(r.p_value, ".2g")] for r in d.rejected]
        parts.append(_table(["candidate", "options", "why not accepted", "ΔBIC", "p"], rows, num_cols=[3, 4]))
    else:
        parts.append("<p>None.</p>")
    parts.append("<h4>Residual plots</h4>")
    figs = _figs(rep, "residual", base)
    parts.append(f'<div class="figrow">{figs}</div>' if figs else "<p>No residual plot (no residuals to plot).</p>")
    return "\n".join(parts)


def _compensation_html(rep: MeasurementReport, base: Path | None) -> str:
    parts = []
    if rep.compensation_basis == "truth":
        assert rep.truth is not None
        parts.append(f"<p>Before/after <b>simulated</b> on a machine with the true parameters of "
                     f"<code>{_e(rep.truth.path.name)}</code>, compensated with the {_e(rep.primary_method)} "
                     "estimate.</p>")
    else:
        parts.append(f'<p class="note">No truth sidecar: the before/after is <b>model-predicted</b>. The machine is '
                     f"assumed to carry exactly the identified errors ({_e(rep.primary_method)}), so “after” shows "
                     "only what the compensation itself leaves (second-order terms). What to expect on the real "
                     "machine: the column “expected after, from the std” (identification uncertainty alone), plus "
                     f"what the PIGE model does not explain (residual RMS {_f(rep.primary.rms_um, '.3f')} µm).</p>")
    if rep.not_compensated:
        unknown = (" The model-predicted machine carries 0 for them too: their real errors are unknown and not in "
                   "these numbers." if rep.compensation_basis == "model" else "")
        parts.append(f'<p class="note"><span class="unid">Not compensated (no value): '
                     f"{_e(', '.join(rep.not_compensated))}</span> — set to 0.{_e(unknown)}</p>")
    head = ["test", "RMSE before [µm]", "RMSE after [µm]", "reduction", "expected after, from the std [µm]",
            "command change RMS [µm]"]
    rows = [[_e(r.trajectory), _f(r.rmse_before_um), _f(r.rmse_after_um), _f(r.reduction * 100, ".1f") + " %",
             _f(r.predicted_after_um, ".3f", "n/a"), _f(r.command_change_rmse_mm * 1e3, ".2f")]
            for r in rep.compensation]
    parts.append(_table(head, rows, num_cols=[1, 2, 3, 4, 5]))
    if rep.compensated_program is not None:
        parts.append(f"<p>Compensated NC program written to <code>{_e(rep.compensated_program)}</code>.</p>")
    parts.append(_figs(rep, "compensation", base))
    return "\n".join(parts)


def _projection_html(rep: MeasurementReport) -> str:
    st = rep.projection
    assert st is not None
    head = ["projection", "rank", "condition", "success rate", "unobserved", "undetermined combinations",
            "determined rate per PIGE"]
    rows, classes = [], []
    for r in st.rows:
        det = ", ".join(f"{k} {v:.0%}" for k, v in r.determined_rate.items())
        und = "<br>".join(f'<span class="unid">{_e(c)}</span>' for c in r.unidentifiable) or "—"
        rows.append([_e(r.projection), _e(f"{r.rank}/{r.n_parameters}"), _f(r.condition, ".3g"),
                     _f(r.success_rate * 100, ".0f") + " %", _e(", ".join(r.unobserved) or "—"), und, _e(det)])
        classes.append("" if r.rank == r.n_parameters else "unid")
    noise = _f(rep.projection_noise_um, ".3g")
    return (f"<p>{_e(st.presets)} random presets simulated on the measured trajectory with {noise} µm noise (the "
            "Gauss–Newton σ) and identified with the double-differential scheme per projection; a preset succeeds "
            "when every PIGE gets a value within 4 standard errors of the preset.</p>"
            + _table(head, rows, row_classes=classes, num_cols=[2, 3]) + f"<p>{_e(st.verdict)}</p>")


def _sobol_html(rep: MeasurementReport, base: Path | None) -> str:
    st = rep.sobol
    assert st is not None
    head = ["parameter"] + [f"{p} {k}" for p in st.projections for k in ("S1", "ST")]
    rows = [[_e(name)] + [_f(v, ".3f") for i in range(len(st.projections))
                          for v in (st.first_order[i, j], st.total_order[i, j])]
            for j, name in enumerate(st.parameters)]
    return (f"<p>First-order (S1) and total (ST) indices of the mean-square projected deviation over the measured "
            f"trajectory, every PIGE uniform on ±15 µm / µrad, {st.n_samples} base samples.</p>"
            + _table(head, rows, num_cols=range(1, 1 + 2 * len(st.projections))) + _figs(rep, "sobol", base))


def _measurement_html(i: int, rep: MeasurementReport, base: Path | None) -> str:
    sid = f"m{i + 1}"
    parts = [f'<section class="measurement" id="{sid}" data-file="{_e(rep.path)}">',
             f"<h2>{i + 1}. {_e(rep.path.name)} — <code>{_e(rep.machine)}</code></h2>"]
    for note in rep.notes:
        parts.append(f'<p class="note">{_e(note)}</p>')
    parts += [f'<section data-section="summary" id="{sid}-summary"><h3>Machine and test</h3>',
              _summary_html(rep), "</section>",
              f'<section data-section="deviations" id="{sid}-deviations"><h3>Measured deviations</h3>',
              _figs(rep, "deviation", base), _figs(rep, "polar", base), "</section>",
              f'<section data-section="identification" id="{sid}-identification"><h3>Identified PIGEs</h3>',
              _figs(rep, "identification", base), _identification_html(rep), "</section>",
              f'<section data-section="diagnosis" id="{sid}-diagnosis"><h3>Diagnosis</h3>',
              _diagnosis_html(rep, base), "</section>",
              f'<section data-section="compensation" id="{sid}-compensation"><h3>Compensation before/after</h3>',
              _compensation_html(rep, base), "</section>"]
    if rep.projection is not None:
        parts += [f'<section data-section="projection-study" id="{sid}-projection"><h3>Projection study</h3>',
                  _projection_html(rep), "</section>"]
    if rep.sobol is not None:
        parts += [f'<section data-section="sobol" id="{sid}-sobol"><h3>Sobol indices</h3>',
                  _sobol_html(rep, base), "</section>"]
    parts.append("</section>")
    return "\n".join(parts)


def findings_text(rep: MeasurementReport) -> str:
    """One-line diagnosis outcome."""
    if rep.diagnosis is None:
        return f"diagnosis failed ({rep.diagnosis_error})"
    return ", ".join(f.effect for f in rep.diagnosis.findings) or "no effect beyond the PIGEs"


def _overview_html(data: ReportData) -> str:
    head = ["#", "file", "machine", "points", "rank", "residual RMS [µm]", "diagnosis", "RMSE before → after [µm]"]
    rows = []
    for i, rep in enumerate(data.measurements):
        gn = rep.identification["gauss-newton"]
        findings = findings_text(rep)
        comp = rep.compensation[0]
        rank = _e(f"{gn.rank}/{len(gn.parameters)}")
        if gn.rank < len(gn.parameters):
            rank = f'<span class="unid">{rank}</span>'
        rows.append([f'<a href="#m{i + 1}">{i + 1}</a>', f"<code>{_e(rep.path.name)}</code>",
                     f"<code>{_e(rep.machine)}</code>", _e(rep.measurement.n_rows), rank, _f(gn.rms_um, ".4f"),
                     _e(findings), f"{_f(comp.rmse_before_um)} → {_f(comp.rmse_after_um)}"
                     + (" (model)" if rep.compensation_basis == "model" else "")])
    return _table(head, rows, num_cols=[3, 5])


def render_html(data: ReportData, *, base: Path | None = None) -> str:
    """The report page: one self-contained HTML document (inline CSS, PNGs as data URIs, no script).

    Parameters
    ----------
    data : ReportData
        With figures drawn (:func:`draw_figures`).
    base : Path, optional
        Figure paths are shown relative to it.
    """
    nav = " ".join(f'<a href="#m{i + 1}">{_e(r.path.name)}</a>' for i, r in enumerate(data.measurements))
    settings = "; ".join(f"{k}: {v}" for k, v in data.settings.items())
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>pige_sym calibration report</title>",
        f"<style>{CSS}</style></head><body>",
        "<header><h1>Five-axis calibration report (R-test)</h1>",
        f"<p>pige_sym {_e(__version__)} — {_e(data.created)} — {_e(settings)}"
        + (f" — NC program <code>{_e(data.program)}</code>" if data.program is not None else "") + "</p>",
        f"<nav>{nav}</nav></header><main>",
        '<section data-section="overview" id="overview"><h2>Overview</h2>', _overview_html(data), "</section>",
    ]
    parts += [_measurement_html(i, rep, base) for i, rep in enumerate(data.measurements)]
    parts += [
        "</main><footer><p>PIGEs: position-independent geometric errors of the rotary axes (ISO 230-7), position "
        "errors in µm, orientation errors in µrad, definitions in CONVENTIONS.md. Standard errors from "
        "σ²(AᵀA)⁺ with σ² = RSS/(N − rank); 95 % intervals from Student's t. A parameter with weight in a "
        "near-null direction of the scaled design is not identifiable and gets no value.</p></footer>",
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"
