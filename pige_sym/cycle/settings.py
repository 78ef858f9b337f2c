"""The cycle's settings file ``pige_cycle/settings.json`` (format ``pige-cycle-settings 1``).

Written by ``pige cycle install`` from its options, read (and checked) by every step of the cycle; a shop edits it
to change a limit.  One JSON object::

    {"format": "pige-cycle-settings 1",
     "ini": "xyzac-trt.ini",               the INI of the configuration (in the same folder)
     "machine": "wC'A'bXYZ(C1)t",          ISO 10791 code of the machine
     "machine_id": "DMU50-2",              the machine's name in the history
     "kinematics": "stock",                stock (xyzac-trt-kins / xyzbc-trt-kins) or pige (pige gen --target linuxcnc)
     "module": "xyzac-trt-kins",           the kinematics module [KINS]KINEMATICS loads
     "axis_sense": {"A": -1, "C": -1},     commanded sense of each rotary axis (CONVENTIONS §9)
     "kinematics_switch": {"identity_code": "M429", "identity_type": 0, "tcp_code": "M428", "tcp_type": 1,
                           "analog_out": 3},
                                           the codes that switch the kinematics (motion.switchkins-type values),
                                           the motion.analog-out-NN that drives motion.switchkins-type (null:
                                           none); null: no switch, the kinematics always TCP
     "sphere_mm": [20, 10, 15],            sphere centre, machine coordinates, every rotary axis at 0 [mm]
     "sphere_radius_mm": 6.35, "stylus_radius_mm": 1.5, "stylus_tool": 9, "stylus_length_mm": 30,
     "probing": {"poses": 12, "contacts": 5, "probe_feed_mm_min": 50, "clearance_mm": 1, "overtravel_mm": 1,
                 "window_mm": 0.3},
     "limits": {"max_change_mm": 0.2, "max_change_deg": 0.1, "sphere_radius_mm": 0.02, "proposal_hours": 8},
     "tolerances": {"format": "pige-tolerances 1", "defaults": {"um": 10, "urad": 30}},
     "timeouts_s": {"prepare": 180, "analyse": 600, "enter": 120},
     "db": "pige_cycle/history.db",        the history: a path relative to the configuration folder, or a URL
     "pige_command": ["/usr/bin/python3", "-m", "pige_sym"],
     "map": {"axes": ["C", "A"], "step_deg": 45, "setups": 3, "per_direction": [], "ranges": ["A=0:90"],
             "spheres_mm": [[-25, 10, 10], [-15, -15, 10]]}}
                                           the map test (M451 P3 Q<k>, pige's component only; null: none): the
                                           mapped axes, the grid step, the number of sphere setups, the axes
                                           mapped per approach direction, the ranges of the axes that do not turn
                                           fully (default 0:90 on a table), the sphere of setups 2..n in machine
                                           coordinates at the reference pose (empty: pige program --map's own,
                                           sphere_mm turned about C by 360/n degrees each)

Limits (docs/linuxcnc-cycle.md): ``max_change_mm``/``max_change_deg`` the largest change ``M451 P2`` enters per
value (position errors in mm, orientation errors in degrees: HEIDENHAIN's MP6600), ``sphere_radius_mm`` how far the
radius the probe finds (R + r − pre-travel) may lie from the stated ``sphere_radius_mm + stylus_radius_mm``
(MP6601: dirt on the sphere, a wrong stylus), ``proposal_hours`` how old a proposal ``M451 P2`` still enters.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import PathLike

FORMAT = "pige-cycle-settings 1"
KINEMATICS = ("stock", "pige")


@dataclass(frozen=True)
class Switch:
    """The configuration's switchable kinematics: the code that selects identity kinematics and the TCP ones, and
    the ``motion.switchkins-type`` each selects (``sparm=identityfirst``: identity 0, TCP 1); ``analog_out``: the
    ``motion.analog-out-NN`` netted to ``motion.switchkins-type`` (what the codes set with ``M68 E<NN>``), through
    which an abort puts the mode back without the codes' synchronisation (None: not found, the codes are called)."""

    identity_code: str
    identity_type: int
    tcp_code: str
    tcp_type: int
    analog_out: int | None = None


@dataclass(frozen=True)
class Probing:
    """How the sphere is probed (``pige program --instrument sphere-probe``'s options of the same names)."""

    poses: int = 12
    contacts: int = 5
    probe_feed_mm_min: float = 50.0
    clearance_mm: float = 1.0
    overtravel_mm: float = 1.0
    window_mm: float = 0.3


@dataclass(frozen=True)
class Limits:
    """What the cycle refuses (module docstring)."""

    max_change_mm: float = 0.2
    max_change_deg: float = 0.1
    sphere_radius_mm: float = 0.02
    proposal_hours: float = 8.0


@dataclass(frozen=True)
class MapTest:
    """The map test at the machine (``M451 P3 Q<k>``; ``pige program --instrument sphere-probe --map``'s options of
    the same names: ``--map``, ``--map-step``, ``--map-setups``, ``--map-per-direction``, ``--map-range``,
    ``--map-point``).  ``spheres_mm``: the sphere of setups 2..``setups`` [mm], machine coordinates at the reference
    pose (setup 1 is ``sphere_mm``); empty: the program's defaults."""

    axes: list[str]
    step_deg: float
    setups: int = 3
    per_direction: list[str] = field(default_factory=list)
    ranges: list[str] = field(default_factory=list)
    spheres_mm: list[list[float]] = field(default_factory=list)


#: how long LinuxCNC waits for pige's process in each step [s] before it ends the cycle with an error (the remap looks
#: a step's timeout up by its name)
TIMEOUTS_S = {"prepare": 180.0, "analyse": 600.0, "enter": 120.0}


def default_timeouts() -> dict[str, float]:
    return dict(TIMEOUTS_S)


def default_tolerances() -> dict[str, Any]:
    return {"format": "pige-tolerances 1", "defaults": {"um": 10, "urad": 30}}


@dataclass(frozen=True)
class CycleSettings:
    """The settings file (module docstring)."""

    format: str
    ini: str
    machine: str
    machine_id: str
    kinematics: str
    module: str
    axis_sense: dict[str, int]
    kinematics_switch: Switch | None
    sphere_mm: list[float] = field(metadata={"length": 3, "max_abs": 1e5})
    sphere_radius_mm: float = field(default=0.0, metadata={"max_abs": 1e3})
    stylus_radius_mm: float = field(default=0.0, metadata={"max_abs": 1e3})
    stylus_tool: int = 0
    stylus_length_mm: float = field(default=0.0, metadata={"max_abs": 1e5})
    probing: Probing = field(default_factory=Probing)
    limits: Limits = field(default_factory=Limits)
    tolerances: dict[str, Any] = field(default_factory=default_tolerances)
    timeouts_s: dict[str, float] = field(default_factory=default_timeouts)
    db: str = "pige_cycle/history.db"
    pige_command: list[str] = field(default_factory=list)
    map: MapTest | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def db_url(self, config: Path) -> str:
        """The history's URL: ``db`` as given, a relative path taken from the configuration folder."""
        if "://" in self.db or Path(self.db).is_absolute():
            return self.db
        return str((config / self.db).resolve())

    def with_limits(self, **changes: float) -> CycleSettings:
        return replace(self, limits=replace(self.limits, **changes))


def _code(text: str) -> bool:
    import re

    return re.fullmatch(r"M\d{1,3}", text) is not None


def _positive(value: float, what: str) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{what} must be a number > 0, got {value!r}")


def check_settings(s: CycleSettings, where: str) -> CycleSettings:
    """Refuse settings no cycle can run with, naming the field (``where``: the file, or the option).

    Raises
    ------
    InputError
    """
    from pige_sym.kernels import load_kernels

    try:
        if s.format != FORMAT:
            raise InputError(f"format is {s.format!r}, expected {FORMAT!r}")
        if not s.ini or "/" in s.ini or not s.ini.endswith(".ini"):
            raise InputError(f"ini {s.ini!r}: the INI's file name, in the configuration folder")
        if s.kinematics not in KINEMATICS:
            raise InputError(f"kinematics {s.kinematics!r}: use stock or pige")
        axes = tuple(load_kernels(s.machine).ROTARY_AXES)
        if set(s.axis_sense) - set(axes) or any(v not in (-1, 1) for v in s.axis_sense.values()):
            raise InputError(f"axis_sense {s.axis_sense}: give -1 or 1 for the rotary axes {', '.join(axes)}")
        sw = s.kinematics_switch
        if sw is not None and (sw.identity_type == sw.tcp_type or not _code(sw.identity_code)
                               or not _code(sw.tcp_code)):
            raise InputError("kinematics_switch: two M-codes (e.g. M429, M428) selecting two different "
                             "switchkins types")
        if sw is not None and sw.analog_out is not None and not 0 <= sw.analog_out <= 63:
            raise InputError(f"kinematics_switch: analog_out {sw.analog_out}: the N of motion.analog-out-N, 0..63")
        for name in ("sphere_radius_mm", "stylus_radius_mm", "stylus_length_mm"):
            _positive(getattr(s, name), name)
        if s.stylus_tool <= 0:
            raise InputError(f"stylus_tool must be a tool number > 0, got {s.stylus_tool}")
        p = s.probing
        if not 2 <= p.poses <= 100 or not 4 <= p.contacts <= 9:
            raise InputError(f"probing: poses 2..100 and contacts 4..9, got {p.poses} and {p.contacts}")
        for name in ("probe_feed_mm_min", "clearance_mm", "overtravel_mm", "window_mm"):
            _positive(getattr(p, name), f"probing.{name}")
        for name, value in asdict(s.limits).items():
            _positive(value, f"limits.{name}")
        if set(s.timeouts_s) != set(TIMEOUTS_S):
            raise InputError(f"timeouts_s: give the seconds of each step {', '.join(TIMEOUTS_S)}, got "
                             f"{', '.join(s.timeouts_s) or 'none'}")
        for name, value in s.timeouts_s.items():
            _positive(value, f"timeouts_s.{name}")
        if not s.machine_id.strip():
            raise InputError("machine_id must not be empty")
        if len(s.pige_command) < 1:
            raise InputError("pige_command must name the program that runs pige")
        if s.map is not None:
            check_map_test(s)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    return s


def check_map_test(s: CycleSettings) -> None:
    """The map settings (:class:`MapTest`): pige's component (the stock trt kinematics hold no map), the machine's
    rotary axes, a grid the component holds, 2..9 setups, a sphere for each setup after the first.

    Raises
    ------
    InputError
    """
    from pige_sym.kernels import load_kernels
    from pige_sym.model.error_motions import check_map_step

    m = s.map
    assert m is not None
    if s.kinematics != "pige":
        raise InputError(f"map: {s.module} holds no error map (LinuxCNC's trt kinematics place the axis lines only): "
                         "the map test at the machine needs pige's kinematics component (docs/linux"
                         "cnc-kinematics.md); with the stock kinematics, measure the maps at the desk and enter the "
                         "positioning maps as COMP_FILEs (docs/maps.md, pige compensate --comp-dir)")
    axes = tuple(load_kernels(s.machine).ROTARY_AXES)
    if not m.axes or any(a not in axes for a in m.axes) or len(set(m.axes)) != len(m.axes) or \
            any(a not in m.axes for a in m.per_direction):
        raise InputError(f"map: axes {m.axes}, per_direction {m.per_direction}: give rotary axes of {s.machine} "
                         f"({', '.join(axes)}), each once; an axis per direction is mapped too")
    for a in m.axes:
        check_map_step(m.step_deg, a)
    if not 2 <= m.setups <= 9:
        raise InputError(f"map: setups {m.setups}: a map test takes 2..9 sphere setups")
    if m.spheres_mm and (len(m.spheres_mm) != m.setups - 1 or any(
            len(v) != 3 or not all(math.isfinite(x) and abs(x) <= 1e5 for x in v) for v in m.spheres_mm)):
        raise InputError(f"map: spheres_mm: give the sphere of setups 2..{m.setups} ({m.setups - 1} points x,y,z "
                         "[mm]), or none for the program's own")
    map_grids(s.machine, m)


@dataclass(frozen=True)
class AxisGrid:
    """One mapped axis' grid as the component's pins hold it (CONVENTIONS angle θ [deg])."""

    axis: str
    start_deg: float
    step_deg: float
    nodes: int
    full_turn: bool


def map_grids(machine: str, test: MapTest) -> list[AxisGrid]:
    """The grid of each mapped axis (module docstring), as ``pige program --map`` visits it.

    Raises
    ------
    InputError
        A range the planner refuses, or more grid angles than the component holds.
    """
    from pige_sym.codegen.targets.linuxcnc_pins import MAP_NODES
    from pige_sym.kernels import load_kernels
    from pige_sym.model.error_motions import is_full_turn
    from pige_sym.planning.map_setups import axis_nodes, map_ranges

    ranges = map_ranges(load_kernels(machine), list(test.ranges) or None)
    out = []
    for a in test.axes:
        nodes = axis_nodes(a, test.step_deg, ranges)
        if nodes.size > MAP_NODES:
            raise InputError(f"map: {a} has {nodes.size} grid angles every {test.step_deg:g} deg; pige's component "
                             f"holds at most {MAP_NODES}: give a larger step_deg")
        out.append(AxisGrid(a, float(nodes[0]), float(test.step_deg), int(nodes.size), is_full_turn(a)))
    return out


def read_settings(path: PathLike) -> CycleSettings:
    """The settings file, validated (:mod:`~pige_sym.measurements.schema`) and checked (:func:`check_settings`).

    Raises
    ------
    FileFormatError, InputError
        Naming the file and the field.
    """
    from pige_sym.measurements.schema import read_json_file

    settings = read_json_file(path, CycleSettings, "cycle settings file")
    try:
        return check_settings(settings, str(path))
    except InputError as exc:
        raise FileFormatError(str(path), None, str(exc).removeprefix(f"{path}: ")) from None


def settings_text(s: CycleSettings) -> str:
    """The settings file's text: one key per line, the same settings always the same bytes."""
    import json

    return json.dumps(s.to_dict(), indent=1, sort_keys=False, ensure_ascii=False) + "\n"
