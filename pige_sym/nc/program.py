"""NC programs: a Siemens 840D-style subset, read losslessly and rewritten block by block.

Block grammar (one block per line; words separated by spaces; case-insensitive)::

    block   := [N<int>] word* [";" comment]
    word    := G<int> | M<int> | F<num> | S<num> | T<int>
             | AXIS <num> | AXIS "=" <num> | AXIS "=" FN "(" <num> ")"   FN: DC ACP ACN IC AC
             | TRAORI | TRAFOOF | G4 F<num>
    AXIS    := X | Y | Z | A | B | C   (the machine's rotary axes)

Lines starting with ``%`` or ``;`` and blank lines are kept verbatim.  Modal state:
G0/G1, G90/G91, TRAORI/TRAFOOF.  Incremental values (G91 or ``IC()``) are resolved
into absolute positions when the start is known; an incremental move whose start is
unknown, arcs (G2/G3), cycles (``CYCLE…``), frames (TRANS, ROT, ATRANS, AROT, G68),
subprogram calls (L…, CALL) and polynomials (POLY) are refused with the line number
unless ``pass_through`` is set (then the block is kept verbatim and not compensated).

Rewriting replaces only the values of the axis words of the blocks it is asked to
change; a block programmed incrementally is rewritten in absolute form (``AC(…)``
for that word).  Every other line is kept byte for byte.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pige_sym.errors import PigeError

AXES = ("X", "Y", "Z", "A", "B", "C")
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_WORD = re.compile(
    rf"(?P<axis>[XYZABC])(?:(?P<plain>{_NUM})|=(?:(?P<eq>{_NUM})|(?P<fn>DC|ACP|ACN|IC|AC)\((?P<arg>{_NUM})\)))"
    rf"(?=\s|;|$)", re.IGNORECASE)
_REFUSE = re.compile(r"\b(G0?2|G0?3|G68|CYCLE\w*|TRANS|ATRANS|ROT|AROT|CALL|POLY|L\d+)\b", re.IGNORECASE)
_TOKEN = re.compile(r"\S+")


class NCProgramError(PigeError):
    """A block the tool cannot read or compensate safely; names the file and line."""

    def __init__(self, path: str, line: int, problem: str) -> None:
        super().__init__(f"{path}:{line}: {problem}")


@dataclass
class AxisWord:
    """An axis word of a block: where it is in the line and what it means."""

    axis: str
    start: int
    end: int
    value: float
    form: str  # "plain", "eq", or the function name DC/ACP/ACN/IC/AC
    incremental: bool


@dataclass
class NCBlock:
    """One line of the program."""

    line_no: int
    text: str  # without the line ending
    ending: str
    words: list[AxisWord] = field(default_factory=list)
    position: dict[str, float | None] = field(default_factory=dict)
    is_motion: bool = False
    rtcp: bool = False
    dwell: bool = False
    stop: bool = False
    passed_through: bool = False


@dataclass
class NCProgram:
    """A parsed program: every line, in order."""

    path: str
    blocks: list[NCBlock]
    rotary_axes: tuple[str, ...]

    def text(self) -> str:
        return "".join(b.text + b.ending for b in self.blocks)


def parse_program(text: str, *, path: str = "<program>", rotary_axes: tuple[str, ...] = ("A", "C"),
                  pass_through: bool = False) -> NCProgram:
    """Parse an 840D-style program (module docstring); never alters the text."""
    allowed = {"X", "Y", "Z", *rotary_axes}
    pos: dict[str, float | None] = dict.fromkeys(("X", "Y", "Z", *rotary_axes))
    incremental = False
    rtcp = False
    blocks = []
    lines = text.splitlines(keepends=True)
    for i, raw in enumerate(lines, start=1):
        body = raw.rstrip("\r\n")
        ending = raw[len(body):]
        block = NCBlock(i, body, ending, position=dict(pos), rtcp=rtcp)
        code = body.split(";", 1)[0]
        stripped = code.strip()
        if not stripped or stripped.startswith("%"):
            blocks.append(block)
            continue
        upper = code.upper()
        if _REFUSE.search(upper):
            if not pass_through:
                word = _REFUSE.search(upper).group(0)  # type: ignore[union-attr]
                raise NCProgramError(path, i, f"unsupported instruction {word!r} (arcs, cycles, frames and calls "
                                     "cannot be compensated safely; use --pass-through to keep such blocks verbatim)")
            block.passed_through = True
            blocks.append(block)
            continue
        tokens = _TOKEN.findall(upper)
        if "TRAORI" in tokens:
            rtcp = True
        if "TRAFOOF" in tokens:
            rtcp = False
        if "G91" in tokens:
            incremental = True
        if "G90" in tokens:
            incremental = False
        block.rtcp = rtcp
        block.dwell = "G4" in tokens or "G04" in tokens
        block.stop = any(t in ("M0", "M00", "M1", "M01") for t in tokens)
        covered = np.zeros(len(code), dtype=bool)
        for mt in _WORD.finditer(code):
            ax = mt.group("axis").upper()
            if ax not in allowed:
                raise NCProgramError(path, i, f"axis word {mt.group(0)!r}: {ax} is not an axis of this machine")
            fn = (mt.group("fn") or "").upper()
            val = float(mt.group("plain") or mt.group("eq") or mt.group("arg"))
            inc = fn == "IC" or (incremental and fn not in ("AC", "DC", "ACP", "ACN"))
            form = fn or ("eq" if mt.group("eq") is not None else "plain")
            block.words.append(AxisWord(ax, mt.start(), mt.end(), val, form, inc))
            covered[mt.start():mt.end()] = True
        # anything else that looks like an axis word is malformed
        for tok in re.finditer(r"\S+", code):
            if covered[tok.start()]:
                continue
            t = tok.group(0).upper()
            if t[0] in "XYZABC" and t not in ("TRAORI", "TRAFOOF") and not t.startswith(("ACP", "ACN", "AC(", "DC(")):
                raise NCProgramError(path, i, f"malformed axis word {tok.group(0)!r}")
        if block.dwell:
            block.words = []
        for w in block.words:
            if w.incremental:
                start = pos[w.axis]
                if start is None:
                    if not pass_through:
                        raise NCProgramError(path, i, f"incremental move of {w.axis} with no known start position")
                    block.passed_through = True
                    continue
                pos[w.axis] = start + w.value
            else:
                pos[w.axis] = w.value
        block.is_motion = bool(block.words) and not block.passed_through
        block.position = dict(pos)
        blocks.append(block)
    return NCProgram(path, blocks, tuple(rotary_axes))


def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def rewrite_program(program: NCProgram, new_positions: Callable[[NCBlock], dict[str, float] | None], *,
                    header_lines: list[str] | None = None, decimals: int = 4) -> str:
    """Rewrite the axis values of motion blocks; every other byte stays as it was.

    ``new_positions(block)`` returns absolute values for axes to change (or None).
    Axes the block did not program are appended after its last axis word.
    """
    out: list[str] = []
    header = [f"; {h}" for h in (header_lines or [])]
    inserted = not header
    for b in program.blocks:
        if not inserted and not b.text.strip().startswith("%"):
            ending = b.ending or "\n"
            out.extend(h + ending for h in header)
            inserted = True
        new = new_positions(b) if b.is_motion else None
        if not new:
            out.append(b.text + b.ending)
            continue
        text = b.text
        pieces = []
        last = 0
        done = set()
        for w in b.words:
            pieces.append(text[last:w.start])
            if w.axis in new:
                val = _fmt(new[w.axis], decimals)
                if w.form == "plain":
                    pieces.append(f"{text[w.start]}{val}" if not w.incremental else f"{text[w.start]}=AC({val})")
                elif w.form == "eq":
                    pieces.append(f"{text[w.start]}={val}" if not w.incremental else f"{text[w.start]}=AC({val})")
                elif w.form == "IC":
                    pieces.append(f"{text[w.start]}=AC({val})")
                else:
                    pieces.append(f"{text[w.start]}={w.form}({val})")
                done.add(w.axis)
            else:
                pieces.append(text[w.start:w.end])
            last = w.end
        extra = "".join(f" {ax}{_fmt(v, decimals)}" for ax, v in new.items() if ax not in done)
        pieces.append(extra + text[last:])
        out.append("".join(pieces) + b.ending)
    return "".join(out)


def to_fanuc(program: NCProgram, positions: Callable[[NCBlock], dict[str, float] | None] | None = None, *,
             header_lines: list[str] | None = None, decimals: int = 4) -> str:
    """ISO/Fanuc-style program: ``N.. G1 X.. Y.. Z.. A.. C..`` with absolute values.

    TRAORI → ``G43.4`` (tool centre point control on), TRAFOOF → ``G49``; dwell
    ``G4 F<s>`` → ``G04 X<s>``; ``;`` comments → ``( … )``; blocks are renumbered.
    Motion blocks are written as ``G0``/``G1`` with every axis at its absolute
    position; their other words (F, S, M …) follow in their order.  Every other block
    keeps its words verbatim (nothing is dropped); a block passed through
    uncompensated says so in its comment.
    """
    out = ["%"] + [f"({h})" for h in header_lines or []] + ["G90"]
    n = 10
    for b in program.blocks:
        code, _, comment = b.text.partition(";")
        comment = comment.strip().replace("(", "[").replace(")", "]")
        toks = [t for t in code.split() if not re.fullmatch(r"N\d+", t, re.IGNORECASE)]
        if code.strip().startswith("%"):
            continue
        if b.passed_through:
            comment = (comment + "; " if comment else "") + "passed through, not compensated"
        if not toks:
            if comment:
                out.append(f"({comment})")
            continue
        upper = [t.upper() for t in toks]
        words: list[str] = []
        if b.dwell:
            f = next((t[1:] for t in upper if t.startswith("F")), "0")
            words += ["G04", f"X{f}"]
            words += [t for t in upper if t not in ("G4", "G04") and not t.startswith("F")]
        elif b.is_motion:
            g = next((t for t in upper if t in ("G0", "G00", "G1", "G01")), None)
            words.append(g or "G1")
            pos = dict(b.position)
            if positions is not None:
                pos.update(positions(b) or {})
            words += [f"{ax}{_fmt(v, decimals)}" for ax, v in pos.items() if v is not None]
            words += [t for t in upper if t not in ("G0", "G00", "G1", "G01") and not _WORD.fullmatch(t)]
        else:
            words = [{"TRAORI": "G43.4", "TRAFOOF": "G49"}.get(t, t) for t in upper]
        out.append(f"N{n} " + " ".join(words) + (f" ({comment})" if comment else ""))
        n += 10
    out.append("%")
    return "\n".join(out) + "\n"


def make_rtest_program(angles_deg: np.ndarray, linear_mm: np.ndarray, rotary_axes: tuple[str, ...], *,
                       rtcp: bool = False, dwell_s: float = 5.0, feed: float = 2000.0,
                       title: str = "R-test program") -> str:
    """An 840D R-test program: one positioning block and one dwell per pose.

    With ``rtcp=False`` X/Y/Z are machine positions of the ball centre (``TRAFOOF``);
    with ``rtcp=True`` they are workpiece coordinates (``TRAORI``).
    """
    lines = [f"; {title}", "; generated by pige_sym", "G90 G17", "TRAORI" if rtcp else "TRAFOOF"]
    n = 10
    for ang, xyz in zip(angles_deg, linear_mm, strict=True):
        rot = " ".join(f"{a}{_fmt(v, 4)}" for a, v in zip(rotary_axes, ang, strict=True))
        lines.append(f"N{n} G1 X{_fmt(xyz[0], 4)} Y{_fmt(xyz[1], 4)} Z{_fmt(xyz[2], 4)} {rot} F{feed:g}")
        lines.append(f"N{n + 5} G4 F{dwell_s:g}")
        n += 10
    lines += ["M30"]
    return "\n".join(lines) + "\n"


def poses_from_program(program: NCProgram) -> tuple[np.ndarray, np.ndarray, list[bool], list[int]]:
    """Measurement poses: the position at each dwell or M00/M01 (at every motion block if there is none).

    Returns angles_deg (m, k), xyz (m, 3), RTCP flag per pose, line numbers.
    """
    marks = [b for b in program.blocks if (b.dwell or b.stop)]
    chosen = marks if marks else [b for b in program.blocks if b.is_motion]
    angles, xyz, rtcp, lines = [], [], [], []
    for b in chosen:
        p = b.position
        if any(p.get(a) is None for a in ("X", "Y", "Z", *program.rotary_axes)):
            continue
        angles.append([p[a] for a in program.rotary_axes])
        xyz.append([p["X"], p["Y"], p["Z"]])
        rtcp.append(b.rtcp)
        lines.append(b.line_no)
    return np.array(angles, dtype=float), np.array(xyz, dtype=float), rtcp, lines
