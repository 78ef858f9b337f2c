"""Read a sphere-probing program back and prove it safe before it drives a machine.

:func:`probe_operations` reads the statements a probing program of :mod:`pige_sym.nc.probe_render` is made
of, in each dialect, into operations (rapid, probe, log) with their line numbers; any other statement is
refused with its line (nothing is guessed).  :func:`verify_probe_program` replays them against the nominal
sphere (centre turned by the rotary axes, radius ``R + r``) and refuses, naming the line:

- a rapid move whose straight segment comes within ``margin`` of the sphere, or that starts from an
  unknown position;
- a rotary move while the stylus is below the top of the sphere plus ``margin`` anywhere along the sweep
  (sampled every 0.5°; on a head the stylus swings with the head about its pivot);
- a probing move that does not start outside the sphere, or whose target is not at least ``overtravel``
  past the surface along the move, or that is not followed by its log statement and then by a retract
  along its own path to its start (where the probe stopped is not known in advance);
- a pose with fewer than four contacts.

On a head or mixed machine (``setup.tool_mm``) the program commands the linear axes and the stylus centre is
the program's point plus the head's offset ``h(θ) = (R_t(θ) − I)·tool`` (CONVENTIONS §7): every check is made
on the stylus centre.  pige writes no Heidenhain program for a head (its inclined moves would need touch-probe
cycle 4, whose syntax no source at hand settles), so none is read.

G-code dialects are also read by the modal interpreter (:mod:`pige_sym.nc.interpreter`, pass-through for the
probing and macro statements): a program it refuses is refused.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pige_sym.errors import InputError, NCProgramError
from pige_sym.kernels import load_kernels
from pige_sym.measurements.axis_sense import to_commanded, to_conventions
from pige_sym.measurements.probe_head import head_offsets
from pige_sym.nc.probe_header import header_agrees
from pige_sym.nc.probe_program import ProbeSetup, nominal_centres, table_frames

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+(?:\.\d*)?|\.\d+))")
_SKIP = {
    "linuxcnc": re.compile(r"\(.*\)|G21 G90 G17 G40 G49 G80 G94|M2"),
    "fanuc": re.compile(r"%|O\d+|\(.*\)|G21 G90 G17 G40 G49 G80 G94|G43 H\d+|POPEN|PCLOS|M30|#10[1-9]=[-+]?[\d.]+|"
                        r"IF\[\[.*\]LT0\.001\]THEN#3000=1\(PIGE NO CONTACT\)"),
    "siemens": re.compile(r";.*|DEF INT PIGE_ERR|G90 G17 G71 G40|TRAFOOF|STOPRE|IF \$AC_MEA\[1\]==0|"
                          r"SETAL\(\d+\)|ENDIF|M30"),
    "heidenhain": re.compile(r"BEGIN PGM \w+ MM|END PGM \w+ MM|;.*|FN 0: Q\d+ = [-+]?[\d.]+|"
                             r"TCH PROBE 0\.0 REF PLANE Q1[123] [XYZ][-+]"),
}
_RAPID = {"linuxcnc": re.compile(r"G0 (.*)"), "fanuc": re.compile(r"G0 (.*)"), "siemens": re.compile(r"G0 (.*)"),
          "heidenhain": re.compile(r"L (.*) R0 FMAX")}
_PROBE = {"linuxcnc": re.compile(r"G38\.2 (.*) F[\d.]+"), "fanuc": re.compile(r"G31 (.*) F[\d.]+"),
          "siemens": re.compile(r"MEAS=1 G1 (.*) F[\d.]+"), "heidenhain": re.compile(r"TCH PROBE 0\.1 (.*)")}
_LOG = {"linuxcnc": None, "fanuc": re.compile(r"DPRNT\[PIGE\*.*\]"), "siemens": re.compile(r"WRITE\(PIGE_ERR,.*\)"),
        "heidenhain": re.compile(r"FN 16: F-PRINT .*")}


@dataclass
class Operation:
    """One statement of a probing program: ``kind``, its words, its 1-based line.

    Kinds: ``rapid``, ``probe`` (a logged probing move), ``log``, ``guard`` (a guarded approach that stops
    the program on contact) and ``confirm`` (a confirming contact whose ``axis`` coordinate must lie within
    ``window`` of ``expected`` [mm], :mod:`pige_sym.nc.probe_safety`).
    """

    kind: str
    words: dict[str, float]
    line: int
    axis: str | None = None
    expected: float | None = None
    window: float | None = None


@dataclass
class ProbeProgramCheck:
    """What :func:`verify_probe_program` found: poses, contacts per pose, smallest distances [mm]."""

    poses: int
    contacts: list[int]
    min_rapid_clearance_mm: float
    min_rotary_clearance_mm: float
    min_overtravel_mm: float
    confirmations: int = 0


_GUARD = {"linuxcnc": re.compile(r"G38\.3 (.*) F[\d.]+"), "fanuc": re.compile(r"G31 (.*) F[\d.]+"),
          "siemens": re.compile(r"MEAS=1 G1 (.*) F[\d.]+"), "heidenhain": re.compile(r"L (.*) R0 F[\d.]+")}
_WINDOW = {"linuxcnc": re.compile(r"o\d+ if \[ABS\[#506([123]) - ([-+\d.]+)\] GT ([\d.]+)\]"),
           "fanuc": re.compile(r"IF\[ABS\[#506([123])-([-+\d.]+)\]GT([\d.]+)\]THEN#3000=3\(.*\)"),
           "siemens": re.compile(r"IF ABS\(\$AA_MW\[([XYZ])\]-([-+\d.]+)\)>([\d.]+)"),
           "heidenhain": re.compile(r"FN 12: IF \+Q1([123]) LT ([-+\d.]+) GOTO LBL \d+")}


def probe_operations(text: str, dialect: str, path: str = "<program>",
                     rotary_axes: tuple[str, ...] | None = None) -> list[Operation]:
    """The operations of a probing program (module docstring).

    The statements that set the controller state must be exactly what pige writes for the state the header
    states (``rotary_axes`` default: those named by the header's pivots); every guarded and confirming move
    must carry exactly pige's check block.  A program read again (a study runs one program on many virtual
    machines) is parsed once: the latest four are kept, and each call gets operations of its own.
    """
    ops = _operations(text, dialect, path, None if rotary_axes is None else tuple(rotary_axes))
    return [Operation(o.kind, dict(o.words), o.line, o.axis, o.expected, o.window) for o in ops]


@lru_cache(maxsize=4)
def _operations(text: str, dialect: str, path: str, rotary_axes: tuple[str, ...] | None) -> tuple[Operation, ...]:
    """:func:`probe_operations` itself."""
    lines = _lines(text, dialect)
    axes = rotary_axes if rotary_axes is not None else _header_axes(text, path)
    fixed = _fixed_blocks(lines, dialect, path, axes)
    ops: list[Operation] = []
    pos = np.full(3, np.nan)
    i = 0
    while i < len(lines):
        line = lines[i]
        if i in fixed or not line or _SKIP[dialect].fullmatch(line):
            i += 1
            continue
        special = _guarded(lines, i, dialect, pos, path)
        if special is not None:
            ops.append(special[0])
            i = special[1]
        else:
            ops += _plain(line, dialect, i + 1, path)
            i += 1
        if ops[-1].kind in ("rapid", "guard", "confirm", "probe"):
            pos = np.array([ops[-1].words.get(a, pos[k]) for k, a in enumerate("XYZ")])
    return tuple(ops)


def _header_axes(text: str, path: str) -> tuple[str, ...]:
    from pige_sym.nc.program_header import read_header

    return tuple(k[len("pivot_"):-len("_mm")] for k in read_header(text, path) if k.startswith("pivot_"))


def _plain(line: str, dialect: str, no: int, path: str) -> list[Operation]:
    """A rapid, logged probing move or log statement (with LinuxCNC's implicit log after ``G38.2``)."""
    log = _LOG[dialect]
    for kind, rx in (("rapid", _RAPID[dialect]), ("probe", _PROBE[dialect]), ("log", log)):
        m = rx.fullmatch(line) if rx is not None else None
        if m:
            words = {a: float(v) for a, v in _WORD.findall(m.group(1))} if kind != "log" else {}
            out = [Operation(kind, words, no)]
            if kind == "probe" and dialect == "linuxcnc":
                out.append(Operation("log", {}, no))
            return out
    raise NCProgramError(path, no, f"not a statement of a pige probing program: {line[:60]!r} (a probing "
                                   "program is checked only as pige wrote it)")


def _lines(text: str, dialect: str) -> list[str]:
    lines = [raw.strip() for raw in text.splitlines()]
    if dialect == "heidenhain":
        lines = [re.sub(r"^\d+ ", "", ln) for ln in lines]
    return lines


def _fixed_blocks(lines: list[str], dialect: str, path: str, rotary_axes: tuple[str, ...]) -> set[int]:
    """Indices of the prologue and epilogue lines, which must be exactly what pige writes for the stated
    controller state (:mod:`pige_sym.nc.probe_safety`); refused when missing or changed."""
    from pige_sym.nc.probe_safety import controller_from_header, epilogue, heidenhain_error_block, prologue
    from pige_sym.nc.program_header import read_header

    header = read_header("\n".join(lines), path)
    if "kinematics" not in header:
        raise NCProgramError(path, None, "no 'pige kinematics' header: this probing program does not state the "
                                         "controller state it needs; write it again with pige program")
    ctrl = controller_from_header(header, path)
    fixed: set[int] = set()
    blocks = [prologue(ctrl, dialect, rotary_axes), epilogue(ctrl, dialect)]
    if dialect == "heidenhain":
        blocks.append(heidenhain_error_block())
    for block in filter(None, blocks):
        at = [i for i in range(len(lines) - len(block) + 1) if lines[i:i + len(block)] == block]
        if len(at) != 1:
            raise NCProgramError(path, None, f"the statements that set the controller state ({block[0][:40]!r} …) "
                                             "are missing or changed: write the program again with pige program")
        fixed |= set(range(at[0], at[0] + len(block)))
    return fixed


def _checked(lines: list[str], i: int, expected: list[str], path: str) -> int:
    """Index after ``expected`` when ``lines`` holds it at ``i`` (the block of a guarded/confirming move)."""
    if lines[i:i + len(expected)] != expected:
        got = next((ln for ln, want in zip(lines[i:], expected, strict=False) if ln != want), "")
        raise NCProgramError(path, i + 1, f"the check of this guarded or confirming move is not as pige writes it "
                                          f"({got[:60]!r})")
    return i + len(expected)


#: Where a confirming move's window check sits relative to its motion line (Heidenhain's confirming block
#: starts 4 lines before its TCH PROBE 0.1).
_WINDOW_AT = {"linuxcnc": 4, "fanuc": 2, "siemens": 5, "heidenhain": 1}


def _guarded(lines: list[str], i: int, dialect: str, pos: np.ndarray, path: str) -> tuple[Operation, int] | None:
    """A guard or confirm operation whose motion is at line index ``i``, and the index after its block."""
    from pige_sym.nc.probe_render import _num
    from pige_sym.nc.probe_safety import Confirm, confirm_lines, guard_lines

    def fmt(v: float) -> str:
        return _num(v, dialect)

    def at(k: int) -> str:
        return lines[k] if 0 <= k < len(lines) else ""

    window = _WINDOW[dialect].fullmatch(at(i + _WINDOW_AT[dialect]))
    if dialect == "heidenhain":
        m = re.fullmatch(r"TCH PROBE 0\.1 (.*)", at(i)) if window else re.fullmatch(r"L (.*) R0 F[\d.]+", at(i))
        start = i - 4 if window else i
    else:
        m = _GUARD[dialect].fullmatch(at(i))
        start = i
    if m is None:
        return None
    words = {a: float(v) for a, v in _WORD.findall(m.group(1))}
    target = np.array([words.get(a, pos[k]) for k, a in enumerate("XYZ")])
    label_m = re.match(r"o(\d+) ", at(i + 1))
    label = int(label_m.group(1)) if label_m else 0
    if window is None:
        if dialect in ("fanuc", "siemens") and not _guard_follows(lines, i, dialect):
            return None  # an ordinary logged probing move
        block = guard_lines(target, dialect, fmt, label)
        return Operation("guard", words, i + 1), _checked(lines, start, block, path)
    axis = window.group(1) if dialect == "siemens" else "XYZ"[int(window.group(1)) - 1]
    value = float(window.group(2))
    if dialect == "heidenhain":
        hi = re.fullmatch(r"FN 11: IF \+Q1[123] GT ([-+\d.]+) GOTO LBL \d+", at(i + 2))
        w = (float(hi.group(1)) - value) / 2 if hi else 0.0
        value, feed = value + w, 0.0
    else:
        w = float(window.group(3))
        feed = float(re.search(r" F([\d.]+)$", at(i)).group(1))  # type: ignore[union-attr]
    block = confirm_lines(Confirm(pos.copy(), target, axis, value), dialect, fmt, feed, w, label)
    return Operation("confirm", words, i + 1, axis, value, w), _checked(lines, start, block, path)


def _guard_follows(lines: list[str], i: int, dialect: str) -> bool:
    nxt = lines[i + 1:i + 3]
    if dialect == "fanuc":
        return bool(nxt) and "GE0.001" in nxt[0]
    return len(nxt) == 2 and nxt[1] == "IF $AC_MEA[1]==1"


def _segment_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    d = b - a
    t = 0.0 if not d.any() else float(min(max((c - a) @ d / (d @ d), 0.0), 1.0))
    e = a + t * d - c
    return math.sqrt(float(e @ e))  # np.linalg.norm's own sum, without its dispatch (one call per move)


def _overtravel(a: np.ndarray, b: np.ndarray, c: np.ndarray, r: float) -> float:
    """Length of the move past the sphere's surface (negative: the target is short of it)."""
    d = b - a
    length = float(np.linalg.norm(d))
    u = d / length
    along = (c - a) @ u
    perp2 = float((c - a) @ (c - a) - along**2)
    if perp2 > r * r:
        return -np.inf
    entry = along - np.sqrt(r * r - perp2)
    return length - entry


def verify_probe_program(text: str, dialect: str, setup: ProbeSetup, rotary_axes: tuple[str, ...], *,
                         path: str = "<program>", margin_mm: float = 0.5) -> ProbeProgramCheck:
    """Replay a probing program against the nominal sphere (module docstring); raises NCProgramError."""
    _interpreter_accepts(text, dialect, rotary_axes, path)
    header_agrees(text, setup, rotary_axes, path)
    replay = _Replay(setup, rotary_axes, path, margin_mm)
    for op in probe_operations(text, dialect, path, rotary_axes):
        replay.step(op)
    _log_opened_after(text, dialect, replay.last_confirm_line, path)
    return replay.result()


#: The read-back's allowance for the 4-decimal coordinates of a program [mm].
WRITTEN_MM = 2e-4
#: Half the last written decimal of an angle [deg].
WRITTEN_DEG = 5e-5


def verify_rendered_program(text: str, dialect: str, setup: ProbeSetup, rotary_axes: tuple[str, ...], *,
                            out: str | None = None) -> ProbeProgramCheck:
    """:func:`verify_probe_program` on a program pige has just made and not yet written (``out``: where it would go).

    A refusal says so and names the line of that text, never a line of a file that does not exist; on a head it
    also says how far the written angles' last decimal moves the stylus, when that is beyond the read-back's
    allowance (a stylus metres from its pivot).

    Raises
    ------
    InputError
    """
    try:
        return verify_probe_program(text, dialect, setup, rotary_axes, path="<program>")
    except NCProgramError as exc:
        made = f"the probing program for {out}" if out else "the probing program made for these options"
        lever = 0.0 if setup.tool_mm is None else float(np.linalg.norm(setup.tool_mm))
        blur = lever * np.radians(WRITTEN_DEG)
        why = (f"; the head turns the stylus {lever:g} mm from its pivot, where rounding the angles to 0.0001 deg "
               f"moves it up to {blur * 1e3:.1f} um: check --tool" if blur > WRITTEN_MM else
               ": check the set-up options")
        raise InputError(f"{made} fails pige's read-back at its line {exc.line}, so nothing was written: "
                         f"{exc.problem}{why}") from None


class _Replay:
    """The state of a replay: position, angles, the nominal centre, and what was found (module docstring)."""

    def __init__(self, setup: ProbeSetup, axes: tuple[str, ...], path: str, margin: float) -> None:
        self.s, self.axes, self.path, self.margin = setup, axes, path, margin
        self.pos = np.full(3, np.nan)
        self.angles = np.zeros(len(axes))
        self.centre = nominal_centres(setup.machine, self.angles[None], setup.sphere_mm, setup.pivots)[0]
        self.poses: list[list[int]] = []  # per rotary positioning: [logged probes, confirming contacts]
        self.rapid_min = self.rot_min = self.over_min = np.inf
        self.pending_log = False
        self.probe_start: np.ndarray | None = None
        self.confirmed: set[str] = set()
        self.last_confirm_line = 0
        self.tcp = setup.controller.kinematics == "tcp"
        self.work = np.full(3, np.nan)  # program coordinates (the machine's, but in TCP kinematics)
        self.frame = (np.eye(3), np.zeros(3))
        self.plain_frame = True  # self.frame is (I, 0): a move's machine position is its program coordinates
        self.head = np.zeros(3)  # a head's offset of the stylus centre from the program's point (CONVENTIONS §7)

    def step(self, op: Operation) -> None:
        if self.pending_log and op.kind != "log":
            raise NCProgramError(self.path, op.line, "a probing move must be followed by its log statement")
        if op.kind == "log":
            self.pending_log = False
            return
        if op.kind == "rapid" and any(a in op.words for a in self.axes):
            self._rotary(op)
            return
        work = np.array([op.words.get(a, self.work[k]) for k, a in enumerate("XYZ")])
        if self.tcp and np.abs(self.angles).max() > 0 and not all(a in op.words for a in "XYZ"):
            raise NCProgramError(self.path, op.line, "in TCP kinematics every move away from the reference pose "
                                                     "gives X, Y and Z (work coordinates)")
        new = self._machine(work)
        if op.kind in ("probe", "confirm", "guard") and (np.isnan(new).any() or np.isnan(self.pos).any()):
            raise NCProgramError(self.path, op.line, "a probing or guarded move from or to an unknown position")
        if op.kind == "rapid" and np.isnan(self.pos[2]) and ("X" in op.words or "Y" in op.words):
            raise NCProgramError(self.path, op.line, "a horizontal rapid move before Z is known (retract Z first)")
        if op.kind == "rapid" and self.probe_start is not None:
            if np.abs(new - self.probe_start).max() > 1e-6:
                raise NCProgramError(self.path, op.line, "after a probing move the probe must first retract along "
                                                         "its path to the move's start (where it stopped is not known)")
            self.probe_start = None
        elif op.kind in ("rapid", "guard"):
            self._clear(new, op)
        else:
            self._probe(new, op)
        self.pos, self.work = new, work

    def _machine(self, work: np.ndarray) -> np.ndarray:
        """Machine position of program coordinates (TCP kinematics: the nominal table motion of the pose)."""
        if self.plain_frame:
            return work + self.head  # keeps a coordinate not yet programmed unknown, and only that one
        return self.frame[0] @ work + self.frame[1]

    def _rotary(self, op: Operation) -> None:
        held = to_commanded(self.angles, self.s.axis_sense, self.axes)  # the program's words are θ_cmd
        target = to_conventions(np.array([op.words.get(a, held[k]) for k, a in enumerate(self.axes)]),
                                self.s.axis_sense, self.axes)
        self.rot_min = min(self.rot_min, _rotary_clearance(self.s, self.angles, target, self.pos, self.path,
                                                           op.line, self.margin, self.work if self.tcp else None))
        self.angles = target
        if self.s.tool_mm is not None:
            self.head = head_offsets(load_kernels(self.s.machine), target[None], self.s.tool_mm)[0][0]
            self.pos = self._machine(self.work)
        self.centre = nominal_centres(self.s.machine, self.angles[None], self.s.sphere_mm, self.s.pivots)[0]
        if self.tcp:
            rot, t = table_frames(self.s.machine, self.angles[None], self.s.pivots)
            self.frame = (rot[0], t[0])
            self.plain_frame = bool(np.array_equal(rot[0], np.eye(3)) and not t[0].any())
            self.pos = self._machine(self.work)
        if self.poses and self.poses[-1] == [0, 0]:
            self.poses.pop()  # a step of a positioning (TCP kinematics turn in steps)
        self.poses.append([0, 0])

    def _clear(self, new: np.ndarray, op: Operation) -> None:
        if np.isnan(self.pos).any():
            return
        dist = _segment_distance(self.pos, new, self.centre) - self.s.r_eff_mm
        if dist < self.margin:
            what = "guarded approach" if op.kind == "guard" else "rapid move"
            raise NCProgramError(self.path, op.line, f"this {what} passes {dist:.3f} mm from the sphere (R + r = "
                                                     f"{self.s.r_eff_mm:g} mm): it would hit it")
        self.rapid_min = min(self.rapid_min, dist)

    def _probe(self, new: np.ndarray, op: Operation) -> None:
        r = self.s.r_eff_mm
        start_gap = float(np.linalg.norm(self.pos - self.centre)) - r
        over = _overtravel(self.pos, new, self.centre, r)
        need = self.s.overtravel_mm if op.kind == "probe" else float(op.window or 0.0)
        if start_gap > 0 and not np.isfinite(over):
            raise NCProgramError(self.path, op.line, f"probing move starts {start_gap:.3f} mm outside the sphere "
                                                     "and never reaches it: is the sphere (--sphere, --pivot) where "
                                                     "the program probes?")
        if start_gap <= 0 or over < need - WRITTEN_MM:  # 4-decimal coordinates
            raise NCProgramError(self.path, op.line, f"probing move starts {start_gap:.3f} mm outside the sphere "
                                                     f"and ends {over:.3f} mm past its surface (needs > 0 and "
                                                     f"≥ {need:g})")
        if not self.poses:
            raise NCProgramError(self.path, op.line, "a probing move before the rotary axes were positioned")
        if op.kind == "confirm":
            self._confirm(new, op, over)
        else:
            if self.confirmed != {"X", "Y", "Z"}:
                raise NCProgramError(self.path, op.line, "the first logged probing move comes before the sphere is "
                                                         "confirmed on its top, +X and +Y sides (write the program "
                                                         "again with pige program)")
            self.over_min = min(self.over_min, over)
            self.poses[-1][0] += 1
            self.pending_log = True
        self.probe_start = self.pos.copy()

    def _confirm(self, new: np.ndarray, op: Operation, over: float) -> None:
        k = "XYZ".index(str(op.axis))
        crossing = new[k] - over * (new[k] - self.pos[k]) / float(np.linalg.norm(new - self.pos))
        if abs(crossing - float(op.expected or 0.0)) > 2e-4 or np.abs(self.angles).max() > 0:
            raise NCProgramError(self.path, op.line, f"this confirming move expects the surface at {op.axis}"
                                                     f"{op.expected:g}, the nominal sphere is at {crossing:.4f} (or "
                                                     "the rotary axes are not at the reference pose)")
        self.confirmed.add(str(op.axis))
        self.poses[-1][1] += 1
        self.last_confirm_line = op.line

    def result(self) -> ProbeProgramCheck:
        measured = list(self.poses)
        if len(measured) > 1 and measured[-1] == [0, 0] and not np.abs(self.angles).max():
            measured.pop()  # the rotary axes turned back to the reference pose after the last pose: no pose
        poses = [p[0] for p in measured if p[0] or not p[1]]
        few = [i for i, k in enumerate(poses) if k < 4]
        if few:
            raise NCProgramError(self.path, None, f"pose {few[0]} has {poses[few[0]]} probing moves; a centre needs 4")
        return ProbeProgramCheck(len(poses), poses, float(self.rapid_min), float(self.rot_min), float(self.over_min),
                                 sum(p[1] for p in measured))


def _log_opened_after(text: str, dialect: str, line: int, path: str) -> None:
    """LinuxCNC and Fanuc open their log once the sphere is confirmed (a confirming contact is not data)."""
    opener = {"linuxcnc": "(PROBEOPEN", "fanuc": "POPEN"}.get(dialect)
    if opener is None:
        return
    at = [no for no, ln in enumerate(text.splitlines(), 1) if ln.strip().startswith(opener)]
    if len(at) != 1 or at[0] < line:
        raise NCProgramError(path, at[0] if at else None, "the probe log must be opened once, after the confirming "
                                                          "contacts")


def _rotary_clearance(setup: ProbeSetup, a0: np.ndarray, a1: np.ndarray, pos: np.ndarray, path: str, line: int,
                      margin: float, work: np.ndarray | None = None) -> float:
    """Height of the stylus above the sphere's top along a rotary sweep (refused when below ``margin``).

    ``work``: in TCP kinematics the stylus keeps its work coordinates and turns with the table.  On a head
    the stylus centre swings with the head about its pivot: ``pos − h(a0) + h(θ)`` along the sweep.
    """
    if np.isnan(pos[2]):
        raise NCProgramError(path, line, "the rotary axes move before Z is programmed (retract first)")
    steps = max(int(np.ceil(np.abs(a1 - a0).max() / 0.5)), 1)
    sweep = a0 + np.linspace(0.0, 1.0, steps + 1)[:, None] * (a1 - a0)
    tops = nominal_centres(setup.machine, sweep, setup.sphere_mm, setup.pivots)[:, 2] + setup.r_eff_mm
    if setup.tool_mm is not None:
        head = head_offsets(load_kernels(setup.machine), np.vstack([a0, sweep]), setup.tool_mm)[0]
        gap = float((pos[2] - head[0, 2] + head[1:, 2] - tops).min())
    elif work is not None:
        stylus = nominal_centres(setup.machine, sweep, work, setup.pivots)[:, 2]
        gap = float((stylus - tops).min())
    else:
        gap = float(pos[2] - tops.max())
    if gap < margin:
        raise NCProgramError(path, line, f"the rotary axes move with the stylus {gap:.3f} mm above the sphere's top "
                                         "during the sweep: retract Z first")
    return gap


def _interpreter_accepts(text: str, dialect: str, rotary_axes: tuple[str, ...], path: str) -> None:
    if dialect == "heidenhain":
        return  # conversational: read by probe_operations only
    from pige_sym.nc.dialects import get_dialect
    from pige_sym.nc.interpreter import interpret

    interpret(text, get_dialect(dialect), rotary_axes, path=path, pass_through=True)
