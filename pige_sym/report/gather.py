"""Data of the HTML report: everything ``pige report`` shows, computed, no file written.

:func:`gather_report` reads every measurement file (and a ``<stem>.truth.json`` sidecar beside
it, when present) and computes into a :class:`ReportData`: the identification with both
methods (Gauss–Newton and the double-differential scheme), the diagnosis, the compensation
before/after on the measured trajectory (and on an NC program when one is given), and, on
request, the projection study and the Sobol indices on the measured trajectory.
:mod:`~pige_sym.report.figures` draws it, :mod:`~pige_sym.report.html` writes the page.

Choices made here
-----------------
- *Compensation before/after.*  With a truth sidecar, the simulated machine carries
  the true parameters (PIGEs and zero-position errors; effects listed in the sidecar
  are not simulated and this is said); without one, the machine is assumed to carry
  exactly the identified errors, so "after" only shows what the compensation
  algorithm itself leaves and the report says the before/after is model-predicted.
  Parameters without a value are compensated as 0 and listed.
- *Primary method.*  ``method`` (default ``diagnosis``) selects the estimate used for
  the model overlay and the compensation: ``gauss-newton``, ``double-differential``,
  or ``diagnosis`` (the PIGEs of the diagnosis' final fit, estimated jointly with the
  accepted extensions, which are not compensated).  Both identification methods are
  always tabulated.
- *Studies* run on the measured trajectory, ball and tool (pivots at their defaults),
  the projection study with the Gauss–Newton fit's σ as the simulated noise.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pige_sym import __version__
from pige_sym.compensation import (
    AngleExtension,
    CompensationParameters,
    CompensationStudyRow,
    angle_extensions,
    compensate_poses,
    compensate_program,
    compensation_study,
    read_program,
    tool_point_error,
)
from pige_sym.diagnosis import DiagnosisResult, diagnose
from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import json_ready
from pige_sym.identification import METHODS, IdentificationError, IdentificationResult, identify
from pige_sym.io import Measurement, read_measurement
from pige_sym.kernels import load_kernels
from pige_sym.nc.program import parse_program, poses_from_program
from pige_sym.simulator import normalise_parameter_name
from pige_sym.studies import ProjectionStudy, SobolStudy, projection_study, sobol_study
from pige_sym.trajectories import Trajectory, approach_directions
from pige_sym.verdict import CheckResult, Tolerances, check, estimates_from_result, read_tolerances

if TYPE_CHECKING:
    from pige_sym.compare import CompareResult

STUDIES = ("projection", "sobol")
SOBOL_EFFECT_UM = 15.0
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
    sobol_ranges: dict[str, float] = field(default_factory=dict)
    sobol_same_as: int | None = None
    figures: list[ReportFigure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    check: CheckResult | None = None
    measured_at: str = ""
    time_source: str = ""

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
            "sobol": None if self.sobol is None else {**self.sobol.to_dict(), "half_ranges": self.sobol_ranges},
            "check": None if self.check is None else self.check.to_dict(),
            "measured_at": self.measured_at, "time_source": self.time_source,
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
    comparison: CompareResult | None = None
    history: HistoryData | None = None
    figures: list[ReportFigure] = field(default_factory=list)
    plan: Any = None  # a graded test plan (pige_sym.planning.Plan), shown by report.plan_section
    plan_html: str = ""

    def to_dict(self) -> dict[str, Any]:
        return json_ready({
            "report": None if self.html_path is None else str(self.html_path),
            "created": self.created, "version": __version__, "settings": self.settings,
            "studies": list(self.studies), "program": None if self.program is None else str(self.program),
            "measurements": [m.to_dict() for m in self.measurements],
            "compare": None if self.comparison is None else self.comparison.to_dict(),
            "history": None if self.history is None else self.history.to_dict(),
        })


@dataclass
class HistoryData:
    """A machine's runs from the history database, for the trend plots.

    Attributes
    ----------
    machine_id : str
    database : str
        URL with the password hidden.
    runs : list of RunRecord
        In measurement order.
    comparisons : list of Comparison
        Consecutive runs.
    limits : dict of str to float
        Tolerance band per parameter [µm, µrad] (from ``--tolerances``, else the last run's check).
    """

    machine_id: str
    database: str
    runs: list[Any]
    comparisons: list[Any]
    limits: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"machine_id": self.machine_id, "database": self.database, "runs": [r.to_dict() for r in self.runs],
                "comparisons": [c.to_dict() for c in self.comparisons], "limits": self.limits}


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


def _check_options(method: str, presets: int, sobol_samples: int, paths: list[Path], others: bool) -> None:
    if method not in PRIMARY_METHODS:
        raise InputError(f"unknown method {method!r}: use {', '.join(PRIMARY_METHODS)}")
    if presets < 1:
        raise InputError("--presets must be at least 1")
    if sobol_samples < 2 or sobol_samples & (sobol_samples - 1):
        raise InputError(f"--samples must be a power of 2, got {sobol_samples}")
    if not paths and not others:
        raise InputError("give at least one measurement file (or --compare BEFORE AFTER, or --history ID)")


def gather_report(measurement_paths: Sequence[str | os.PathLike[str]], *, studies: Iterable[str] = (),
                  program: str | os.PathLike[str] | None = None, method: str = "diagnosis",
                  projection: str = "xyz", with_zero: bool = False, presets: int = 50, sobol_samples: int = 2048,
                  seed: int = 0, progress: bool = False, tolerances: str | os.PathLike[str] | None = None,
                  rule: str = "guard", k: float = 2.0,
                  compare: tuple[str | os.PathLike[str], str | os.PathLike[str]] | None = None,
                  history: str | None = None, db: str | None = None) -> ReportData:
    """Compute everything a report shows (no files written).

    Parameters
    ----------
    measurement_paths : sequence of path-like
        ``pige-rtest 1`` files; all are read (and their truth sidecars checked) before
        any computation, so a bad file fails fast.  May be empty with ``compare`` or ``history``.
    studies : iterable of {"projection", "sobol"}
    program : path-like, optional
        An 840D-style NC program compensated with each measurement's estimate.
    method : {"diagnosis", "gauss-newton", "double-differential"}
        Primary estimate (module docstring); default the diagnosis' final fit, the PIGEs used
        for compensation.
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
    tolerances : path-like, optional
        Tolerance file: each measurement gets a ``pige check`` verdict (``rule``, ``k``).
    compare : (before, after), optional
        Two measurements of the same program: the measured before/after section.
    history, db : str, optional
        Machine id and database URL: the trend section.

    Returns
    -------
    ReportData

    Raises
    ------
    PigeError
        Bad input (file format, truth sidecar, program, option); the message names it.
    """
    study_set = parse_studies(studies)
    paths = [Path(p) for p in measurement_paths]
    _check_options(method, presets, sobol_samples, paths, compare is not None or history is not None)
    loaded = []
    for p in paths:
        m = read_measurement(p)
        loaded.append((p, m, read_truth(p, m.machine)))
    tol = read_tolerances(tolerances) if tolerances is not None else None
    program_text = read_program(program) if program is not None else None
    steps_per_file = 4 + len(study_set) + (program is not None)
    options = _Options(method, projection, with_zero, study_set, presets, sobol_samples, seed, tol, rule, k,
                       None if program is None else Path(program), program_text)
    from tqdm import tqdm

    with tqdm(total=steps_per_file * len(paths), desc="report", unit="step", disable=not progress) as bar:
        reports = [_gather_one(p, label, m, truth, options, bar)
                   for (p, m, truth), label in zip(loaded, _labels(paths), strict=True)]
    _share_identical_sobol(reports)
    created = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    data = ReportData(reports, study_set, options.program, _settings_shown(options), created)
    if compare is not None:
        from pige_sym.compare import compare_measurements

        data.comparison = compare_measurements(*compare)
    if history is not None:
        data.history = gather_history(history, db, tol)
    return data


def _settings_shown(o: _Options) -> dict[str, str]:
    """The options a report was built with, as shown in its header."""
    settings = {"primary method": o.method, "projection": o.projection, "zero-position errors": str(o.with_zero),
                "studies": ", ".join(o.studies) or "none"}
    if "projection" in o.studies:
        settings["projection-study presets"] = str(o.presets)
    if "sobol" in o.studies:
        settings["Sobol samples"] = str(o.sobol_samples)
    if o.tolerances is not None:
        rule = f"{o.rule} rule" + (f", k = {o.k:g}" if o.rule == "guard" else "")
        settings["tolerances"] = f"{o.tolerances.path} ({rule})"
    return settings


@dataclass
class _Options:
    method: str
    projection: str
    with_zero: bool
    studies: tuple[str, ...]
    presets: int
    sobol_samples: int
    seed: int
    tolerances: Tolerances | None
    rule: str
    k: float
    program: Path | None
    program_text: str | None


def _gather_one(p: Path, label: str, m: Measurement, truth: Truth | None, opt: _Options, bar: Any) -> MeasurementReport:
    """Identification, diagnosis, compensation, program, verdict and studies of one file."""
    from pige_sym.history.store import measurement_time

    bar.set_postfix_str(f"{p.name}: identification")
    results = {meth: identify(m, method=meth, projection=opt.projection, with_zero=opt.with_zero) for meth in METHODS}
    bar.update(1)
    bar.set_postfix_str(f"{p.name}: diagnosis")
    diag: DiagnosisResult | None = None
    diag_error = None
    try:
        diag = diagnose(m)
    except IdentificationError as exc:  # the data are fine; one candidate fit is not: report it, go on
        diag_error = str(exc)
    bar.update(1)
    primary = opt.method if diag is not None or opt.method != "diagnosis" else "gauss-newton"
    rep = _compensation(p, label, m, truth, results, diag, primary, bar)
    rep.measured_at, rep.time_source = measurement_time(p, m.metadata, None)
    if diag_error is not None:
        rep.diagnosis_error = diag_error
        rep.notes.append(f"the diagnosis failed on these data ({diag_error})"
                         + ("; the Gauss–Newton estimate is compensated instead" if primary != opt.method else ""))
    if opt.tolerances is not None:
        source = diag if primary == "diagnosis" and diag is not None else rep.primary
        rep.check = check(estimates_from_result(source, str(p)), opt.tolerances, rule=opt.rule, k=opt.k)
    if opt.program_text is not None and opt.program is not None:
        bar.set_postfix_str(f"{p.name}: program")
        _program(rep, opt.program, opt.program_text)
        bar.update(1)
    _studies(rep, opt, bar)
    bar.update(1)  # the figures are drawn by write_report; keep the step count honest
    return rep


def _same_setup(a: Measurement, b: Measurement) -> bool:
    return (a.machine == b.machine and a.angles_deg.shape == b.angles_deg.shape
            and np.array_equal(a.angles_deg, b.angles_deg) and np.array_equal(a.ball_mm, b.ball_mm)
            and ((a.tool_mm is None and b.tool_mm is None)
                 or (a.tool_mm is not None and b.tool_mm is not None and np.array_equal(a.tool_mm, b.tool_mm))))


def _share_identical_sobol(reports: list[MeasurementReport]) -> None:
    """The Sobol indices depend on the trajectory, ball and tool only: show them once per set-up."""
    for i, rep in enumerate(reports):
        for j in range(i):
            if rep.sobol is not None and reports[j].sobol is not None and reports[j].sobol_same_as is None \
                    and _same_setup(rep.measurement, reports[j].measurement):
                rep.sobol_same_as = j + 1
                break


def sobol_half_ranges(m: Measurement, effect_um: float = SOBOL_EFFECT_UM) -> dict[str, float]:
    """Half-range per location PIGE [its unit] whose RMS effect on the ball over the trajectory is ``effect_um``.

    The parameters are scaled like the identification's columns, so position (µm) and orientation
    (µrad) errors compete on equal terms in the Sobol study.
    """
    kern = load_kernels(m.machine)
    names = list(kern.LOCATION_PARAMETERS)
    jac = kern.jacobian(m.angles_deg, None, m.ball_mm, None, m.tool_mm)[1:, :, : len(names)]
    scale = np.sqrt((jac**2).sum(axis=1).mean(axis=0))
    return {n: (effect_um / float(c) if c > 0 else effect_um) for n, c in zip(names, scale, strict=True)}


def _studies(rep: MeasurementReport, opt: _Options, bar: Any) -> None:
    m, p = rep.measurement, rep.path
    kern = load_kernels(m.machine)
    traj = _measured_trajectory(m)
    if m.pivots_mm and opt.studies:
        rep.notes.append("the studies place the rotary-axis pivots at the origin (the file gives pivots)")
    if "projection" in opt.studies:
        bar.set_postfix_str(f"{p.name}: projection study")
        sigma = rep.identification["gauss-newton"].sigma_um
        noise = sigma if math.isfinite(sigma) and sigma > 0 else 0.25
        rep.projection = projection_study(kern.MACHINE_CODE, traj, presets=opt.presets, noise_um=noise,
                                          seed=opt.seed, ball_mm=m.ball_mm, tool_mm=m.tool_mm, progress=False)
        rep.projection_noise_um = noise
        bar.update(1)
    if "sobol" in opt.studies:
        bar.set_postfix_str(f"{p.name}: Sobol indices")
        rep.sobol_ranges = sobol_half_ranges(m)
        rep.sobol = sobol_study(kern.MACHINE_CODE, traj, n=opt.sobol_samples, ball_mm=m.ball_mm,
                                tool_mm=m.tool_mm, seed=opt.seed, ranges=rep.sobol_ranges)
        bar.update(1)


def gather_history(machine_id: str, db: str | None, tol: Tolerances | None) -> HistoryData:
    """Runs and consecutive comparisons of a machine; tolerance band from ``tol`` or the last stored check."""
    from pige_sym.history import compare_runs, connect, list_runs

    engine = connect(db)
    runs = list_runs(engine, machine_id)
    comps = [compare_runs(a, b, from_run=a.id, to_run=b.id) for a, b in zip(runs, runs[1:], strict=False)]
    if tol is not None:
        limits = tol.resolve(runs[-1].machine_code)
    else:
        last = next((r.check for r in reversed(runs) if r.check), None)
        limits = {str(i["name"]): float(i["limit"]) for i in (last or {}).get("items", [])}
    return HistoryData(machine_id, engine.url.render_as_string(hide_password=True), runs, comps, limits)


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


def findings_text(rep: MeasurementReport) -> str:
    """One-line diagnosis outcome."""
    if rep.diagnosis is None:
        return f"diagnosis failed ({rep.diagnosis_error})"
    return ", ".join(f.effect for f in rep.diagnosis.findings) or "no effect beyond the PIGEs"

