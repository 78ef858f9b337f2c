"""Rewriting: new poses into the blocks that need them, every other byte kept.

Rules (each one is checked again by :mod:`pige_sym.nc.verify` on the written text):

- only blocks given a target pose change, and only the *digits* of their axis words
  (``X  16.339`` keeps its spaces, ``X=IC(5)`` its form, ``/``, ``N`` numbers, comments,
  every other word and the line ending stay as they were);
- a word keeps the block's mode: an incremental word (G91, ``=IC()``) gets the increment
  from the position the *output* program has reached (tracked by running the output
  through its own interpreter as it is written), an absolute word the absolute value; an
  inch block gets inches (5 decimals), a mm block mm (4 decimals), rotary axes degrees
  (4 decimals); ISO/Fanuc values always carry a decimal point;
- a word whose value would not change is left byte-identical;
- an axis the block does not program is appended (after the block's last axis word, in the
  block's mode) only when its target differs from where the output program already has it;
- a header (comment lines) goes after the leading ``%``/``%_N_…``/``O…``/``;$PATH`` lines, never
  before them nor between a byte-order mark and the program name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from pige_sym.errors import NCProgramError
from pige_sym.nc.interpreter import Interpreter, Program
from pige_sym.nc.program import format_number
from pige_sym.nc.state import Block

_LEAD = re.compile(r"^\ufeff?\s*(?:%|O\d+|;\s*\$PATH)", re.IGNORECASE)


@dataclass
class WordChange:
    """One word of one block: as written and as rewritten (``old`` empty for an added word)."""

    axis: str
    old: str
    new: str


@dataclass
class RewrittenBlock:
    """A block the rewriter changed.

    Attributes
    ----------
    line_in, line_out : int
        Line number in the input and in the output.
    text_in, text_out : str
    words : list of WordChange
    """

    line_in: int
    line_out: int
    text_in: str
    text_out: str
    words: list[WordChange] = field(default_factory=list)


@dataclass
class Rewrite:
    """The output text, what changed, and targets the rewriter had to leave (with why)."""

    text: str
    changed: list[RewrittenBlock]
    header_lines: int
    skipped: dict[int, str]


def decimals_for(block: Block, axis_index: int) -> int:
    """Decimals written for an axis word: 4 (mm, deg) or 5 (inch)."""
    return 5 if axis_index < 3 and block.state.inch else 4


def header_position(program: Program) -> int:
    """Index of the first line after the program's leading identity lines."""
    i = 0
    for b in program.blocks:
        if not _LEAD.match(b.text) and b.text.strip("\ufeff \t"):
            break
        i += 1
    return i


def rewrite_program(program: Program, targets: dict[int, tuple[float, ...]], *, header: list[str] | None = None,
                    pass_through: bool = False) -> Rewrite:
    """Write ``targets`` (line number → pose [mm, deg], ``program.axes`` order) into the program.

    The output is interpreted as it is written; a target that cannot be written in the block's
    mode (the output position of an axis is unknown) is left out and reported in ``skipped``.
    """
    dialect = program.dialect
    out_interp = Interpreter(dialect, program.rotary_axes, path=f"{program.path} (output)", pass_through=pass_through)
    ending = next((b.ending for b in program.blocks if b.ending), "\n")
    head_at = header_position(program) if header else -1
    pieces: list[str] = []
    changed: list[RewrittenBlock] = []
    skipped: dict[int, str] = {}
    line_out = 0
    for idx, block in enumerate(program.blocks):
        if idx == head_at:
            for h in header or []:
                line_out += 1
                text = dialect.comment(h)
                out_interp.feed(line_out, text, ending)
                pieces.append(text + ending)
        line_out += 1
        text = block.text
        target = targets.get(block.line_no)
        if target is not None:
            new = _rewrite_block(block, target, out_interp.pos, dialect.decimal_point)
            if new is None:
                skipped[block.line_no] = "an axis this block would need to program has no known output position"
            elif new[0] != text:
                text = new[0]
                changed.append(RewrittenBlock(block.line_no, line_out, block.text, text, new[1]))
        ob = out_interp.feed(line_out, text, block.ending)
        if target is not None and block.line_no not in skipped:
            _check_reached(ob, target, program.path)
        pieces.append(text + block.ending)
    if header and head_at == len(program.blocks):
        pieces.extend(dialect.comment(h) + ending for h in header)
    return Rewrite("".join(pieces), changed, len(header or []), skipped)


def _rewrite_block(block: Block, target: tuple[float, ...], out_pos: list[float | None],
                   point: bool) -> tuple[str, list[WordChange]] | None:
    """New text of one block and its word changes; None when an axis position needed is unknown."""
    edits: list[tuple[int, int, str]] = []
    added: list[str] = []
    words: list[WordChange] = []
    for i, axis in enumerate(block.axes):
        factor = block.state.unit_mm if i < 3 else 1.0
        dec = decimals_for(block, i)
        want = target[i] / factor
        prev = None if out_pos[i] is None else out_pos[i] / factor  # type: ignore[operator]
        tok = block.axis_words.get(axis)
        incremental = axis in block.incremental_axes if tok is not None else block.state.incremental
        if tok is not None:
            if incremental and prev is None:
                return None
            value = want - prev if incremental else want  # type: ignore[operator]
            digits = format_number(value, dec, point=point)
            if float(digits) != tok.value:
                edits.append((tok.value_start, tok.value_end, digits))
                rel0, rel1 = tok.value_start - tok.start, tok.value_end - tok.start
                words.append(WordChange(axis, tok.text, tok.text[:rel0] + digits + tok.text[rel1:]))
            continue
        if prev is None:
            return None
        if abs(want - prev) < 0.5 * 10.0**-dec:
            continue
        digits = format_number(want - prev if incremental else want, dec, point=point)
        added.append(f"{axis}{digits}")
        words.append(WordChange(axis, "", added[-1]))
    text = block.text
    if added:
        at = max(t.end for t in block.axis_words.values())
        edits.append((at, at, " " + " ".join(added)))
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text, words


def _check_reached(block: Block, target: tuple[float, ...], path: str) -> None:
    """The output block must reach the target to within the rounding of its words."""
    for i, (got, want) in enumerate(zip(block.after, target, strict=True)):
        tol = 0.51 * 10.0 ** -decimals_for(block, i) * (block.state.unit_mm if i < 3 else 1.0) + 1e-9
        if got is None or abs(got - want) > tol:
            raise NCProgramError(path, block.line_no, f"internal check failed: the rewritten block reaches "
                                 f"{block.axes[i]}={got} instead of {want:.6f}; nothing was written")
