"""Conformance verdicts with the measurement uncertainty (ISO 14253-1 decision rules), ``pige check``.

Tolerance file (``pige-tolerances 1``, JSON, strict)::

    {
      "format": "pige-tolerances 1",                 required, exactly this text
      "machine": "wC'A'bXYZ(C1)t",                   optional: refuse estimates of another machine
      "description": "acceptance after the overhaul", optional free text
      "defaults": {"um": 10, "urad": 20},            optional: a limit for every location PIGE of that unit
      "limits": {"EX0C": 8, "angular_error_C.cos_urad": 25}
    }

Every limit is a positive finite number in the parameter's unit (µm for position errors, µrad
for orientation and zero-position errors, the unit of an effect parameter as the diagnosis
reports it), at most ``MAX_PIGE`` (10 mm or 10 mrad: a tolerance no PIGE can exceed accepts anything),
and bounds the *absolute* value: the tolerance zone is ``[-limit, +limit]``.
``limits`` names PIGEs (``EX0C``; letter O accepted for the digit zero) or effect parameters
as ``<effect id>.<parameter>`` (``angular_error_C.cos_urad``, ``backlash_C.b_urad``).  Unknown
keys, NaN/Infinity, strings, booleans, non-positive numbers, duplicate keys and names the
machine does not have are refused with the file and the field (exit status 2).

Decision rules (value ``v``, standard uncertainty ``u``, coverage factor ``k``, limit ``L``):

- ``guard`` (default; ISO 14253-1 conformance/non-conformance zones reduced by the expanded
  uncertainty ``U = k·u``): ``pass`` when ``|v| + U <= L``, ``fail`` when ``|v| - U > L``,
  ``undecided`` otherwise;
- ``simple`` (simple acceptance, the uncertainty shown but not used): ``pass`` when
  ``|v| <= L``, else ``fail``.

Under both rules a parameter without a value (not identifiable, not estimated) or without a
finite uncertainty (guard rule) is ``undecided``: no number is invented.  The verdict is ``fail``
when any item fails, else ``undecided`` when any item is undecided, else ``pass``.  A limit on
an effect the diagnosis did not accept produces no item; it is listed under ``not_assessed``
with the reason (the effect is not in the model, so there is no value to judge).

The tolerance reader (:class:`Tolerances`, :func:`read_tolerances`) is a small dataclass and one
validation function so that it can later move into a shared JSON-schema module.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pige_sym.constants import MAX_PIGE
from pige_sym.errors import FileFormatError, InputError

TOLERANCE_FORMAT = "pige-tolerances 1"
RULES = ("guard", "simple")
STATUSES = ("pass", "fail", "undecided")
DEFAULT_K = 2.0
_TOP_KEYS = {"format", "machine", "description", "defaults", "limits"}
_UNITS = ("um", "urad")


# ---------------------------------------------------------------------------------------------
# tolerance file


@dataclass
class Tolerances:
    """Limits of a tolerance file.

    Attributes
    ----------
    path : str
        Where they were read (for messages).
    limits : dict of str to float
        Parameter name to limit on ``|value|`` [its unit], as written (names not yet checked
        against a machine: :meth:`resolve` does that).
    defaults : dict of {"um", "urad"} to float
        Limit for every location PIGE of that unit without its own limit.
    machine : str or None
    description : str
    """

    path: str
    limits: dict[str, float] = field(default_factory=dict)
    defaults: dict[str, float] = field(default_factory=dict)
    machine: str | None = None
    description: str = ""

    def resolve(self, machine: str) -> dict[str, float]:
        """Limits by canonical parameter name for ``machine``.

        Raises
        ------
        FileFormatError
            The file is for another machine, or names a parameter or effect the machine does not have.
        """
        from pige_sym.kernels import load_kernels
        from pige_sym.model.effects import EffectSpec, catalogue
        from pige_sym.simulation.simulator import normalise_parameter_name

        kern = load_kernels(machine)
        if self.machine is not None and load_kernels(self.machine).MACHINE_CODE != kern.MACHINE_CODE:
            raise FileFormatError(self.path, None, f"machine: the tolerances are for {self.machine}, the estimates "
                                                   f"for {kern.MACHINE_CODE}")
        out = {p: self.defaults[kern.UNITS[p]] for p in kern.LOCATION_PARAMETERS if kern.UNITS[p] in self.defaults}
        effects = catalogue(tuple(kern.ROTARY_AXES))
        for name, limit in self.limits.items():
            if "." in name:
                effect, _, param = name.partition(".")
                effect, harmonic = split_harmonic(effect)
                if harmonic is not None and not (harmonic.isdigit() and int(harmonic) >= 1):
                    raise FileFormatError(self.path, None, f"limits.{name}: @h must be followed by a harmonic 1, 2, "
                                                           "... (e.g. angular_error_C@h2.cos_urad)")
                if effect not in effects or effect == "outliers":
                    raise FileFormatError(self.path, None, f"limits.{name}: {effect!r} is not an effect of "
                                                           f"{kern.MACHINE_CODE} (known: {', '.join(effects[:-1])})")
                known = EffectSpec(effect).param_names
                if param not in known:
                    raise FileFormatError(self.path, None, f"limits.{name}: {effect} has the parameters "
                                                           f"{', '.join(known)}")
                out[name] = limit
                continue
            key = normalise_parameter_name(name)
            if key not in kern.PARAMETERS:
                raise FileFormatError(self.path, None, f"limits.{name}: not a parameter of {kern.MACHINE_CODE} "
                                                       f"(its PIGEs: {', '.join(kern.PARAMETERS)})")
            out[key] = limit
        if not out:
            raise FileFormatError(self.path, None, "no limit applies: give \"limits\" or \"defaults\"")
        return out


def looks_like_json(path: str | os.PathLike[str]) -> bool:
    """True when the file's first non-blank character opens a JSON object (a saved result, not a measurement)."""
    from pige_sym.files import peek_input

    return peek_input(path).lstrip().startswith(b"{")


def strict_json(path: str | os.PathLike[str]) -> Any:
    """Parse a JSON file strictly (NaN/Infinity, duplicate keys, non-UTF-8 refused): :func:`~.schema.load_json`.

    Raises
    ------
    FileFormatError
    InputError
        The file does not exist.
    """
    from pige_sym.measurements.schema import load_json

    if not Path(path).exists():
        raise InputError(f"{path}: no such file")
    return load_json(path, "JSON file")


def _limit(value: Any, path: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FileFormatError(path, None, f"{where}: expected a positive number, got {json.dumps(value)}")
    x = float(value)
    if not math.isfinite(x) or x <= 0:
        said = "a number beyond ±1.8e308" if math.isinf(x) else repr(value)
        raise FileFormatError(path, None, f"{where}: a limit must be a positive finite number, got {said}")
    if x > MAX_PIGE:
        raise FileFormatError(path, None, f"{where}: a limit of {x:g} accepts any machine (no PIGE or effect exceeds "
                              f"{MAX_PIGE:g} um or urad): give the tolerance the machine is held to, e.g. 10")
    return x


def tolerances_from_dict(data: Any, path: str) -> Tolerances:
    """Validate a parsed tolerance file (module docstring); ``path`` is used in messages.

    Raises
    ------
    FileFormatError
        Naming the field and what to write instead.
    """
    if not isinstance(data, dict):
        raise FileFormatError(path, None, "expected a JSON object (see `pige check --help`)")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise FileFormatError(path, None, f"unknown key(s) {', '.join(unknown)}: allowed are "
                                          f"{', '.join(sorted(_TOP_KEYS))}")
    if data.get("format") != TOLERANCE_FORMAT:
        raise FileFormatError(path, None, f"format: expected {TOLERANCE_FORMAT!r}, got {data.get('format')!r}")
    machine = data.get("machine")
    if machine is not None and not isinstance(machine, str):
        raise FileFormatError(path, None, "machine: expected an ISO 10791 machine code (text)")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise FileFormatError(path, None, "description: expected text")
    defaults_raw = data.get("defaults", {})
    if not isinstance(defaults_raw, dict):
        raise FileFormatError(path, None, 'defaults: expected an object like {"um": 10, "urad": 20}')
    bad = sorted(set(defaults_raw) - set(_UNITS))
    if bad:
        raise FileFormatError(path, None, f"defaults: unknown unit(s) {', '.join(bad)}: use um, urad")
    defaults = {u: _limit(v, path, f"defaults.{u}") for u, v in defaults_raw.items()}
    limits_raw = data.get("limits", {})
    if not isinstance(limits_raw, dict):
        raise FileFormatError(path, None, 'limits: expected an object of parameter: limit, e.g. {"EX0C": 8}')
    limits = {str(k): _limit(v, path, f"limits.{k}") for k, v in limits_raw.items()}
    if not limits and not defaults:
        raise FileFormatError(path, None, 'no limit: give "limits" and/or "defaults"')
    return Tolerances(path, limits, defaults, machine, description)


def read_tolerances(path: str | os.PathLike[str]) -> Tolerances:
    """Read and validate a tolerance file (module docstring)."""
    return tolerances_from_dict(strict_json(path), str(path))


# ---------------------------------------------------------------------------------------------
# decision


def decide(value: float | None, std: float | None, limit: float, *, rule: str = "guard",
           k: float = DEFAULT_K) -> tuple[str, str]:
    """Status of one parameter against a symmetric limit.

    Parameters
    ----------
    value, std : float or None
        Estimate and standard uncertainty [unit of the limit]; None/NaN when there is none.
    limit : float
        Bound on ``|value|`` (> 0).
    rule : {"guard", "simple"}
    k : float
        Coverage factor of the expanded uncertainty ``U = k·std`` (guard rule).

    Returns
    -------
    status : {"pass", "fail", "undecided"}
    reason : str
        Plain-text justification with the numbers.
    """
    if rule not in RULES:
        raise InputError(f"unknown decision rule {rule!r}: use {', '.join(RULES)}")
    if not (math.isfinite(k) and k >= 0):
        raise InputError(f"--k must be a finite number >= 0, got {k}")
    if value is None or not math.isfinite(value):
        return "undecided", "not identifiable from these data: no value"
    mag = abs(value)
    if rule == "simple":
        return ("pass", f"|v| {mag:.3g} <= {limit:g}") if mag <= limit else ("fail", f"|v| {mag:.3g} > {limit:g}")
    if std is None or not math.isfinite(std) or std < 0:
        return "undecided", "no finite uncertainty"
    u_exp = k * std
    if mag + u_exp <= limit:
        return "pass", f"|v| + {k:g}u = {mag + u_exp:.3g} <= {limit:g}"
    if mag - u_exp > limit:
        return "fail", f"|v| - {k:g}u = {mag - u_exp:.3g} > {limit:g}"
    return "undecided", f"{mag - u_exp:.3g} <= {limit:g} < {mag + u_exp:.3g} (|v| ∓ {k:g}u straddles the limit)"


@dataclass
class Estimates:
    """Values of one run to be judged.

    Attributes
    ----------
    machine : str
        Canonical machine code.
    method : str
        ``gauss-newton``, ``double-differential`` or ``diagnosis``.
    source : str
        File they come from.
    values, std : dict of str to float or None
        By parameter [µm, µrad]; None where undetermined.
    units : dict of str to str
    effects : list of str
        Effect ids accepted by the diagnosis (their parameters are in ``values``).
    """

    machine: str
    method: str
    source: str
    values: dict[str, float | None]
    std: dict[str, float | None]
    units: dict[str, str]
    effects: list[str] = field(default_factory=list)


@dataclass
class CheckItem:
    """One judged parameter (value and std [unit])."""

    name: str
    value: float | None
    std: float | None
    limit: float
    unit: str
    status: str
    reason: str


@dataclass
class CheckResult:
    """Outcome of ``pige check``."""

    verdict: str
    rule: str
    k: float
    machine: str
    method: str
    source: str
    tolerances: str
    items: list[CheckItem]
    not_assessed: dict[str, str] = field(default_factory=dict)

    @property
    def exit_status(self) -> int:
        """0 only when every item passes, else 1."""
        return 0 if self.verdict == "pass" else 1

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        return json_ready({**asdict(self), "items": [asdict(i) for i in self.items]})

    def format(self) -> str:
        """Plain-text table and verdict line."""
        rule = (f"guard band U = {self.k:g}u (ISO 14253-1)" if self.rule == "guard"
                else "simple acceptance (uncertainty not used)")
        source = f"{self.source}: " if self.source else ""
        given = self.tolerances in ("", "tolerances")  # a dict in a script: no file to name
        limits = "limits set by the calling script (no tolerance file)" if given else f"tolerances {self.tolerances}"
        lines = [f"{source}{self.method} estimate of {self.machine}, {limits}, {rule}",
                 f"{'parameter':28s} {'value':>9s} {'std':>7s} {'limit':>8s} unit  status     why"]
        for it in self.items:
            v = "—" if it.value is None else f"{it.value:.3f}"
            s = "—" if it.std is None else f"{it.std:.3f}"
            lines.append(f"{it.name:28s} {v:>9s} {s:>7s} {it.limit:8g} {it.unit:5s} {it.status:10s} {it.reason}")
        for name, why in self.not_assessed.items():
            lines.append(f"{name:28s} not assessed: {why}")
        lines.append(f"verdict: {self.verdict.upper()}")
        return "\n".join(lines)


def overall(statuses: list[str]) -> str:
    """``fail`` if any fails, else ``undecided`` if any is undecided, else ``pass`` (no item: undecided)."""
    if not statuses:
        return "undecided"
    if "fail" in statuses:
        return "fail"
    return "undecided" if "undecided" in statuses else "pass"


def check(est: Estimates, tol: Tolerances, *, rule: str = "guard", k: float = DEFAULT_K) -> CheckResult:
    """Judge every parameter that has a limit.

    Returns
    -------
    CheckResult
        Items in the order of the limits (location PIGEs first).
    """
    if rule not in RULES:
        raise InputError(f"unknown decision rule {rule!r}: use {', '.join(RULES)}")
    if not (math.isfinite(k) and k >= 0):
        raise InputError(f"--k must be a finite number >= 0, got {k}")
    limits = tol.resolve(est.machine)
    items: list[CheckItem] = []
    skipped: dict[str, str] = {}
    for name, limit in _per_harmonic(limits, est).items():
        if "." in name and split_harmonic(name.partition(".")[0])[0] not in est.effects:
            skipped[name] = "effect not accepted by the diagnosis (not in the model): no value to judge"
            continue
        value, std = est.values.get(name), est.std.get(name)
        if name not in est.values:
            status, reason = "undecided", f"not estimated by {est.method}"
            if name in _zero_names(est.machine):
                reason += " (estimate the zero-position errors, e.g. identify --with-zero)"
        else:
            status, reason = decide(value, std, limit, rule=rule, k=k)
        items.append(CheckItem(name, value, std, limit, est.units.get(name, ""), status, reason))
    return CheckResult(overall([i.status for i in items]), rule, k, est.machine, est.method, est.source, tol.path,
                       items, skipped)


def split_harmonic(effect: str) -> tuple[str, str | None]:
    """``angular_error_C@h2`` → (``angular_error_C``, ``2``); an id without ``@h`` → (id, None)."""
    base, sep, harmonic = effect.partition("@h")
    return base, (harmonic if sep else None)


def _per_harmonic(limits: dict[str, float], est: Estimates) -> dict[str, float]:
    """The limits by the names the estimate holds (the tolerance-name rule): where the diagnosis accepts one
    harmonic of an effect its parameters are ``<effect>.<param>``; where it accepts several they are named
    ``<effect>@h<h>.<param>`` (:func:`pige_sym.diagnosis.diagnose` names them so), and a tolerance
    ``<effect>.<param>`` applies to the parameter of every accepted harmonic, each judged on its own;
    ``<effect>@h<h>.<param>`` applies to harmonic h alone (and wins over the general one)."""
    out: dict[str, float] = {}
    for name, limit in limits.items():
        effect, dot, param = name.partition(".")
        if dot and "@h" not in effect and name not in est.values:
            harmonics = sorted(n for n in est.values if n.startswith(effect + "@h") and n.endswith("." + param))
            if harmonics:
                out |= {n: limit for n in harmonics if n not in limits}
                continue
        out[name] = limit
    return out


def _zero_names(machine: str) -> tuple[str, ...]:
    from pige_sym.kernels import load_kernels

    return tuple(load_kernels(machine).ZERO_PARAMETERS)


# ---------------------------------------------------------------------------------------------
# estimates from results and saved JSON


def estimates_from_result(result: Any, source: str) -> Estimates:
    """Estimates of an :class:`~pige_sym.identification.least_squares.IdentificationResult` or a ``DiagnosisResult``."""
    from pige_sym.kernels import load_kernels

    final = getattr(result, "final", result)
    effects = [f.effect for f in getattr(result, "findings", [])]
    method = "diagnosis" if final is not result else final.method

    def num(x: float) -> float | None:
        return float(x) if math.isfinite(float(x)) else None

    values = {p: num(v) for p, v in zip(final.parameters, final.values, strict=True)}
    std = {p: (num(s) if values[p] is not None else None) for p, s in zip(final.parameters, final.std, strict=True)}
    return Estimates(load_kernels(final.machine).MACHINE_CODE, method, source, values, std, dict(final.units),
                     effects)


def _number_map(data: Any, path: str, key: str) -> dict[str, float | None]:
    if not isinstance(data, dict):
        raise FileFormatError(path, None, f"{key}: expected an object of parameter: number or null")
    out: dict[str, float | None] = {}
    for name, v in data.items():
        if v is None:
            out[name] = None
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise FileFormatError(path, None, f"{key}.{name}: expected a number or null, got {json.dumps(v)}")
        else:
            out[name] = float(v)
    return out


def estimates_from_json(data: Any, path: str) -> Estimates:
    """Estimates from the JSON of ``pige identify --json`` or ``pige diagnose --json``.

    Raises
    ------
    FileFormatError
        A required field (machine, pige, std, units) is missing or not of the right type.
    """
    from pige_sym.kernels import load_kernels

    if not isinstance(data, dict) or not all(k in data for k in ("machine", "pige", "std", "units")):
        raise FileFormatError(path, None, "expected the JSON of `pige identify --json` or `pige diagnose --json` "
                                          "(keys machine, pige, std, units)")
    if not isinstance(data["machine"], str) or not isinstance(data["units"], dict):
        raise FileFormatError(path, None, "machine must be text and units an object")
    values = _number_map(data["pige"], path, "pige")
    std = _number_map(data["std"], path, "std")
    effects = []
    for i, f in enumerate(data.get("findings") or []):
        if not isinstance(f, dict) or not isinstance(f.get("effect"), str):
            raise FileFormatError(path, None, f"findings[{i}]: expected an object with an effect id")
        effects.append(f["effect"])
    return Estimates(load_kernels(data["machine"]).MACHINE_CODE, str(data.get("method", "gauss-newton")), path,
                     values, {k: (std.get(k) if values[k] is not None else None) for k in values},
                     {str(k): str(v) for k, v in data["units"].items()}, effects)
