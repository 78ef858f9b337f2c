"""Read a sphere-probing program back and prove it safe before it drives a machine.

:func:`probe_operations` reads the statements a probing program of :mod:`pige_sym.nc.probe_render` is made
of, in each dialect, into operations (rapid, probe, log) with their line numbers; any other statement is
refused with its line (nothing is guessed).  :func:`verify_probe_program` replays them against the nominal
sphere (centre turned by the rotary axes, radius ``R + r``) and refuses, naming the line:

- a rapid move whose straight segment comes within ``margin`` of the sphere, or that starts from an
  unknown position;
- a rotary move while the stylus is below the top of the sphere plus ``margin`` anywhere along the sweep
  (sampled every 0.5°);
- a probing move that does not start outside the sphere, or whose target is not at least ``overtravel``
  past the surface along the move, or that is not followed by its log statement and then by a retract
  along its own path to its start (where the probe stopped is not known in advance);
- a pose with fewer than four contacts.

G-code dialects are also read by the modal interpreter (:mod:`pige_sym.nc.interpreter`, pass-through for the
probing and macro statements): a program it refuses is refused.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pige_sym.errors import NCProgramError
from pige_sym.nc.probe_program import ProbeSetup, nominal_centres

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+(?:\.\d*)?|\.\d+))")
_SKIP = {
    "linuxcnc": re.compile(r"\(.*\)|G21 G90 G17 G40 G49 G80 G94|M2"),
    "fanuc": re.compile(r"%|O\d+|\(.*\)|G21 G90 G17 G40 G49 G80 G94|POPEN|PCLOS|M30|#10[1-9]=[-+]?[\d.]+|"
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
    """One statement of a probing program: ``kind`` rapid/probe/log, its words, its 1-based line."""

    kind: str
    words: dict[str, float]
    line: int


@dataclass
class ProbeProgramCheck:
    """What :func:`verify_probe_program` found: poses, contacts per pose, smallest distances [mm]."""

    poses: int
    contacts: list[int]
    min_rapid_clearance_mm: float
    min_rotary_clearance_mm: float
    min_overtravel_mm: float


def probe_operations(text: str, dialect: str, path: str = "<program>") -> list[Operation]:
    """The operations of a probing program (module docstring)."""
    ops: list[Operation] = []
    for no, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if dialect == "heidenhain":
            line = re.sub(r"^\d+ ", "", line)
        if not line or _SKIP[dialect].fullmatch(line):
            continue
        log = _LOG[dialect]
        for kind, rx in (("rapid", _RAPID[dialect]), ("probe", _PROBE[dialect]), ("log", log)):
            m = rx.fullmatch(line) if rx is not None else None
            if m:
                words = {a: float(v) for a, v in _WORD.findall(m.group(1))} if kind != "log" else {}
                ops.append(Operation(kind, words, no))
                if kind == "probe" and dialect == "linuxcnc":
                    ops.append(Operation("log", {}, no))
                break
        else:
            raise NCProgramError(path, no, f"not a statement of a pige probing program: {line[:60]!r} (a probing "
                                           "program is checked only as pige wrote it)")
    return ops


def _segment_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    d = b - a
    t = 0.0 if not d.any() else float(np.clip((c - a) @ d / (d @ d), 0.0, 1.0))
    return float(np.linalg.norm(a + t * d - c))


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
    r = setup.r_eff_mm
    pos = np.full(3, np.nan)
    angles = np.zeros(len(rotary_axes))
    centre = nominal_centres(setup.machine, angles[None], setup.sphere_mm, setup.pivot_mm)[0]
    contacts: list[int] = []
    rapid_min = rot_min = over_min = np.inf
    pending_log = False
    probe_start: np.ndarray | None = None
    for op in probe_operations(text, dialect, path):
        if pending_log and op.kind != "log":
            raise NCProgramError(path, op.line, "a probing move must be followed by its log statement")
        if op.kind == "log":
            pending_log = False
            continue
        new = pos.copy()
        for k, a in enumerate("XYZ"):
            new[k] = op.words.get(a, new[k])
        rot = [op.words[a] for a in rotary_axes if a in op.words]
        if op.kind == "rapid" and rot:
            target = np.array([op.words.get(a, angles[k]) for k, a in enumerate(rotary_axes)])
            rot_min = min(rot_min, _rotary_clearance(setup, angles, target, pos, path, op.line, margin_mm))
            angles = target
            centre = nominal_centres(setup.machine, angles[None], setup.sphere_mm, setup.pivot_mm)[0]
            contacts.append(0)
            continue
        if op.kind == "probe" and (np.isnan(new).any() or np.isnan(pos).any()):
            raise NCProgramError(path, op.line, "a probing move from or to an unknown position")
        if op.kind == "rapid" and np.isnan(pos[2]) and ("X" in op.words or "Y" in op.words):
            raise NCProgramError(path, op.line, "a horizontal rapid move before Z is known (retract Z first)")
        if op.kind == "rapid" and probe_start is not None:
            if np.abs(new - probe_start).max() > 1e-6:
                raise NCProgramError(path, op.line, "after a probing move the probe must first retract along its "
                                                    "path to the move's start (the contact point is not known)")
            probe_start = None
        elif op.kind == "rapid":
            if not np.isnan(pos).any():
                dist = _segment_distance(pos, new, centre) - r
                if dist < margin_mm:
                    raise NCProgramError(path, op.line, f"this rapid move passes {dist:.3f} mm from the sphere "
                                                        f"(R + r = {r:g} mm): it would hit it")
                rapid_min = min(rapid_min, dist)
        else:
            start_gap = float(np.linalg.norm(pos - centre)) - r
            over = _overtravel(pos, new, centre, r)
            if start_gap <= 0 or over < setup.overtravel_mm - 2e-4:  # 4-decimal coordinates
                raise NCProgramError(path, op.line, f"probing move starts {start_gap:.3f} mm outside the sphere and "
                                                    f"ends {over:.3f} mm past its surface (needs > 0 and "
                                                    f"≥ {setup.overtravel_mm:g})")
            over_min = min(over_min, over)
            if not contacts:
                raise NCProgramError(path, op.line, "a probing move before the rotary axes were positioned")
            contacts[-1] += 1
            pending_log = True
            probe_start = pos.copy()
        pos = new
    few = [i for i, k in enumerate(contacts) if k < 4]
    if few:
        raise NCProgramError(path, None, f"pose {few[0]} has {contacts[few[0]]} probing moves; a centre needs 4")
    return ProbeProgramCheck(len(contacts), contacts, float(rapid_min), float(rot_min), float(over_min))


def _rotary_clearance(setup: ProbeSetup, a0: np.ndarray, a1: np.ndarray, pos: np.ndarray, path: str, line: int,
                      margin: float) -> float:
    """Height of the stylus above the sphere's top along a rotary sweep (refused when below ``margin``)."""
    if np.isnan(pos[2]):
        raise NCProgramError(path, line, "the rotary axes move before Z is programmed (retract first)")
    steps = max(int(np.ceil(np.abs(a1 - a0).max() / 0.5)), 1)
    sweep = a0 + np.linspace(0.0, 1.0, steps + 1)[:, None] * (a1 - a0)
    tops = nominal_centres(setup.machine, sweep, setup.sphere_mm, setup.pivot_mm)[:, 2] + setup.r_eff_mm
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
