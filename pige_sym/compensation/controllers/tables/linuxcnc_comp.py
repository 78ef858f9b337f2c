"""LinuxCNC ``[JOINT_n]COMP_FILE``: the positioning map of each rotary joint as a compensation file.

What LinuxCNC 2.9.0~pre1 does with the file (read at commit f1270d6ed7, Debian's ``linuxcnc-uspace``):

- ``docs/src/config/ini-config.adoc`` ([JOINT_n] section): ``COMP_FILE`` holds one triplet per line, in machine
  units, "nominal" (the commanded position) first, nominals ascending, positions between two nominals
  interpolated, at most 256 triplets per joint; ``COMP_FILE_TYPE`` (0 or 1) must be given with it; with a
  ``COMP_FILE`` the joint's ``BACKLASH`` is not used.
- ``src/emc/motion/usrmotintf.cc`` (``usrmotLoadComp``): each line is read with ``sscanf("%lf %lf %lf")``
  and the first line that is not three numbers ends the file, so the file has no header and no comment.
  Type 0: the trim is ``nominal − value`` (the file holds where the joint actually is); type 1: the trim is
  the value itself.  pige writes type 1.
- ``src/emc/motion/command.c`` (``EMCMOT_SET_JOINT_COMP``): nominals must increase; more than
  ``EMCMOT_COMP_SIZE`` = 256 entries (``motion.h``) are refused; slopes are taken between consecutive
  entries, and ``motion.c`` puts entries at ∓``DBL_MAX`` with zero slope: below the first nominal the first
  trim holds, above the last the last.
- ``src/emc/motion/control.c`` (``compute_screw_comp``): the forward trim (interpolated) while the joint's
  ``vel_cmd > 0``, the reverse one while ``vel_cmd < 0``, and at rest whatever was there before (0 until the
  joint first moves); the result is ramped (``backlash_filt``) at half the joint's velocity and
  acceleration limits.  ``output_to_hal``: ``motor_pos_cmd = pos_cmd + trim``; ``process_inputs``:
  ``pos_fb = motor_pos_fb − trim``.  So **the trim is added to the joint's commanded position** and the
  joint feedback (and every position LinuxCNC shows or logs) stays the commanded one.
- ``scripts/linuxcnc.in`` line 774 (``cd "$INI_DIR"``): a relative ``COMP_FILE`` is opened in the INI's folder.

The trim of a rotary joint is ``−e`` (:mod:`.positioning`: the axis stands at θ_cmd + e), forward = the
joint's commanded angle increasing.  Joints: 0 X, 1 Y, 2 Z, then the rotary axes in letter order, as in
``xyzac-trt-kins`` / ``xyzbc-trt-kins`` (``[TRAJ]COORDINATES = XYZAC``) and in pige's kinematics component.
A full-turn axis' table covers as many whole turns around 0 as 256 entries allow (its map repeats every
360°); a tilt axis' table is its grid.  The 256 entries are checked before any value is weighed
(:func:`check_format`), every trim against ``--max-change`` before a file is written (:mod:`..entry_checks`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pige_sym.compensation.controllers.entry_checks import check_entries
from pige_sym.compensation.controllers.tables.positioning import PositioningMap, entered_map_values, positioning_maps
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

#: ``EMCMOT_COMP_SIZE`` (src/emc/motion/motion.h, 2.9.0~pre1).
COMP_SIZE = 256
SOURCE = "LinuxCNC 2.9.0~pre1 (f1270d6ed7): src/emc/motion/usrmotintf.cc, command.c, control.c; ini-config.adoc"
#: Decimals of a trim [deg]: 1e-10 deg (1.7e-12 rad); LinuxCNC stores it as a float (motion.h), 7 digits.
TRIM_DECIMALS = 10


@dataclass(frozen=True)
class CompTable:
    """One joint's compensation file.

    Attributes
    ----------
    axis : str
    joint : int
    nominal_deg, forward_deg, reverse_deg : (n,) [deg]
        Commanded angle and the trims added to it moving forward (increasing) and in reverse.
    notes : list of str
    """

    axis: str
    joint: int
    nominal_deg: np.ndarray
    forward_deg: np.ndarray
    reverse_deg: np.ndarray
    notes: tuple[str, ...]

    @property
    def file_name(self) -> str:
        return f"pige_joint{self.joint}_{self.axis.lower()}.comp"

    def text(self) -> str:
        """The file: ``nominal forward reverse`` per line, nothing else (module docstring)."""
        rows = zip(self.nominal_deg, self.forward_deg, self.reverse_deg, strict=True)
        return "".join(f"{n:.10g} {f + 0.0:.{TRIM_DECIMALS}f} {r + 0.0:.{TRIM_DECIMALS}f}\n" for n, f, r in rows)


def joint_number(machine: str, axis: str) -> int:
    """The joint of a rotary axis: 3 + its index in letter order (module docstring)."""
    return 3 + tuple(load_kernels(machine).ROTARY_AXES).index(axis)


def full_turn_travel(pm: PositioningMap) -> tuple[float, float]:
    """The most whole turns around 0 whose nodes fit in 256 entries (one turn when not even two do)."""
    per_turn = pm.grid.n
    if per_turn + 1 > COMP_SIZE:
        raise InputError(f"{pm.axis}: a grid of {per_turn} angles per turn needs {per_turn + 1} entries; LinuxCNC "
                         f"takes at most {COMP_SIZE} per joint (EMCMOT_COMP_SIZE, src/emc/motion/motion.h)")
    turns = (COMP_SIZE - 1) // (2 * per_turn)
    return (-360.0 * turns, 360.0 * turns) if turns else (-180.0, 180.0)


def table_nodes(pm: PositioningMap, travel_cmd_deg: tuple[float, float] | None = None) -> np.ndarray:
    """The nominals of one axis' file [deg, commanded]: ``travel_cmd_deg`` or, for a full turn, the whole turns that
    fit (:func:`full_turn_travel`), else the grid.

    Raises
    ------
    InputError
        More than 256 entries (``EMCMOT_COMP_SIZE``).
    """
    travel = travel_cmd_deg if travel_cmd_deg is not None else (full_turn_travel(pm) if pm.full_turn else None)
    nodes = pm.nodes_cmd(travel)
    if nodes.size > COMP_SIZE:
        raise InputError(f"{pm.axis}: {nodes.size} entries over commanded {nodes[0]:g}..{nodes[-1]:g} deg; LinuxCNC "
                         f"takes at most {COMP_SIZE} per joint (EMCMOT_COMP_SIZE, src/emc/motion/motion.h)")
    return nodes


def check_format(params: CompensationParameters) -> None:
    """The files' format limits (256 entries per joint), checked before any value is weighed or computed."""
    for pm in positioning_maps(params).values():
        table_nodes(pm)


def comp_table(machine: str, pm: PositioningMap, travel_cmd_deg: tuple[float, float] | None = None,
               limits: Any = None) -> CompTable:
    """The compensation file of one axis (module docstring); every trim held to ``limits``
    (:class:`~pige_sym.compensation.controllers.entry_checks.ChangeLimits`, ``--max-change``).

    Raises
    ------
    InputError
        More than 256 entries, or a trim beyond ``limits``.
    """
    nodes = table_nodes(pm, travel_cmd_deg)
    forward = -pm.commanded_error_deg(nodes, +1)
    reverse = -pm.commanded_error_deg(nodes, -1)
    joint = joint_number(machine, pm.axis)
    where = f"LinuxCNC COMP_FILE pige_joint{joint}_{pm.axis.lower()}.comp"
    for field, trims in (("forward trim", forward), ("reverse trim", reverse)):
        check_entries(where, field, trims, "deg", limits, nodes, f"commanded {pm.axis}")
    span = (f"commanded {pm.axis} {nodes[0]:g}..{nodes[-1]:g} deg, {nodes.size} entries"
            + (" (the map repeats every 360 deg)" if pm.full_turn else ""))
    notes = (*pm.notes(), f"{pm.axis} = joint {joint}: {span}; beyond them the end values hold (command.c, "
             f"motion.c): keep [JOINT_{joint}]MIN_LIMIT/MAX_LIMIT inside")
    return CompTable(pm.axis, joint, nodes, forward, reverse, notes)


def comp_tables(params: CompensationParameters, limits: Any = None) -> list[CompTable]:
    """The compensation file of every rotary axis whose map holds φ."""
    return [comp_table(params.machine, pm, limits=limits) for pm in positioning_maps(params).values()]


def comp_files(tables: list[CompTable]) -> dict[str, str]:
    """File name → text of every compensation file (what ``pige compensate --comp-dir`` writes)."""
    return {t.file_name: t.text() for t in tables}


def render_lines(tables: list[CompTable]) -> list[str]:
    """The INI lines that load the files ``tables`` (:func:`comp_tables`), with what the files hold (comments); empty
    without maps."""
    if not tables:
        return []
    out = [f"# the positioning maps as [JOINT_n]COMP_FILE ({SOURCE}): COMP_FILE_TYPE 1, the trim [deg] is added to "
           "the joint's commanded angle, forward = the commanded angle increasing",
           "# for the stock kinematics; pige's component (below) carries the maps itself: enter one or the other",
           "# files written by --comp-dir DIR (a relative path is opened in the INI's folder, scripts/linuxcnc.in); "
           "with a COMP_FILE the joint's BACKLASH is not used",
           "# the trims act from the joint's first move after start-up (control.c: at rest the last trim holds, "
           "0 at start): move each rotary joint after homing"]
    for t in tables:
        out += [f"#   {n}" for n in t.notes]
        out += [f"[JOINT_{t.joint}]", f"COMP_FILE = {t.file_name}", "COMP_FILE_TYPE = 1"]
    return out


def entered_values(params: CompensationParameters, tables: list[CompTable]) -> dict[str, float]:
    """What the compensation files ``tables`` (:func:`comp_tables`, the ones printed) enter
    (:func:`~.positioning.entered_map_values`): each joint's trims as printed, forward and reverse (a trim is −e,
    module docstring)."""
    maps = positioning_maps(params)
    out: dict[str, float] = {}
    for table in tables:
        pm = maps[table.axis]
        forward = np.round(table.forward_deg, TRIM_DECIMALS)
        reverse = np.round(table.reverse_deg, TRIM_DECIMALS)

        def printed(theta_cmd_deg: np.ndarray, direction_cmd: int, nominal: np.ndarray = table.nominal_deg,
                    fwd: np.ndarray = forward, rev: np.ndarray = reverse) -> np.ndarray:
            at = np.asarray(theta_cmd_deg, dtype=float)
            idx = np.argmin(np.abs(nominal[None, :] - at[:, None]), axis=1)
            return np.asarray(-(rev if direction_cmd < 0 else fwd)[idx], dtype=float)

        out |= entered_map_values(params, pm, printed)
    return out
