"""What a probing program states, sets and checks on the controller before it probes (issue: safe programs).

A probing program is only safe when the controller is in the state it was planned for.  This module holds
that state (:class:`ProbeController`), the header that states it (:mod:`pige_sym.nc.program_header`), and
the statements that set and check it:

**Kinematics** (``kinematics``).  ``identity``: the controller's linear axes are the program's X Y Z (RTCP
off), the state the plan is made in.  LinuxCNC's switchable kinematics are a machine state that outlives a
program (the shipped trt configurations switch with user M-codes, ``M429`` identity and ``M428`` TCP), so
a LinuxCNC program sets identity with the declared ``--rtcp-off`` code and ends with the declared
``--rtcp-on`` code: it leaves the machine in TCP kinematics, the state five-axis work runs in.  The other
dialects switch their tool-centre-point function off in the program (``TRAFOOF``, ``G49``, ``FUNCTION
RESET TCPM``), which their program end resets anyway.  ``tcp`` (LinuxCNC only): the controller's TCP
kinematics stay on (a configuration without a switch, or switched on with ``--rtcp-on``); the program's
coordinates are then work coordinates, the sphere stands still in them, and the import maps every logged
contact back through the nominal kinematics the controller held (:mod:`pige_sym.measurements.probe_import`).
A LinuxCNC program whose mode cannot be known (no switch code for identity) is refused.

**Stylus** (``stylus_tool``, ``stylus_length_mm``).  The stylus is a tool: its number and length (gauge
line to the stylus-ball centre, the controlled point) are stated in the header.  LinuxCNC checks that the
spindle holds that tool (``#5400``), activates its length (``G43 H``) and checks the active length
(``#5403``) against the stated one to 0.5 µm; otherwise it aborts with the reason.

**Work offset** (``work_offset``, ``work_offset_mm``).  The program selects the stated work offset (G54 …
G59.3) and, on LinuxCNC, checks its X Y Z against the stated values, its rotary offsets and XY rotation
against 0, and the G92 offsets against 0 (``#5211…``, ``#5221…`` per system, ``#5230`` rotation), aborting
with the values found: ``--sphere`` and ``--pivot`` are coordinates in that system.

**First moves** (``window_mm``).  Before the log is opened, at the reference pose, the program confirms the
sphere: straight down over its nominal centre from the safe height (a *guarded* approach that aborts on
any contact), a probing move onto the top, then one onto the +X and one onto the +Y side (each reached by a
guarded descent beside the sphere); each contact must lie within ``window_mm`` of where the sphere's
nominal surface is, else the program stops with a message naming what to check.  Only then does anything
else move.  Per dialect: LinuxCNC ``G38.3`` with ``#5070`` (tripped) and ``#5061…#5063``; Fanuc ``G31``
with the skip position ``#5061…#5063`` and alarms ``#3000``; Siemens ``MEAS=1`` with ``$AC_MEA[1]``,
``$AA_MW`` and ``SETAL``; Heidenhain a positioning move at probing feed (the TNC stops on a deflected stylus
during positioning) and ``TCH PROBE 0`` with the touch point in ``Q11…Q13``, checked by ``FN 11/12``
jumps to an ``FN 14: ERROR``.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from pige_sym.errors import InputError

KINEMATICS = ("identity", "tcp")
WORK_OFFSETS = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
#: Tolerance of the LinuxCNC checks of the stated tool length and work offset [mm].
VALUE_TOLERANCE_MM = 0.0005
#: Siemens user alarms: no contact (as today), contact on a guarded approach, a contact outside the window.
SIEMENS_ALARMS = {"miss": 65000, "guard": 65001, "window": 65002}
#: Fanuc macro alarms (#3000 = n): no contact, contact on a guarded approach, a contact outside the window.
FANUC_ALARMS = {"miss": 1, "guard": 2, "window": 3}
HEIDENHAIN_ERROR_LABEL = 99
HEIDENHAIN_END_LABEL = 98


@dataclass(frozen=True)
class ProbeController:
    """The controller state a probing program sets and checks (module docstring).

    Attributes
    ----------
    kinematics : {"identity", "tcp"}
    rtcp_off, rtcp_on : str or None
        LinuxCNC's kinematics switch codes (``M429``, ``M428`` in the shipped trt sims).
    stylus_tool : int
    stylus_length_mm : float [mm]
        Gauge line to the stylus-ball centre: the tool length of the stylus tool.
    work_offset : str
        ``G54`` … ``G59.3``.
    work_offset_mm : tuple of 3 float [mm]
        The X Y Z of that work offset the program assumes.
    window_mm : float [mm]
        How far a confirming contact may lie from the nominal surface.
    """

    kinematics: str = "identity"
    rtcp_off: str | None = None
    rtcp_on: str | None = None
    stylus_tool: int = 1
    stylus_length_mm: float = 100.0
    work_offset: str = "G54"
    work_offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    window_mm: float = 0.3

    def check(self, dialect: str) -> None:
        """Refuse a state the dialect cannot set or a program cannot know (InputError naming the option)."""
        if self.kinematics not in KINEMATICS:
            raise InputError(f"--kinematics {self.kinematics!r}: use identity or tcp")
        for code, flag in ((self.rtcp_off, "--rtcp-off"), (self.rtcp_on, "--rtcp-on")):
            if code is not None and not re.fullmatch(r"[MG]\d{1,4}(\.\d)?", code):
                raise InputError(f"{flag} {code!r}: give one M or G code, e.g. M428")
        from pige_sym.nc.dialects import get_dialect
        from pige_sym.nc.dialects.base import kinematics_switch_codes

        table = None if dialect == "heidenhain" else get_dialect(dialect)  # no code table for HEIDENHAIN here
        kinematics_switch_codes(table, [self.rtcp_on] if self.rtcp_on else [], [self.rtcp_off] if self.rtcp_off else [])
        if dialect == "linuxcnc" and self.kinematics == "identity" and (self.rtcp_off is None or self.rtcp_on is None):
            raise InputError("LinuxCNC keeps its kinematics between programs: a probing program in identity "
                             "kinematics must switch to them and back; give the configuration's codes "
                             "--rtcp-off CODE --rtcp-on CODE (the shipped trt sims: M429 and M428), or probe in "
                             "the TCP kinematics with --kinematics tcp")
        if self.kinematics == "tcp" and dialect != "linuxcnc":
            raise InputError(f"--kinematics tcp: the {dialect} log's coordinates under the tool-centre-point "
                             "function are not settled here; probe with RTCP off (--kinematics identity)")
        if self.kinematics == "tcp" and self.rtcp_off is not None:
            raise InputError("--kinematics tcp keeps the TCP kinematics on: --rtcp-off is not used (give only "
                             "--rtcp-on CODE when the program must switch them on)")
        if not (0 < self.stylus_tool < 100000) or not (0 < self.stylus_length_mm < 1000):
            raise InputError("--stylus-tool must be a tool number (1-99999) and --stylus-length a length in "
                             "(0, 1000) mm")
        if self.work_offset not in WORK_OFFSETS:
            raise InputError(f"--work-offset {self.work_offset}: use one of {', '.join(WORK_OFFSETS)}")
        if not 0.01 <= self.window_mm <= 5:
            raise InputError(f"--window {self.window_mm:g}: give 0.01 to 5 mm")

    def header_items(self) -> dict[str, str]:
        """The header lines that state this state (:mod:`pige_sym.nc.program_header`)."""
        codes = " ".join(c for c in (self.rtcp_off, self.rtcp_on) if c)
        out = {"kinematics": self.kinematics}
        if codes:
            out["kinematics_codes"] = f"off={self.rtcp_off or '-'} on={self.rtcp_on or '-'}"
        return out | {
            "stylus_tool": str(self.stylus_tool), "stylus_length_mm": _g(self.stylus_length_mm),
            "work_offset": f"{self.work_offset} {', '.join(_g(v) for v in self.work_offset_mm)}",
            "window_mm": _g(self.window_mm)}


def _g(v: float) -> str:
    """A length [mm] as written in the header and in G-code expressions: to 1 nm, trailing zeros dropped
    (six significant digits would round a 123.4567 mm stylus to 123.457, which the read-back then refuses)."""
    text = f"{float(v):.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def controller_from_header(items: Mapping[str, str], path: str) -> ProbeController:
    """The state a program's header states (refused when an item is missing or malformed)."""
    try:
        codes = dict(part.split("=", 1) for part in items.get("kinematics_codes", "").split())
        offset, _, values = items["work_offset"].partition(" ")
        vec = [float(v) for v in values.split(",")]
        return ProbeController(items["kinematics"], None if codes.get("off", "-") == "-" else codes["off"],
                               None if codes.get("on", "-") == "-" else codes["on"], int(items["stylus_tool"]),
                               float(items["stylus_length_mm"]), offset, (vec[0], vec[1], vec[2]),
                               float(items["window_mm"]))
    except (KeyError, ValueError, IndexError) as exc:
        raise InputError(f"{path}: the probing program's header does not state its controller state "
                         f"({exc}): write the program again with pige program") from None


# --------------------------------------------------------------------------- prologue and epilogue


def _system_parameter(work_offset: str) -> int:
    """LinuxCNC's first parameter of a coordinate system (G54 ``#5221``, G55 ``#5241``, …, 20 apart)."""
    return 5221 + 20 * WORK_OFFSETS.index(work_offset)


def linuxcnc_prologue(ctrl: ProbeController, rotary_axes: tuple[str, ...]) -> list[str]:
    """Kinematics, stylus tool, tool length and work offset, set and checked (LinuxCNC)."""
    out = []
    if ctrl.kinematics == "identity":
        out.append(f"{ctrl.rtcp_off} (identity kinematics: --rtcp-off)")
    elif ctrl.rtcp_on:
        out.append(f"{ctrl.rtcp_on} (TCP kinematics: --rtcp-on)")
    t, length, tol = ctrl.stylus_tool, ctrl.stylus_length_mm, VALUE_TOLERANCE_MM
    out += [f"o900 if [#5400 NE {t}]",
            f"(abort, PIGE: the spindle holds tool #5400; this program probes with the stylus tool {t}: load it "
            f"[T{t} M6] and run again)",
            "o900 endif", f"G43 H{t}",
            f"o901 if [ABS[#5403 - {_g(length)}] GT {tol}]",
            f"(abort, PIGE: the length of tool {t} is #5403 mm; the program was written for --stylus-length "
            f"{_g(length)} mm [gauge line to the stylus centre])",
            "o901 endif", ctrl.work_offset]
    base = _system_parameter(ctrl.work_offset)
    xyz = " OR ".join(f"[ABS[#{base + k} - {_g(v)}] GT {tol}]" for k, v in enumerate(ctrl.work_offset_mm))
    rot = " OR ".join(f"[#{base + 3 + 'ABC'.index(a[0])} NE 0]" for a in rotary_axes)
    g92 = " OR ".join(f"[#{5211 + k} NE 0]" for k in (0, 1, 2, *('ABC'.index(a[0]) + 3 for a in rotary_axes)))
    want = ", ".join(_g(v) for v in ctrl.work_offset_mm)
    if ctrl.kinematics == "tcp":
        at_zero = " OR ".join(f"[ABS[#{5423 + 'ABC'.index(a[0])}] GT {tol}]" for a in rotary_axes)
        out += [f"o905 if [{at_zero}]",
                "(abort, PIGE: in TCP kinematics the program starts with the rotary axes at 0 [its first move is up "
                "along Z]: position them first)", "o905 endif"]
    out += [f"o902 if [{xyz}]",
            f"(abort, PIGE: {ctrl.work_offset} is X#{base} Y#{base + 1} Z#{base + 2}; the program assumes "
            f"{want}: --sphere and --pivot are in that system [--work-offset])",
            "o902 endif",
            f"o903 if [{rot} OR [#{base + 9} NE 0]]",
            f"(abort, PIGE: {ctrl.work_offset} offsets a rotary axis or rotates XY: the logged angles would not "
            "be the machine's)",
            "o903 endif",
            f"o904 if [{g92}]",
            "(abort, PIGE: G92 offsets are active: clear them with G92.1 before probing)",
            "o904 endif"]
    return out


def prologue(ctrl: ProbeController, dialect: str, rotary_axes: tuple[str, ...]) -> list[str]:
    """The statements after the modal line that set (and on LinuxCNC check) the controller state."""
    if dialect == "linuxcnc":
        return linuxcnc_prologue(ctrl, rotary_axes)
    if dialect == "heidenhain":
        return ["FUNCTION RESET TCPM", f"; stylus tool {ctrl.stylus_tool}, length {_g(ctrl.stylus_length_mm)} mm, "
                f"work offset {ctrl.work_offset}: confirmed by the first contacts"]
    return [ctrl.work_offset]


def epilogue(ctrl: ProbeController, dialect: str) -> list[str]:
    """Restore the kinematics (LinuxCNC: the declared TCP code) before the program end."""
    if dialect == "linuxcnc" and ctrl.kinematics == "identity":
        return [f"{ctrl.rtcp_on} (TCP kinematics again: --rtcp-on)"]
    return []


# --------------------------------------------------------------------------- guarded and confirming moves


@dataclass(frozen=True)
class Confirm:
    """A confirming contact: probe from ``start`` to ``target`` along ``axis``; the contact's ``axis``
    coordinate must be ``expected`` ± window [mm]."""

    start: np.ndarray
    target: np.ndarray
    axis: str
    expected: float


def confirmation_moves(centre: np.ndarray, r_eff: float, clearance: float, window: float,
                       safe_z: float) -> list[tuple[str, np.ndarray] | Confirm]:
    """The reference-pose confirmation (module docstring): ``("rapid"|"guard", point)`` and :class:`Confirm`.

    Every point is in program coordinates at the reference pose [mm]; the probe starts over the centre at
    ``safe_z`` and ends there.
    """
    c = np.asarray(centre, dtype=float)
    top = c[2] + r_eff
    plane = top + clearance
    past = window + 0.2  # each confirming move goes this far past the nominal surface
    out: list[tuple[str, np.ndarray] | Confirm] = [("rapid", np.array([c[0], c[1], safe_z])),
                                                   ("guard", np.array([c[0], c[1], plane])),
                                                   Confirm(np.array([c[0], c[1], plane]),
                                                           np.array([c[0], c[1], top - past]), "Z", top)]
    for k, axis in ((0, "X"), (1, "Y")):
        side = c.copy()
        side[k] += r_eff + clearance
        over = np.array([side[0], side[1], plane])
        target = side.copy()
        target[k] = c[k] + r_eff - past
        out += [("rapid", over), ("guard", side), Confirm(side, target, axis, float(c[k] + r_eff)),
                ("rapid", over)]
    out.append(("rapid", np.array([c[0], c[1], plane])))
    out.append(("rapid", np.array([c[0], c[1], safe_z])))
    return out


#: Feed of the guarded approaches [mm/min]: slow enough for the stylus to stop within its overtravel.
GUARD_FEED_MM_MIN = 500.0
_CHECK_WHAT = "check --sphere, --pivot, the work offset and the stylus length"


def _words(p: np.ndarray, fmt: Callable[[float], str]) -> str:
    return " ".join(f"{a}{fmt(float(p[k]))}" for k, a in enumerate("XYZ"))


def guard_lines(point: np.ndarray, dialect: str, fmt: Callable[[float], str], label: int) -> list[str]:
    """A guarded approach to ``point`` that stops the program on any contact (module docstring)."""
    feed = f"{GUARD_FEED_MM_MIN:g}" if dialect == "heidenhain" else fmt(GUARD_FEED_MM_MIN)
    words = _words(point, fmt)
    if dialect == "linuxcnc":
        return [f"G38.3 {words} F{feed}", f"o{label} if [#5070 EQ 1]",
                f"(abort, PIGE: contact while approaching {words}: the sphere is not where the program expects "
                f"it; {_CHECK_WHAT})", f"o{label} endif"]
    if dialect == "fanuc":
        miss = "+".join(f"ABS[#{5061 + k}-{fmt(float(point[k]))}]" for k in range(3))
        return [f"G31 {words} F{feed}",
                f"IF[[{miss}]GE0.001]THEN#3000={FANUC_ALARMS['guard']}(PIGE CONTACT ON APPROACH)"]
    if dialect == "siemens":
        return [f"MEAS=1 G1 {words} F{feed}", "STOPRE", "IF $AC_MEA[1]==1", f"SETAL({SIEMENS_ALARMS['guard']})",
                "ENDIF"]
    return [f"L {words} R0 F{feed}"]


def confirm_lines(conf: Confirm, dialect: str, fmt: Callable[[float], str], feed: float, window: float,
                  label: int) -> list[str]:
    """A confirming contact and its window check (module docstring)."""
    k = "XYZ".index(conf.axis)
    target = _words(conf.target, fmt)
    lo, hi = fmt(conf.expected - window), fmt(conf.expected + window)
    expected, w, f = fmt(conf.expected), fmt(window), fmt(feed)
    if dialect == "linuxcnc":
        return [f"G38.3 {target} F{f}", f"o{label} if [#5070 EQ 0]",
                f"(abort, PIGE: no contact: the sphere's surface should be at {conf.axis}{expected}; {_CHECK_WHAT})",
                f"o{label} endif", f"o{label + 1} if [ABS[#{5061 + k} - {expected}] GT {w}]",
                f"(abort, PIGE: the sphere's surface is at {conf.axis}#{5061 + k}, expected {expected} +- {w} mm; "
                f"{_CHECK_WHAT})", f"o{label + 1} endif"]
    if dialect == "fanuc":
        miss = "+".join(f"ABS[#{5061 + i}-{fmt(float(conf.target[i]))}]" for i in range(3))
        return [f"G31 {target} F{f}", f"IF[[{miss}]LT0.001]THEN#3000={FANUC_ALARMS['miss']}(PIGE NO CONTACT)",
                f"IF[ABS[#{5061 + k}-{expected}]GT{w}]THEN#3000={FANUC_ALARMS['window']}(PIGE SPHERE NOT AT "
                "EXPECTED PLACE)"]
    if dialect == "siemens":
        return [f"MEAS=1 G1 {target} F{f}", "STOPRE", "IF $AC_MEA[1]==0", f"SETAL({SIEMENS_ALARMS['miss']})",
                "ENDIF", f"IF ABS($AA_MW[{conf.axis}]-{expected})>{w}", f"SETAL({SIEMENS_ALARMS['window']})",
                "ENDIF"]
    q = 11 + k
    sign = "+" if conf.target[k] > conf.start[k] else "-"
    pre = [f"FN 0: Q{11 + i} = {fmt(float(conf.start[i]))}" for i in range(3)]
    return [*pre, f"TCH PROBE 0.0 REF PLANE Q{q} {conf.axis}{sign}", f"TCH PROBE 0.1 {target}",
            f"FN 12: IF +Q{q} LT {lo} GOTO LBL {HEIDENHAIN_ERROR_LABEL}",
            f"FN 11: IF +Q{q} GT {hi} GOTO LBL {HEIDENHAIN_ERROR_LABEL}"]


def heidenhain_error_block() -> list[str]:
    """The jump over, and the label of, the error the Heidenhain window checks go to."""
    return [f"FN 9: IF +0 EQU +0 GOTO LBL {HEIDENHAIN_END_LABEL}", f"LBL {HEIDENHAIN_ERROR_LABEL}",
            "FN 14: ERROR = 250", f"LBL {HEIDENHAIN_END_LABEL}"]
