"""Read-back: the written program, interpreted again from scratch, against the original.

Checks (any failure means nothing is written):

- the output has the input's lines plus the header lines, in order;
- every line the rewriter did not change is byte-identical (line ending included);
- every changed line is the input line with only its axis words' numbers changed and, perhaps, words
  appended (a space and the word each): its text with those numbers taken out (and the added words)
  is byte for byte the input's with its axis numbers taken out, so a dropped word, a changed F or N
  word, comment or space is caught;
- every block is of the same kind (no move became something else) in the same modal state
  (units, distance mode, RTCP, work offset, frame);
- at every block the output pose and the original pose are both known or both unknown, and
  differ by at most the change limit (``max_mm`` for X/Y/Z, ``max_deg`` for rotary axes),
  so an uncompensated block that inherits a compensated position (an incremental move, an
  axis not programmed) is also within it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from operator import itemgetter

import numpy as np

from pige_sym.nc.interpreter import Program, interpret
from pige_sym.nc.lexer import word_spans
from pige_sym.nc.plain_blocks import plain_groups
from pige_sym.nc.state import MM_PER_INCH, Block, ModalState


@dataclass
class Verification:
    """Result of the read-back.

    Attributes
    ----------
    ok : bool
    problems : list of str
        One line each (``line N: …``), empty when ``ok``.
    max_change_mm, max_change_deg : float
        Largest difference between output and original pose over all blocks [mm], [deg].
    """

    ok: bool
    problems: list[str] = field(default_factory=list)
    max_change_mm: float = 0.0
    max_change_deg: float = 0.0
    read_back: Program | None = None


def verify(original: Program, out_text: str, changed_lines: set[int], header_lines: int, header_at: int, *,
           max_mm: float, max_deg: float, pass_through: bool = False,
           targets: dict[int, tuple[float, ...]] | None = None) -> Verification:
    """Interpret ``out_text`` and compare it with ``original`` (module docstring).

    ``changed_lines`` are input line numbers the rewriter changed; the header occupies output
    lines ``header_at + 1 … header_at + header_lines`` (0-based insertion index ``header_at``).
    ``targets`` (input line → pose [mm, deg]) must be reached by the changed blocks to within the
    rounding of their words (half a unit of the last decimal written).
    """
    out = interpret(out_text, original.dialect, original.rotary_axes, path=f"{original.path} (read back)",
                    pass_through=pass_through)
    blocks = out.blocks[:header_at] + out.blocks[header_at + header_lines:] if header_lines else out.blocks
    if len(blocks) != len(original.blocks):
        return Verification(False, [f"the output has {len(out.blocks)} lines, expected {len(original.blocks)} + "
                                    f"{header_lines} header lines"])
    problems: list[str] = []
    changed: list[tuple[Block, Block]] = []  # the pairs of the lines the rewriter changed
    rows: list[int] = []
    for i, (a, b) in enumerate(zip(original.blocks, blocks, strict=True)):
        if a.line_no in changed_lines:
            changed.append((a, b))
            rows.append(i)
            if a.ending != b.ending:
                problems.append(f"line {a.line_no}: its line ending changed")
        elif a.text != b.text or a.ending != b.ending:
            problems.append(f"line {a.line_no}: changed although it should be byte-identical")
    problems += _skeletons([(a, b) for a, b in changed if a.text != b.text], original)
    problems += _kinds_and_states(original.blocks, blocks)
    after = out.after_array()
    if header_lines:
        after = np.delete(after, np.s_[header_at:header_at + header_lines], axis=0)
    if targets and changed:
        problems += _missed(changed, after[rows], targets)
    worst_mm, worst_deg = _compare_poses(original, after, max_mm, max_deg, problems)
    return Verification(not problems, problems, worst_mm, worst_deg, out)


def _kinds_and_states(original: list[Block], blocks: list[Block]) -> list[str]:
    """Lines that read back as another kind of block or in another modal state (:func:`_modal`)."""
    modal: dict[int, tuple] = {}
    for b in (*original, *blocks):
        if id(b.state) not in modal:
            modal[id(b.state)] = _modal(b.state)
    kinds_a, kinds_b = [b.kind for b in original], [b.kind for b in blocks]
    modal_a, modal_b = [modal[id(b.state)] for b in original], [modal[id(b.state)] for b in blocks]
    if kinds_a == kinds_b and modal_a == modal_b:
        return []
    return [f"line {a.line_no}: reads back as a different kind of block or modal state"
            for a, ka, kb, ma, mb in zip(original, kinds_a, kinds_b, modal_a, modal_b, strict=True)
            if ka != kb or ma != mb]


def _skeletons(pairs: list[tuple[Block, Block]], original: Program) -> list[str]:
    """Changed lines whose text differs from the input's anywhere but in axis numbers and added words.

    Lines that program every axis plainly (and read back plainly) are compared by the text around
    their numbers (:func:`pige_sym.nc.plain_blocks.plain_groups`); the others word by word.
    """
    if not pairs:
        return []
    numbers, order = plain_groups(len(original.axes))
    text_only = itemgetter(*[j for j in order if j not in numbers])  # every piece but the numbers
    all_axes = itemgetter(*numbers)
    sk_a: list[tuple | None] = [None] * len(pairs)
    sk_b = list(sk_a)
    for r, (a, b) in enumerate(pairs):
        if a.plain_ is not None and b.plain_ is not None:
            cut_a = a.plain_.groups()
            if None not in all_axes(cut_a):
                sk_a[r], sk_b[r] = text_only(cut_a), text_only(b.plain_.groups())
    problems = []
    for (a, b), x, y in zip(pairs, sk_a, sk_b, strict=True):
        if x is not None and y is not None:
            same = x == y
        else:
            wa, wb = _word_skeleton(a, set()), _word_skeleton(b, set(b.axis_words) - set(a.axis_words))
            same = wa is not None and wa == wb
        if not same:
            problems.append(f"line {a.line_no}: the rewritten line differs from the input in more than its axis "
                            "numbers (a word dropped or another character changed)")
    return problems


def _word_skeleton(block: Block, added: set[str]) -> str | None:
    """The line with its axis numbers replaced by ``#`` and the ``added`` words (with the space before) cut out."""
    line = block.text
    try:
        spans = word_spans(line, block.axis_words)
    except ValueError:
        return None
    pieces, at = [], 0
    for axis, (start, end, v0, v1) in sorted(spans.items(), key=lambda kv: kv[1][0]):
        if axis in added:
            if line[start - 1:start] != " ":
                return None
            pieces.append(line[at:start - 1])
        else:
            pieces += (line[at:v0], "#")
        at = v1 if axis not in added else end
    pieces.append(line[at:])
    return "".join(pieces)


def _compare_poses(original: Program, b: np.ndarray, max_mm: float, max_deg: float,
                   problems: list[str]) -> tuple[float, float]:
    """Poses known in both or neither, and within the limits; returns the largest changes [mm], [deg].

    ``b`` (n, k): the read-back's position after each of the original's blocks [mm, deg].
    """
    a = original.after_array()
    known = ~np.isnan(a)
    for i, j in zip(*np.nonzero(known != ~np.isnan(b)), strict=True):
        problems.append(f"line {original.blocks[i].line_no}: {original.axes[j]} is "
                        f"{'un' if np.isnan(b[i, j]) else ''}known after the rewrite")
    diff = np.where(known & ~np.isnan(b), np.abs(a - b), 0.0)
    limit = np.array([max_mm] * 3 + [max_deg] * (a.shape[1] - 3))
    for i, j in zip(*np.nonzero(diff > limit), strict=True):
        unit = "mm" if j < 3 else "deg"
        problems.append(f"line {original.blocks[i].line_no}: {original.axes[j]} moved by {diff[i, j]:.4f} {unit} "
                        f"(limit {limit[j]:g} {unit})")
    return float(diff[:, :3].max(initial=0.0)), float(diff[:, 3:].max(initial=0.0))


def _missed(pairs: list[tuple[Block, Block]], got: np.ndarray, targets: dict[int, tuple[float, ...]]) -> list[str]:
    """Changed blocks (input, read back) that do not reach their target to within the rounding of their words.

    ``got`` (len(pairs), k): where the read-back blocks end [mm, deg].
    """
    if not pairs:
        return []
    want = np.array([targets[a.line_no] for a, _ in pairs], dtype=float).reshape(got.shape)
    inch = np.array([b.state.inch for _, b in pairs], dtype=bool)[:, None] & (np.arange(got.shape[1]) < 3)
    tol = np.where(inch, 0.51e-5 * MM_PER_INCH, 0.51e-4) + 1e-9
    bad = np.isnan(got) | ~(np.abs(got - want) <= tol)
    out = []
    for r, i in zip(*np.nonzero(bad), strict=True):
        a, b = pairs[r]
        out.append(f"line {a.line_no}: the rewritten block reaches {b.axes[i]}={b.after[i]} instead of "
                   f"{want[r, i]:.6f}")
    return out


def _modal(st: ModalState) -> tuple:
    """What must read back the same: distance mode, units, RTCP, work offset, frame, motion mode."""
    return (st.incremental, st.inch, st.rtcp, st.offset, bool(st.frame), st.motion)
