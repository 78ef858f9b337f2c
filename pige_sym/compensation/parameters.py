"""What compensation starts from: identified parameters, accepted diagnosis extensions, per-pose values.

A parameter file is the JSON that ``pige identify --json`` (optionally with the accepted findings of
``pige diagnose --json``) writes: ``machine``, ``parameters`` (name → value [µm, µrad]), ``ball_mm``,
``pivots_mm``, ``tool_mm`` and, where the controller commands an axis in the reverse sense,
``axis_sense`` (CONVENTIONS §9).  Angle extensions (``angular_error_<AXIS>``, ``backlash_<AXIS>``) become a
pose-dependent zero-position error :math:`E_{a0a}` (CONVENTIONS §3); the other findings are listed with
the reason they are not compensated.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import FileFormatError, InputError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import missing_tool
from pige_sym.measurements.schema import MAX_PIGE
from pige_sym.model.effects import EffectSpec
from pige_sym.model.error_motions import error_maps_from
from pige_sym.model.trajectories import approach_directions

COMPENSABLE_KINDS = ("angular_error", "backlash")


NOT_COMPENSATED_WHY = {
    "thermal_drift": "time-dependent (depends on when the program runs)",
    "probe_trigger": "the probe's, not the machine's: calibrate the probe per probing direction",
    "table_drift": "the test's sphere or nest moved on the table: a set-up error of the test, not of the machine",
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
            Direction of approach of each axis (:func:`~pige_sym.model.trajectories.approach_directions`).
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
    axis_sense : dict of str to int
        Axes the controller commands in the reverse of CONVENTIONS' sense (axis → −1, CONVENTIONS §9), as
        the parameter file records it: NC angles and controller angle entries are written in that sense.
    std : dict of str to float
        Standard errors the file states [µm, µrad] (PIGEs and effect parameters ``<id>.<param>``).
    covariance : (tuple of str, ndarray (q, q)) or None
        The estimates' covariance the file states, with the names of its rows.
    set_to_zero : list of str
        PIGEs without a value in the file, set to 0 by ``--allow-missing`` (never weighed or entered).
    ball_mm : list of float or None
        The measured point (ball or sphere centre at the reference pose) [mm].
    weighing : Weighing or None
        How ``values`` were chosen from the file's estimates when they are the entered values
        (:func:`pige_sym.compensation.weighing.with_entered`); None when they are the file's own.
    error_maps : ErrorMaps or None
        The rotary axes' error maps of the file (CONVENTIONS §10), compensated with the PIGEs.
    error_map_std : dict
        axis → motion → standard errors of the map values (NaN where none).
    in_force : dict of str to float or None
        A check-up's entries (:mod:`pige_sym.verdict.checkup.to_enter`): ``values`` are then the changes since the
        values in force (an entry that adds adds them; an absolute entry is printed as the change to add to the
        value it holds, never as a value); None: ``values`` are the machine's errors (``pige compensate``).
    held : dict of str to float
        PIGEs a check-up held at their values in force: never entered (their ``values`` are 0, no change).
    """

    machine: str
    values: dict[str, float]
    units: dict[str, str]
    tool_mm: list[float] | None
    pivots_mm: dict[str, list[float]]
    source: str
    ignored: list[str]
    extensions: list[AngleExtension] = field(default_factory=list)
    axis_sense: dict[str, int] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    covariance: tuple[tuple[str, ...], np.ndarray] | None = None
    set_to_zero: list[str] = field(default_factory=list)
    ball_mm: list[float] | None = None
    weighing: Any = None
    error_maps: Any = None
    error_map_std: dict[str, dict[str, tuple[float, ...]]] = field(default_factory=dict)
    in_force: dict[str, float] | None = None
    held: dict[str, float] = field(default_factory=dict)

    def covariance_of(self, names: list[str]) -> tuple[np.ndarray | None, str]:
        """The covariance of ``names`` (q, q) and where it comes from: ``covariance``, ``std`` or ``none``.

        The file's covariance when it covers every name; else the standard errors as uncorrelated ones
        when the file gives one for every name (and each is positive); else ``None``.
        """
        if self.covariance is not None and set(names) <= set(self.covariance[0]):
            idx = [self.covariance[0].index(n) for n in names]
            cov = self.covariance[1][np.ix_(idx, idx)]
            if (np.diag(cov) > 0).all():
                return cov, "covariance"
        if all(self.std.get(n, 0.0) > 0 for n in names):
            return np.diag([self.std[n] ** 2 for n in names]), "std"
        return None, "none"


def load_parameters(path: str | os.PathLike[str], machine: str | None = None, *,
                    allow_missing: bool = False) -> CompensationParameters:
    """Read ``pige identify/diagnose --json`` output (validated by :mod:`~pige_sym.measurements.schema`).

    A PIGE without a value (not identifiable, or missing) is refused unless ``allow_missing``;
    then it is set to 0 and named in ``ignored``.  ``machine`` (``--machine`` or the program's
    header) must agree with the file's machine.
    """
    from pige_sym.measurements.schema import read_params_file

    return _parameters(read_params_file(path, machine=machine, allow_missing=allow_missing))


def parameters_from_result(result: Any, machine: str | None = None, *,
                           allow_missing: bool = False) -> CompensationParameters:
    """:func:`load_parameters` on a result in memory (``IdentificationResult`` or ``DiagnosisResult``).

    The result goes through its JSON form and the same validation as a file, so a script and
    ``pige compensate`` accept and refuse exactly the same estimates.
    """
    import json

    from pige_sym.files import to_json
    from pige_sym.measurements.schema import params_document

    source = "the diagnosis" if hasattr(result, "final") else "the identification"
    data = json.loads(to_json(result.to_dict()))
    return _parameters(params_document(data, source, machine=machine, allow_missing=allow_missing))


def _parameters(doc: Any) -> CompensationParameters:
    """Compensation parameters of a validated parameter document (:class:`~pige_sym.measurements.schema.ParamsFile`)."""
    kern = load_kernels(doc.machine)
    ignored = [f"{k} (no value in the file: set to 0 by --allow-missing)" for k in doc.set_to_zero]
    extensions, skipped = _extensions({"findings": doc.findings}, doc.path, tuple(kern.ROTARY_AXES))
    ignored += [f"{effect} ({why})" for effect, why in skipped.items()]
    described = {e.spec.id for e in extensions} | set(skipped)
    ignored += [f"{name} (no finding describes it)" for name in doc.effect_values
                if name.split(".", 1)[0] not in described]
    tool = None if doc.tool_mm is None else list(doc.tool_mm)
    why = missing_tool(kern.MACHINE_CODE, tool, '"tool_mm": [x, y, z] (pige identify --json writes it)')
    if why:
        raise FileFormatError(doc.path, None, why)
    pivots = {a: list(v) for a, v in doc.pivots_mm.items()}
    cov = None if doc.covariance is None else (tuple(doc.covariance_names), np.asarray(doc.covariance, dtype=float))
    return CompensationParameters(kern.MACHINE_CODE, dict(doc.pige), dict(doc.units), tool, pivots, doc.path,
                                  ignored, extensions, dict(doc.axis_sense), dict(doc.std), cov,
                                  list(doc.set_to_zero), None if doc.ball_mm is None else list(doc.ball_mm),
                                  error_maps=error_maps_from(doc.error_motions),
                                  error_map_std={ax: {n: tuple(v) for n, v in m["std"].items()}
                                                 for ax, m in (doc.error_motions or {}).items()})


def extension_prefixes(extensions: list[AngleExtension]) -> list[str]:
    """The name prefix of each extension's parameters as the diagnosis writes them: ``<id>``, or ``<id>@h<h>``
    where two extensions share an id (:func:`pige_sym.diagnosis.diagnose._param_names`)."""
    ids = [e.spec.id for e in extensions]
    return [e.spec.id if ids.count(e.spec.id) == 1 else f"{e.spec.id}@h{e.spec.harmonic}" for e in extensions]


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
    from pige_sym.model.effects import OPTION_KEYS

    out: list[AngleExtension] = []
    skipped: dict[str, str] = {}
    for rec in records:
        if "params" in rec:
            if not isinstance(rec["params"], dict) or not isinstance(rec.get("options") or {}, dict):
                raise InputError(f"effect {rec['effect']}: params and options must be objects of name: value")
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
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or abs(v) > MAX_PIGE:
                raise InputError(f"effect {spec.id}: {name} {v!r:.40} must be a finite number within "
                                 f"±{MAX_PIGE:g} {spec.units[name]}")
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
    out = np.tile(parameter_vector(kern, values), (a.shape[0], 1))
    if extensions:
        appr = approach_directions(a) if approach is None else np.atleast_2d(approach)
        axes = tuple(kern.ROTARY_AXES)
        for ext in extensions:
            ax = ext.spec.axis
            out[:, kern.PARAMETERS.index(f"E{ax[0]}0{ax}")] += ext.zero_error_urad(a, axes, appr)
    return out


def parameter_vector(kern: Any, values: dict[str, float]) -> np.ndarray:
    return np.array([values.get(n, 0.0) for n in kern.PARAMETERS])


def kern_axes(machine: str, side: str) -> list[Any]:
    from pige_sym.codegen.machine_code import parse_machine_code

    st = parse_machine_code(machine)
    axes = st.workpiece_axes if side == "workpiece" else st.tool_axes
    return [a for a in axes if a.kind == "rotary"]


def kern_axes_names(machine: str) -> list[str]:
    return [a.name for a in kern_axes(machine, "tool")]
