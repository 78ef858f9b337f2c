"""Plain NC blocks, read fast: the run of CAM-post lines ``[N…] [G0|G1] [axis words] [F…] [; comment]``.

Most of a CAM program is *plain* blocks.  :func:`plain_pattern` is the regex of one (its groups cut
the line into pieces that, joined, are the line: :func:`plain_groups`); :class:`PlainBlocks` is the
part of :class:`~pige_sym.nc.interpreter.Interpreter` that reads a run of them in one batch
(positions by :func:`track_positions`, NumPy) and the per-line fast path for simple word blocks.  Both
give exactly the blocks the full path gives (``tests/test_nc_fastpath.py`` and the property tests
compare them); a line the full path would refuse is left to it, so that it gets its message.
"""

from __future__ import annotations

import re
import sys
from dataclasses import replace
from itertools import chain, repeat
from typing import TYPE_CHECKING, Any

import numpy as np

from pige_sym.nc.dialects import Dialect
from pige_sym.nc.lexer import Token
from pige_sym.nc.state import Block, ModalState

MAX_ABS_VALUE = 1e5  # mm or deg: larger axis values are refused as absurd
_NUM = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)"
SIMPLE_SIEMENS = re.compile(rf"(?P<words>(?:[ \t]*[A-Za-z][ \t]*{_NUM}(?=[ \t;]|$))*)[ \t]*(?:;.*)?")
SIMPLE_ISO = re.compile(rf"(?P<words>(?:[ \t]*[A-Za-z][ \t]*{_NUM}(?![eE.\d]))*)[ \t]*(?:\([^()]*\)[ \t]*)?")
_SIMPLE_WORD = re.compile(rf"([A-Za-z])[ \t]*({_NUM})")
_new_token = tuple.__new__
_SIMPLE_EFFECTS: dict[str, object] = {
    "motion:G0": {"motion": "G0"}, "motion:G1": {"motion": "G1"}, "motion:G2": {"motion": "G2"},
    "motion:G3": {"motion": "G3"}, "dist:abs": {"incremental": False}, "dist:inc": {"incremental": True},
    "units:mm": {"inch": False, "units_programmed": True}, "units:inch": {"inch": True, "units_programmed": True},
    "feed:G93": {"feed": "G93"}, "feed:G94": {"feed": "G94"}, "feed:G95": {"feed": "G95"},
    "plane:G17": {"plane": "G17"}, "plane:G18": {"plane": "G18"}, "plane:G19": {"plane": "G19"}, "benign": {},
    "end": "end", "rtcp:on": {"rtcp": True, "rtcp_programmed": True},
    "rtcp:off": {"rtcp": False, "rtcp_programmed": True}, "stop": "stop",
    "comp:on": {"cutter_comp": True}, "comp:off": {"cutter_comp": False}, "cycle:cancel": {"cycle": False},
}


def plain_pattern(axes: tuple[str, ...], dialect: Dialect) -> re.Pattern[str] | None:
    """The regex of a *plain* block: ``[N…] [G0|G1] [axis words in machine order] [F…] [; comment]``.

    Every word must end at a boundary at least as strict as the lexer's (840D: a space, ``;`` or the
    end of the line; ISO: no exponent, point or digit).  The groups cut the line into pieces that,
    joined, are the line (:func:`plain_groups` tells which is which): the head (``N…``, ``G…``; it
    holds group 2, the motion code's digits), then per axis the spaces before it, its letter (with the
    spaces after it) and its number (None when the block does not program it), then the rest.
    None when the dialect gives G0/G1 another meaning (``--rtcp-on G1``) or an axis name is not one letter.
    """
    if dialect.action("G0") != "motion:G0" or dialect.action("G1") != "motion:G1" or \
            not all(len(a) == 1 and "A" <= a <= "Z" for a in axes):
        return None
    end = r"(?=[ \t;]|$)" if dialect.siemens else r"(?![eE.\d])"
    num, sp = _NUM, r"[ \t]*"
    if sys.version_info >= (3, 11):  # the same matches without backtracking: a number can only end where it does
        num, sp = r"[-+]?+(?>\d++(?:\.\d*+)?+|\.\d++)", r"[ \t]*+"

    def letter(a: str) -> str:
        return f"[{a}{a.lower()}]"

    head = rf"({sp}(?:{letter('N')}{sp}{num}{end})?(?:{sp}{letter('G')}{sp}(0*[01]){end})?)"
    words = "".join(rf"(?:({sp})({letter(a)}{sp})({num}){end})?" for a in axes)
    return re.compile(head + words + rf"((?:{sp}{letter('F')}{sp}{num}{end})?{sp}(?:;.*)?)")


def plain_groups(k: int) -> tuple[list[int], list[int]]:
    """Indices in ``match.groups()`` of a plain block with ``k`` axes: its numbers, and all pieces in line order.

    The pieces (head, then per axis the spaces before it, its letter and its number, then the rest)
    joined are the line; the number of axis ``i`` is piece ``3i + 3``, its letter piece ``3i + 2``.
    """
    return [3 * i + 4 for i in range(k)], [0, *range(2, 3 * k + 3)]


def track_positions(values: np.ndarray, present: np.ndarray, start: np.ndarray, incremental: bool) -> np.ndarray:
    """Positions after each block of a plain run, shape=(n, k) [mm, deg] (NaN: unknown).

    ``values`` (n, k) are the words in mm/deg (NaN where ``present`` is False), ``start`` (k,) the
    position before the run.  Absolute words set their axis; incremental words add, in order (the
    same floating-point sums as block by block: ``np.add.accumulate`` adds left to right).
    """
    n, k = values.shape
    if not incremental:
        last = np.maximum.accumulate(np.where(present, np.arange(n)[:, None], -1), axis=0)
        taken = np.take_along_axis(values, np.maximum(last, 0), axis=0)
        return np.where(last >= 0, taken, start)
    out = np.empty((n, k))
    for j in range(k):
        acc = np.add.accumulate(np.concatenate(([start[j]], values[present[:, j], j])))
        out[:, j] = acc[np.cumsum(present[:, j])]
    return out


class PlainBlocks:
    """Batch and per-line fast paths of the interpreter (mixed into :class:`~pige_sym.nc.interpreter.Interpreter`).

    The attributes and methods below are the interpreter's; they are declared here for the type checker.
    """

    dialect: Dialect
    axes: tuple[str, ...]
    pos: list[float | None]
    state: ModalState
    _axis_set: frozenset[str]
    _simple_rx: re.Pattern[str]
    _simple_codes: dict[str, object]
    _plain_numbers: Any

    if TYPE_CHECKING:
        def _set_state(self, changes: dict[str, object]) -> None: ...

        def _move(self, block: Block, others: Any, axis_words: dict[str, Token]) -> None: ...

    def _plain_run(self, first: int, texts: list[str], endings: list[str],
                   matches: list[re.Match[str]]) -> list[Block]:
        """Blocks of consecutive plain lines, read at once (motion G0/G1, no cycle: :meth:`run`).

        Stops before a line whose value the full path would refuse (absurd, or an ISO integer), so that
        line gets the full path and its message.
        """
        k = len(self.axes)
        groups = list(map(self._plain_numbers, map(re.Match.groups, matches, repeat("nan", len(matches)))))
        table = np.array(list(map(float, chain.from_iterable(groups))), dtype=float).reshape(-1, k + 1)
        values = table[:, 1:]
        bad = np.abs(values) > MAX_ABS_VALUE
        if self.dialect.decimal_point:
            bad |= np.array([[v != "nan" and "." not in v for v in g[1:]] for g in groups], dtype=bool) & (values != 0)
        rows = int(np.argmax(bad.any(axis=1))) if bad.any() else len(texts)
        if rows == 0:
            return []
        values, motion = values[:rows], table[:rows, 0]
        values[:, :3] *= self.state.unit_mm
        present = ~np.isnan(values)
        start = np.array([np.nan if p is None else p for p in self.pos], dtype=float)
        after = track_positions(values, present, start, self.state.incremental)
        states = self._motion_states(motion)
        return self._batch_blocks(first, texts[:rows], endings[:rows], states, present, after, matches[:rows])

    def _motion_states(self, motion: np.ndarray) -> list[ModalState]:
        """The modal state of each plain block (after its own G0/G1: ``motion`` 0, 1 or NaN); sets the last."""
        st = self.state
        by_code = {0.0: st if st.motion == "G0" else replace(st, motion="G0"),
                   1.0: st if st.motion == "G1" else replace(st, motion="G1")}
        states = []
        current = st
        for g in motion.tolist():
            if g == g:
                current = by_code[g]
            states.append(current)
        self.state = current
        return states

    def _batch_blocks(self, first: int, texts: list[str], endings: list[str], states: list[ModalState],
                      present: np.ndarray, after: np.ndarray, matches: list[re.Match[str]]) -> list[Block]:
        """The blocks of a plain run, with the reasons :meth:`_why_not` gives, and the position after it."""
        n, k = present.shape
        st = states[0]  # the run changes only the motion mode
        inc = st.incremental
        moves = np.asarray(present.any(axis=1), dtype=bool)
        unknown = np.isnan(after)
        rows_after = after.tolist()
        for r in np.flatnonzero(unknown.any(axis=1)).tolist():
            rows_after[r] = [None if u else x for x, u in zip(rows_after[r], unknown[r].tolist(), strict=True)]
        after_t = list(map(tuple, rows_after))
        before_t = [tuple(self.pos), *after_t[:-1]]
        cause = st.lost or st.locked or st.frame or ("cutter radius compensation active" if st.cutter_comp else "")
        reasons = [""] * n
        if cause:
            reasons = [cause if m else "" for m in moves.tolist()]
        else:
            before_unknown = np.concatenate(([None in before_t[0]], unknown[:-1].any(axis=1)))
            partial = np.full(n, inc) | (present.sum(axis=1) != k)
            for r in np.flatnonzero(moves & (unknown.any(axis=1) | (before_unknown & partial))).tolist():
                missing = [a for a, v in zip(self.axes, after_t[r], strict=True) if v is None]
                reasons[r] = (f"pose not known ({', '.join(missing)} not programmed yet)" if missing
                              else "pose before the block not known")
        kinds = ["move" if m else "" for m in moves.tolist()]
        incs: list[frozenset[str]] = [frozenset()] * n
        if inc:
            incs = [frozenset(a for a, p in zip(self.axes, row, strict=True) if p) for row in present.tolist()]
        self.pos = list(after_t[-1])
        return list(map(Block, range(first, first + n), texts, endings, [[] for _ in range(n)], states, before_t,
                        after_t, repeat(self.axes), repeat(None), matches, incs, kinds, reasons))

    def _simple(self, line_no: int, lex_text: str, text: str, ending: str,
                before: tuple[float | None, ...]) -> Block | None:
        """Fast path for the commonest block: plain words and a trailing comment, nothing to refuse.

        Gives the same result as the full path (the property tests exercise both); returns None
        (use the full path) for anything else.  ``Block.tokens`` then holds only the axis words.
        """
        m = self._simple_rx.fullmatch(lex_text)
        if m is None:
            return None
        changes: dict[str, object] = {}
        stop = False
        axis_words: dict[str, Token] = {}
        cache = self._simple_codes
        for letter, num in _SIMPLE_WORD.findall(lex_text, 0, m.end("words")):
            letter = letter.upper()
            if letter in "GM":
                key = letter + num
                effect = cache.get(key)
                if effect is None:
                    code = Token("word", key, 0, len(key), letter, float(num), 1, len(key)).code
                    effect = _SIMPLE_EFFECTS.get(self.dialect.action(code) or "")
                    if effect is None:
                        return None
                    cache[key] = effect
                if effect == "stop":
                    stop = True
                elif effect == "end":
                    changes["lost"] = f"after the end of the program at line {line_no}"
                else:
                    changes.update(effect)  # type: ignore[call-overload]
            elif letter in self._axis_set:
                value = float(num)
                if letter in axis_words or abs(value) > MAX_ABS_VALUE or \
                        (self.dialect.decimal_point and value != 0 and "." not in num):
                    return None  # the full path refuses it, with the word as written
                # offsets -1: where the digits are is found again only if the block is rewritten
                axis_words[letter] = _new_token(Token, ("word", letter + num, -1, -1, letter, value, -1, -1, ""))
            elif letter not in "NFSTDH":
                return None
        if changes:
            self._set_state(changes)
        block = Block(line_no, text, ending, list(axis_words.values()), self.state, before, before, self.axes)
        block.stop = stop
        if axis_words:
            block.axis_words = axis_words
            self._move(block, (), axis_words)
        return block
