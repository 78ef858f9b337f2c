"""The configuration's kinematics as the cycle sees them: which values they hold, where those are set, and the
nominal axis lines the probing program is written for.

**Stock trt kinematics** (``xyzac-trt-kins``, ``xyzbc-trt-kins``; docs/controller-corrections.md): the values are the
five pins that place the two axis lines, ``x-rot-point``, ``y-rot-point``, ``z-rot-point`` and the tilt line's
offsets (``y-offset``/``z-offset``, ``x-offset``/``z-offset``) [mm]; a pin netted to a signal is set through the
signal (``sets``: HAL refuses ``setp`` on it).  The lines they hold are the program's pivots: C through
``(x-rot-point, y-rot-point)``, A through ``(y-rot-point + y-offset, z-rot-point + z-offset)``, B through
``(x-rot-point + x-offset, z-rot-point + z-offset)``; 2.9's trt kinematics turn both axes against CONVENTIONS'
sense (σ = −1, CONVENTIONS §9) unless ``conventional-directions`` is set.  They hold the axis-line positions only:
the tilts are named, not entered.

**pige's kinematics component** (``pige gen --target linuxcnc``, docs/linuxcnc-kinematics.md): the values are its 8
location PIGE pins ``<name>.ey0a`` … [µm, µrad]; the nominal pivots and senses are its ``pivot-<axis>-<x|y|z>`` and
``sense-<axis>`` pins, which the cycle reads and never changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pige_sym.cycle.hal_scan import HalScan, Setting
from pige_sym.cycle.ini import IniDocument
from pige_sym.errors import InputError, UnsupportedMachineError

#: The stock trt modules: machine code and tilt axis.
STOCK = {"xyzac-trt-kins": ("wC'A'bXYZ(C1)t", "A"), "xyzbc-trt-kins": ("wC'B'bXYZ(C1)t", "B")}
ROT_POINTS = ("x-rot-point", "y-rot-point", "z-rot-point")
TILT_OFFSETS = {"A": ("y-offset", "z-offset"), "B": ("x-offset", "z-offset")}
#: Decimals a value is written with: pins in mm to 0.1 nm (as pige compensate prints them), PIGEs and map values to
#: 0.1 nm / nrad; a map grid's angles [deg] to 1e-9 deg, its node count and full-turn bit [n] as integers.
DECIMALS = {"mm": 7, "um": 4, "urad": 4, "deg": 9, "n": 0}
MAX_VALUE = {"mm": 1e5, "um": 1e4, "urad": 1e4, "deg": 360.0, "n": 1e3}


def format_value(value: float, unit: str) -> str:
    """A value as the values file and halcmd get it: fixed decimals (:data:`DECIMALS`), no ``-0``."""
    text = f"{round(float(value), DECIMALS[unit]) + 0.0:.{DECIMALS[unit]}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


@dataclass(frozen=True)
class ValuePin:
    """One value the kinematics hold: the HAL ``pin``, the ``signal`` it is set through (or None: ``setp``), the
    ``value`` the configuration sets [``unit``], ``where`` (file:line, None when nothing sets it: 0) and what it
    ``holds``."""

    pin: str
    signal: str | None
    value: float
    where: str | None
    unit: str
    holds: str

    @property
    def target(self) -> str:
        """What a HAL command names to set it: the signal, else the pin."""
        return self.signal or self.pin

    def command(self, value: float) -> str:
        """The halcmd line that sets it to ``value``."""
        verb = "sets" if self.signal else "setp"
        return f"{verb} {self.target} {format_value(value, self.unit)}"


@dataclass(frozen=True)
class KinematicsSetup:
    """What the cycle needs of the configuration's kinematics (module docstring).

    Attributes
    ----------
    kinematics : {"stock", "pige"}
    module : str
    machine : str
        ISO 10791 code.
    axis_sense : dict of str to int
    pivots_mm : dict of str to (3,) [mm]
        Nominal axis lines, machine coordinates: the program's ``--pivot``.
    pins : tuple of ValuePin
        The values the cycle enters, in a fixed order.
    """

    kinematics: str
    module: str
    machine: str
    axis_sense: dict[str, int]
    pivots_mm: dict[str, tuple[float, float, float]]
    pins: tuple[ValuePin, ...]

    def held(self) -> list[str]:
        """The PIGEs these kinematics hold (the others are named, never entered)."""
        from pige_sym.kernels import load_kernels

        kern = load_kernels(self.machine)
        if self.kinematics == "pige":
            return list(kern.LOCATION_PARAMETERS)
        return [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]


def kinematics_module(doc: IniDocument) -> tuple[str, str]:
    """The module ``[KINS]KINEMATICS`` loads and where (file:line).

    Raises
    ------
    InputError
        No ``[KINS] KINEMATICS``.
    """
    found = doc.values("KINS", "KINEMATICS")
    if not found or not found[0].value.split():
        raise InputError(f"{doc.name}: no [KINS] KINEMATICS: the cycle enters values into the kinematics the INI "
                         "loads; give the machine's INI")
    return found[0].value.split()[0], f"{doc.name}:{found[0].line}"


def read_kinematics(doc: IniDocument, scan: HalScan, *, kinematics: str | None = None,
                    machine: str | None = None) -> KinematicsSetup:
    """The kinematics of the configuration (module docstring), checked against ``kinematics``/``machine`` when given.

    Raises
    ------
    InputError
        Kinematics the cycle cannot enter values into, or that contradict the options, naming the line.
    """
    module, where = kinematics_module(doc)
    if module in STOCK:
        if kinematics == "pige":
            raise InputError(f"{where}: KINEMATICS = {module}, LinuxCNC's stock trt kinematics, but --kinematics pige: "
                             "give --kinematics stock, or load pige's component (docs/linuxcnc-kinematics.md)")
        code = STOCK[module][0]
        if machine is not None and _canonical(machine) != code:
            raise InputError(f"--machine {machine}: {where} loads {module}, the kinematics of {code}")
        return _stock(module, scan)
    if kinematics == "stock":
        raise InputError(f"{where}: KINEMATICS = {module} is not LinuxCNC's stock trt kinematics (xyzac-trt-kins, "
                         "xyzbc-trt-kins): give --kinematics pige for pige's component, or the INI of a trt machine")
    code = _pige_machine(module, machine, where)
    return _pige(module, code, scan)


def _canonical(code: str) -> str:
    from pige_sym.kernels import load_kernels

    return str(load_kernels(code).MACHINE_CODE)


def _pige_machine(module: str, machine: str | None, where: str) -> str:
    """The machine of pige's component ``module``: ``--machine``, else the shipped machine whose default component
    name it is; refused otherwise."""
    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.codegen.targets.linuxcnc_pins import check_machine, default_name
    from pige_sym.constants import SHIPPED_MACHINES

    if machine is None:
        named = [c for c in SHIPPED_MACHINES if default_name(c) == module]
        if not named:
            raise InputError(f"{where}: KINEMATICS = {module} is neither LinuxCNC's stock trt kinematics nor pige's "
                             "component by its default name (pige_xyzac_trt, ...): give --machine CODE and "
                             "--kinematics pige for pige's component, or the INI of a trt machine")
        machine = named[0]
    code = _canonical(machine)
    try:
        check_machine(parse_machine_code(code))
    except UnsupportedMachineError as exc:
        raise InputError(f"--machine {machine}: {exc}") from None
    return code


def _number(setting: Setting, what: str, unit: str) -> float:
    from pige_sym.options import strict_float

    v = strict_float(setting.value)
    if v is None or not math.isfinite(v) or abs(v) > MAX_VALUE[unit]:
        raise InputError(f"{setting.where}: {what} = {setting.value!r} is not a value a machine holds (a number "
                         f"within ±{MAX_VALUE[unit]:g} {unit})")
    return v


def value_pin(scan: HalScan, pin: str, unit: str, holds: str, *, via_signal: bool = True,
              new_pin: bool = False) -> ValuePin:
    """Where ``pin`` gets its value in the configuration: its signal's ``sets``, its ``setp``, or nothing (0).

    Raises
    ------
    InputError
        A netted pin whose signal nothing sets, a netted pin where ``via_signal`` is False, or a pin that may be set
        in a file pige cannot read (``new_pin``: a pin LinuxCNC's own library files, ``LIB:``, cannot name, such as
        the map pins of pige's component; the configuration's own unread files still count).
    """
    if pin in scan.nets:
        signal = scan.nets[pin]
        if not via_signal:
            raise InputError(f"{scan.net_where[pin].where}: {pin} is netted to {signal}: the cycle sets this pin "
                             "with setp; remove the net")
        if signal not in scan.sets:
            raise InputError(f"{scan.net_where[pin].where}: {pin} is netted to {signal}, which no sets line of the "
                             "configuration sets: add 'HALCMD = sets {signal} VALUE' to the INI")
        s = scan.sets[signal]
        return ValuePin(pin, signal, _number(s, signal, unit), s.where, unit, holds)
    if pin in scan.setp:
        s = scan.setp[pin]
        return ValuePin(pin, None, _number(s, pin, unit), s.where, unit, holds)
    unread = [f for f in scan.unread if not (new_pin and f.startswith("LIB:"))]
    if unread:
        raise InputError(f"{pin} is not set in the files pige reads, and the configuration loads "
                         f"{', '.join(unread)}, which pige does not read: set it in the INI (HALCMD = setp "
                         f"{pin} VALUE) so that the cycle knows its value")
    return ValuePin(pin, None, 0.0, None, unit, holds)


def _stock(module: str, scan: HalScan) -> KinematicsSetup:
    code, tilt = STOCK[module]
    names = (*ROT_POINTS, *TILT_OFFSETS[tilt])
    holds = {"x-rot-point": "C line x", "y-rot-point": "C line y", "z-rot-point": "C line z (and the tilt line's)",
             "y-offset": "A line y - C line y", "x-offset": "B line x - C line x", "z-offset": f"{tilt} line z"}
    pins = tuple(value_pin(scan, f"{module}.{n}", "mm", holds[n]) for n in names)
    conventional = scan.setp.get(f"{module}.conventional-directions")
    sense = 1 if conventional is not None and _number(conventional, "conventional-directions", "mm") == 1 else -1
    lines = _trt_lines(tilt, {n: p.value for n, p in zip(names, pins, strict=True)})
    return KinematicsSetup("stock", module, code, {tilt: sense, "C": sense}, lines, pins)


def _pige(module: str, code: str, scan: HalScan) -> KinematicsSetup:
    from pige_sym.codegen.targets.linuxcnc_pins import error_pin
    from pige_sym.kernels import load_kernels

    kern = load_kernels(code)
    axes = tuple(kern.ROTARY_AXES)
    pins = tuple(value_pin(scan, error_pin(module, n), kern.UNITS[n], n, via_signal=False)
                 for n in kern.LOCATION_PARAMETERS)
    pivots: dict[str, tuple[float, float, float]] = {}
    sense: dict[str, int] = {}
    for a in axes:
        xyz = [value_pin(scan, f"{module}.pivot-{a.lower()}-{c}", "mm", f"{a} pivot {c}", via_signal=False).value
               for c in "xyz"]
        pivots[a] = (xyz[0], xyz[1], xyz[2])
        s = value_pin(scan, f"{module}.sense-{a.lower()}", "mm", f"{a} sense", via_signal=False)
        sense[a] = -1 if s.value < 0 else 1  # the component: any negative value means -1
    return KinematicsSetup("pige", module, code, sense, pivots, pins)


def lines_of(setup: KinematicsSetup, values: dict[str, float]) -> dict[str, tuple[float, float, float]]:
    """The nominal axis lines with ``values`` (pin → value) in force: the stock lines move with their pins; pige's
    component keeps its pivots (its PIGE pins move the lines)."""
    if setup.kinematics == "pige":
        return dict(setup.pivots_mm)
    tilt = next(a for a in setup.pivots_mm if a != "C")
    return _trt_lines(tilt, {p.pin.split(".", 1)[1]: values.get(p.pin, p.value) for p in setup.pins})


def _trt_lines(tilt: str, v: dict[str, float]) -> dict[str, tuple[float, float, float]]:
    """The axis lines of the trt pins ``v`` (short names) [mm] (module docstring)."""
    xr, yr, zr = v["x-rot-point"], v["y-rot-point"], v["z-rot-point"]
    tilt_line = (0.0, yr + v["y-offset"], zr + v["z-offset"]) if tilt == "A" else \
        (xr + v["x-offset"], 0.0, zr + v["z-offset"])
    return {tilt: tilt_line, "C": (xr, yr, zr)}


def config_path(ini: Path) -> Path:
    """The configuration folder of ``ini``."""
    return ini.resolve().parent
