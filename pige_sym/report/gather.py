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

import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.compensation.parameters import angle_extensions
from pige_sym.diagnosis.diagnose import DiagnosisResult, diagnose
from pige_sym.diagnosis.joint import JointDiagnosis, diagnose_joint
from pige_sym.errors import FileFormatError, InputError
from pige_sym.identification.joint import common_machine
from pige_sym.identification.least_squares import METHODS, IdentificationError, identify
from pige_sym.identification.model_check import check_model
from pige_sym.identification.studies import projection_study, sobol_study
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import BallbarRun
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.sets import read_files
from pige_sym.nc.program_file import read_program
from pige_sym.report.before_after import compensation_before_after, measured_trajectory, program_section
from pige_sym.report.data import (
    PRIMARY_METHODS,
    SOBOL_EFFECT_UM,
    STUDIES,
    HistoryData,
    JointReport,
    MeasurementReport,
    ReportData,
    Truth,
)
from pige_sym.simulation.simulator import normalise_parameter_name
from pige_sym.verdict.check import Estimates, Tolerances, check, estimates_from_result, read_tolerances


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
    from pige_sym.measurements.schema import load_json

    data = load_json(tp, "truth sidecar")
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
        effects = "effect" if len(names) == 1 else "effects"
        notes.append(f"the truth sidecar also lists the {effects} {', '.join(names)}: the before/after simulates the "
                     f"{simulated} only")
    return Truth(tp, values, notes, extensions, records)


def _labels(paths: Sequence[Path]) -> list[str]:
    out: list[str] = []
    for p in paths:
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", p.stem) or "measurement"
        label, k = base, 2
        while label in out:
            label, k = f"{base}-{k}", k + 1
        out.append(label)
    return out


def _check_options(method: str, presets: int, sobol_samples: int | None, paths: list[Path], others: bool) -> None:
    if method not in PRIMARY_METHODS:
        raise InputError(f"unknown method {method!r}: use {', '.join(PRIMARY_METHODS)}")
    if presets < 1:
        raise InputError("--presets must be at least 1")
    if sobol_samples is not None and (sobol_samples < 2 or sobol_samples & (sobol_samples - 1)):
        raise InputError(f"--samples must be a power of 2, got {sobol_samples}")
    if not paths and not others:
        raise InputError("give at least one measurement file (or --compare BEFORE AFTER, or --history ID)")


def gather_report(measurement_paths: Sequence[str | os.PathLike[str]], *, studies: Iterable[str] = (),
                  program: str | os.PathLike[str] | None = None, method: str = "diagnosis",
                  projection: str = "xyz", with_zero: bool = False, presets: int = 50, sobol_samples: int | None = None,
                  seed: int = 0, progress: bool = False, tolerances: str | os.PathLike[str] | None = None,
                  rule: str = "guard", k: float = 2.0,
                  compare: tuple[str | os.PathLike[str], str | os.PathLike[str]] | None = None,
                  history: str | None = None, db: str | None = None, joint: bool = False,
                  maps: Any = None) -> ReportData:
    """Compute everything a report shows (no files written).

    Parameters
    ----------
    measurement_paths : sequence of path-like
        ``pige-rtest 1`` files (R-test runs, probe imports) and ``pige-ballbar 1`` setups; all are
        read (and their truth sidecars checked) before any computation, so a bad file fails fast, and a
        file given twice is refused.  Each R-test/probe file gets its own section; the files of a
        machine with a ballbar file (or, with ``joint``, two files or more) also get a joint section
        (:mod:`~pige_sym.report.joint_section`).  Files fitted jointly (a ballbar file among them, or ``joint``)
        must measure one machine, as ``identify`` requires of them (the same check): an AC and a BC ballbar file
        are refused, not reported side by side.  May be empty with ``compare`` or ``history``.
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
    sobol_samples : int or None
        ``None``: exact Sobol indices; a power of 2: Monte-Carlo base sample size.
    seed : int
    progress : bool
        Show a tqdm progress bar on stderr.
    tolerances : path-like, optional
        Tolerance file: each measurement gets a ``pige check`` verdict (``rule``, ``k``).
    compare : (before, after), optional
        Two measurements of the same program: the measured before/after section.
    history, db : str, optional
        Machine id and database URL: the trend section.
    joint : bool
        Also identify two or more R-test/probe files of one machine jointly (ballbar files always are).
    maps : MapSpec, optional
        Fit the error maps of these axes jointly from every file (:mod:`~pige_sym.report.map_section`).

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
    loaded, every = _read_inputs(paths, joint)
    tol = read_tolerances(tolerances) if tolerances is not None else None
    program_text = read_program(program) if program is not None else None
    steps_per_file = 4 + len(study_set) + (program is not None)
    from pige_sym.diagnosis.map_gain import mapped_effects

    options = _Options(method, projection, with_zero, study_set, presets, sobol_samples, seed, tol, rule, k,
                       None if program is None else Path(program), program_text, tuple(mapped_effects(maps)))
    from tqdm import tqdm

    with tqdm(total=steps_per_file * len(loaded), desc="report", unit="step", disable=not progress) as bar:
        reports = [_gather_one(p, label, m, truth, options, bar)
                   for (p, m, truth), label in zip(loaded, _labels([x[0] for x in loaded]), strict=True)]
    _share_identical_sobol(reports)
    created = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    data = ReportData(reports, study_set, options.program, _settings_shown(options), created)
    data.joints = gather_joints(every, tolerances=tol, rule=rule, k=k, every_group=joint,
                                diagnoses={rep.path: rep.diagnosis for rep in reports})
    _gather_beyond_files(data, every, compare, history, db, tol, maps)
    return data


def _gather_beyond_files(data: ReportData, every: list[tuple[Path, Any, Truth | None]], compare: Any,
                         history: str | None, db: str | None, tol: Any, maps: Any) -> None:
    """The sections that are not one file's: measured before/after, the history's trend, the error maps."""
    if compare is not None:
        from pige_sym.verdict.compare import compare_measurements

        data.comparison = compare_measurements(*compare)
    if history is not None:
        data.history = gather_history(history, db, tol)
    if maps is not None:
        from pige_sym.report.map_section import gather_maps

        data.maps = gather_maps([(str(p), x) for p, x, _ in every], maps)


def _common_truth(truths: Sequence[Truth | None], diag: JointDiagnosis) -> dict[str, float] | None:
    """The true values every file's sidecar gives alike, or None: the PIGEs, and the parameters
    (``<effect>.<parameter>``) of each effect seen jointly whose whole is determined (nothing removed) when
    every sidecar lists the same effect with the same harmonic."""
    if not truths or any(t is None for t in truths):
        return None
    first = truths[0]
    assert first is not None
    if any(t is None or t.values != first.values or t.effects != first.effects for t in truths):
        return None
    out = dict(first.values)
    for f in diag.effects:
        match = [e for e in first.effects if e.get("effect") == f.effect
                 and all(float(e.get(k, 1.0)) == float(v) for k, v in f.options.items() if k == "harmonic")]
        if len(match) == 1 and not f.removed:
            out |= {f"{f.effect}.{p}": float(match[0].get(p, 0.0)) for p in f.params}
    return out


def gather_joints(items: Sequence[tuple[Path, Measurement | BallbarRun, Truth | None]], *,
                  tolerances: Tolerances | None = None, rule: str = "guard", k: float = 2.0,
                  every_group: bool = False, diagnoses: dict[Path, DiagnosisResult | None] | None = None
                  ) -> list[JointReport]:
    """The joint sections of a report's files (module docstring).

    Parameters
    ----------
    items : sequence of (path, contents, truth sidecar or None)
        Every file of the report, R-test, probe and ballbar, in the order given.
    tolerances : Tolerances, optional
        Judge each joint estimate.
    rule, k
        Decision rule and coverage factor of the check.
    every_group : bool
        Also the machines with two R-test/probe files or more (not only those with a ballbar file: a
        ballbar setup alone determines only some combinations, R-test runs of one machine may be a
        before and an after).
    diagnoses : dict of Path to DiagnosisResult or None, optional
        The R-test/probe files' own diagnoses already made for their sections (not made again).

    Returns
    -------
    list of JointReport
        One per machine with a ballbar file (``every_group``: or with two files or more), in order of
        first appearance.
    """
    groups: dict[str, list[int]] = {}
    for i, (_, item, _) in enumerate(items):
        groups.setdefault(load_kernels(item.machine).MACHINE_CODE, []).append(i)
    out = []
    for machine, idx in groups.items():
        has_ballbar = any(isinstance(items[i][1], BallbarRun) for i in idx)
        if not has_ballbar and not (every_group and len(idx) > 1):
            continue
        labelled = [(items[i][0].name, items[i][1]) for i in idx]
        diag = diagnose_joint(labelled, diagnoses=[(diagnoses or {}).get(items[i][0]) for i in idx])
        verdict = None
        if tolerances is not None:  # the joint diagnosis, effects included: what `pige check F1 F2 …` judges
            source = " + ".join(items[i][0].name for i in idx)
            verdict = check(estimates_from_result(diag, source), tolerances, rule=rule, k=k)
        out.append(JointReport(machine, [items[i][0] for i in idx], diag, verdict,
                               _common_truth([items[i][2] for i in idx], diag), _ballbar_curves(labelled, diag)))
    return out


def _read_inputs(paths: list[Path], joint: bool) -> tuple[list[tuple[Path, Measurement, Truth | None]],
                                                         list[tuple[Path, Measurement | BallbarRun, Truth | None]]]:
    """(R-test/probe files with their truth, every file with its truth), each read and checked once; files fitted
    jointly (a ballbar file among them, or ``joint``) must measure one machine, as identify asks (the same check)."""
    loaded, every = [], []
    for p, item in read_files(paths) if paths else []:
        truth = read_truth(p, item.machine)
        every.append((Path(p), item, truth))
        if isinstance(item, Measurement):
            loaded.append((Path(p), item, truth))
    if joint or any(isinstance(x, BallbarRun) for _, x, _ in every):
        common_machine([(p.name, x) for p, x, _ in every], apart="report them apart (one report per machine)")
    return loaded, every


def _ballbar_curves(items: list[tuple[str, Measurement | BallbarRun]],
                    diag: JointDiagnosis) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Each ballbar file's measured ``dL`` and its joint fit (the final one: with the effects seen jointly,
    and the file's constant) [µm]."""
    final = diag.joint if diag.extended is None else diag.extended
    return [(label, item.dl_um, f.fitted_um) for (label, item), f in zip(items, final.files, strict=True)
            if isinstance(item, BallbarRun) and f.fitted_um is not None]


def _settings_shown(o: _Options) -> dict[str, str]:
    """The options a report was built with, as shown in its header."""
    settings = {"primary method": o.method, "projection": o.projection,
                "zero-position errors": "estimated" if o.with_zero else "not estimated",
                "studies": ", ".join(o.studies) or "none"}
    if "projection" in o.studies:
        settings["projection-study presets"] = str(o.presets)
    if "sobol" in o.studies:
        settings["Sobol indices"] = "exact" if o.sobol_samples is None else f"{o.sobol_samples} Monte-Carlo samples"
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
    sobol_samples: int | None
    seed: int
    tolerances: Tolerances | None
    rule: str
    k: float
    program: Path | None
    program_text: str | None
    exclude: tuple[str, ...] = ()  # with --map: the mapped axes' one-harmonic motions (the maps hold them)


def _gather_one(p: Path, label: str, m: Measurement, truth: Truth | None, opt: _Options, bar: Any) -> MeasurementReport:
    """Identification, diagnosis, compensation, program, verdict and studies of one file."""
    from pige_sym.verdict.history.records import measurement_time

    bar.set_postfix_str(f"{p.name}: identification")
    results = {meth: identify(m, method=meth, projection=opt.projection, with_zero=opt.with_zero) for meth in METHODS}
    bar.update(1)
    bar.set_postfix_str(f"{p.name}: diagnosis")
    diag: DiagnosisResult | None = None
    diag_error = None
    try:
        diag = diagnose(m, exclude=opt.exclude)
    except IdentificationError as exc:  # the data are fine; one candidate fit is not: report it, go on
        diag_error = str(exc)
    bar.update(1)
    primary = opt.method if diag is not None or opt.method != "diagnosis" else "gauss-newton"
    rep = compensation_before_after(p, label, m, truth, results, diag, primary, bar)
    rep.model_check = check_model(m, results["gauss-newton"])
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
        program_section(rep, opt.program, opt.program_text)
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
    traj = measured_trajectory(m)
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
    from pige_sym.verdict.history import changes, connect, list_runs

    engine = connect(db, create=False)
    runs = list_runs(engine, machine_id)
    comps = changes.compare_consecutive(runs)
    judged = None
    if tol is not None:
        limits = tol.resolve(runs[-1].machine_code)
        judged = check(_run_estimates(runs[-1]), tol)  # the last run against the tolerances of this report
    else:
        last = next((r.check for r in reversed(runs) if r.check), None)
        limits = {str(i["name"]): float(i["limit"]) for i in (last or {}).get("items", [])}
    from pige_sym.verdict.history.connection import where

    return HistoryData(machine_id, where(engine).shown, runs, comps, limits, judged)


def _run_estimates(run: Any) -> Estimates:
    """The stored estimate of a history run, to be judged (:func:`pige_sym.verdict.check.check`)."""
    def number(x: float) -> float | None:
        return float(x) if math.isfinite(float(x)) else None

    values = {p: number(v) for p, v in zip(run.parameters, run.values, strict=True)}
    std = {p: number(s) if values[p] is not None else None for p, s in zip(run.parameters, run.std, strict=True)}
    return Estimates(run.machine_code, run.method, f"run {run.id} ({Path(run.file_name).name})", values, std,
                     dict(run.units), [str(f.get("effect")) for f in run.effects])


def findings_text(rep: MeasurementReport) -> str:
    """One-line diagnosis outcome."""
    if rep.diagnosis is None:
        return f"diagnosis failed ({rep.diagnosis_error})"
    return ", ".join(f.effect for f in rep.diagnosis.findings) or "no effect beyond the PIGEs"
