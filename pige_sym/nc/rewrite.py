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
from operator import itemgetter

import numpy as np

from pige_sym.nc.interpreter import Program
from pige_sym.nc.lexer import word_spans
from pige_sym.nc.plain_blocks import plain_groups
from pige_sym.nc.program import format_number, format_numbers
from pige_sym.nc.state import MM_PER_INCH, Block

_LEAD = re.compile(r"^\ufeff?\s*(?:%|O\d+|;\s*\$PATH)", re.IGNORECASE)


@dataclass(slots=True)
class RewrittenBlock:
    """A block the rewriter changed.

    Attributes
    ----------
    line_in, line_out : int
        Line number in the input and in the output.
    text_in, text_out : str
    words : list of dict
        ``{"axis", "old", "new"}`` per changed or added word: the word as written and as rewritten
        (``old`` empty for an added word), as in the change report.
    """

    line_in: int
    line_out: int
    text_in: str
    text_out: str
    words: list[dict[str, str]] = field(default_factory=list)


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
    texts, changed, skipped = _rewrite_all(program, targets)
    pieces = list(map(str.__add__, texts, [b.ending for b in program.blocks]))
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


def _rewrite_all(program: Program, targets: dict[int, tuple[float, ...]],
                 ) -> tuple[list[str], list[RewrittenBlock], dict[int, str]]:
    """Every line's new text, the changed blocks in line order, and the targets left out (with why).

    Plain blocks that program every axis absolutely are done at once (:func:`_rewrite_plain`); the
    others one by one in order, following the output's offset from the input (:func:`rewrite_program`).
    """
    blocks = program.blocks
    index, new_texts, new_words, offsets = _rewrite_plain(program, targets)
    ready = dict(zip(index, offsets, strict=True))
    texts = [b.text for b in blocks]
    rows = [r for r, words in enumerate(new_words) if words]
    for r in rows:
        texts[index[r]] = new_texts[r]
    lines = [blocks[index[r]].line_no for r in rows]
    found = list(zip([index[r] for r in rows], map(RewrittenBlock, lines, lines, [blocks[index[r]].text for r in rows],
                                                   [new_texts[r] for r in rows], [new_words[r] for r in rows]),
                     strict=True))
    skipped: dict[int, str] = {}
    offset: list[float | None] = [0.0] * len(program.axes)  # output minus input position [mm, deg]
    for i in sorted(set(range(len(blocks))).difference(index)):
        block = blocks[i]
        if i - 1 in ready:
            offset = ready[i - 1]
        target = targets.get(block.line_no)
        if target is None:
            offset = _carry(block, offset)
            continue
        out_pos = [None if b is None or o is None else b + o for b, o in zip(block.before, offset, strict=True)]
        new = _rewrite_block(block, target, out_pos, program.dialect.decimal_point)
        if new is None:
            skipped[block.line_no] = "an axis this block would need to program has no known output position"
            continue
        if new[0] != block.text:
            texts[i] = new[0]
            found.append((i, RewrittenBlock(block.line_no, block.line_no, block.text, new[0], new[1])))
        offset = [None if a is None else w - a for w, a in zip(new[2], block.after, strict=True)]
    found.sort(key=itemgetter(0))  # (already in order but for the blocks done one by one)
    return texts, [c for _, c in found], skipped


def _rewrite_plain(program: Program, targets: dict[int, tuple[float, ...]],
                   ) -> tuple[list[int], list[str], list[list[dict[str, str]]], list[list[float | None]]]:
    """:func:`_rewrite_block` for every target block that is plain and programs every axis absolutely, at once.

    Such a block does not depend on where the output program stands before it, so all are done
    together: the line is already cut into its text and numbers (``Block.plain_``), the new numbers
    are formatted in one call (:func:`format_numbers`) and compared as floats with numpy (a number
    whose value would not change keeps its digits).  Returns the blocks' indices in ``program.blocks``
    and per block its new text, its word changes (empty: unchanged) and the offsets (output − input)
    after it [mm, deg].
    """
    axes, k = program.axes, len(program.axes)
    numbers, order = plain_groups(k)
    programs_all = itemgetter(*numbers)
    index = [i for i, b in enumerate(program.blocks) if b.plain_ is not None and b.kind == "move"
             and b.line_no in targets and not b.state.incremental]
    rows = [program.blocks[i] for i in index]
    cuts = [b.plain_.groups() for b in rows]  # type: ignore[union-attr]
    if any(None in programs_all(cut) for cut in cuts):  # keep the blocks that program every axis
        keep = [r for r, c in enumerate(cuts) if None not in programs_all(c)]
        index, rows, cuts = [index[r] for r in keep], [rows[r] for r in keep], [cuts[r] for r in keep]
    if not rows:
        return [], [], [], []
    n = len(rows)
    cols = list(zip(*cuts, strict=True))  # per group of the pattern, its text in every row
    old = [cols[j] for j in numbers]
    linear = (np.arange(k) < 3)[:, None] & np.array([b.state.inch for b in rows], dtype=bool)  # (k, n)
    factor = np.where(linear, MM_PER_INCH, 1.0)
    want = np.array([targets[b.line_no] for b in rows], dtype=float).T / factor
    flat = format_numbers(want.ravel(), np.where(linear, 5, 4).ravel(), point=program.dialect.decimal_point)
    digits = [flat[i * n:(i + 1) * n] for i in range(k)]
    after = program.after_array()[index].T
    old_value = after.copy()  # an absolute mm or degree word's value is where its axis is after the block
    for i in range(min(k, 3)):
        inch = np.flatnonzero(linear[i])
        if inch.size:  # inch: the value as written, not the mm it was converted to
            old_value[i, inch] = [float(old[i][r]) for r in inch.tolist()]
    new_value = np.array(list(map(float, flat))).reshape(k, n)
    same = old_value == new_value
    offsets = (np.where(same, old_value, new_value) * factor - after).T.tolist()
    pieces = [cols[j] for j in order]  # the line in pieces; the numbers, kept or new:
    for i, j in enumerate(numbers):
        pieces[order.index(j)] = np.where(same[i], np.array(old[i], dtype=object),
                                          np.array(digits[i], dtype=object)).tolist()
    texts = list(map("".join, zip(*pieces, strict=True)))
    letters = [cols[j - 1] for j in numbers]
    old_words = list(zip(*[list(map(str.__add__, letters[i], old[i])) for i in range(k)], strict=True))
    new_words = list(zip(*[list(map(str.__add__, letters[i], digits[i])) for i in range(k)], strict=True))
    words = [[{"axis": a, "old": o, "new": w} for a, o, w, kept in zip(axes, olds, news, row_same, strict=True)
              if not kept] for olds, news, row_same in zip(old_words, new_words, same.T.tolist(), strict=True)]
    return index, texts, words, offsets


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
                   point: bool) -> tuple[str, list[dict[str, str]], list[float]] | None:
    """New text of one block, its word changes and the pose it reaches [mm, deg] (as written, rounded).

    None when an axis position the block needs is unknown.
    """
    line = block.text
    edits: list[tuple[int, int, str]] = []
    added: list[str] = []
    words: list[dict[str, str]] = []
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
                words.append({"axis": axis, "old": line[start:end], "new": line[start:v0] + digits + line[v1:end]})
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
        words.append({"axis": axis, "old": "", "new": added[-1]})
    if added:
        at = max(span[1] for span in spans.values())
        edits.append((at, at, " " + " ".join(added)))
    for start, end, new in sorted(edits, reverse=True):
        line = line[:start] + new + line[end:]
    return line, words, reached
