"""``linuxcnc``: the trt kinematics ``xyzac-trt-kins`` / ``xyzbc-trt-kins``, HAL input pins [mm].

``src/emc/kinematics/trtfuncs.c`` (LinuxCNC master, commit 5c41560ebbc3a40f84a5547bc6f7c5cd9278ba6b):
the C line is at ``(x-rot-point, y-rot-point)``; the A line (xyzac) passes through ``(y-rot-point +
y-offset, z-rot-point + z-offset)``, the B line (xyzbc) through ``(x-rot-point + x-offset, z-rot-point +
z-offset)``.  So the four axis-line positions are entered; the axis tilts are not representable (the model
has no axis directions), nor are the zero-position errors (joint home offsets, whose sign depends on the
homing set-up: not printed).  HAL has no "add": with today's pin values (``current``) absolute ``setp``
lines are printed, otherwise the change of each pin as a comment.

Beside them, the complete correction: pige's own kinematics component (``pige gen --target linuxcnc``,
docs/linuxcnc-kinematics.md) carries every PIGE and zero-position error as a HAL pin, for any machine it
supports (heads and mixed machines too).  Its pins hold absolute values (the identified PIGEs [µm, µrad], the
axis senses and the nominal pivots the PIGEs refer to), so its ``setp`` lines need no ``current``.  Pin
names come from the kernels' metadata (:mod:`pige_sym.codegen.targets.linuxcnc_pins`, no SymPy).
"""

from __future__ import annotations

from pige_sym.compensation.controllers import ControllerOptions
from pige_sym.compensation.controllers.axis_lines import signed
from pige_sym.compensation.controllers.scope import scope_lines
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError, UnsupportedMachineError
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
    """The stock trt pins (module docstring) and, beside them, pige's kinematics component with every PIGE.

    Raises
    ------
    InputError
        Neither the stock trt kinematics nor pige's component can describe the machine.
    """
    try:
        trt = _render_trt(params, options)
    except InputError as exc:
        trt_refusal = str(exc)
        trt = ""
    try:
        pige = pige_kinematics_lines(params)
    except (InputError, UnsupportedMachineError) as exc:
        if not trt:
            raise InputError(f"{trt_refusal}; pige's kinematics component: {exc}") from None
        return trt + f"\n# pige's kinematics component cannot describe this machine: {exc}"
    if not trt:
        trt = f"# LinuxCNC's stock trt kinematics: {trt_refusal}"
    return trt + "\n" + "\n".join(pige)


def _render_trt(params: CompensationParameters, options: ControllerOptions) -> str:
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


def _senses(params: CompensationParameters, axes: tuple[str, ...]) -> dict[str, int]:
    """σ per rotary axis (CONVENTIONS §9): −1 where the parameter file records a reversed sense, else +1."""
    return {a: -1 if params.axis_sense.get(a, 1) < 0 else 1 for a in axes}


def pige_kinematics_lines(params: CompensationParameters) -> list[str]:
    """pige's kinematics component for ``params.machine``: how to load it and its ``setp`` lines (absolute).

    Raises
    ------
    UnsupportedMachineError
        The component cannot describe the machine (:func:`~pige_sym.codegen.targets.linuxcnc_pins.check_machine`).
    """
    import numpy as np

    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.codegen.targets import linuxcnc_pins as pins
    from pige_sym.model.trajectories import make_trajectory

    kern = load_kernels(params.machine)
    structure = parse_machine_code(kern.MACHINE_CODE)
    pins.check_machine(structure)
    name = pins.default_name(structure)
    axes = tuple(kern.ROTARY_AXES)
    unset = {s.split()[0] for s in params.ignored}
    angles = make_trajectory(kern.MACHINE_CODE, "cone-frustum").angles_deg
    vector = np.array([0.0 if n in unset else params.values.get(n, 0.0) for n in kern.PARAMETERS])  # µm, µrad
    tilt = float(np.linalg.norm(kern.orientation_jacobian(angles) @ vector, axis=1).max())
    out = [f"# the complete correction: pige's kinematics component {name} carries every PIGE and zero-position "
           "error (docs/linuxcnc-kinematics.md):",
           f"#   pige gen --target linuxcnc \"{kern.MACHINE_CODE}\" && halcompile --install {name}.comp",
           f"#   [KINS] KINEMATICS = {name} sparm=identityfirst, JOINTS = {3 + len(axes)}, "
           f"[TRAJ] COORDINATES = XYZ{''.join(axes)}; net motion.tooloffset.z to {name}.tool-offset",
           "#   to first order it puts the tool point on target; left: the tool's orientation error (up to "
           f"{tilt:.3g} urad on the default cone) and the pose-dependent extensions: "
           f"{', '.join(e.spec.id for e in params.extensions) or 'none'}"]
    out += [f"setp {name}.sense-{a.lower()} {s}" for a, s in _senses(params, axes).items()]
    for a in axes:
        pivot = params.pivots_mm.get(a, [0.0, 0.0, 0.0])
        out += [f"setp {name}.pivot-{a.lower()}-{c} {float(v):.6f}" for c, v in zip("xyz", pivot, strict=True)]
    if kern.TOOL_ROTARY:
        out.append(f"# set {name}.tool-x, -y, -z to the gauge point relative to the {kern.TOOL_ROTARY[-1]} pivot at "
                   "the reference pose [mm] (the machine's, not the test's tool); the tool length comes from "
                   "tool-offset")
    for n in kern.PARAMETERS:
        pin = pins.error_pin(name, n)
        if n in unset:
            out.append(f"# {pin}: no value in the parameter file (left as it is)")
        elif n not in params.values:
            out.append(f"# {pin}: not estimated (the parameter file has no {n}; left as it is)")
        else:
            out.append(f"setp {pin} {params.values.get(n, 0.0):.4f}")
    return out
