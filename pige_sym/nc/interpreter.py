"""The modal NC interpreter: every block of a program, with the pose before and after it.

One pass over the lines (:class:`Interpreter` can also be fed line by line).  Runs of *plain*
blocks (``[N…] [G0|G1] [axis words in machine order] [F…] [; comment]``, :func:`plain_pattern`,
what CAM posts write) are read in one batch with the same result as block by block
(``tests/test_nc_fastpath.py`` compares them on random plain and near-plain blocks); anything
else is read block by block.  Per block, in this order:

1. ``%…`` lines (``%``, ``%_N_NAME_MPF``) and blank lines are kept as they are;
2. a leading ``/`` (block skip) is noted: a skippable block is never changed, the axes it
   programs become unknown (they stand at one of two places), and if it changes a modal code
   the state is lost;
3. the line is lexed (:mod:`pige_sym.nc.lexer`; comments, strings and labels are never words);
4. every G/M code and keyword is looked up in the dialect (:mod:`pige_sym.nc.dialects`);
   unknown G codes, calls, control flow, variables and expressions are refused with the
   line — or, with ``pass_through``, the block is kept and what it may change becomes unknown
   (after a call or a jump: everything);
5. modal codes are applied (distance mode, units, motion mode, RTCP, work offset, frames,
   cutter compensation, canned cycles);
6. the axis words move the position: absolute or incremental (G91, ``=IC()``) in the block's
   units; an arc's end point is tracked like a line's; reference (G28/G74), machine-coordinate
   (G53/SUPA), probing/spline/thread moves and cycle blocks make their axes unknown.

A linear move (G0/G1) is *compensable* when no frame, cutter compensation, cycle or
unknown state is active, the block is not skippable, and the full pose after it is known
and either the pose before is known or the block programs every axis absolutely.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field, replace
from operator import itemgetter
from typing import NoReturn

import numpy as np

from pige_sym.errors import NCProgramError
from pige_sym.nc.dialects import Dialect
from pige_sym.nc.lexer import LexError, Token, tokenize
from pige_sym.nc.plain_blocks import (
    MAX_ABS_VALUE,
    SIMPLE_ISO,
    SIMPLE_SIEMENS,
    PlainBlocks,
    plain_groups,
    plain_pattern,
)
from pige_sym.nc.state import Block, ModalState

_SKIP = re.compile(r"\s*/\d?")
_ISO_FLOW = re.compile(r"IF|GOTO|WHILE|DO\s*\d|END\s*\d|THEN", re.IGNORECASE)
_ARC_NAMES = {"CR", "AR", "I", "J", "K", "I1", "J1", "K1", "TURN", "CT"}
_LINEAR = {"G0", "G1", ""}
_LINES = re.compile(r"[^\r\n]*(?:\r\n|\n|\r)?")
_LINE_PARTS = re.compile(r"([^\r\n]*)(\r\n|\n|\r|)")


@dataclass
class Program:
    """An interpreted program: every line, in order.

    Attributes
    ----------
    path : str
    blocks : list of Block
    dialect : Dialect
    axes : tuple of str
        X, Y, Z and the rotary axes.
    notes : list of str
        Assumptions the interpreter made (default units, unknown M codes …).
    """

    path: str
    blocks: list[Block]
    dialect: Dialect
    axes: tuple[str, ...]
    notes: list[str] = field(default_factory=list)
    after_: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def after_array(self) -> np.ndarray:
        """Position after every block, shape=(len(blocks), len(axes)) [mm, deg], NaN where unknown.

        Made once (the blocks of an interpreted program do not change).
        """
        if self.after_ is None:
            after = np.array([b.after for b in self.blocks], dtype=float)
            self.after_ = after.reshape(len(self.blocks), len(self.axes))
        return self.after_

    @property
    def rotary_axes(self) -> tuple[str, ...]:
        return self.axes[3:]

    def text(self) -> str:
        """The program text, byte for byte as read."""
        return "".join(b.text + b.ending for b in self.blocks)


class Interpreter(PlainBlocks):
    """Tracks the modal state and positions through the blocks fed to it.

    Parameters
    ----------
    dialect : Dialect
    rotary_axes : tuple of str
        The machine's rotary axis letters.
    path : str
        File name for messages.
    pass_through : bool
        Keep refused blocks (calls, control flow, expressions) instead of raising.
    fast : bool
        Use the fast paths for plain blocks: batches (:meth:`run`) and the per-line one (same results; off
        only to test that).
    """

    def __init__(self, dialect: Dialect, rotary_axes: tuple[str, ...], *, path: str = "<program>",
                 pass_through: bool = False, fast: bool = True) -> None:
        self.dialect = dialect
        self.axes = ("X", "Y", "Z", *rotary_axes)
        self.path = path
        self.pass_through = pass_through
        self.state = ModalState()
        self.pos: list[float | None] = [None] * len(self.axes)
        self._axis_set = frozenset(self.axes)
        self._axis_index = {a: i for i, a in enumerate(self.axes)}
        self._fast = fast
        self._simple_rx = SIMPLE_SIEMENS if dialect.siemens else SIMPLE_ISO
        self._simple_codes: dict[str, object] = {}
        self._plain_rx = plain_pattern(self.axes, dialect) if fast else None
        self._plain_numbers = itemgetter(1, *plain_groups(len(self.axes))[0])

    # -- public -------------------------------------------------------------------------
    def feed(self, line_no: int, text: str, ending: str) -> Block:
        """Interpret one line (without its ending) and return its block."""
        before = tuple(self.pos)
        lex_text = text.replace("\ufeff", " ") if line_no == 1 else text
        skip_m = _SKIP.match(lex_text) if "/" in lex_text else None
        skip = bool(skip_m)
        if skip and skip_m is not None:
            lex_text = " " * skip_m.end() + lex_text[skip_m.end():]
        stripped = lex_text.strip()
        if not stripped or stripped.startswith("%"):
            return Block(line_no, text, ending, [], self.state, before, before, self.axes)
        if self._fast and not skip:
            simple = self._simple(line_no, lex_text, text, ending, before)
            if simple is not None:
                return simple
        try:
            tokens = tokenize(lex_text, siemens=self.dialect.siemens)
        except LexError as exc:
            raise self._error(line_no, f"column {exc.column + 1}: {exc.problem}") from None
        block = Block(line_no, text, ending, tokens, self.state, before, before, self.axes, skip=skip)
        if skip:
            self._skippable(block)
        else:
            self._interpret(block)
        return block

    def run(self, lines: Iterable[str], first_line: int = 1) -> list[Block]:
        """Interpret lines that keep their endings (``str.splitlines(keepends=True)``).

        Runs of plain blocks (:func:`plain_pattern`) in a linear motion mode are read in one batch
        (:meth:`_plain_run`: same blocks as line by line, which the property tests check).
        """
        raws = list(lines)
        texts = [raw.rstrip("\r\n") for raw in raws]
        return self.run_parts(texts, [raw[len(t):] for raw, t in zip(raws, texts, strict=True)], first_line)

    def run_parts(self, texts: list[str], endings: list[str], first_line: int = 1) -> list[Block]:
        """:meth:`run` on lines given as their texts and their endings (:func:`split_parts`)."""
        n = len(texts)
        matches = list(map(self._plain_rx.fullmatch, texts)) if self._plain_rx is not None else [None] * n
        out: list[Block] = []
        i = 0
        while i < n:
            if matches[i] is not None and not self.state.cycle and self.state.motion in _LINEAR:
                j = i + 1
                while j < n and matches[j] is not None:
                    j += 1
                done = self._plain_run(first_line + i, texts[i:j], endings[i:j], matches[i:j])  # type: ignore[arg-type]
                out += done
                i += len(done)
                if done:
                    continue
            out.append(self.feed(first_line + i, texts[i], endings[i]))
            i += 1
        return out


    def _skippable(self, block: Block) -> None:
        state0 = self.state
        self._interpret(block)
        changed_state = self.state != state0
        # an axis the block programs is at one of two places depending on the switch: unknown
        self.pos = [None if axis in block.axis_words or p is None else p
                    for axis, p in zip(self.axes, self.pos, strict=True)]
        if changed_state:
            self.state = replace(state0, lost=f"the block-skip block at line {block.line_no} changes the modal "
                                 "state depending on the skip switch")
        block.after = tuple(self.pos)
        if block.kind == "move":
            block.reason = "block skip /: the block may or may not run"

    def _interpret(self, block: Block) -> None:
        codes, words, refusals = self._classify(block)
        if refusals:
            self._refused(block, refusals, words)
            return
        actions = [a for a, _ in codes]
        self._apply_modal(block, codes)
        block.state = self.state
        block.stop = "stop" in actions
        if "dwell" in actions:
            self._dwell(block, words)
            return
        axis_words = {k: t for k, t in words.items() if k in self.axes}
        if not axis_words or any(a.startswith("frame") for a in actions):
            return  # TRANS X10, G92 X0, G10 L2 X..: frame data, not a move
        block.axis_words = axis_words
        self._move(block, actions, axis_words)

    def _classify(self, block: Block) -> tuple[list[tuple[str, Token]], dict[str, Token], list[tuple[str, Token]]]:
        """Split the tokens into codes with their action, address words, and refusals."""
        codes: list[tuple[str, Token]] = []
        words: dict[str, Token] = {}
        refusals: list[tuple[str, Token]] = []
        if not self.dialect.siemens and any(t.kind == "other" for t in block.tokens):
            code_text = "".join(t.text if t.kind != "comment" else " " for t in block.tokens)
            flow = _ISO_FLOW.search(code_text)
            if flow:
                refusals.append(("control flow", Token("other", flow.group(), 0, 0, flow.group().upper())))
        siemens = self.dialect.siemens
        for i, tok in enumerate(block.tokens):
            kind = tok.kind
            if kind in ("comment", "string"):
                continue
            if kind == "word" and tok.key in "GM":
                self._code(tok.code, tok, codes, refusals)
            elif kind == "word":
                self._address(tok, words, refusals)
            elif kind == "assign":
                self._assignment(tok, block.tokens[i + 1:i + 2], words, refusals)
            elif kind == "call":
                key = tok.key
                action = self.dialect.action(key)
                if key == "CYCLE800" and re.fullmatch(r"CYCLE800\s*\(\s*\)", tok.text, re.IGNORECASE):
                    action = "frame:cancel"
                if action is None:
                    refusals.append(("a call of a subprogram or cycle", tok))
                else:
                    codes.append((action, tok))
            elif kind == "name" and siemens:
                if tok.key.endswith(":") and i == 0:
                    continue  # label
                self._code(tok.key.rstrip(":"), tok, codes, refusals)
            else:
                refusals.append(("a variable or expression", tok))
        return codes, words, refusals

    def _code(self, code: str, tok: Token, codes: list[tuple[str, Token]],
              refusals: list[tuple[str, Token]]) -> None:
        action = self.dialect.action(code)
        if action is None and code.startswith("M"):
            refusals.append((f"unknown code {code} (if it switches RTCP declare it with --rtcp-on/--rtcp-off; "
                             "the tool never guesses what a code does)", tok))
        elif action is None:
            refusals.append((f"unknown code {code} (the tool never guesses what a code does)", tok))
        elif action.startswith("refuse:"):
            refusals.append((action.split(":", 1)[1], tok))
        else:
            codes.append((action, tok))

    def _address(self, tok: Token, words: dict[str, Token], refusals: list[tuple[str, Token]]) -> None:
        key = tok.key
        if key == "N":
            return
        if key == "O":
            if self.dialect.name == "linuxcnc":
                refusals.append(("an O-code (subroutine, loop or conditional)", tok))
            return
        if key == "L" and self.dialect.siemens:
            refusals.append(("a subprogram call", tok))
            return
        if key in words:
            refusals.append((f"{key} programmed twice in one block", tok))
            return
        if key in "ABCUVW" and key not in self.axes:
            refusals.append((f"{key} is not an axis of this machine ({', '.join(self.axes)})", tok))
            return
        words[key] = tok

    def _assignment(self, tok: Token, following: list[Token], words: dict[str, Token],
                    refusals: list[tuple[str, Token]]) -> None:
        key = tok.key
        if key == "T" and following and following[0].kind == "string":
            return  # T="tool name"
        if tok.function == "expr":
            refusals.append(("an expression", tok))
        elif key in self.axes or key in _ARC_NAMES:
            if key in words:
                refusals.append((f"{key} programmed twice in one block", tok))
            words[key] = tok
        elif key in ("F", "S", "D", "T", "H"):
            words[key] = tok
        else:
            refusals.append((f"an assignment to {key}", tok))

    def _refused(self, block: Block, refusals: list[tuple[str, Token]], words: dict[str, Token]) -> None:
        why, tok = refusals[0]
        message = f"{why}: {tok.text!r}"
        if not self.pass_through:
            raise self._error(block.line_no, message + " cannot be compensated safely; use --pass-through to keep "
                              "such blocks unchanged (the tool then tracks what it can)")
        block.kind = "pass"
        block.reason = f"passed through: {message}"
        if any(w in why for w in ("call", "control flow", "O-code", "return", "unknown code")):
            self.state = replace(self.state, lost=f"line {block.line_no}: {message}")
            self.pos = [None] * len(self.axes)
        else:
            for k in words:
                if k in self.axes:
                    self.pos[self.axes.index(k)] = None
            if any(t.key in self.axes for _, t in refusals):
                for _, t in refusals:
                    if t.key in self.axes:
                        self.pos[self.axes.index(t.key)] = None
        block.state = self.state
        block.after = tuple(self.pos)

    # -- modal codes --------------------------------------------------------------------
    def _apply_modal(self, block: Block, codes: list[tuple[str, Token]]) -> None:
        changes: dict[str, object] = {}
        for action, tok in codes:
            head, _, arg = action.partition(":")
            if head == "motion":
                changes["motion"] = arg
            elif head == "dist":
                changes["incremental"] = arg == "inc"
            elif head == "units":
                changes["inch"] = arg == "inch"
                changes["units_programmed"] = True
            elif head == "rtcp":
                changes["rtcp"] = arg == "on"
                changes["rtcp_programmed"] = True
            elif head == "offset":
                changes["offset"] = self._offset_name(tok, block)
            elif head == "frame":
                changes.update(self._frame(arg, tok, block))
            elif head == "comp":
                changes["cutter_comp"] = arg == "on"
            elif head in ("feed", "plane"):
                changes[head] = arg
            elif head == "cycle":
                changes["cycle"] = arg != "cancel"
            elif head == "end":
                changes["lost"] = f"after the end of the program at line {block.line_no}"
        if changes:
            self._set_state(changes)

    def _set_state(self, changes: dict[str, object]) -> None:
        st = self.state
        if any(getattr(st, k) != v for k, v in changes.items()):
            self.state = replace(st, **changes)  # type: ignore[arg-type]
            if self.state.rtcp != st.rtcp:
                # X/Y/Z switch between machine and workpiece coordinates: where they stand is unknown
                self.pos[0:3] = [None, None, None]

    def _offset_name(self, tok: Token, block: Block) -> str:
        name = tok.code
        if name in ("G54.1", "G154"):
            p = next((t for t in block.tokens if t.kind == "word" and t.key == "P"), None)
            name += f"P{p.value:g}" if p is not None and p.value is not None else "P?"
        return name

    def _frame(self, arg: str, tok: Token, block: Block) -> dict[str, str]:
        code = tok.code
        where = f"{code} at line {block.line_no}"
        if arg == "lock":
            return {"locked": f"{where} changes the work offsets"}
        if arg == "cancel":
            return {"frame": ""}
        if code == "G52" or (self.dialect.siemens and tok.kind == "name"):
            values = [t.value for t in block.tokens if t.kind in ("word", "assign") and t.key in self.axes]
            if not values or (code == "G52" and all(v == 0 for v in values)):
                return {"frame": ""}  # TRANS / ROT / G52 X0 Y0: frame cleared
        return {"frame": f"the frame {where} is active (program coordinates unknown)"}

    # -- words --------------------------------------------------------------------------
    def _dwell(self, block: Block, words: dict[str, Token]) -> None:
        block.dwell = True
        for letter, factor in self.dialect.dwell_letters.items():
            tok = words.get(letter)
            if tok is not None and tok.value is not None:
                block.dwell_s = tok.value * factor
                break
        block.after = tuple(self.pos)

    def _move(self, block: Block, actions: Iterable[str], axis_words: dict[str, Token]) -> None:
        st = self.state
        new = list(self.pos)
        inc_axes = set()
        unit = st.unit_mm
        check_point = self.dialect.decimal_point
        index = self._axis_index
        for key, tok in axis_words.items():
            i = index[key]
            value = tok.value
            if value is None or abs(value) > MAX_ABS_VALUE or (check_point and value != 0 and not tok.has_point):
                self._bad_value(block, tok)
                continue  # unreachable: _bad_value raises
            if i < 3:
                value *= unit
            incremental = tok.function in ("IC", "CIC") or (st.incremental and tok.function in ("", "="))
            if incremental:
                inc_axes.add(key)
                new[i] = None if self.pos[i] is None else self.pos[i] + value  # type: ignore[operator]
            else:
                new[i] = value
        if inc_axes:
            block.incremental_axes = frozenset(inc_axes)
        special = ("ref" if "ref" in actions else "machine" if "machine" in actions else None) if actions else None
        if special or st.cycle or st.motion == "other":
            for key in axis_words:
                new[self.axes.index(key)] = None
            block.kind = "pass"
            block.reason = {"ref": "reference / fixed-point move: end position unknown in program coordinates",
                            "machine": "machine-coordinate move (G53/SUPA): end position unknown in program "
                            "coordinates"}.get(special or "", "canned cycle or untracked motion: end position unknown")
        elif st.motion in ("G2", "G3"):
            block.kind = "pass"
            block.reason = f"arc {st.motion}: end point tracked, never changed"
        else:
            block.kind = "move"
            block.reason = self._why_not(block, new, inc_axes, axis_words)
        self.pos = new
        block.after = tuple(new)

    def _bad_value(self, block: Block, tok: Token) -> NoReturn:
        """Raise for an axis value that is absurd or, on ISO/Fanuc, has no decimal point."""
        if tok.value is not None and abs(tok.value) <= MAX_ABS_VALUE:
            raise self._error(block.line_no, f"{tok.text.strip()!r} has no decimal point: on ISO/Fanuc controls "
                              "it means least input increments (0.001 mm), not mm; write it with a point "
                              f"({tok.key}{tok.value:g}.) so its meaning is unambiguous")
        raise self._error(block.line_no, f"{tok.text.strip()!r}: value out of any machine's range")

    def _why_not(self, block: Block, new: list[float | None], inc_axes: AbstractSet[str],
                 axis_words: dict[str, Token]) -> str:
        st = self.state
        for cause in (st.lost, st.locked, st.frame):
            if cause:
                return cause
        if st.cutter_comp:
            return "cutter radius compensation active"
        if None in new:
            missing = [a for a, v in zip(self.axes, new, strict=True) if v is None]
            return f"pose not known ({', '.join(missing)} not programmed yet)"
        if None in self.pos and (inc_axes or len(axis_words) != len(self.axes)):
            return "pose before the block not known"
        return ""

    # -- helpers ------------------------------------------------------------------------
    def _error(self, line_no: int, problem: str) -> NCProgramError:
        return NCProgramError(self.path, line_no, problem)




def split_lines(text: str) -> list[str]:
    """Lines with their endings; only ``\\r\\n``, ``\\n`` and ``\\r`` end a line (not form feeds etc.)."""
    lines = _LINES.findall(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def split_parts(text: str) -> tuple[list[str], list[str]]:
    """:func:`split_lines` as two lists: each line without its ending, and its ending (``""`` for the last)."""
    parts = _LINE_PARTS.findall(text)
    if parts and parts[-1] == ("", ""):
        parts.pop()
    if not parts:
        return [], []
    texts, endings = zip(*parts, strict=True)
    return list(texts), list(endings)


def interpret(text: str, dialect: Dialect, rotary_axes: tuple[str, ...], *, path: str = "<program>",
              pass_through: bool = False) -> Program:
    """Interpret a whole program (module docstring); never alters the text."""
    interp = Interpreter(dialect, rotary_axes, path=path, pass_through=pass_through)
    blocks = interp.run_parts(*split_parts(text))
    notes = []
    if any(b.kind == "move" for b in blocks) and not any(b.state.units_programmed for b in blocks):
        notes.append("the program does not state its units: mm assumed (the controller's power-on default)")
    return Program(path, blocks, dialect, interp.axes, notes)
