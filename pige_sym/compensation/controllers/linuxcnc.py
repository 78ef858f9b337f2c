"""``linuxcnc``: the trt kinematics ``xyzac-trt-kins`` / ``xyzbc-trt-kins``, HAL input pins [mm].

``src/emc/kinematics/trtfuncs.c`` (LinuxCNC master, commit 5c41560ebbc3a40f84a5547bc6f7c5cd9278ba6b):
the C line is at ``(x-rot-point, y-rot-point)``; the A line (xyzac) passes through ``(y-rot-point +
y-offset, z-rot-point + z-offset)``, the B line (xyzbc) through ``(x-rot-point + x-offset, z-rot-point +
z-offset)``.  So the four axis-line positions are entered; the axis tilts are not representable (the model
has no axis directions), nor are the zero-position errors (joint home offsets, whose sign depends on the
homing set-up: not printed).  HAL has no "add": with today's pin values (``current``) absolute ``setp``
lines are printed, otherwise the change of each pin as a comment.
"""

from __future__ import annotations

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import signed
from pige_sym.compensation.controllers.scope import scope_lines
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

TITLE = "LinuxCNC trt kinematics (xyzac-trt-kins, xyzbc-trt-kins), HAL pins"
#: LinuxCNC trt kinematics module of each tilt axis (src/emc/kinematics/xyzac-trt-kins.c, xyzbc-trt-kins.c).
TRT_MODULES = {"A": "xyzac-trt-kins", "B": "xyzbc-trt-kins"}
#: Their HAL input pins (trtfuncs.c, trtKinematicsSetup).
TRT_PINS = ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset", "tool-offset",
            "conventional-directions")


def representable(params: CompensationParameters) -> list[str]:
    """The four axis-line positions [µm]."""
    kern = load_kernels(params.machine)
    return [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]


def linuxcnc_trt_deltas(params: CompensationParameters) -> tuple[str, dict[str, float]]:
    """The trt kinematics module and the change of each of its HAL pins [mm] (module docstring).

    Raises
    ------
    InputError
        The machine is not a tilting rotary table with C on an A or B tilt axis.
    """
    kern = load_kernels(params.machine)
    axes = tuple(kern.ROTARY_AXES)
    tilt = next((a for a in axes if a[0] in "AB"), None)
    if kern.TOOL_ROTARY or tilt is None or "C" not in axes or len(axes) != 2:
        raise InputError(f"{kern.MACHINE_CODE}: LinuxCNC's trt kinematics describe a tilting rotary table (C on an "
                         "A or B tilt axis, xyzac-trt-kins / xyzbc-trt-kins); no mapping for this machine")
    v = {k: params.values.get(k, 0.0) * 1e-3 for k in kern.LOCATION_PARAMETERS}
    deltas = {"x-rot-point": v["EX0C"], "y-rot-point": v["EY0C"], "z-rot-point": 0.0}
    if tilt == "A":
        deltas |= {"y-offset": v["EY0A"] - v["EY0C"], "z-offset": v["EZ0A"]}
    else:
        deltas |= {"x-offset": v["EX0B"] - v["EX0C"], "z-offset": v["EZ0B"]}
    return TRT_MODULES[tilt], deltas


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """``setp`` lines with absolute values when ``options.current`` gives today's pin values, otherwise the
    change of each pin as a comment (HAL has no "add")."""
    current = options.current
    module, deltas = linuxcnc_trt_deltas(params)
    out = [f"# LinuxCNC {module} (src/emc/kinematics/trtfuncs.c): HAL pins [mm], parameters from {params.source}",
           *scope_lines(params, "linuxcnc", "# ")]
    unknown = sorted(set(current or {}) - set(TRT_PINS))
    if unknown:
        raise InputError(f"--current {unknown[0]}: not a pin of {module} ({', '.join(TRT_PINS)})")
    for pin, d in deltas.items():
        if current is not None and pin in current:
            out.append(f"setp {module}.{pin} {current[pin] + d:.6f}")
        else:
            out.append(f"# {module}.{pin}: add {signed(d, 6)} (give --current {pin}=VALUE,... or your HAL file "
                       "for the setp line)")
    return "\n".join(out)
