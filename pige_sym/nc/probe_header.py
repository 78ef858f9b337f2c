"""What a probing program's header states, read back: the set-up and controller state it was written for.

A pige probing program (``pige format: pige-probe 1``, :mod:`pige_sym.nc.program_header`) states its
machine, dialect, commanded axis sense, the nominal pivot of every rotary axis, the sphere and the radii,
the stylus centre from the head's pivot on a head machine (``tool_mm``), and the controller state
(:class:`~pige_sym.nc.probe_safety.ProbeController`).  :func:`header_setup` turns that into the items a
command needs (``import-probe --program``, ``simulate --program``) and :func:`header_agrees` refuses a
program whose header disagrees with the options a command was given, so a program, its log and its import
cannot be mixed up.  Numbers are compared to the header's six significant digits.

Every number of the header (the ``*_mm`` items and the work offset's) must be a finite ASCII decimal within the
readers' physical bound (:data:`~pige_sym.measurements.measurement.LIMITS`), and radii, the stylus length and the
window positive: anything else is a damaged header, refused with its line and item before any number is used (a
``tool_mm`` of 1e300 ended the import in a traceback, a NaN was blamed on the log).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pige_sym.errors import InputError, NCProgramError
from pige_sym.measurements.axis_sense import METADATA_KEY as SENSE_KEY
from pige_sym.measurements.axis_sense import describe_axis_sense, parse_axis_sense
from pige_sym.nc.probe_program import ProbeSetup
from pige_sym.nc.probe_safety import ProbeController, controller_from_header
from pige_sym.nc.program_header import read_header_lines

PROBE_FORMAT = "pige-probe 1"


@dataclass(frozen=True)
class HeaderSetup:
    """The set-up a probing program states (module docstring).

    Attributes
    ----------
    machine, dialect : str
    axis_sense : dict of str to int
    pivots_mm : dict of str to ndarray, shape=(3,) [mm]
    sphere_mm : ndarray, shape=(3,) [mm]
    sphere_radius_mm, stylus_radius_mm : float [mm]
    controller : ProbeController
    tool_mm : ndarray, shape=(3,) [mm], or None
        Head machines: the stylus centre from the last tool-side pivot (CONVENTIONS §7).
    """

    machine: str
    dialect: str
    axis_sense: dict[str, int]
    pivots_mm: dict[str, np.ndarray]
    sphere_mm: np.ndarray
    sphere_radius_mm: float
    stylus_radius_mm: float
    controller: ProbeController
    tool_mm: np.ndarray | None = None


def header_setup(text: str, path: str) -> HeaderSetup:
    """The set-up a probing program's header states.

    Raises
    ------
    NCProgramError
        Not a pige probing program (no ``pige format: pige-probe 1``), or an item missing or malformed.
    """
    from pige_sym.kernels import load_kernels

    lines = read_header_lines(text, path)
    items = {key: value for key, (value, _) in lines.items()}
    if items.get("format") != PROBE_FORMAT:
        raise NCProgramError(path, None, f"not a pige probing program (no 'pige format: {PROBE_FORMAT}' header "
                                         "line): the program must be the one pige program wrote")
    check_header_numbers(lines, path)
    try:
        kern = load_kernels(items["machine"])
        axes = tuple(kern.ROTARY_AXES)
        pivots = {a: _vec(items[f"pivot_{a}_mm"]) for a in axes}
        return HeaderSetup(kern.MACHINE_CODE, items["dialect"], parse_axis_sense(items.get(SENSE_KEY, ""), axes),
                           pivots, _vec(items["sphere_mm"]), float(items["sphere_radius_mm"]),
                           float(items["stylus_radius_mm"]), controller_from_header(items, path),
                           _vec(items["tool_mm"]) if "tool_mm" in items else None)
    except (KeyError, ValueError, InputError) as exc:
        raise NCProgramError(path, None, f"the probing program's header is incomplete or malformed ({exc}): write "
                                         "it again with pige program") from None


#: Header numbers that must be positive [mm].
POSITIVE_ITEMS = ("sphere_radius_mm", "stylus_radius_mm", "stylus_length_mm", "window_mm")


def check_header_numbers(lines: Mapping[str, tuple[str, int]], path: str) -> None:
    """Refuse a header number that is not a finite ASCII decimal within the physical bound (module docstring).

    Raises
    ------
    NCProgramError
        Naming the line and the item, and what to do.
    """
    from pige_sym.measurements.measurement import LIMITS
    from pige_sym.options import strict_float

    for key, (value, line) in lines.items():
        if key == "work_offset":
            numbers = value.partition(" ")[2]
        elif key.endswith("_mm"):
            numbers = value
        else:
            continue
        for part in (p.strip() for p in numbers.split(",")):
            v = strict_float(part)
            problem = (f"{part!r} is not a finite number (an ASCII decimal)" if v is None else
                       f"{part} mm is not physical (|value| <= {LIMITS['mm']:g} mm)" if abs(v) > LIMITS["mm"] else
                       f"{part} mm must be positive" if key in POSITIVE_ITEMS and not v > 0 else None)
            if problem:
                raise NCProgramError(path, line, f"header item pige {key}: {problem}: the program's header is "
                                                 "damaged; write the program again with pige program")


def _vec(text: str) -> np.ndarray:
    v = np.array([float(x) for x in text.split(",")])
    if v.shape != (3,):
        raise ValueError(f"{text!r} is not three numbers")
    return v


def _close(a: np.ndarray | float, b: np.ndarray | float) -> bool:
    return bool(np.allclose(a, b, rtol=2e-6, atol=2e-6))


def header_agrees(text: str, setup: ProbeSetup, rotary_axes: tuple[str, ...], path: str) -> HeaderSetup:
    """The program's header, refused unless it states ``setup`` exactly.

    Raises
    ------
    NCProgramError
        Naming the first item that differs, with both values.
    """
    h = header_setup(text, path)
    pivots = setup.pivots
    per_axis = dict(pivots) if isinstance(pivots, Mapping) else {a: pivots for a in rotary_axes}
    sense = {a: -1 for a in rotary_axes if setup.axis_sense.get(a, 1) == -1}
    checks = [("machine", h.machine, setup.machine, h.machine == _canonical(setup.machine)),
              (SENSE_KEY, describe_axis_sense(h.axis_sense), describe_axis_sense(sense), h.axis_sense == sense),
              ("sphere_mm", h.sphere_mm, setup.sphere_mm, _close(h.sphere_mm, setup.sphere_mm)),
              ("sphere_radius_mm", h.sphere_radius_mm, setup.sphere_radius_mm,
               _close(h.sphere_radius_mm, setup.sphere_radius_mm)),
              ("stylus_radius_mm", h.stylus_radius_mm, setup.stylus_radius_mm,
               _close(h.stylus_radius_mm, setup.stylus_radius_mm)),
              ("controller state", h.controller, setup.controller, _same_controller(h.controller, setup.controller))]
    checks += [(f"pivot_{a}_mm", h.pivots_mm[a], per_axis[a], _close(h.pivots_mm[a], per_axis[a])) for a in rotary_axes]
    same_tool = h.tool_mm is None if setup.tool_mm is None else (h.tool_mm is not None
                                                                  and _close(h.tool_mm, setup.tool_mm))
    checks.append(("tool_mm", h.tool_mm, setup.tool_mm, same_tool))
    for name, stated, given, ok in checks:
        if not ok:
            option = _OPTIONS.get(name, "--pivot" if name.startswith("pivot_") else name)
            run = f"{option} is not given" if given is None else f"this run has {_shown(given)} ({option})"
            raise NCProgramError(path, None, f"the program states {name} {_shown(stated)}, but {run}: give {option} "
                                             "as the program states it, or leave out what its header states (give "
                                             "--program alone), or write the program again")
    return h


#: The option that gives each header item (the controller state is several).
_OPTIONS = {"machine": "--machine", SENSE_KEY: "--axis-sense", "sphere_mm": "--sphere",
            "sphere_radius_mm": "--sphere-radius", "stylus_radius_mm": "--stylus-radius", "tool_mm": "--tool",
            "controller state": "--kinematics/--rtcp-off/--rtcp-on/--stylus-tool/--stylus-length/--work-offset/"
                                "--window"}


def _shown(value: object) -> str:
    """A header value as a person reads it: ``0, 0, -160`` for a vector, ``none`` for None."""
    if value is None:
        return "none"
    if isinstance(value, np.ndarray):
        return ", ".join(f"{float(v):g}" for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _canonical(code: str) -> str:
    from pige_sym.kernels import load_kernels

    return str(load_kernels(code).MACHINE_CODE)


def _same_controller(a: ProbeController, b: ProbeController) -> bool:
    same = (a.kinematics, a.rtcp_off, a.rtcp_on, a.stylus_tool, a.work_offset) == \
        (b.kinematics, b.rtcp_off, b.rtcp_on, b.stylus_tool, b.work_offset)
    numbers = np.array([a.stylus_length_mm, a.window_mm, *a.work_offset_mm])
    return same and _close(numbers, np.array([b.stylus_length_mm, b.window_mm, *b.work_offset_mm]))
