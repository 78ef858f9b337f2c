"""What every step of a run reads first: the configuration as it is now, and the request LinuxCNC wrote.

- the **settings** (:mod:`~pige_sym.cycle.settings`) and the **INI** they were installed into;
- the **kinematics** (:mod:`~pige_sym.cycle.kinematics`): what they hold and where it is set;
- the **values in force**: the running HAL's (:mod:`~pige_sym.cycle.hal_live`), else the values file's;
- the **fingerprint** of the configuration in force (:func:`fingerprint`): SHA-256 of the INI, every HAL file it
  runs (``values.hal`` included), the settings, and the values in force; a proposal is entered only into the
  configuration it was made for;
- the **request** (``request.json``, written by the remap at the start of the cycle): the mode and LinuxCNC's state
  then (tool, coordinate system and its offsets, G92, positions, ``motion.switchkins-type``).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

from pige_sym.cycle.hal_scan import HalScan, scan_configuration
from pige_sym.cycle.ini import IniDocument, parse_ini
from pige_sym.cycle.kinematics import KinematicsSetup, format_value, read_kinematics
from pige_sym.cycle.layout import Layout
from pige_sym.cycle.settings import CycleSettings, read_settings
from pige_sym.errors import InputError

REQUEST_FORMAT = "pige-cycle-request 1"
MODES = ("check", "optimise", "enter", "checkup", "map")


@dataclass(frozen=True)
class Request:
    """LinuxCNC's state at the start of the cycle (module docstring); written by the remap.

    ``offset`` is the active coordinate system's X Y Z A B C U V W [mm, deg], ``rotation`` its XY rotation [deg];
    ``position`` X Y Z A B C in program coordinates; ``switchkins_type`` None without switchable kinematics;
    ``setup`` the map test's setup ``k`` of ``M451 P3 Q<k>`` (None for the other modes).
    """

    format: str
    code: str
    mode: str
    started: str
    tool: int
    system: int
    offset: list[float] = field(metadata={"length": 9, "max_abs": 1e6})
    rotation: float = 0.0
    g92_on: bool = False
    position: list[float] = field(default_factory=list, metadata={"length": 6, "max_abs": 1e7})
    switchkins_type: int | None = None
    setup: int | None = None


def read_request(run: Path) -> Request:
    from pige_sym.measurements.schema import read_json_file

    req = read_json_file(run / "request.json", Request, "cycle request")
    if req.format != REQUEST_FORMAT or req.mode not in MODES or not 1 <= req.system <= 9:
        raise InputError(f"{run / 'request.json'}: not a request of this version of the cycle (format {req.format!r}, "
                         f"mode {req.mode!r}, system {req.system}): install the cycle again")
    return req


@dataclass
class Context:
    """A step's view of the configuration (module docstring)."""

    layout: Layout
    settings: CycleSettings
    ini: Path
    doc: IniDocument
    scan: HalScan
    setup: KinematicsSetup
    in_force: dict[str, float]
    live: bool
    file_values: dict[str, float]

    def fingerprint(self) -> dict[str, str]:
        return fingerprint(self)


def read_context(config: Path, *, live: bool = True) -> Context:
    """The configuration of ``config`` as it is now (module docstring).

    Raises
    ------
    InputError, FileFormatError
        An installation pige cannot read (the settings, the INI, the values file), naming the file.
    """
    from pige_sym.cycle.hal_live import hal_running, read_live
    from pige_sym.cycle.map_pins import with_map_pins
    from pige_sym.cycle.values import read_values
    from pige_sym.files import read_input_text

    layout = Layout(config.resolve())
    settings = read_settings(layout.settings)
    ini = layout.config / settings.ini
    doc = parse_ini(read_input_text(ini, what="INI file"), str(ini))
    scan = scan_configuration(ini, doc)
    setup = with_map_pins(read_kinematics(doc, scan, kinematics=settings.kinematics, machine=settings.machine),
                          settings, scan)
    if setup.module != settings.module:
        raise InputError(f"{ini}: the kinematics are {setup.module} now, {layout.settings} says {settings.module}: "
                         "install the cycle again")
    file_values = read_values(layout.values, setup)
    running = live and hal_running()
    in_force = read_live(setup) if running else dict(file_values)
    return Context(layout, settings, ini, doc, scan, setup, in_force, running, file_values)


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def fingerprint(ctx: Context) -> dict[str, str]:
    """SHA-256 of each part of the configuration in force, and of all of them (``all``)."""
    parts = {"ini": _sha(ctx.ini.read_bytes()),
             "hal files": _sha(b"".join(_sha(f.read_bytes()).encode() + str(f).encode() for f in ctx.scan.files)),
             "settings": _sha(ctx.layout.settings.read_bytes()),
             "values in force": _sha("\n".join(f"{p.target}={format_value(ctx.in_force[p.pin], p.unit)}"
                                               for p in ctx.setup.pins).encode())}
    parts["all"] = _sha("".join(parts.values()).encode())
    return parts


def changed_parts(then: dict[str, str], now: dict[str, str]) -> list[str]:
    """Which parts of the configuration differ between two fingerprints."""
    return [k for k in now if k != "all" and then.get(k) != now[k]]
