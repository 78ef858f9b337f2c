"""Rewriting: new poses into the blocks that need them, every other byte kept.

Rules (each one is checked again by :mod:`pige_sym.nc.verify` on the written text):

- only blocks given a target pose change, and only the *digits* of their axis words
  (``X  16.339`` keeps its spaces, ``X=IC(5)`` its form, ``/``, ``N`` numbers, comments,
  every other word and the line ending stay as they were);
- a word keeps the block's mode: an incremental word (G91, ``=IC()``) gets the increment
  from the position the *output* program has reached , an absolute word the absolute value; an
  inch block gets inches (5 decimals), a mm block mm (4 decimals), rotary axes degrees
  (4 decimals); ISO/Fanuc values always carry a decimal point;
- the output position is followed as an offset from the input position (:func:`rewrite_program`);
- a word whose value would not change is left byte-identical;
- an axis the block does not program is appended (after the block's last axis word, in the
  block's mode) only when its target differs from where the output program already has it;
- a header (comment lines) goes after the leading ``%``/``%_N_…``/``O…``/``;$PATH`` lines, never
  before them nor between a byte-order mark and the program name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from pige_sym.nc.interpreter import Program
from pige_sym.nc.lexer import word_spans
from pige_sym.nc.program import format_number, format_numbers
from pige_sym.nc.state import MM_PER_INCH, Block

_LEAD = re.compile(r"^\ufeff?\s*(?:%|O\d+|;\s*\$PATH)", re.IGNORECASE)


@dataclass(slots=True)
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


def header_position(program: Program) -> int:
    """Index of the first line after the program's leading identity lines."""
    i = 0
    for b in program.blocks:
        if not _LEAD.match(b.text) and b.text.strip("\ufeff \t"):
            break
        i += 1
    return i


def rewrite_program(program: Program, targets: dict[int, tuple[float, ...]], *,
                    header: list[str] | None = None) -> Rewrite:
    """Write ``targets`` (line number → pose [mm, deg], ``program.axes`` order) into the program.

    The position the *output* reaches is followed as an offset from the input's: an absolute
    word resets its axis' offset to what was written, every other axis keeps its offset (an
    incremental word moves both programs by the same amount).  The read-back
    (:mod:`pige_sym.nc.verify`) then checks this against a full interpretation of the output.
    A target that cannot be written (an axis' output position unknown) is left out and reported
    in ``skipped``.  The header goes in only when a block changed.
    """
    dialect = program.dialect
    ending = next((b.ending for b in program.blocks if b.ending), "\n")
    n = len(program.axes)
    offset: list[float | None] = [0.0] * n  # output minus input position [mm, deg]
    pieces: list[str] = []
    changed: list[RewrittenBlock] = []
    skipped: dict[int, str] = {}
    ready = _rewrite_plain(program, targets, dialect.decimal_point)
    for block in program.blocks:
        text = block.text
        target = targets.get(block.line_no)
        done = ready.get(block.line_no) if target is not None else None
        if done is not None:
            if done[0] != text:
                text = done[0]
                changed.append(RewrittenBlock(block.line_no, block.line_no, block.text, text, done[1]))
            offset = done[2]
        elif target is not None:
            out_pos = [None if b is None or o is None else b + o for b, o in zip(block.before, offset, strict=True)]
            new = _rewrite_block(block, target, out_pos, dialect.decimal_point)
            if new is None:
                skipped[block.line_no] = "an axis this block would need to program has no known output position"
            else:
                if new[0] != text:
                    text = new[0]
                    changed.append(RewrittenBlock(block.line_no, block.line_no, block.text, text, new[1]))
                offset = [None if a is None else w - a for w, a in zip(new[2], block.after, strict=True)]
        else:
            offset = _carry(block, offset)
        pieces.append(text + block.ending)
    n_head = 0
    if header and changed:
        at = header_position(program)
        lines = [dialect.comment(h) + ending for h in header]
        if at == len(pieces) and pieces and not pieces[-1].endswith(("\n", "\r")):
            pieces[-1] += ending
        pieces[at:at] = lines
        n_head = len(lines)
        for c in changed:
            c.line_out = c.line_in + n_head if c.line_in > at else c.line_in
    return Rewrite("".join(pieces), changed, n_head, skipped)


def _rewrite_plain(program: Program, targets: dict[int, tuple[float, ...]],
                   point: bool) -> dict[int, tuple[str, list[WordChange], list[float | None]]]:
    """:func:`_rewrite_block` for every target block that is plain and programs every axis absolutely, at once.

    Such a block does not depend on where the output program stands before it, so all are done
    together: numbers formatted in one call (:func:`format_numbers`), compared as floats with numpy.
    Returns per line the new text, its word changes and the offsets (output − input) after it.
    """
    axes = program.axes
    k = len(axes)
    rows = [b for b in program.blocks if b.plain_ is not None and b.line_no in targets and not b.state.incremental
            and b.kind == "move"]
    if not rows:
        return {}
    found = list(map(re.Pattern.fullmatch, [b.plain_ for b in rows], [b.text for b in rows]))  # type: ignore[misc]
    groups = list(map(re.Match.groups, found))  # type: ignore[arg-type]
    keep = [r for r, g in enumerate(groups) if None not in g[2::2]]
    if not keep:
        return {}
    rows, found, groups = [rows[r] for r in keep], [found[r] for r in keep], [groups[r] for r in keep]
    inch = np.array([b.state.inch for b in rows], dtype=bool)
    factor = np.where(inch[:, None] & (np.arange(k) < 3), MM_PER_INCH, 1.0)
    decimals = np.where(inch[:, None] & (np.arange(k) < 3), 5, 4)
    want = np.array([targets[b.line_no] for b in rows], dtype=float) / factor
    digits = format_numbers(want.ravel(), decimals.ravel(), point=point)
    old = np.array(list(map(float, [v for g in groups for v in g[2::2]])))
    new = np.array(list(map(float, digits)))
    same = new == old
    written = np.where(same, old, new).reshape(-1, k)
    offsets = (written * factor - np.array([b.after for b in rows], dtype=float)).tolist()
    out = {}
    same_rows = same.reshape(-1, k).tolist()
    for r, (b, m) in enumerate(zip(rows, found, strict=True)):
        row_same = same_rows[r]
        if all(row_same):
            out[b.line_no] = (b.text, [], offsets[r])
            continue
        out[b.line_no] = (*_splice(b, m, [None if s else digits[r * k + i] for i, s in enumerate(row_same)]),
                          offsets[r])
    return out


def _splice(block: Block, m: re.Match[str], new_digits: list[str | None]) -> tuple[str, list[WordChange]]:
    """The plain block's text (matched as ``m``) with axis ``i``'s digits replaced by ``new_digits[i]`` (None: kept)."""
    line = block.text
    regs = m.regs
    pieces = []
    words = []
    at = 0
    for i, digits in enumerate(new_digits):
        if digits is None:
            continue
        (start, end), (v0, v1) = regs[2 * i + 2], regs[2 * i + 3]
        pieces += (line[at:v0], digits)
        at = v1
        words.append(WordChange(block.axes[i], line[start:end], line[start:v0] + digits + line[v1:end]))
    pieces.append(line[at:])
    return "".join(pieces), words


def _carry(block: Block, offset: list[float | None]) -> list[float | None]:
    """Offsets after an unchanged block: an absolute word of the block re-synchronises its axis."""
    if not block.kind:
        return offset
    out = list(offset)
    for i, axis in enumerate(block.axes):
        if block.after[i] is None:
            out[i] = None
        elif axis in block.axis_words and axis not in block.incremental_axes:
            out[i] = 0.0
        elif block.before[i] is None:
            out[i] = None
    return out


def _rewrite_block(block: Block, target: tuple[float, ...], out_pos: list[float | None],
                   point: bool) -> tuple[str, list[WordChange], list[float]] | None:
    """New text of one block, its word changes and the pose it reaches [mm, deg] (as written, rounded).

    None when an axis position the block needs is unknown.
    """
    line = block.text
    edits: list[tuple[int, int, str]] = []
    added: list[str] = []
    words: list[WordChange] = []
    reached: list[float] = []
    spans = word_spans(line, block.axis_words)
    unit = block.state.unit_mm
    for i, axis in enumerate(block.axes):
        factor = unit if i < 3 else 1.0
        dec = 5 if i < 3 and block.state.inch else 4
        want = target[i] / factor
        prev = None if out_pos[i] is None else out_pos[i] / factor  # type: ignore[operator]
        tok = block.axis_words.get(axis)
        if tok is not None:
            incremental = axis in block.incremental_axes
            if incremental and prev is None:
                return None
            digits = format_number(want - prev if incremental else want, dec, point=point)  # type: ignore[operator]
            written = float(digits)
            if written == tok.value:
                written = tok.value
            else:
                start, end, v0, v1 = spans[axis]
                edits.append((v0, v1, digits))
                words.append(WordChange(axis, line[start:end], line[start:v0] + digits + line[v1:end]))
            reached.append(((prev or 0.0) + written if incremental else written) * factor)
            continue
        if prev is None:
            return None
        if abs(want - prev) < 0.5 * 10.0**-dec:
            reached.append(prev * factor)
            continue
        incremental = block.state.incremental
        digits = format_number(want - prev if incremental else want, dec, point=point)
        reached.append((prev + float(digits) if incremental else float(digits)) * factor)
        added.append(f"{axis}{digits}")
        words.append(WordChange(axis, "", added[-1]))
    if added:
        at = max(span[1] for span in spans.values())
        edits.append((at, at, " " + " ".join(added)))
    for start, end, new in sorted(edits, reverse=True):
        line = line[:start] + new + line[end:]
    return line, words, reached
