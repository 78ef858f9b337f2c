"""NC programs for the rest of pige_sym: read one (any dialect), list its poses, write an R-test program.

Reading goes through the modal interpreter (:mod:`pige_sym.nc.interpreter`) in the dialect
detected from the text (:mod:`pige_sym.nc.detect`) unless one is given.  Positions are in
mm and degrees.  R-test programs are written natively in each dialect:

- ``siemens``: ``G90 G17 G71``, ``TRAFOOF`` or ``TRAORI``, ``N10 G1 X.. Y.. Z.. A.. C.. F..``,
  dwell ``G4 F<s>``, ``M30``;
- ``fanuc``: ``%``, ``O1000``, ``G90 G17 G21``, ``G49`` or ``G43.4 H1``, every value with a
  decimal point, dwell ``G04 X<s>``, ``M30``, ``%``;
- ``linuxcnc``: ``G90 G17 G21``, dwell ``G4 P<s>``, ``M2``, comments in parentheses (RTCP
  programs need the machine's kinematics switch: they are refused here).
"""

from __future__ import annotations

from collections.abc import Mapping
from itertools import repeat

import numpy as np

from pige_sym.errors import InputError, NCProgramError
from pige_sym.nc.detect import detect_dialect
from pige_sym.nc.dialects import get_dialect
from pige_sym.nc.interpreter import Program, interpret
from pige_sym.nc.state import Block

NCProgram = Program
NCBlock = Block
AXES = ("X", "Y", "Z", "A", "B", "C")

__all__ = ["AXES", "NCBlock", "NCProgram", "NCProgramError", "format_number", "make_rtest_program",
           "parse_program", "poses_from_program"]


def parse_program(text: str, *, path: str = "<program>", rotary_axes: tuple[str, ...] = ("A", "C"),
                  pass_through: bool = False, dialect: str | None = None) -> Program:
    """Interpret a program (module docstring); never alters the text.

    Parameters
    ----------
    text : str
    path : str
        For messages and dialect detection (``.ngc``, ``.mpf``).
    rotary_axes : tuple of str
    pass_through : bool
        Keep calls, control flow and expressions (tracking what can be tracked) instead of refusing.
    dialect : str, optional
        ``siemens``, ``fanuc`` or ``linuxcnc``; detected from the text when omitted.
    """
    name = dialect or detect_dialect(text, path)
    return interpret(text, get_dialect(name), tuple(rotary_axes), path=path, pass_through=pass_through)


def format_number(value: float, decimals: int, *, point: bool) -> str:
    """``value`` with at most ``decimals`` decimals, trailing zeros removed; ``point`` keeps a ``.`` (``120.``)."""
    s = f"{value:.{decimals}f}".rstrip("0")
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    if not point:
        s = s.rstrip(".")
        return s or "0"
    return s if s not in ("", ".") else "0."


def format_numbers(values: np.ndarray, decimals: np.ndarray, *, point: bool) -> list[str]:
    """:func:`format_number` of every value (1-D), byte for byte, with C-level string operations.

    ``decimals`` (same shape, each >= 1) per value.  ``"%.nf" % v`` is the formatting of ``f"{v:.nf}"``.
    """
    if len(values) == 0:
        return []
    if (decimals == decimals[0]).all():
        fmt = f"%.{int(decimals[0])}f\n" * len(values)
    else:
        fmt = "".join([f"%.{d}f\n" for d in decimals.tolist()])
    out = list(map(str.rstrip, (fmt % tuple(values.tolist())).split("\n")[:-1], repeat("0")))  # 120.5000 -> 120.5
    if "-0." in out:
        out = ["0." if s == "-0." else s for s in out]  # -0.0000 -> -0. -> 0.
    if not point:
        out = list(map(str.rstrip, out, repeat(".")))  # 120. -> 120, 0. -> 0
    return out


def make_rtest_program(angles_deg: np.ndarray, linear_mm: np.ndarray, rotary_axes: tuple[str, ...], *,
                       rtcp: bool = False, dwell_s: float = 5.0, feed: float = 2000.0,
                       title: str = "R-test program", dialect: str = "siemens",
                       axis_sense: Mapping[str, int] | None = None) -> str:
    """An R-test program: one positioning block and one dwell per pose (module docstring).

    Parameters
    ----------
    angles_deg : (n, k) [deg]
        CONVENTIONS angles θ; written as the commanded θ_cmd = σ·θ.
    linear_mm : (n, 3) [mm]
        Machine positions of the ball centre (``rtcp=False``) or workpiece coordinates (``rtcp=True``).
    axis_sense : dict of str to int, optional
        Axes the controller commands in the reverse sense (CONVENTIONS §9); recorded in the header
        (:mod:`pige_sym.nc.program_header`) when any.
    """
    from pige_sym.measurements.axis_sense import METADATA_KEY, format_axis_sense, to_commanded
    from pige_sym.nc.program_header import header_lines

    point = dialect == "fanuc"
    sense = dict(axis_sense or {})
    angles_deg = to_commanded(np.asarray(angles_deg, dtype=float), sense, rotary_axes)
    recorded = format_axis_sense(sense, rotary_axes)
    stated = header_lines({METADATA_KEY: recorded}, dialect) if recorded else []

    def num(v: float) -> str:
        return format_number(float(v), 4, point=point)

    words = []
    for ang, xyz in zip(angles_deg, linear_mm, strict=True):
        rot = " ".join(f"{a}{num(v)}" for a, v in zip(rotary_axes, ang, strict=True))
        words.append(f"X{num(xyz[0])} Y{num(xyz[1])} Z{num(xyz[2])} {rot}")
    clean = title.replace("(", "[").replace(")", "]")
    if dialect == "siemens":
        lines = [f"; {title}", "; generated by pige_sym", *stated, "G90 G17 G71", "TRAORI" if rtcp else "TRAFOOF"]
        motion, dwell, end = "G1", f"G4 F{dwell_s:g}", "M30"
    elif dialect == "fanuc":
        lines = ["%", "O1000", f"({clean})", "(generated by pige_sym)", *stated, "G90 G17 G21",
                 "G43.4 H1" if rtcp else "G49"]
        motion, dwell, end = "G01", f"G04 X{format_number(dwell_s, 3, point=True)}", "M30"
    elif dialect == "linuxcnc":
        if rtcp:
            raise InputError("LinuxCNC has no standard RTCP code: write the program in machine coordinates "
                             "(without --rtcp) or use the siemens/fanuc dialect")
        lines = [f"({clean})", "(generated by pige_sym)", *stated, "G90 G17 G21"]
        motion, dwell, end = "G1", f"G4 P{format_number(dwell_s, 3, point=True)}0", "M2"
    else:
        raise InputError(f"unknown dialect {dialect!r}: use siemens, fanuc or linuxcnc")
    n = 10
    for w in words:
        lines.append(f"N{n} {motion} {w} F{num(feed)}")
        lines.append(f"N{n + 5} {dwell}")
        n += 10
    lines.append(end)
    if dialect == "fanuc":
        lines.append("%")
    return "\n".join(lines) + "\n"


def poses_from_program(program: Program) -> tuple[np.ndarray, np.ndarray, list[bool], list[int]]:
    """Measurement poses: the position at each dwell or M00/M01 (at every linear move if there is none).

    Returns angles_deg (m, k) [deg], xyz (m, 3) [mm], RTCP flag per pose, line numbers.
    Poses with an axis whose position is unknown are left out.
    """
    marks = [b for b in program.blocks if (b.dwell or b.stop)]
    chosen = marks if marks else [b for b in program.blocks if b.is_motion]
    angles, xyz, rtcp, lines = [], [], [], []
    k = len(program.rotary_axes)
    for b in chosen:
        if any(v is None for v in b.after):
            continue
        angles.append(list(b.after[3:]))
        xyz.append(list(b.after[:3]))
        rtcp.append(b.rtcp)
        lines.append(b.line_no)
    return (np.array(angles, dtype=float).reshape(-1, k), np.array(xyz, dtype=float).reshape(-1, 3), rtcp, lines)
