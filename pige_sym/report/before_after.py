"""Compensation before/after for the report: on the measured trajectory, and on an NC program when one
is given.  The correction is the compensation stage's (:func:`pige_sym.compensation.stage.compensate`, its result
kept in ``rep.compensation_result``); the report only evaluates what it corrected on the simulated machine.

With a truth sidecar the simulated machine carries the true parameters; without one it carries the
identified ones and the report says the before/after is model-predicted (see
:mod:`~pige_sym.report.gather`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.compensation.parameters import AngleExtension, CompensationParameters, angle_extensions
from pige_sym.compensation.result import Compensation
from pige_sym.compensation.stage import PosesRequest, ProgramRequest, compensate
from pige_sym.compensation.study import before_after
from pige_sym.diagnosis.diagnose import DiagnosisResult
from pige_sym.errors import InputError
from pige_sym.identification.result import IdentificationResult
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.model.trajectories import Trajectory
from pige_sym.report.data import MeasurementReport, Truth


def measured_trajectory(m: Measurement) -> Trajectory:
    desc = m.trajectory or "measured angles"
    return Trajectory("measured", tuple(m.rotary_axes), m.angles_deg, m.t_s, desc)


def compensation_before_after(p: Path, label: str, m: Measurement, truth: Truth | None,
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
    identified, rep.not_compensated, _ = rep.estimate()
    if method == "diagnosis" and diag is not None:
        rep.extensions, skipped = angle_extensions([f.to_dict() for f in diag.findings], tuple(kern.ROTARY_AXES))
        rep.extensions_not_compensated = [f"{effect} ({why})" for effect, why in skipped.items()]
    pivots = m.pivots_mm or None
    result = compensate(estimate_parameters(rep), poses=PosesRequest(m.angles_deg, np.tile(m.ball_mm, (m.n_rows, 1))))
    rep.compensation_result, rep.weighing = result, result.weighing
    values, extensions = _machine(rep)
    rep.compensation = [before_after(kern.MACHINE_CODE, values, result.poses, truth_extensions=extensions,
                                     description=measured_trajectory(m).description, pivots_mm=pivots,
                                     tool_mm=m.tool_mm, predicted_after_um=_expected(result))]
    if not rep.not_compensated:
        vec = np.array([identified.get(n, 0.0) for n in kern.PARAMETERS])
        rep.model_um = kern.deviation(m.angles_deg, vec, m.ball_mm, pivots, m.tool_mm)
    if truth is not None:
        rep.notes += truth.notes
    bar.update(1)
    return rep


def _machine(rep: MeasurementReport) -> tuple[dict[str, float], list[AngleExtension]]:
    """The simulated machine's parameters and angle errors: the truth's, else the identified ones (model-predicted)."""
    if rep.truth is not None:
        return rep.truth.values, list(rep.truth.extensions)
    return rep.estimate()[0], list(rep.extensions)


def _expected(result: Compensation) -> float:
    """The error the stage predicts the correction leaves [µm] (NaN when the estimate states no uncertainty)."""
    w = result.weighing
    return w.predicted["entered"].expected_um if "entered" in w.predicted and w.covariance_from != "none" else math.nan


def program_section(rep: MeasurementReport, program: Path, text: str) -> None:
    """The compensation stage on the NC program with the primary estimate; before/after on its corrected poses."""
    m = rep.measurement
    result = compensate(estimate_parameters(rep), program=ProgramRequest(text, str(program)))
    assert result.program is not None
    comp = result.program.poses
    if comp is None:
        raise InputError(f"{program}: no block to compensate (no linear move with every axis programmed: X, Y, Z, "
                         f"{', '.join(m.rotary_axes)})")
    values, extensions = _machine(rep)
    row = before_after(rep.machine, values, comp, truth_extensions=extensions,
                       description=f"NC program {program.name} ({comp.angles_deg.shape[0]} poses)",
                       pivots_mm=m.pivots_mm or None, tool_mm=m.tool_mm, predicted_after_um=_expected(result))
    if comp.angles_deg.shape == m.angles_deg.shape and np.allclose(comp.angles_deg, m.angles_deg, atol=1e-6) \
            and rep.compensation:
        # the program is the measured test itself: one row, not the same numbers twice
        row.trajectory = f"{row.trajectory}, the measured test"
        rep.compensation[0] = row
    else:
        rep.compensation.append(row)
    rep.compensated_program_text = result.program.text
    rep.compensation_result, rep.weighing = result, result.weighing


def estimate_parameters(rep: MeasurementReport) -> CompensationParameters:
    """The primary estimate as compensation reads it: values, standard errors and covariance, extensions."""
    res, m = rep.primary, rep.measurement
    identified, missing, _ = rep.estimate()
    cov = res.covariance_dict()
    return CompensationParameters(
        machine=rep.machine, values=identified, units={k: res.units.get(k, "") for k in identified},
        tool_mm=None if m.tool_mm is None else [float(x) for x in m.tool_mm],
        pivots_mm={k: [float(x) for x in v] for k, v in m.pivots_mm.items()},
        source=f"{rep.path.name} ({rep.primary_method})",
        ignored=list(rep.not_compensated) + list(rep.extensions_not_compensated), extensions=list(rep.extensions),
        std={n: float(v) for n, v in zip(res.parameters, res.std, strict=True) if math.isfinite(v)},
        covariance=None if cov is None else (tuple(cov["parameters"]), np.asarray(cov["matrix"], dtype=float)),
        set_to_zero=list(missing), ball_mm=[float(x) for x in m.ball_mm])
