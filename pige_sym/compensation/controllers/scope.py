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

from pige_sym.compensation.controllers import get_controller
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.weighing import ErrorPrediction, Weighing, estimate_of, travel_poses, weigh, weighing_rows
from pige_sym.kernels import load_kernels


@dataclass
class ControllerScope:
    """What one controller style holds of a parameter set, and the tool-point error it leaves.

    Attributes
    ----------
    entered, not_representable : list of str
    before, controller_only, complete : ErrorPrediction or None
        Predicted RMS tool-point error [µm] over ``judged_on``: uncorrected, after this controller's
        entries, after every entered value; None without standard errors in the file.
    judged_on : str
    """

    entered: list[str]
    not_representable: list[str]
    before: ErrorPrediction | None
    controller_only: ErrorPrediction | None
    complete: ErrorPrediction | None
    judged_on: str


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


def tool_point_summary(params: CompensationParameters, style: str) -> ControllerScope:
    """Entered, not representable, and the predicted tool-point error uncorrected / these entries / complete."""
    kern = load_kernels(params.machine)
    held = set(representable(params, style))
    values = {k: v for k, v in params.values.items() if v != 0.0}
    entered = [n for n in kern.PARAMETERS if n in values and n in held]
    missing = [f"{n} {values[n]:+.3g} {kern.UNITS[n]}" for n in kern.PARAMETERS if n in values and n not in held]
    missing += [f"{e.spec.id} ({', '.join(f'{k}={v:.3g}' for k, v in e.params.items())} urad: depends on the pose)"
                for e in params.extensions]
    missing += list(params.ignored)
    if params.error_maps is not None:
        tables = set(_map_motions(params, style))
        left = [f"{ax}:{name}" for ax, m in params.error_maps.axes.items() for name in m.values
                if f"{ax}:{name}" not in tables]
        if left:
            missing.append(f"the error maps {', '.join(left)} (CONVENTIONS §10; the NC rewrite compensates them)")
    w = weighing_of(params)
    return ControllerScope(entered, missing, w.predicted_for({}), w.predicted_for({n: values[n] for n in entered}),
                           w.predicted_for(estimate_of(params)), w.judged_on)


def _map_motions(params: CompensationParameters, style: str) -> list[str]:
    """The maps (``<axis>:<motion>``) the style's tables carry."""
    return list(getattr(get_controller(style), "map_motions", lambda _p: [])(params))


def weighing_lines(params: CompensationParameters, comment: str, style: str | None = None) -> list[str]:
    """The rule, and per value not entered as estimated: its estimate ± std and what is entered (with ``style``: a
    value that controller does not hold said to be weighed for the NC rewrite only)."""
    w = weighing_of(params)
    if w.covariance_from == "none":
        return [f"{comment}{note}" for note in w.notes]
    carried = None if style is None else set(representable(params, style)) | set(_map_motions(params, style))
    rows = weighing_rows(w, params.units, carried) or [
        "every estimate is entered as estimated (each many standard errors from 0)"]
    return [f"{comment}weighed by uncertainty (docs/algorithms.md): {w.rule}", *(f"{comment}{n}" for n in w.notes),
            *(f"{comment}  {r}" for r in rows)]


def scope_lines(params: CompensationParameters, style: str, comment: str) -> list[str]:
    """The scope as text lines, each starting with the style's comment marker."""
    s = tool_point_summary(params, style)
    base = getattr(get_controller(style), "base_data", None)
    extra = [n for n in (base(params) if base else []) if params.values.get(n, 0.0) != 0.0]
    note = ([f"{comment}printed below as changes of base data, not entered above (the error after entering leaves "
             f"them out): {', '.join(extra)}"] if extra else [])
    if s.before and s.controller_only and s.controller_only.expected_um > s.before.expected_um:
        note.append(f"{comment}WARNING: entering only these values makes the predicted tool-point error LARGER "
                    f"({s.controller_only.expected_um:.2f} > {s.before.expected_um:.2f} um): what they cannot "
                    "hold outweighs them; do not enter them alone (use the NC rewrite)")
    if s.before and s.controller_only and s.complete:
        predicted = (f"{comment}predicted tool-point RMS error over {s.judged_on}: uncorrected {s.before.text()}; "
                     f"after these entries only {s.controller_only.text()}; after every entered value (pige's "
                     f"kinematics, or the NC rewrite: pige compensate PROGRAM) {s.complete.text()}")
    else:
        predicted = f"{comment}predicted tool-point error: not predicted (the parameter file states no uncertainty)"
    return weighing_lines(params, comment, style) + note + [
        f"{comment}entered: {', '.join(s.entered) or 'nothing'}",
        f"{comment}NOT representable in this controller's kinematics (only the NC rewrite compensates them): "
        f"{'; '.join(s.not_representable) or 'none'}",
        predicted,
    ]
