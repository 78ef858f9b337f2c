"""``linuxcnc``: the trt kinematics ``xyzac-trt-kins`` / ``xyzbc-trt-kins``, HAL input pins [mm].

``src/emc/kinematics/trtfuncs.c`` (LinuxCNC 2.9.0~pre1, commit f1270d6ed7, as Debian ships it; master
5c41560ebbc3 reads the same): the C line is at ``(x-rot-point, y-rot-point)``; the A line (xyzac) passes
through ``(y-rot-point + y-offset, z-rot-point + z-offset)``, the B line (xyzbc) through ``(x-rot-point +
x-offset, z-rot-point + z-offset)``.  So the four axis-line positions are entered; the axis tilts are not
representable (the model has no axis directions), nor are the zero-position errors (joint home offsets,
whose sign depends on the homing set-up: not printed).  The pin positions do not depend on the axes'
commanded senses (CONVENTIONS §9: 2.9's trt kinematics turn both axes against CONVENTIONS' sense).

The rot-point pins came with commit 135b0ce522 ("switchable kinematics", 2021-06-19), first in v2.9.0-pre1;
2.8's trt modules have ``y-offset``/``x-offset``, ``z-offset`` and ``tool-offset`` only and turn C about
the machine origin: LinuxCNC ≥ 2.9 is required.

HAL has no "add": with today's values (``--current``: :mod:`.hal_config`) absolute lines are printed —
``setp <module>.<pin> <value>``, or ``sets <signal> <value>`` for a pin connected to a signal (halcmd
refuses ``setp`` on it); a pin a configuration file does not mention is at 0 (a new HAL pin starts at 0,
``src/hal/hal_lib.c``); otherwise the change of each pin is printed as a comment.

Beside them, the complete correction: pige's own kinematics component (``pige gen --target linuxcnc``,
docs/linuxcnc-kinematics.md) carries every PIGE and zero-position error as a HAL pin, for any machine it
supports (heads and mixed machines too).  Its pins hold absolute values (the identified PIGEs [µm, µrad], the
axis senses and the nominal pivots the PIGEs refer to), so its ``setp`` lines need no ``current``.  Pin
names come from the kernels' metadata (:mod:`pige_sym.codegen.targets.linuxcnc_pins`, no SymPy).

Error maps (CONVENTIONS §10): the positioning map of each rotary joint as a ``[JOINT_n]COMP_FILE`` for the stock
kinematics (:mod:`.tables.linuxcnc_comp`, written by ``--comp-dir``), and every map as pins of pige's component
(:mod:`.tables.linuxcnc_kins_maps`).
"""

from __future__ import annotations

from typing import Any

from pige_sym.compensation.controllers import ControllerOptions, built_tables
from pige_sym.compensation.controllers.axis_lines import MM_DECIMALS, origin_pivots_note, signed
from pige_sym.compensation.controllers.hal_config import HalConfig
from pige_sym.compensation.controllers.scope import scope_lines
from pige_sym.compensation.controllers.tables import linuxcnc_comp, linuxcnc_kins_maps
from pige_sym.compensation.controllers.tables.linuxcnc_comp import render_lines as comp_file_lines
from pige_sym.compensation.controllers.tables.linuxcnc_kins_maps import map_setp_lines
from pige_sym.compensation.controllers.tables.positioning import positioning_names
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.result import Section
from pige_sym.errors import InputError, UnsupportedMachineError
from pige_sym.kernels import load_kernels

TITLE = "LinuxCNC >= 2.9 trt kinematics (xyzac-trt-kins, xyzbc-trt-kins) and pige's kinematics component, HAL pins"
#: LinuxCNC trt kinematics module of each tilt axis (src/emc/kinematics/xyzac-trt-kins.c, xyzbc-trt-kins.c).
TRT_MODULES = {"A": "xyzac-trt-kins", "B": "xyzbc-trt-kins"}
#: Their HAL input pins (trtfuncs.c, trtKinematicsSetup).
TRT_PINS = ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset", "tool-offset",
            "conventional-directions")
#: The axis lines the trt pins hold (trtfuncs.c, module docstring): per module and axis, each coordinate
#: across the axis as the sum of pins.
TRT_LINES: dict[str, dict[str, dict[str, tuple[str, ...]]]] = {
    "xyzac-trt-kins": {"C": {"x": ("x-rot-point",), "y": ("y-rot-point",)},
                       "A": {"y": ("y-rot-point", "y-offset"), "z": ("z-rot-point", "z-offset")}},
    "xyzbc-trt-kins": {"C": {"x": ("x-rot-point",), "y": ("y-rot-point",)},
                       "B": {"x": ("x-rot-point", "x-offset"), "z": ("z-rot-point", "z-offset")}},
}
#: How far a configured axis line may lie from the parameter file's pivot and still be the same line [mm]:
#: their rounding, pige writes pivots to 1 nm (program headers, the component's pins) and trt pins to 0.1 nm.
PIVOT_AGREEMENT_MM = 2e-6
#: The options of ``pige compensate`` this controller reads (:func:`~pige_sym.compensation.controllers.check_options`).
OPTIONS = ("--current", "--comp-dir")
VERSION = ("# requires LinuxCNC >= 2.9: the rot-point pins came with commit 135b0ce522 (switchable kinematics, "
           "first in 2.9.0-pre1); 2.8's trt modules turn C about the machine origin")


def representable(params: CompensationParameters) -> list[str]:
    """The four axis-line positions [µm]."""
    kern = load_kernels(params.machine)
    return [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]


def entries(params: CompensationParameters, options: ControllerOptions | None) -> list[tuple[Any, ...]]:
    """Each way of entering the printed lines, with exactly what it carries: the stock trt pins (the four axis-line
    positions), those and the COMP_FILEs (the positioning maps' trims, as printed), and pige's component (every
    PIGE, zero-position error and map value, as its ``setp`` lines print them)."""
    from pige_sym.compensation.controllers.scope import kinematic_values
    from pige_sym.compensation.controllers.tables.linuxcnc_comp import entered_values as comp_values
    from pige_sym.compensation.controllers.tables.linuxcnc_kins_maps import entered_map_values

    built = built_tables(tables, params, options)
    out: list[tuple[Any, ...]] = []
    try:
        linuxcnc_trt_deltas(params)
    except InputError:
        pass
    else:
        trt = kinematic_values(params, "linuxcnc")
        out.append(("the trt pins", trt))
        comp = comp_values(params, [t for t in built if isinstance(t, linuxcnc_comp.CompTable)])
        if comp:
            out.append(("the trt pins and the COMP_FILEs", trt | comp))
    if not _component_describes(params):
        return out
    unset = {s.split()[0] for s in params.ignored}
    kern = load_kernels(params.machine)
    values = {n: round(params.values[n], 4) for n in kern.PARAMETERS if n in params.values and n not in unset}
    return [*out, ("pige's kinematics component", values | entered_map_values(_component_maps(built)), False)]


def _component_describes(params: CompensationParameters) -> bool:
    """Whether pige's kinematics component can describe the machine (:func:`~pige_sym.codegen.targets.
    linuxcnc_pins.check_machine`)."""
    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.codegen.targets import linuxcnc_pins as pins

    try:
        pins.check_machine(parse_machine_code(params.machine))
    except (InputError, UnsupportedMachineError):
        return False
    return True


def _component_maps(built: list[Any]) -> list[linuxcnc_kins_maps.ComponentMap]:
    return [t for t in built if isinstance(t, linuxcnc_kins_maps.ComponentMap)]


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


def tables(params: CompensationParameters, options: ControllerOptions) -> list[Any]:
    """Built once: the COMP_FILEs of the stock kinematics, every trim held to ``--max-change``
    (:func:`.tables.linuxcnc_comp.comp_tables`; none where the stock trt kinematics cannot describe the machine), and
    the maps as pige's component's pins hold them (:func:`.tables.linuxcnc_kins_maps.component_maps`; none where the
    component cannot)."""
    out: list[Any] = []
    try:
        linuxcnc_trt_deltas(params)
    except InputError:
        pass
    else:
        out += linuxcnc_comp.comp_tables(params, options.change_limits())
    return out + (linuxcnc_kins_maps.component_maps(params) if _component_describes(params) else [])


def check_tables(params: CompensationParameters, options: ControllerOptions) -> None:
    """The COMP_FILEs' and the component's map limits (256 entries per joint, ``MAP_NODES`` uniform grid angles),
    before any value is weighed (:mod:`.tables.linuxcnc_comp`, :mod:`.tables.linuxcnc_kins_maps`)."""
    linuxcnc_comp.check_format(params)
    linuxcnc_kins_maps.check_format(params)


def render(params: CompensationParameters, options: ControllerOptions) -> str:
    """Every section (:func:`sections`) in turn, each under a line that says what it is and where it goes: the stock
    trt pins, the COMP_FILEs' INI lines, and, beside them, pige's kinematics component with every PIGE and map.

    Raises
    ------
    InputError
        Neither the stock trt kinematics nor pige's component can describe the machine, or today's
        configuration contradicts the parameters (:func:`check_current`).
    """
    return render_sections(sections(params, options))


def render_sections(parts: list[Section]) -> str:
    """The printed text of the sections (:func:`render`): the compensation stage renders the sections it computed."""
    out = []
    for sec in parts:
        if sec.kind == "comp":
            continue  # the compensation files themselves: --comp-dir or --out-dir writes them
        out += [f"# ==== {sec.name} ({sec.kind.upper()}; --out-dir writes it as {sec.file}) ====", sec.text]
    return "\n".join(out)


def sections(params: CompensationParameters, options: ControllerOptions) -> list[Section]:
    """The entries by target file, each pasted whole (or written by ``--out-dir``): the stock trt kinematics' HAL
    lines, the COMP_FILEs' INI lines and the files, pige's component's INI and HAL lines (nets included)."""
    from pige_sym.compensation.controllers.tables.linuxcnc_comp import comp_files

    check_current(params, options.current)
    built = built_tables(tables, params, options)
    comp_tables = [t for t in built if isinstance(t, linuxcnc_comp.CompTable)]
    try:
        linuxcnc_trt_deltas(params)
    except InputError as exc:
        trt_refusal: str | None = str(exc)
    else:  # refusals of --current (another machine's configuration, unknown pins) are the user's to fix
        trt_refusal = None
    limits = options.change_limits()
    pige_refusal: str | None = None
    try:
        ini, hal = pige_kinematics_lines(params, limits, _component_maps(built))
    except (InputError, UnsupportedMachineError) as exc:
        if trt_refusal is not None:
            raise InputError(f"{trt_refusal}; pige's kinematics component: {exc}") from None
        ini, hal, pige_refusal = [], [], str(exc)
    summary = [f"# LinuxCNC corrections of {params.machine}, parameters from {params.source}",
               *scope_lines(params, "linuxcnc", "# ", options)]
    out = []
    if trt_refusal is None:
        trt = [*summary, *_render_trt(params, options)]
        if pige_refusal is not None:
            trt.append(f"# pige's kinematics component cannot describe this machine: {pige_refusal}")
        out.append(Section("the stock trt kinematics: HAL lines", "trt-kins.hal", "hal", "\n".join(trt)))
        comp = comp_file_lines(comp_tables)
        if comp:
            out.append(Section("with the stock kinematics, the positioning maps as COMP_FILEs: INI lines, each "
                               "under its [JOINT_n] section", "comp-files.ini", "ini", "\n".join(comp)))
            out += [Section(f"compensation file {n}", n, "comp", t) for n, t in comp_files(comp_tables).items()]
    else:
        summary.append(f"# LinuxCNC's stock trt kinematics: {trt_refusal}")
    if pige_refusal is None:
        if trt_refusal is not None:
            ini = summary + ini
        out.append(Section("or instead, pige's kinematics component: INI keys, each in its section", "pige-kins.ini",
                           "ini", "\n".join(ini)))
        out.append(Section("pige's kinematics component: HAL lines", "pige-kins.hal", "hal", "\n".join(hal)))
    return out


def _render_trt(params: CompensationParameters, options: ControllerOptions) -> list[str]:
    """Absolute ``setp``/``sets`` lines from today's values (``options.current``), else each change as a comment."""
    module, deltas = linuxcnc_trt_deltas(params)
    config = _config(options.current)
    out = [f"# LinuxCNC {module} (src/emc/kinematics/trtfuncs.c): HAL pins [mm], parameters from {params.source}",
           VERSION]
    if config is not None and config.unread:
        out.append(f"# --current {config.source}: not read: {', '.join(config.unread)} (pins set there are unknown)")
    for pin, d in deltas.items():
        out += _pin_lines(module, pin, d, config)
    return out


def check_current(params: CompensationParameters, current: object) -> None:
    """Refuse today's configuration (``--current``) when it contradicts the parameters, before anything is printed.

    The configuration must be of LinuxCNC's trt kinematics for this machine (a table C on an A or B tilt
    axis: not a head or mixed machine, not the other tilt axis), name only their pins, hold bounded values
    (:meth:`~.hal_config.HalConfig.pin_value`), and place each axis line where the parameter file's pivot is
    (within :data:`PIVOT_AGREEMENT_MM`): else the trt pins and pige's component would be printed for two
    different machines.

    Raises
    ------
    InputError
        Naming both values and where each comes from.
    """
    config = _config(current)
    if config is None:
        return
    try:
        module = linuxcnc_trt_deltas(params)[0]
    except InputError:
        kins = f"a configuration of {config.module} ({config.module_where})" if config.module else "trt pins"
        raise InputError(f"--current {config.name}: {kins}, LinuxCNC's kinematics of a tilting rotary table (C on an "
                         f"A or B tilt axis), but {params.source} holds the parameters of {params.machine}, whose "
                         f"rotary axes are {_sides(params)}: give the parameters and the configuration of one "
                         "machine") from None
    if config.module is not None and config.module != module:
        raise InputError(f"--current {config.name}: its kinematics are {config.module} ({config.module_where}), "
                         f"but {params.source} holds the parameters of {params.machine}, which needs {module}: give "
                         "this machine's configuration")
    unknown = sorted(set(config.pins) - set(TRT_PINS))
    if unknown:
        raise InputError(f"--current {config.pin_where.get(unknown[0], config.name)}: {unknown[0]} is not a pin of "
                         f"{module} ({', '.join(TRT_PINS)})")
    for pin in TRT_PINS:
        config.pin_value(pin)  # bounded where it is set
    for axis, coordinates in TRT_LINES[module].items():
        _check_axis(params, config, axis, coordinates)


def _sides(params: CompensationParameters) -> str:
    kern = load_kernels(params.machine)
    return ", ".join(f"{a} ({'tool' if a in kern.TOOL_ROTARY else 'table'})" for a in kern.ROTARY_AXES)


def _check_axis(params: CompensationParameters, config: HalConfig, axis: str,
                coordinates: dict[str, tuple[str, ...]]) -> None:
    """Refuse an axis line of the configuration that is not where the parameter file's pivot puts it (a check-up's
    changes: where the values in force put it, the nominal pivot moved by them)."""
    pivot = [float(x) for x in params.pivots_mm.get(axis, [0.0, 0.0, 0.0])]
    if params.in_force is not None:
        pivot = [x + params.in_force.get(f"E{c.upper()}0{axis}", 0.0) * 1e-3 for c, x in zip("xyz", pivot,
                                                                                                strict=True)]
    held: dict[str, tuple[float, str]] = {}
    for coordinate, pins in coordinates.items():
        values = [config.pin_value(p) for p in pins]
        if all(v is not None for v in values):  # else the configuration does not say: comments, not values
            found = [v for v in values if v is not None]
            how = " + ".join(f"{p} {v.value:.10g} ({v.source})" for p, v in zip(pins, found, strict=True))
            held[coordinate] = (sum(v.value for v in found), how)
    wrong = [c for c, (line, _) in held.items() if abs(line - pivot["xyz".index(c)]) > PIVOT_AGREEMENT_MM]
    if not wrong:
        return
    coordinate, (line, how) = wrong[0], held[wrong[0]]
    stated = (f"pivots_mm.{axis}" if axis in params.pivots_mm else
              f"no pivots_mm.{axis}: the axis line through the origin, CONVENTIONS §2")
    if params.in_force is not None:
        stated += (" moved by the values in force (the last full calibration's correction and the check-ups' "
                   "entered since: enter them first, or give the configuration that holds them)")
    nominal = pivot["xyz".index(coordinate)]
    suggested = ",".join(f"{held[c][0] if c in held else x:.10g}" for c, x in zip("xyz", pivot, strict=True))
    raise InputError(f"--current {config.name}: the {axis} axis line is at {coordinate} = {line:.10g} mm there "
                     f"({how}), but {params.source} puts it at {coordinate} = {nominal:.10g} mm ({stated}): they "
                     f"contradict each other by {abs(line - nominal):.4g} mm; give the configuration of the machine "
                     "the parameters were identified on, or identify from a test written with its axis lines "
                     f"(pige program --pivot {axis}={suggested})")


def _config(current: object) -> HalConfig | None:
    if current is None or isinstance(current, HalConfig):
        return current
    if isinstance(current, dict):
        pins = {str(k): float(v) for k, v in current.items()}
        return HalConfig(None, pins=pins, pin_where=dict.fromkeys(pins, "PIN=VALUE"))
    raise InputError(f"--current: expected PIN=VALUE,... or a configuration file, not {type(current).__name__}")


def _pin_lines(module: str, pin: str, d: float, config: HalConfig | None) -> list[str]:
    """The line(s) for one pin: ``sets``/``setp`` with the new value, or the change as a comment."""
    add = f"add {signed(d, MM_DECIMALS)}"
    if config is None:
        return [f"# {module}.{pin}: {add} (give --current PIN=VALUE,... or the machine's INI or HAL file for the "
                "absolute line)"]
    if pin in config.nets:
        signal = config.nets[pin]
        if signal in config.signals:
            return [f"# {module}.{pin} is connected to signal {signal}: set the signal (setp is refused on it)",
                    f"sets {signal} {config.signals[signal] + d:.{MM_DECIMALS}f}"]
        return [f"# {module}.{pin} is connected to signal {signal}, which {config.source} does not set: {add} to "
                "what drives it"]
    if pin in config.pins:
        return [f"setp {module}.{pin} {config.pins[pin] + d:.{MM_DECIMALS}f}"]
    if config.source is None:
        return [f"# {module}.{pin}: {add} (not in --current: give its value as {pin}=VALUE)"]
    if config.unread:
        return [f"# {module}.{pin}: {add} (not set in {config.source}; it may be set in the files not read)"]
    return [f"# {module}.{pin} is not set in {config.source}: a HAL pin starts at 0 (src/hal/hal_lib.c)",
            f"setp {module}.{pin} {d:.{MM_DECIMALS}f}"]


def _senses(params: CompensationParameters, axes: tuple[str, ...]) -> dict[str, int]:
    """σ per rotary axis (CONVENTIONS §9): −1 where the parameter file records a reversed sense, else +1."""
    return {a: -1 if params.axis_sense.get(a, 1) < 0 else 1 for a in axes}


def pige_kinematics_lines(params: CompensationParameters, limits: object = None,
                          maps: list[linuxcnc_kins_maps.ComponentMap] | None = None) -> tuple[list[str], list[str]]:
    """pige's kinematics component for ``params.machine``: its INI keys (how to load it), and its HAL lines: how to
    build it, its ``setp`` lines (absolute), the map pins (``maps`` as built, None: built here) held to ``limits``
    (``--max-change``, :mod:`.entry_checks`), and the nets it needs (the tool length, each rotary joint's velocity).

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
    ini = [f"# pige's kinematics component {name} instead of the stock kinematics: set these keys in their sections "
           "of the machine's INI (docs/linuxcnc-kinematics.md)", "[KINS]", f"KINEMATICS = {name} sparm=identityfirst",
           f"JOINTS = {3 + len(axes)}", "[TRAJ]", f"COORDINATES = XYZ{''.join(axes)}"]
    out = [f"# the complete correction: pige's kinematics component {name} carries every PIGE and zero-position "
           "error (docs/linuxcnc-kinematics.md); build and install it with:",
           f"#   pige gen --target linuxcnc \"{kern.MACHINE_CODE}\" && sudo halcompile --install {name}.comp",
           "#   to first order it puts the tool point on target; left: the tool's orientation error (up to "
           f"{tilt:.3g} urad on the default cone) and the pose-dependent extensions: "
           f"{', '.join(e.spec.id for e in params.extensions) or 'none'}"]
    out += [f"setp {name}.sense-{a.lower()} {s}" for a, s in _senses(params, axes).items()]
    note = origin_pivots_note(params, "--current refuses a configuration whose trt pins put them elsewhere")
    out += [f"# {note}"] if note else []
    for a in axes:
        pivot = params.pivots_mm.get(a, [0.0, 0.0, 0.0])
        out += [f"setp {name}.pivot-{a.lower()}-{c} {float(v):.6f}" for c, v in zip("xyz", pivot, strict=True)]
    if kern.TOOL_ROTARY:
        out.append(f"# set {name}.tool-x, -y, -z to the gauge point relative to the {kern.TOOL_ROTARY[-1]} pivot at "
                   "the reference pose [mm] (the machine's, not the test's tool); the tool length comes from "
                   "tool-offset")
    for n in kern.PARAMETERS:
        pin = pins.error_pin(name, n)
        if n in params.held:
            out.append(f"# {pin}: held by the check-up at {params.held[n]:+.4f} (the value in force): leave it as "
                       "it is")
        elif params.in_force is not None and n in params.values:
            out.append(f"# {pin}: add {params.values[n]:+.4f} to the value it holds (the change since the values in "
                       "force; the pin holds the absolute value)")
        elif n in unset:
            out.append(f"# {pin}: no value in the parameter file (left as it is)")
        elif n not in params.values:
            out.append(f"# {pin}: not estimated (the parameter file has no {n}; left as it is)")
        else:
            out.append(f"setp {pin} {params.values.get(n, 0.0):.4f}")
    return ini, out + map_setp_lines(params, name, limits, maps) + component_nets(params, name)


def component_nets(params: CompensationParameters, name: str) -> list[str]:
    """The nets the component needs: the tool length (``tool-offset``) and each rotary joint's velocity command
    (``vel-<axis>``: the direction of approach a map per direction acts by)."""
    kern = load_kernels(params.machine)
    out = ["# the nets the component needs (if a pin named here already drives a signal of another name, link the "
           "component's pin to that signal instead):",
           "# the tool length, as the stock trt kinematics take it (the shipped configurations name the signal "
           ":tool-offset; remove their net to xyzac-trt-kins.tool-offset)",
           f"net :tool-offset motion.tooloffset.z => {name}.tool-offset"]
    for i, a in enumerate(kern.ROTARY_AXES):
        per = params.error_maps is not None and a in params.error_maps.axes and any(
            n.endswith(("+", "-", ":reversal")) for n in params.error_maps.axes[a].values)
        out.append(f"# {a}'s direction of approach from joint {3 + i}'s velocity command"
                   + (f" ({a}'s map is per direction)" if per else " (used by a map per direction)"))
        out.append(f"net pige-vel-{a.lower()} joint.{3 + i}.vel-cmd => {name}.vel-{a.lower()}")
    return out


def map_motions(params: CompensationParameters) -> list[str]:
    """The maps the stock kinematics hold with their COMP_FILEs (``<axis>:<name>``): φ; pige's component, printed
    beside them, carries every map."""
    return positioning_names(params)
