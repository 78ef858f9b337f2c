"""What a controller's kinematic description can hold, what it cannot, and what that leaves at the tool.

Per style, the controller module's ``representable`` names the PIGEs its entries carry (CONVENTIONS §3):

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

:func:`tool_point_summary` predicts, on the default test (cone frustum, ball at ``DEFAULT_BALL_MM``), the
tool-point RMSE before correction, after entering only what the controller holds, and after the NC rewrite.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pige_sym.compensation.controllers import get_controller
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.study import compensation_study
from pige_sym.constants import DEFAULT_BALL_MM
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import make_trajectory


@dataclass
class ControllerScope:
    """What one controller style holds of a parameter set, and the tool-point error it leaves [µm]."""

    entered: list[str]
    not_representable: list[str]
    rmse_before_um: float
    rmse_table_only_um: float
    rmse_nc_rewrite_um: float


def representable(params: CompensationParameters, style: str) -> list[str]:
    """The PIGEs a style's entries carry (module docstring)."""
    return list(get_controller(style).representable(params))


def positions_and_zeros(params: CompensationParameters) -> list[str]:
    """The axis-line positions [µm] and the zero-position errors [µrad] of the machine's rotary axes."""
    kern = load_kernels(params.machine)
    position = [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]
    return position + [n for n in kern.PARAMETERS if n in kern.ZERO_PARAMETERS]


def tool_point_summary(params: CompensationParameters, style: str) -> ControllerScope:
    """Entered, not representable, and the predicted tool-point RMSE before / table only / NC rewrite."""
    kern = load_kernels(params.machine)
    held = set(representable(params, style))
    values = {k: v for k, v in params.values.items() if v != 0.0}
    entered = [n for n in kern.PARAMETERS if n in values and n in held]
    missing = [f"{n} {values[n]:+.3g} {kern.UNITS[n]}" for n in kern.PARAMETERS if n in values and n not in held]
    missing += [f"{e.spec.id} ({', '.join(f'{k}={v:.3g}' for k, v in e.params.items())} urad: depends on the pose)"
                for e in params.extensions]
    missing += list(params.ignored)
    traj = make_trajectory(kern.MACHINE_CODE, "cone-frustum")
    tool = params.tool_mm if kern.TOOL_ROTARY else None
    common: dict[str, Any] = {"truth": params.values, "ball_mm": DEFAULT_BALL_MM, "tool_mm": tool,
                              "pivots_mm": params.pivots_mm or None, "truth_extensions": params.extensions}
    table = compensation_study(kern.MACHINE_CODE, [traj], identified={n: values[n] for n in entered}, **common)[0]
    nc = compensation_study(kern.MACHINE_CODE, [traj], identified=params.values, extensions=params.extensions,
                            **common)[0]
    return ControllerScope(entered, missing, table.rmse_before_um, table.rmse_after_um, nc.rmse_after_um)


def scope_lines(params: CompensationParameters, style: str, comment: str) -> list[str]:
    """The scope as text lines, each starting with the style's comment marker."""
    s = tool_point_summary(params, style)
    base = getattr(get_controller(style), "base_data", None)
    extra = [n for n in (base(params) if base else []) if params.values.get(n, 0.0) != 0.0]
    note = ([f"{comment}printed below as changes of base data, not entered above (the RMSE after entering leaves "
             f"them out): {', '.join(extra)}"] if extra else [])
    if s.rmse_table_only_um > s.rmse_before_um:
        note.append(f"{comment}WARNING: entering only these values makes the predicted tool-point error LARGER "
                    f"({s.rmse_table_only_um:.3f} > {s.rmse_before_um:.3f} um on the default cone): what they cannot "
                    "hold outweighs them; do not enter them alone (use the NC rewrite)")
    return note + [
        f"{comment}entered: {', '.join(s.entered) or 'nothing'}",
        f"{comment}NOT representable in this controller's kinematics (only the NC rewrite compensates them): "
        f"{'; '.join(s.not_representable) or 'none'}",
        f"{comment}predicted tool-point RMSE on the default cone (ball {', '.join(f'{x:g}' for x in DEFAULT_BALL_MM)} "
        f"mm): {s.rmse_before_um:.3f} um uncorrected, {s.rmse_table_only_um:.3f} um after entering these values "
        f"only, {s.rmse_nc_rewrite_um:.3f} um after the NC rewrite (pige compensate PROGRAM)",
    ]
