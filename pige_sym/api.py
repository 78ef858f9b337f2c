"""The public Python API: what a calibration script calls, with the same rules as the ``pige`` command.

One function per step of a calibration, measure → identify → diagnose → check → compensate, plus
planning the test and simulating one.  Every function takes plain values or file paths and returns
the result dataclasses the command line prints (``.to_dict()`` gives their JSON).  Bad input raises
:class:`pige_sym.errors.PigeError` subclasses whose message says what to fix (the command line turns
them into exit status 2).  Importing this module is cheap: each function imports what it needs.

A whole calibration on a simulated AC table:

>>> import pige_sym.api as pige
>>> run = pige.simulate("wC'A'bXYZ(C1)t", pige="random", seed=1, noise_um=0.25)
>>> result = pige.identify(run)
>>> f"rank {result.rank}/{len(result.parameters)}"
'rank 8/8'
>>> diagnosis = pige.diagnose(run)
>>> [f.effect for f in diagnosis.findings]
[]
>>> verdict = pige.check(diagnosis, {"format": "pige-tolerances 1", "defaults": {"um": 30, "urad": 40}})
>>> verdict.verdict
'pass'

Units: positions and position errors in µm, angles in degrees, orientation errors in µrad, machine
coordinates in mm (CONVENTIONS §3).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pige_sym.constants import DEFAULT_BALL_MM, DEFAULT_MACHINE

if TYPE_CHECKING:
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.compensation.result import Compensation
    from pige_sym.diagnosis.joint import JointDiagnosis
    from pige_sym.diagnosis.results import DiagnosisResult
    from pige_sym.identification.joint import JointResult
    from pige_sym.identification.result import IdentificationResult
    from pige_sym.measurements.measurement import Measurement
    from pige_sym.planning.plan import Plan
    from pige_sym.verdict.check import CheckResult

__all__ = ["check", "compensate", "diagnose", "identify", "identify_files", "plan", "read", "simulate", "write"]

PathLike = str | os.PathLike[str]


def read(path: PathLike) -> Measurement:
    """Read a measurement file, strictly (a violation names the file, line and field).

    Parameters
    ----------
    path : path-like
        A ``pige-rtest 1`` file (CONVENTIONS §6).

    Returns
    -------
    Measurement
        ``angles_deg`` (n, k) [deg], ``deviation_um`` (n, 3) [µm], ``ball_mm`` (3,) [mm], ...

    Examples
    --------
    >>> import os, tempfile
    >>> import pige_sym.api as pige
    >>> folder = tempfile.mkdtemp()
    >>> path = pige.write(pige.simulate(seed=3), os.path.join(folder, "run.csv"))
    >>> m = pige.read(path)
    >>> m.machine, m.rotary_axes, m.deviation_um.shape
    ("wC'A'bXYZ(C1)t", ('A', 'C'), (31, 3))
    """
    from pige_sym.measurements.rtest import read_measurement

    return read_measurement(path)


def write(measurement: Measurement, path: PathLike, *, force: bool = False) -> Path:
    """Write a measurement file (``pige-rtest 1``), atomically; never over an existing file without ``force``.

    Parameters
    ----------
    measurement : Measurement
    path : path-like
        Missing parent folders are created.
    force : bool
        Replace an existing regular file (never a folder, device or link target that is not a file).

    Returns
    -------
    Path
        The path written.

    Examples
    --------
    >>> import os, tempfile
    >>> import pige_sym.api as pige
    >>> path = os.path.join(tempfile.mkdtemp(), "run.csv")
    >>> _ = pige.write(pige.simulate(seed=1), path)
    >>> pige.write(pige.simulate(seed=2), path)
    Traceback (most recent call last):
    ...
    pige_sym.errors.InputError: ...exists...
    >>> pige.read(pige.write(pige.simulate(seed=2), path, force=True)).n_rows
    31
    """
    from pige_sym.files import check_output
    from pige_sym.measurements.rtest_writer import write_measurement

    return write_measurement(measurement, check_output(path, force=force))


def simulate(machine: str = DEFAULT_MACHINE, *, trajectory: str = "cone-frustum",
             pige: str | Mapping[str, float] | None = "random", effects: Sequence[str] = (), noise_um: float = 0.25,
             seed: int | None = 0, ball_mm: Sequence[float] = DEFAULT_BALL_MM) -> Measurement:
    """Simulate an R-test on a machine with known errors (the truth a round trip is checked against).

    Parameters
    ----------
    machine : str
        ISO 10791 structure code, e.g. ``"wC'A'bXYZ(C1)t"``.
    trajectory : str
        ``cone-frustum``, ``figure-eight``, ``steps`` or an angle file.
    pige : "random", mapping of name to value [µm, µrad], or None (all zero)
    effects : sequence of str
        Effects beyond the PIGEs, as ``pige simulate --effect`` takes them (``"angular_error_C"``).
    noise_um : float
        Sensor noise σ per component [µm].
    seed : int or None
    ball_mm : (3,) [mm]
        Ball centre at the reference pose.

    Returns
    -------
    Measurement

    Examples
    --------
    >>> import pige_sym.api as pige
    >>> m = pige.simulate("wC'B'bXYZ(C1)t", pige={"EX0C": 5.0}, noise_um=0.0)
    >>> round(float(abs(m.deviation_um).max()), 3) > 0
    True
    """
    from pige_sym.kernels import load_kernels
    from pige_sym.model.effects import parse_effect
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.simulation.simulator import parse_pige, random_pige
    from pige_sym.simulation.simulator import simulate as run

    kern = load_kernels(machine)
    code = kern.MACHINE_CODE
    if pige == "random":
        values = random_pige(code, seed)
    elif isinstance(pige, str):
        values = parse_pige(pige, code, seed)
    else:
        values = dict(pige or {})
    traj = make_trajectory(code, trajectory)
    instances = [parse_effect(e, tuple(kern.ROTARY_AXES)) for e in effects]
    sim = run(code, traj, pige=values, effects=instances, noise_um=noise_um, seed=seed,
              ball_mm=[float(x) for x in ball_mm])
    return sim.measurement


def _measurement(data: Measurement | PathLike) -> Measurement:
    if isinstance(data, (str, os.PathLike)):
        return read(data)
    return data


def identify(data: Measurement | PathLike, *, method: str = "gauss-newton", projection: str = "xyz",
             loss: str = "linear", with_zero: bool = False) -> IdentificationResult:
    """Identify the PIGEs with uncertainty and identifiability (``pige identify``).

    Parameters
    ----------
    data : Measurement or path-like
    method : {"gauss-newton", "double-differential"}
    projection : str
        ``xyz`` (default), ``x``, ``y``, ``z``, a vector ``"a,b,c"`` or ``htm:...`` (CONVENTIONS §5).
    loss : {"linear", "soft_l1", "huber"}
        Robust losses flag outlier rows and leave them out of the final fit.
    with_zero : bool
        Also estimate the zero-position errors (10 parameters on a two-rotary-axis machine).

    Returns
    -------
    IdentificationResult
        ``parameters`` (names), ``values`` and ``std`` (P,) [µm or µrad], NaN where the data cannot
        determine a parameter (then named in ``unidentifiable``), ``covariance`` (P, P).

    Examples
    --------
    >>> import pige_sym.api as pige
    >>> run = pige.simulate(pige={"EX0C": 8.0, "EB0A": -12.0}, noise_um=0.0)
    >>> r = pige.identify(run)
    >>> round(r.value("EX0C"), 6), round(r.value("EB0A"), 6)
    (8.0, -12.0)
    >>> r = pige.identify(run, projection="x")
    >>> r.rank < len(r.parameters), len(r.unidentifiable) > 0
    (True, True)
    """
    from pige_sym.identification.least_squares import identify as run

    return run(_measurement(data), method=method, projection=projection, loss=loss, with_zero=with_zero)


def identify_files(paths: Sequence[PathLike], *, with_zero: bool = False) -> JointResult:
    """Identify the PIGEs jointly from several files of one machine (``pige identify F1 F2 ...``).

    R-test runs, probe imports and ballbar setups (``pige-ballbar 1``) mix freely; each ``zero: relative``
    ballbar file gets its own free constant; what the set cannot determine is named and gets no value.

    Parameters
    ----------
    paths : sequence of path-like
    with_zero : bool
        Also estimate the zero-position errors.

    Returns
    -------
    JointResult
        ``result`` (an ``IdentificationResult`` of the PIGEs, method ``joint``) and ``files`` (per file: rows,
        its own σ [µm], the RMS of its joint residual [µm], its constant).

    Examples
    --------
    >>> import os, tempfile
    >>> import pige_sym.api as pige
    >>> from pige_sym.measurements.ballbar import write_ballbar
    >>> from pige_sym.simulation.ballbar import ballbar_setup, simulate_ballbar
    >>> folder = tempfile.mkdtemp()
    >>> ac, truth = "wC'A'bXYZ(C1)t", {"EX0C": 5.0, "EY0A": -4.0}
    >>> paths = [write_ballbar(simulate_ballbar(ac, ballbar_setup(ac, kind, axis, tilt_deg=tilt), pige=truth,
    ...          noise_um=0.01, seed=1), os.path.join(folder, f"{kind}{axis}{tilt}.csv"))
    ...          for kind in ("radial", "tangential", "axial") for axis, tilt in (("C", 0), ("C", -45), ("A", 0))]
    >>> one = pige.identify_files(paths[:1]).result
    >>> one.rank < len(one.parameters), len(one.unidentifiable) > 0
    (True, True)
    >>> joint = pige.identify_files(paths).result
    >>> joint.rank, round(joint.value("EX0C"), 1), round(joint.value("EY0A"), 1)
    (8, 5.0, -4.0)
    """
    from pige_sym.identification.joint import identify_joint
    from pige_sym.measurements.sets import read_files

    return identify_joint(read_files(paths), with_zero=with_zero)


def diagnose_files(paths: Sequence[PathLike], *, progress: bool = False, exclude: Sequence[str] = ()) -> JointDiagnosis:
    """Diagnose several files of one machine (``pige diagnose F1 F2 ...``).

    Each R-test or probe file gets its own catalogue diagnosis; ballbar setups are checked for
    agreement and, when the set is made of ballbar setups only, searched jointly for catalogue
    effects; an F test says whether the files agree on one set of PIGEs and, with three or more,
    which file does not.  The final estimate is the joint fit (with the effects seen jointly).

    Parameters
    ----------
    paths : sequence of path-like
    progress : bool
        Progress bars of the per-file diagnoses on stderr.
    exclude : sequence of str
        Catalogue ids the per-file diagnoses leave out (``--map``: the mapped axes' one-harmonic motions).

    Returns
    -------
    JointDiagnosis
        ``agreement`` (F, dof, p), ``files`` (per file: findings, agreement with the others),
        ``final`` (the joint PIGE estimate), ``notes``.

    Examples
    --------
    >>> import os, tempfile
    >>> import pige_sym.api as pige
    >>> from pige_sym.measurements.ballbar import write_ballbar
    >>> from pige_sym.simulation.ballbar import ballbar_setup, simulate_ballbar
    >>> folder, ac = tempfile.mkdtemp(), "wC'A'bXYZ(C1)t"
    >>> setups = [(kind, axis, tilt) for kind in ("radial", "tangential", "axial")
    ...           for axis, tilt in (("C", 0), ("C", -45), ("A", 0))]
    >>> paths = [write_ballbar(simulate_ballbar(ac, ballbar_setup(ac, kind, axis, tilt_deg=tilt), pige={"EX0C": 5.0},
    ...          noise_um=0.1, seed=20 + i), os.path.join(folder, f"{kind}{axis}{tilt}.csv"))
    ...          for i, (kind, axis, tilt) in enumerate(setups)]
    >>> d = pige.diagnose_files(paths)
    >>> d.agreement.p_value > 0.01, any(f.disagrees for f in d.files)
    (True, False)
    """
    from pige_sym.diagnosis.joint import diagnose_joint
    from pige_sym.measurements.sets import read_files

    return diagnose_joint(read_files(paths), progress=progress, exclude=exclude)


def diagnose(data: Measurement | PathLike, *, candidates: Sequence[str] | None = None,
             progress: bool = False) -> DiagnosisResult:
    """Find, name and fit what the PIGE model misses (``pige diagnose``).

    Parameters
    ----------
    data : Measurement or path-like
    candidates : sequence of str, optional
        Restrict the search to these catalogue ids (default: the whole catalogue).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    DiagnosisResult
        ``findings`` (accepted effects with their parameters and evidence), ``rejected``,
        ``final`` (PIGEs fitted jointly with the findings: the estimate to compensate with).

    Examples
    --------
    >>> import pige_sym.api as pige
    >>> run = pige.simulate(pige="random", effects=["angular_error_C"], seed=2)
    >>> d = pige.diagnose(run)
    >>> d.findings[0].effect
    'angular_error_C'
    """
    from pige_sym.diagnosis.diagnose import diagnose as run

    return run(_measurement(data), candidates=None if candidates is None else list(candidates), progress=progress)


def check(estimate: IdentificationResult | DiagnosisResult | JointDiagnosis | PathLike,
          tolerances: Mapping[str, Any] | PathLike, *, rule: str = "guard", k: float = 2.0,
          method: str = "diagnosis") -> CheckResult:
    """In tolerance?  pass / fail / undecided per parameter with its uncertainty (ISO 14253-1, ``pige check``).

    Parameters
    ----------
    estimate : IdentificationResult, DiagnosisResult, JointDiagnosis or path-like
        A result (a joint diagnosis of several files: its final estimate with the effects found), a
        saved ``identify/diagnose --json`` (a file whose first character opens a JSON
        object) or a measurement file (estimated now with ``method``).
    tolerances : mapping or path-like
        A ``pige-tolerances 1`` document (``{"format": ..., "defaults": {"um": 10, "urad": 20}, "limits": {...}}``)
        or its file.
    rule : {"guard", "simple"}
        ``guard``: pass when ``|value| + k·u <= limit``, fail when ``|value| − k·u > limit``.
    k : float
        Coverage factor.
    method : {"diagnosis", "gauss-newton", "double-differential"}
        How a measurement file is estimated (``diagnosis``: the PIGEs fitted with the accepted findings).

    Returns
    -------
    CheckResult
        ``verdict`` (``pass``, ``fail`` or ``undecided``), ``items``, ``exit_status``.

    Examples
    --------
    >>> import pige_sym.api as pige
    >>> r = pige.identify(pige.simulate(pige={"EX0C": 12.0}, seed=4))
    >>> pige.check(r, {"format": "pige-tolerances 1", "limits": {"EX0C": 5}}).verdict
    'fail'
    >>> pige.check(r, {"format": "pige-tolerances 1", "limits": {"EX0C": 50}}).verdict
    'pass'
    """
    from pige_sym.verdict.check import check as judge
    from pige_sym.verdict.check import (
        estimates_from_json,
        estimates_from_result,
        looks_like_json,
        read_tolerances,
        strict_json,
        tolerances_from_dict,
    )

    tol = tolerances_from_dict(dict(tolerances), "tolerances") if isinstance(tolerances, Mapping) \
        else read_tolerances(tolerances)
    if not isinstance(estimate, (str, os.PathLike)):
        est = estimates_from_result(estimate, "")  # in memory: no file to name
    elif looks_like_json(estimate):
        est = estimates_from_json(strict_json(estimate), str(estimate))
    elif method == "diagnosis":
        est = estimates_from_result(diagnose(estimate), str(estimate))
    else:
        est = estimates_from_result(identify(estimate, method=method), str(estimate))
    return judge(est, tol, rule=rule, k=k)


def compensate(program: PathLike,
               parameters: IdentificationResult | DiagnosisResult | CompensationParameters | PathLike, *,
               machine: str | None = None, dialect: str | None = None, pass_through: bool = False,
               max_change_mm: float | None = None, max_change_deg: float | None = None, allow_missing: bool = False,
               rtcp_on: Sequence[str] = (), rtcp_off: Sequence[str] = (), enter: str = "weighed") -> Compensation:
    """Rewrite an NC program so the tool lands where the nominal program intended (``pige compensate``).

    The output is in the program's own dialect, read back and verified before it is returned;
    nothing is written to disk (write ``result.text`` yourself, e.g. with
    :func:`pige_sym.files.atomic_write_text`).

    Parameters
    ----------
    program : path-like
        Siemens 840D, ISO/Fanuc/Haas or LinuxCNC program.
    parameters : IdentificationResult, DiagnosisResult, CompensationParameters or path-like
        The estimate to compensate with (a diagnosis uses its final fit and its compensable
        findings), or a saved ``identify/diagnose --json``.
    machine : str, optional
        The machine the program is for; must agree with the estimate's machine.
    dialect : str, optional
        Override the detected dialect.
    pass_through : bool
        Keep calls, control flow and expressions unchanged instead of refusing the program.
    max_change_mm, max_change_deg : float, optional
        Refuse corrections larger than these (defaults as ``pige compensate``).
    allow_missing : bool
        Set PIGEs without a value to 0 (and say so) instead of refusing.
    rtcp_on, rtcp_off : sequence of str
        Extra codes that switch RTCP on or off on this controller (``pige compensate --rtcp-on``).
    enter : {"weighed", "all"}
        Enter each estimate weighed by its uncertainty (``report.weighing`` says what and why,
        :mod:`pige_sym.compensation.weighing`), or every estimate as it is.

    Returns
    -------
    Compensation
        The compensation stage's result (:mod:`pige_sym.compensation.result`): ``text`` (the compensated program),
        ``report`` (changed blocks, largest change, notes), ``weighing``, ``undetermined``, ``advice``.

    Examples
    --------
    >>> import os, tempfile
    >>> import pige_sym.api as pige
    >>> path = os.path.join(tempfile.mkdtemp(), "part.mpf")
    >>> _ = open(path, "w").write("; machine: wC'A'bXYZ(C1)t\\nTRAORI\\nG90 G1 X10 Y0 Z5 A20 C30 F500\\nM30\\n")
    >>> r = pige.identify(pige.simulate(pige={"EX0C": 10.0}, noise_um=0.0))
    >>> out = pige.compensate(path, r)
    >>> out.report.compensated, out.report.moves
    (1, 1)
    """
    from pige_sym.compensation import stage
    from pige_sym.compensation.parameters import CompensationParameters, load_parameters, parameters_from_result
    from pige_sym.nc.program_file import read_program

    text = read_program(program)
    if isinstance(parameters, CompensationParameters):
        params = parameters
    elif isinstance(parameters, (str, os.PathLike)):
        params = load_parameters(parameters, machine, allow_missing=allow_missing)
    else:
        params = parameters_from_result(parameters, machine, allow_missing=allow_missing)
    return stage.compensate(params, enter=enter, program=stage.ProgramRequest(
        text, str(program), dialect, pass_through, max_change_mm, max_change_deg, tuple(rtcp_on), tuple(rtcp_off)))


def plan(machine: str = DEFAULT_MACHINE, *, points: int = 30, limits: Sequence[str] = (), noise_um: float = 0.25,
         ball_mm: Sequence[float] = DEFAULT_BALL_MM, tool_mm: Sequence[float] | None = None,
         criterion: str = "worst", reveal: Sequence[str] = (), seed: int = 0) -> Plan:
    """Plan the test before the machine moves: the poses that determine every PIGE best (``pige plan``).

    Parameters
    ----------
    machine : str
    points : int
        Poses after the reference pose.
    limits : sequence of str
        Axis ranges ``"A=-90:90"`` (rotary, deg) or ``"Z=-50:200"`` (linear, mm).
    noise_um : float
        Sensor noise per component [µm]: the predicted standard errors scale with it.
    ball_mm, tool_mm : (3,) [mm]
        Ball position (and the ball's offset from the last tool-side pivot on head machines).
    criterion : {"worst", "A", "D"}
    reveal : sequence of str
        Catalogue effects the test must be able to reveal (``"backlash_C"``).
    seed : int
        The search is seeded: the same request gives the same plan.

    Returns
    -------
    Plan
        ``angles_deg`` (n + 1, k) [deg] with row 0 the reference pose, ``prediction`` (predicted std per
        PIGE), ``baseline`` (the default cone with the same points), ``angle_file_text()``.

    Examples
    --------
    >>> import pige_sym.api as pige
    >>> p = pige.plan(points=12, limits=["A=-90:90"])
    >>> p.angles_deg.shape, p.prediction.worst < p.baseline.worst
    ((13, 2), True)
    """
    import numpy as np

    from pige_sym.kernels import load_kernels
    from pige_sym.planning import PlanRequest, Setup, parse_limits, plan_test, search_ball_region

    setup = Setup(load_kernels(machine).MACHINE_CODE, np.asarray(ball_mm, dtype=float),
                  None if tool_mm is None else np.asarray(tool_mm, dtype=float), None, noise_um=noise_um)
    from pige_sym.constants import DEFAULT_DWELL_S, DEFAULT_MOVE_S
    from pige_sym.planning import parse_reveal

    req = PlanRequest(setup, int(points), parse_limits(list(limits), setup.kernels), search_ball_region(None),
                      criterion, parse_reveal(",".join(reveal) or None, tuple(setup.kernels.ROTARY_AXES)),
                      DEFAULT_MOVE_S, DEFAULT_DWELL_S, seed)
    return plan_test(req)
