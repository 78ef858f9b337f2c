"""Compensation before/after for the report: on the measured trajectory, and on an NC program when one
is given.

With a truth sidecar the simulated machine carries the true parameters; without one it carries the
identified ones and the report says the before/after is model-predicted (see
:mod:`~pige_sym.report.gather`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.compensation.kinematics import compensate_poses, tool_point_error
from pige_sym.compensation.parameters import AngleExtension, CompensationParameters, angle_extensions
from pige_sym.compensation.study import CompensationStudyRow, compensation_study
from pige_sym.diagnosis.diagnose import DiagnosisResult
from pige_sym.errors import InputError
from pige_sym.identification.result import IdentificationResult
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.model.trajectories import Trajectory, approach_directions
from pige_sym.nc.compensate import compensate_program
from pige_sym.nc.program import parse_program, poses_from_program
from pige_sym.report.data import MeasurementReport, Truth


def measured_trajectory(m: Measurement) -> Trajectory:
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
    identified, rep.not_compensated, covariance = rep.estimate()
    if method == "diagnosis" and diag is not None:
        rep.extensions, skipped = angle_extensions([f.to_dict() for f in diag.findings], tuple(kern.ROTARY_AXES))
        rep.extensions_not_compensated = [f"{effect} ({why})" for effect, why in skipped.items()]
    machine_values = truth.values if truth is not None else identified
    # the model-predicted machine carries what was identified, extensions included
    machine_extensions = truth.extensions if truth is not None else rep.extensions
    pivots = m.pivots_mm or None
    entered = weighed_parameters(rep, m.angles_deg, np.tile(m.ball_mm, (m.n_rows, 1)))
    rep.compensation = compensation_study(kern.MACHINE_CODE, [measured_trajectory(m)], truth=machine_values,
                                          identified=entered.values, covariance=covariance, ball_mm=m.ball_mm,
                                          tool_mm=m.tool_mm, pivots_mm=pivots, truth_extensions=machine_extensions,
                                          extensions=entered.extensions)
    _expected_from_weighing(rep.compensation[0], entered)
    if not rep.not_compensated:
        vec = np.array([identified.get(n, 0.0) for n in kern.PARAMETERS])
        rep.model_um = kern.deviation(m.angles_deg, vec, m.ball_mm, pivots, m.tool_mm)
    if truth is not None:
        rep.notes += truth.notes
    bar.update(1)
    return rep


def program_section(rep: MeasurementReport, program: Path, text: str) -> None:
    """Compensate the NC program with the primary estimate; before/after on its poses."""
    m = rep.measurement
    kern = load_kernels(m.machine)
    prog = parse_program(text, path=str(program), rotary_axes=tuple(kern.ROTARY_AXES))
    angles, xyz, rtcp, _lines = poses_from_program(prog)
    if angles.shape[0] == 0:
        raise InputError(f"{program}: no pose with every axis programmed (X, Y, Z, {', '.join(kern.ROTARY_AXES)})")
    identified, _missing, covariance = rep.estimate()
    machine_values = rep.truth.values if rep.truth is not None else identified
    machine_extensions = rep.truth.extensions if rep.truth is not None else rep.extensions
    pivots = m.pivots_mm or None
    points = np.array(xyz, dtype=float)
    if (~np.asarray(rtcp, dtype=bool)).any():
        from pige_sym.compensation.kinematics import workpiece_points

        off = ~np.asarray(rtcp, dtype=bool)
        points[off] = workpiece_points(kern, angles[off], points[off], pivots, m.tool_mm)
    params = weighed_parameters(rep, angles, points)
    row = program_before_after(rep.machine, machine_values, params.values, angles, xyz, rtcp,
                               description=f"NC program {program.name} ({angles.shape[0]} poses)", pivots_mm=pivots,
                               tool_mm=m.tool_mm, covariance=covariance, truth_extensions=machine_extensions,
                               extensions=params.extensions)
    _expected_from_weighing(row, params)
    if angles.shape == m.angles_deg.shape and np.allclose(angles, m.angles_deg, atol=1e-6) and rep.compensation:
        # the program is the measured test itself: one row, not the same numbers twice
        row.trajectory = f"{row.trajectory}, the measured test"
        rep.compensation[0] = row
    else:
        rep.compensation.append(row)
    rep.compensated_program_text = compensate_program(text, estimate_parameters(rep), path=str(program))


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


def weighed_parameters(rep: MeasurementReport, angles: np.ndarray, points: np.ndarray) -> CompensationParameters:
    """What compensation enters of the primary estimate, weighed by its uncertainty on these poses
    (:mod:`pige_sym.compensation.weighing`); the weighing is kept in ``rep.weighing`` (the last poses judged)."""
    from pige_sym.compensation.weighing import program_poses, weigh, with_entered

    params = estimate_parameters(rep)
    rep.weighing = weigh(params, program_poses(angles, points))
    return with_entered(params, rep.weighing)


def _expected_from_weighing(row: CompensationStudyRow, entered: CompensationParameters) -> None:
    """The row's expected error after compensation from the weighing (uncertainty and what is not entered)."""
    w = entered.weighing
    if w is not None and "entered" in w.predicted and w.covariance_from != "none":
        row.predicted_after_um = w.predicted["entered"].expected_um
