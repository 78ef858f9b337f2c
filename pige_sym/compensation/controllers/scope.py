"""What a controller's kinematic description can hold, what it cannot, and what that leaves at the tool.

Per style, the controller module's ``representable`` names the PIGEs its entries carry (CONVENTIONS §3), and
its optional ``map_motions(params)`` the error maps (``<axis>:<motion>``, CONVENTIONS §10) its tables carry;
every other map is named as not representable:

- ``linuxcnc`` (``xyzac-trt-kins`` / ``xyzbc-trt-kins``, ``src/emc/kinematics/trtfuncs.c``): the rotary
  table's C line is at ``(x-rot-point, y-rot-point)``; the tilt axis (A about X, B about Y) turns about the
  line through ``(y-rot-point + y-offset, z-rot-point + z-offset)`` (A) or ``(x-rot-point + x-offset,
  z-rot-point + z-offset)`` (B).  So the four axis-line positions are entered (``EX0C, EY0C`` move the
  rot point; the tilt line moves by its own errors, the offsets take the difference); the axis tilts are
  not representable (the model has no axis directions), nor are the zero-position errors (joint home
  offsets, whose sign depends on the homing set-up: not printed).
- ``siemens``, ``heidenhain``, ``fanuc``: the axis-line positions and the zero offsets as printed by
  their modules; the axis directions are printed as a comment only (they live in base data that the
  calibration should not overwrite).

Angle extensions of a diagnosis (``angular_error_*``, ``backlash_*``) depend on the pose: no kinematic
table holds them; only the NC rewrite compensates them.

The values come weighed by their uncertainty (:mod:`pige_sym.compensation.weighing`, judged over the axes'
travel): :func:`tool_point_summary` predicts, with a 95 % bound, the tool-point RMS error over those poses
uncorrected, after entering only what the controller holds, and after entering every entered value (the NC
rewrite, or pige's own kinematics component).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pige_sym.compensation.controllers import get_controller
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.result import EntryChoice
from pige_sym.compensation.weighing import ErrorPrediction, Weighing, estimate_of, travel_poses, weigh, weighing_rows
from pige_sym.kernels import load_kernels


@dataclass
class ControllerScope:
    """What one controller style holds of a parameter set, and the tool-point error it leaves.

    Attributes
    ----------
    not_representable : list of str
    before, complete : ErrorPrediction or None
        Predicted RMS tool-point error [µm] over ``judged_on``: uncorrected, and after every entered value;
        None without standard errors in the file.
    choices : list of EntryChoice
        Each way of entering the printed lines (fewest values first): exactly the values they carry and the error
        they leave.
    judged_on : str
    """

    not_representable: list[str]
    before: ErrorPrediction | None
    complete: ErrorPrediction | None
    choices: list[EntryChoice]
    judged_on: str

    @property
    def entered(self) -> list[str]:
        """The PIGEs and zero-position errors the first way of entering carries."""
        return [n for n in self.choices[0].values if "@" not in n] if self.choices else []

    @property
    def controller_only(self) -> ErrorPrediction | None:
        """The error left by the first way of entering (the controller's own kinematic entries)."""
        return self.choices[0].predicted if self.choices else self.before


def representable(params: CompensationParameters, style: str) -> list[str]:
    """The PIGEs a style's entries carry (module docstring)."""
    return list(get_controller(style).representable(params))


def positions_and_zeros(params: CompensationParameters) -> list[str]:
    """The axis-line positions [µm] and the zero-position errors [µrad] of the machine's rotary axes."""
    kern = load_kernels(params.machine)
    position = [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]
    return position + [n for n in kern.PARAMETERS if n in kern.ZERO_PARAMETERS]


def weighing_of(params: CompensationParameters) -> Weighing:
    """The weighing ``params`` were entered by, or one judged over the axes' travel."""
    return params.weighing if params.weighing is not None else weigh(params, travel_poses(params))


def kinematic_values(params: CompensationParameters, style: str) -> dict[str, float]:
    """The PIGEs and zero-position errors a style's kinematic entries carry, as entered (non-zero ones)."""
    kern = load_kernels(params.machine)
    held = set(representable(params, style))
    return {n: params.values[n] for n in kern.PARAMETERS if params.values.get(n, 0.0) != 0.0 and n in held}


def entry_choices(params: CompensationParameters, style: str, options: Any = None) -> list[EntryChoice]:
    """Each way of entering the printed lines with exactly the values they carry (the controller module's
    ``entries(params, options)``: (label, values) or (label, values, own); by default its kinematic entries alone),
    predicted on the weighing's poses."""
    module = get_controller(style)
    w = weighing_of(params)
    found = getattr(module, "entries", None)
    raw = found(params, options) if found is not None else [("these entries", kinematic_values(params, style))]
    known = set(w.estimate)
    out = []
    for label, values, *own in raw:
        kept = {n: float(v) for n, v in values.items() if n in known}
        out.append(EntryChoice(label, kept, w.predicted_for(kept), bool(own[0]) if own else True))
    return out


def controller_scope(params: CompensationParameters, style: str, options: Any = None) -> ControllerScope:
    """Not representable (by no way of entering the controller's own entries), each way of entering and the predicted
    tool-point error uncorrected / each / complete."""
    kern = load_kernels(params.machine)
    values = {k: v for k, v in params.values.items() if v != 0.0}
    choices = entry_choices(params, style, options)
    carried = {n for c in choices if c.own for n in c.values}
    missing = [f"{n} {values[n]:+.3g} {kern.UNITS[n]}" for n in kern.PARAMETERS if n in values and n not in carried]
    missing += [f"{e.spec.id} ({', '.join(f'{k}={v:.3g}' for k, v in e.params.items())} urad: depends on the pose)"
                for e in params.extensions]
    missing += list(params.ignored)
    if params.error_maps is not None:
        motions = {n.split("@")[0] for n in carried if "@" in n}
        left = [f"{ax}:{name}" for ax, m in params.error_maps.axes.items() for name in m.values
                if f"{ax}:{name}" not in motions]
        if left:
            missing.append(f"the error maps {', '.join(left)} (CONVENTIONS §10; the NC rewrite compensates them)")
    w = weighing_of(params)
    return ControllerScope(missing, w.predicted_for({}), w.predicted_for(estimate_of(params)), choices, w.judged_on)


def tool_point_summary(params: CompensationParameters, style: str, options: Any = None) -> ControllerScope:
    """:func:`controller_scope` (the name the JSON printers use)."""
    return controller_scope(params, style, options)


def names_text(values: dict[str, float]) -> str:
    """``EX0C, EY0C; C:ECC+ at 12 grid angles`` for the names of entered values."""
    plain = [n for n in values if "@" not in n]
    maps: dict[str, int] = {}
    for n in values:
        if "@" in n:
            key = n.split("@")[0]
            maps[key] = maps.get(key, 0) + 1
    said = ", ".join(plain)
    mapped = ", ".join(f"{m} at {k} grid angle{'' if k == 1 else 's'}" for m, k in maps.items())
    return "; ".join(x for x in (said, mapped) if x) or "nothing"


def _map_motions(params: CompensationParameters, style: str) -> list[str]:
    """The maps (``<axis>:<motion>``) the style's tables carry."""
    return list(getattr(get_controller(style), "map_motions", lambda _p: [])(params))


def weighing_lines(params: CompensationParameters, comment: str, style: str | None = None,
                   scope: ControllerScope | None = None) -> list[str]:
    """The rule, and per value not entered as estimated: its estimate ± std and what is entered (with ``style``: a
    value that controller does not hold said to be weighed for the NC rewrite only; with ``scope``, what its own
    ways of entering carry decides it)."""
    w = weighing_of(params)
    if w.covariance_from == "none":
        return [f"{comment}{note}" for note in w.notes]
    if scope is not None:
        carried: set[str] | None = {n.split("@")[0] for c in scope.choices if c.own for n in c.values}
    else:
        carried = None if style is None else set(representable(params, style)) | set(_map_motions(params, style))
    rows = weighing_rows(w, params.units, carried) or [
        "every estimate is entered as estimated (each many standard errors from 0)"]
    return [f"{comment}weighed by uncertainty (docs/algorithms.md): {w.rule}", *(f"{comment}{n}" for n in w.notes),
            *(f"{comment}  {r}" for r in rows)]


def scope_lines(params: CompensationParameters, style: str, comment: str, options: Any = None) -> list[str]:
    """The scope as text lines, each starting with the style's comment marker (the stage's scope when
    ``options.scope`` holds it, else computed here)."""
    s = getattr(options, "scope", None) or controller_scope(params, style, options)
    base = getattr(get_controller(style), "base_data", None)
    extra = [n for n in (base(params) if base else []) if params.values.get(n, 0.0) != 0.0]
    note = ([f"{comment}printed below as changes of base data, not entered above (the error after entering leaves "
             f"them out): {', '.join(extra)}"] if extra else [])
    for c in s.choices:
        if s.before and c.predicted and c.predicted.expected_um > s.before.expected_um:
            what = "these values" if len(s.choices) == 1 else c.label
            note.append(f"{comment}WARNING: entering only {what} makes the predicted tool-point error LARGER "
                        f"({c.predicted.expected_um:.2f} > {s.before.expected_um:.2f} um): what they cannot hold "
                        "outweighs them; do not enter them alone (use the NC rewrite)")
    if s.before and s.complete and all(c.predicted for c in s.choices):
        after = "; ".join(f"after {c.label} {c.predicted.text()}" for c in s.choices if c.predicted)
        predicted = (f"{comment}predicted tool-point RMS error over {s.judged_on}: uncorrected {s.before.text()}; "
                     f"{after + '; ' if after else ''}after every entered value (pige's kinematics, or the NC "
                     f"rewrite of a program) {s.complete.text()}")
    else:
        predicted = f"{comment}predicted tool-point error: not predicted (the parameter file states no uncertainty)"
    entered = [f"{comment}entered by {c.label}: {names_text(c.values)}" for c in s.choices] or [
        f"{comment}entered: nothing"]
    return weighing_lines(params, comment, style, s) + note + entered + [
        f"{comment}NOT representable in this controller's kinematics (only the NC rewrite compensates them): "
        f"{'; '.join(s.not_representable) or 'none'}",
        predicted,
    ]
