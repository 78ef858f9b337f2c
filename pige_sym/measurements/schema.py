"""One strict validator for every JSON file pige reads: dataclasses describe the documents.

Reading (:func:`~pige_sym.measurements.strict_json.load_json`)
---------------------------------------------------------------
Strict JSON text (:mod:`pige_sym.measurements.strict_json`: regular files only, bounded size and depth, no
``NaN``, no repeated keys, over-long integers as the float they denote).  Every refusal is a
:class:`~pige_sym.errors.FileFormatError` naming the file, the line when known, and the field as a path
(``pige.EX0C``).

Schemas (:func:`from_json`)
---------------------------
A schema is a dataclass; its type hints say what each key holds:

``str``, ``bool``, ``int``, ``float``
    exactly that JSON type (a bool is not a number, ``"5"`` is not a number); a float is
    finite and, when the field's metadata has ``max_abs``, within ±max_abs;
``list[T]``, ``tuple[T, ...]``
    a JSON array (metadata ``length`` fixes its length);
``dict[str, T]``
    a JSON object;
``T | None``
    ``null`` allowed;
``Any``
    any JSON value (still depth-bounded).

Keys not declared are refused (with the list of known keys), except those in the
schema's ``IGNORED_KEYS`` (informational keys other pige commands write).  Fields
without a default are required.

Parameter files (:func:`read_params_file`)
------------------------------------------
The output of ``pige identify --json`` / ``pige diagnose --json`` or a hand-written
``{"machine": "...", "pige": {"EX0C": 5.0, ...}}``: every location PIGE of the machine
must have a finite value within ±:data:`MAX_PIGE` µm or µrad; a missing or ``null`` one
is refused unless ``allow_missing`` (then it is set to 0 and named in
``ParamsFile.set_to_zero``).  The file's ``machine`` must agree with the caller's.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np

from pige_sym.constants import MAX_PIGE as _MAX_PIGE
from pige_sym.errors import FileFormatError, InputError, PigeError, SchemaRefusal
from pige_sym.files import PathLike
from pige_sym.measurements.strict_json import MAX_DEPTH, MAX_INT_DIGITS, MAX_JSON_BYTES, load_json, strict_loads

#: Largest magnitude of a PIGE [µm or µrad] (:data:`pige_sym.constants.MAX_PIGE`).
MAX_PIGE = _MAX_PIGE
#: Largest magnitude of a position in a parameter file [mm].
MAX_POSITION_MM = 1e5

T = TypeVar("T")

__all__ = ["MAX_DEPTH", "MAX_INT_DIGITS", "MAX_JSON_BYTES", "load_json", "strict_loads"]  # read here, used by many


def _type_name(x: Any) -> str:
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, (int, float)):
        return "a number"
    if isinstance(x, str):
        return f"a string {x[:20]!r}"
    if isinstance(x, list):
        return "a list"
    return "an object"


def _check(tp: Any, value: Any, where: str, meta: Mapping[str, Any]) -> Any:
    """``value`` validated against the type hint ``tp`` (module docstring)."""
    origin = typing.get_origin(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            return _check(rest[0], value, where, meta)
        for a in rest:
            try:
                return _check(a, value, where, meta)
            except SchemaRefusal:
                continue
        raise SchemaRefusal(where, f"unexpected {_type_name(value)}")
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SchemaRefusal(where, f"expected a number, got {_type_name(value)}")
        v = float(value)
        if not math.isfinite(v):
            raise SchemaRefusal(where, "expected a finite number, got one beyond ±1.8e308")
        limit = meta.get("max_abs")
        if limit is not None and abs(v) > limit:
            raise SchemaRefusal(where, f"{v:g} is not physical (|value| <= {limit:g})")
        return v
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SchemaRefusal(where, f"expected an integer, got {_type_name(value)}")
        return value
    if tp in (str, bool):
        if not isinstance(value, tp):
            wanted = "a string" if tp is str else "true or false"
            raise SchemaRefusal(where, f"expected {wanted}, got {_type_name(value)}")
        return value
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise SchemaRefusal(where, f"expected a list, got {_type_name(value)}")
        n = meta.get("length")
        if n is not None and len(value) != n:
            raise SchemaRefusal(where, f"expected {n} values, got {len(value)}")
        (item,) = typing.get_args(tp)[:1]
        out = [_check(item, v, f"{where}[{i}]", meta) for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if origin is dict:
        if not isinstance(value, dict):
            raise SchemaRefusal(where, f"expected an object, got {_type_name(value)}")
        _, item = typing.get_args(tp)
        return {str(k): _check(item, v, f"{where}.{k}", meta) for k, v in value.items()}
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _from_dict(tp, value, where)
    raise TypeError(f"schema type {tp!r} is not supported")  # pragma: no cover - a programming error


def _from_dict(cls: type[T], value: Any, where: str) -> T:
    if not isinstance(value, dict):
        raise SchemaRefusal(where, f"expected an object, got {_type_name(value)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    ignored: frozenset[str] = getattr(cls, "IGNORED_KEYS", frozenset())
    unknown = sorted(k for k in value if k not in fields and k not in ignored)
    if unknown:
        prefix = f"{where}." if where else ""
        raise SchemaRefusal("", f"unknown key {prefix}{unknown[0]!r} (known: {', '.join(fields)})")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        sub = f"{where}.{name}" if where else name
        if name not in value:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise SchemaRefusal(sub, "missing")
            continue
        kwargs[name] = _check(hints[name], value[name], sub, f.metadata)
    return cls(**kwargs)


def from_json(cls: type[T], data: Any, path: PathLike) -> T:
    """Validate parsed JSON ``data`` against the dataclass ``cls``; FileFormatError naming the field."""
    try:
        return _from_dict(cls, data, "")
    except SchemaRefusal as exc:
        raise FileFormatError(str(path), None, str(exc)) from None


def read_json_file(path: PathLike, cls: type[T], what: str = "JSON file") -> T:
    """:func:`load_json` then :func:`from_json`."""
    return from_json(cls, load_json(path, what), path)


# --------------------------------------------------------------------------------------------- parameter files


def _vec3_mm() -> Any:
    return field(default=None, metadata={"length": 3, "max_abs": MAX_POSITION_MM})


@dataclass(frozen=True)
class CovarianceDocument:
    """``covariance`` of a parameter file: the estimates' covariance over ``parameters`` [µm², µm·µrad, µrad²].

    ``matrix`` is square, symmetric and positive semi-definite, one row per name of ``parameters`` (each a
    determined parameter of ``pige``, or a map value with a number, named ``<axis>:<motion>@<angle>``, e.g.
    ``C:EXC@30``); its diagonal is the square of ``std`` (or of the map value's std) where the file gives both.
    """

    parameters: list[str]
    matrix: list[list[float]]


@dataclass(frozen=True)
class ParamsDocument:
    """A parameter file as written (``pige identify --json``, ``pige diagnose --json`` or by hand).

    ``pige`` maps a parameter name to its value [µm or µrad] or ``null`` (not identifiable);
    names with a dot (``angular_error_C.cos_urad``) are effect parameters of a diagnosis.
    """

    pige: dict[str, float | None] = field(metadata={"max_abs": MAX_PIGE})
    machine: str | None = None
    units: dict[str, str] | None = None
    tool_mm: list[float] | None = _vec3_mm()
    ball_mm: list[float] | None = _vec3_mm()
    pivots_mm: dict[str, list[float]] | None = field(default=None, metadata={"length": 3,
                                                                              "max_abs": MAX_POSITION_MM})
    findings: list[Any] | None = None
    axis_sense: dict[str, int] | None = None
    effects: list[Any] | None = None  # several files' diagnosis: the effects seen jointly (findings, alike)
    std: dict[str, float | None] | None = field(default=None, metadata={"max_abs": MAX_PIGE})
    covariance: CovarianceDocument | None = None
    error_motions: dict[str, dict[str, Any]] | None = None
    not_identifiable: list[Any] | None = None  # identify --map: why a PIGE has no value, what would determine it

    #: Keys ``pige identify/diagnose --json`` write that a parameter file does not use.
    IGNORED_KEYS: ClassVar[frozenset[str]] = frozenset({
        "method", "projection", "loss", "ci95", "rank", "n_parameters", "condition", "rms_um", "sigma_um",
        "dof", "n_rows", "n_obs", "observability", "unidentifiable", "outlier_rows", "vif", "baseline", "options",
        "plots", "rejected", "params", "bic", "heldout_rms_um", "unobservable", "identifiable", "warnings",
        "unobserved", "clusters", "files", "map_step_deg", "map_undetermined", "model_check", "effects_searched",
        "joint_effects", "agreement", "notes", "null_space", "map_notes",
    })


@dataclass(frozen=True)
class ParamsFile:
    """A validated parameter file.

    Attributes
    ----------
    path : str
    machine : str
        Canonical machine code.
    pige : dict of str to float [µm, µrad]
        Every location PIGE of the machine, plus the zero-position ones the file gives.
    effect_values : dict of str to float
        Effect parameters (names with a dot), finite, as given.
    set_to_zero : tuple of str
        PIGEs missing or null in the file, set to 0 because ``allow_missing`` was given.
    units : dict of str to str
    tool_mm : tuple of 3 float [mm] or None
    pivots_mm : dict of str to tuple of 3 float [mm]
    findings : list
        ``findings`` of a diagnosis (unvalidated structure beyond strict JSON).
    axis_sense : dict of str to int
        Axes the measured controller commands in the reverse of CONVENTIONS' sense (axis → −1, CONVENTIONS §9).
    std : dict of str to float
        Standard errors of the determined values [µm, µrad] (``null`` ones left out).
    covariance_names, covariance : tuple of str, (q, q) or None
        The estimates' covariance and the names of its rows (:class:`CovarianceDocument`).
    ball_mm : (3,) [mm] or None
        The measured point (ball or sphere centre at the reference pose).
    error_motions : dict or None
        The validated error maps (CONVENTIONS §10, :func:`~pige_sym.measurements.error_motions_file.
        read_error_motions`): axis → ``angle_deg``, ``full_turn``, ``value`` and ``std`` per motion.
    """

    path: str
    machine: str
    pige: dict[str, float]
    effect_values: dict[str, float]
    set_to_zero: tuple[str, ...]
    units: dict[str, str]
    tool_mm: tuple[float, float, float] | None
    pivots_mm: dict[str, tuple[float, float, float]]
    findings: list[Any]
    axis_sense: dict[str, int] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    covariance_names: tuple[str, ...] = ()
    covariance: tuple[tuple[float, ...], ...] | None = None
    ball_mm: tuple[float, float, float] | None = None
    error_motions: dict[str, Any] | None = None


def refuse_unphysical(names: list[str], values: Any, std: Any, units: dict[str, str], source: str) -> None:
    """Refuse an estimate of a PIGE beyond ±:data:`MAX_PIGE` by more than 3 standard errors.

    The parameter reader refuses such values; an identification that would print one comes from a wrong
    set-up (a ball, pivot or tool position, a probe import's options) or another machine's data, not from a
    machine that runs: it is refused where it is computed, naming what to check.

    Raises
    ------
    IdentificationError
    """
    from pige_sym.errors import IdentificationError
    from pige_sym.measurements.measurement import unphysical

    found = unphysical(names, values, std, MAX_PIGE)
    if found is not None:
        name, v = found
        raise IdentificationError(f"{source}: {name} = {v:.1f} {units.get(name, '')} is beyond ±{MAX_PIGE:g}, "
                                  "more than any machine that runs: the set-up in the file is wrong (ball_mm, "
                                  "pivot_<axis>_mm, tool_mm, axis_sense; for a probe import --pivot, --units, "
                                  "--axis-sense) or the data are another machine's")


def read_params_file(path: PathLike, *, machine: str | None = None, allow_missing: bool = False) -> ParamsFile:
    """Read and validate a parameter file (module docstring); :func:`params_document` on its JSON."""
    return params_document(load_json(path, "parameter file"), path, machine=machine, allow_missing=allow_missing)


def params_document(data: Any, path: PathLike, *, machine: str | None = None,
                    allow_missing: bool = False) -> ParamsFile:
    """Validate a parameter document already in memory (a file's JSON, or a result's ``to_dict()``).

    Parameters
    ----------
    data : JSON value
    path : path-like
        Where it comes from, for messages (a file name, or e.g. ``<identification>``).
    machine : str or None
        The machine the caller works on (``--machine`` or an NC program's header); must agree
        with the file's ``machine`` when both are given.
    allow_missing : bool
        Set missing or ``null`` location PIGEs to 0 (named in ``set_to_zero``) instead of refusing.

    Raises
    ------
    FileFormatError
        Malformed file (names the field).
    InputError
        Machine missing or disagreeing.
    """
    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.kernels import load_kernels

    p = str(path)
    doc = from_json(ParamsDocument, data, path)
    code = _agreed_machine(p, doc.machine, machine, parse_machine_code)
    kern = load_kernels(code)
    known = set(kern.PARAMETERS)
    unknown = sorted(k for k in doc.pige if "." not in k and k not in known)
    if unknown:
        raise FileFormatError(p, None, f"pige.{unknown[0]}: not a parameter of {kern.MACHINE_CODE} "
                              f"(known: {', '.join(kern.PARAMETERS)})")
    for axis in doc.pivots_mm or {}:
        if axis not in kern.ROTARY_AXES:
            raise FileFormatError(p, None, f"pivots_mm.{axis}: not a rotary axis of {kern.MACHINE_CODE} (axes: "
                                  f"{', '.join(kern.ROTARY_AXES)})")
    for name, unit in (doc.units or {}).items():
        if name in kern.UNITS and unit != kern.UNITS[name]:
            raise FileFormatError(p, None, f"units.{name}: {unit!r}, but {name} is in {kern.UNITS[name]}")
    values = {k: v for k, v in doc.pige.items() if "." not in k and v is not None}
    missing = [k for k in kern.LOCATION_PARAMETERS if doc.pige.get(k) is None]
    if missing and not allow_missing:
        said = "null (not identifiable)" if all(k in doc.pige for k in missing) else "missing or null"
        raise FileFormatError(p, None, f"pige.{missing[0]}: {said}; every PIGE of {kern.MACHINE_CODE} needs a value "
                              f"({', '.join(missing)}): {_missing_remedy(doc.not_identifiable, missing)}; to "
                              "compensate with the others and leave these uncorrected, pass --allow-missing (they are "
                              "entered as 0)")
    for k in missing:
        values[k] = 0.0
    sense = _axis_sense(p, doc.axis_sense, kern.ROTARY_AXES)
    effects = {k: v for k, v in doc.pige.items() if "." in k}
    bad_effect = [k for k, v in effects.items() if v is None]
    if bad_effect:
        raise FileFormatError(p, None, f"pige.{bad_effect[0]}: an effect parameter needs a value")
    std = {k: v for k, v in (doc.std or {}).items() if v is not None}
    negative = [k for k, v in std.items() if v < 0]
    if negative:
        raise FileFormatError(p, None, f"std.{negative[0]}: a standard error cannot be negative")
    from pige_sym.measurements.error_motions_file import read_error_motions

    maps = read_error_motions(doc.error_motions, p, kern) if doc.error_motions else None
    map_values, map_std = _map_names(maps)
    determined = set(values) - set(missing) | set(effects) | set(map_values)
    cov = _covariance(p, doc.covariance, determined, std | map_std)
    return ParamsFile(
        path=p, machine=kern.MACHINE_CODE, pige=values, effect_values={k: float(v or 0.0) for k, v in effects.items()},
        set_to_zero=tuple(missing), units=dict(doc.units or kern.UNITS),
        tool_mm=None if doc.tool_mm is None else (doc.tool_mm[0], doc.tool_mm[1], doc.tool_mm[2]),
        pivots_mm={a: (v[0], v[1], v[2]) for a, v in (doc.pivots_mm or {}).items()},
        findings=list(doc.findings or []) + list(doc.effects or []),
        axis_sense=sense, std=std, covariance_names=tuple(doc.covariance.parameters) if doc.covariance and cov else (),
        covariance=cov, ball_mm=None if doc.ball_mm is None else (doc.ball_mm[0], doc.ball_mm[1], doc.ball_mm[2]),
        error_motions=maps,
    )



def _missing_remedy(reasons: list[Any] | None, missing: list[str]) -> str:
    """What would determine the missing PIGEs: the file's own remedy (``not_identifiable`` of ``pige identify
    --map``), else measure again so that the identification determines them."""
    usable = [r for r in reasons or [] if isinstance(r, dict) and isinstance(r.get("remedy"), str)
              and isinstance(r.get("parameters"), list)]
    best = max(usable, key=lambda r: len(set(missing) & set(r["parameters"])), default=None)
    if best is not None and set(missing) & set(best["parameters"]):
        return f"to determine them, {best['remedy']}"
    return "measure so that they are determined (pige identify says which combination its data do not see)"


def _map_names(maps: dict[str, Any] | None) -> tuple[set[str], dict[str, float]]:
    """The map values with a number, named ``<axis>:<motion>@<angle>`` (``C:EXC@30``, as a covariance names them),
    and their standard errors."""
    names: set[str] = set()
    stds: dict[str, float] = {}
    for axis, m in (maps or {}).items():
        for motion, vals in m["value"].items():
            for g, v, sd in zip(m["angle_deg"], vals, m["std"].get(motion, [math.nan] * len(vals)), strict=True):
                if math.isfinite(v):
                    names.add(f"{axis}:{motion}@{g:g}")
                    if math.isfinite(sd):
                        stds[f"{axis}:{motion}@{g:g}"] = float(sd)
    return names, stds


def _covariance(path: str, cov: CovarianceDocument | None, determined: set[str],
                std: dict[str, float]) -> tuple[tuple[float, ...], ...] | None:
    """The validated covariance rows (:class:`CovarianceDocument`), or None."""
    if cov is None:
        return None
    names, rows = cov.parameters, cov.matrix
    bad = [n for n in names if n not in determined]
    if bad or len(set(names)) != len(names):
        why = f"{bad[0]!r} has no value in pige" if bad else "a name is repeated"
        raise FileFormatError(path, None, f"covariance.parameters: {why}; give each determined parameter once")
    if len(rows) != len(names) or any(len(r) != len(names) for r in rows):
        raise FileFormatError(path, None, f"covariance.matrix: expected {len(names)} rows of {len(names)} numbers, one "
                              "per name of covariance.parameters")
    m = np.asarray(rows, dtype=float)
    scale = float(np.abs(m).max(initial=0.0)) or 1.0
    if not np.isfinite(m).all() or np.abs(m - m.T).max(initial=0.0) > 1e-9 * scale:
        raise FileFormatError(path, None, "covariance.matrix: must be finite and symmetric")
    if m.size and np.linalg.eigvalsh(m).min() < -1e-9 * scale:
        raise FileFormatError(path, None, "covariance.matrix: not positive semi-definite (not a covariance)")
    for i, n in enumerate(names):
        if n in std and not math.isclose(math.sqrt(max(m[i, i], 0.0)), std[n], rel_tol=1e-6, abs_tol=1e-9):
            raise FileFormatError(path, None, f"covariance.matrix: the variance of {n} ({m[i, i]:.6g}) is not std.{n} "
                                  f"squared ({std[n] ** 2:.6g}); write both from one identification")
    return tuple(tuple(float(x) for x in r) for r in m)


def _axis_sense(path: str, given: dict[str, int] | None, rotary_axes: tuple[str, ...]) -> dict[str, int]:
    """``axis_sense`` of a parameter file: rotary axes of the machine mapped to -1 or +1 (CONVENTIONS §9)."""
    out: dict[str, int] = {}
    for axis, sign in (given or {}).items():
        if axis not in rotary_axes:
            raise FileFormatError(path, None, f"axis_sense.{axis}: not a rotary axis of this machine "
                                  f"(axes: {', '.join(rotary_axes)})")
        if isinstance(sign, bool) or sign not in (-1, 1):
            raise FileFormatError(path, None, f"axis_sense.{axis}: {sign!r}; the sense is -1 or 1")
        if sign == -1:
            out[axis] = -1
    return out


def _agreed_machine(path: str, in_file: str | None, given: str | None, parse: Any) -> str:
    """The canonical machine both the file and the caller name (one of them may be silent)."""
    def canon(code: str, who: str) -> str:
        try:
            return str(parse(code).canonical)
        except PigeError as exc:
            raise FileFormatError(path, None, f"{who}: {exc}") from None

    file_code = canon(in_file, "machine") if in_file is not None else None
    given_code = canon(given, "--machine") if given is not None else None
    if file_code and given_code and file_code != given_code:
        raise InputError(f"{path} is for machine {file_code}, but this run is for {given_code}: use the parameter "
                         "file identified on this machine")
    code = file_code or given_code
    if code is None:
        raise InputError(f"{path} names no machine: give --machine")
    return code
