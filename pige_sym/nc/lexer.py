"""Lexer: one NC block (one line) into tokens that know their exact place in the line.

Grammar (shared by the dialects; ``siemens`` switches on the 840D extensions)::

    block    := [BOM] ["/"] token*
    token    := comment | string | word | assign | call | name | other
    comment  := ";" <rest of line>                    (every dialect)
              | "(" <anything but ")"> ")"            (a parenthesis not attached to a name)
    string   := '"' <anything but '"'> '"'            (840D: MSG("..."), T="tool")
    word     := LETTER space* NUMBER                   (X  16.339, G43.4, N10, X-.5)
    NUMBER   := [+-] (digits ["." digits*] | "." digits)   -- no exponent, no nan/inf
    assign   := NAME space* "=" space* (FN "(" NUMBER ")" | NUMBER | <expression>)
                                                       (840D: X=AC(10), C=DC(30), R1=5, A3=...)
    call     := NAME "(" (string | <no parenthesis>)* ")"   (840D: TRAORI(1), CYCLE800(...))
    name     := NAME [":"]                             (840D keywords TRAORI, GOTOF, labels LBL1:)
    other    := any other character (#, [, ], =, ...)  -- expressions, macro variables

A word must end at a word boundary: in the 840D dialect the next character may not be a
letter, digit, ``.`` or ``_`` (``LABELC1`` is a name, never the word ``C1``); in ISO/Fanuc
and rs274ngc words may be written without spaces (``G1X10.Y20.``) but a number followed by
an exponent (``1e400``) or by another ``.`` is malformed.  The lexer never changes text:
every token has ``start``/``end`` offsets into the line and, for numbers,
``value_start``/``value_end`` so a rewrite replaces only the digits.
"""

from __future__ import annotations

import math
import re
from functools import lru_cache
from typing import NamedTuple

from pige_sym.errors import LexError as LexError

NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)"
FUNCTIONS = ("ACP", "ACN", "AC", "IC", "DC", "CAC", "CIC", "CDC", "CACP", "CACN")

_COMMON = (
    r"(?P<space>\s+)"
    r"|(?P<semi>;.*)"
)
_SIEMENS = re.compile(
    _COMMON
    + rf"|(?P<assign>(?P<aname>[A-Z_$][A-Z0-9_$]*)\s*=\s*"
    rf"(?:(?P<fn>{'|'.join(FUNCTIONS)})\s*\(\s*(?P<fnum>{NUMBER})\s*\)|(?P<anum>{NUMBER}))?)"
    rf"|(?P<word>(?P<letter>[A-Z])[ \t]*(?P<num>{NUMBER}))(?![A-Z0-9_.(])"
    r"|(?P<call>(?P<cname>[A-Z_][A-Z0-9_]*)\s*\((?:\"[^\"]*\"|[^()\"])*\))"
    r"|(?P<name>[A-Z_$][A-Z0-9_$]*:?)"
    r"|(?P<paren>\([^()]*\))"
    r"|(?P<string>\"[^\"]*\")"
    r"|(?P<other>.)",
    re.IGNORECASE,
)
_ISO = re.compile(
    _COMMON
    + r"|(?P<paren>\([^()]*\))"
    rf"|(?P<word>(?P<letter>[A-Z])[ \t]*(?P<num>{NUMBER}))(?![eE][-+]?\d|\.|\d)"
    rf"|(?P<bad>[A-Z][ \t]*{NUMBER}(?:[eE][-+]?\d+|\.)?)"
    r"|(?P<others>[^A-Z;(\s\"]{2,})"  # where no other token can start: one "other" token per character
    r"|(?P<other>.)",
    re.IGNORECASE,
)
_CODES: dict[tuple[str, str], str] = {}
_PLAIN_WORD = re.compile(rf"([A-Z])[ \t]*({NUMBER})", re.IGNORECASE)


class Token(NamedTuple):
    """One token of a block.

    Attributes
    ----------
    kind : str
        ``comment``, ``string``, ``word``, ``assign``, ``call``, ``name`` or ``other``.
    text : str
        The token exactly as written.
    start, end : int
        Offsets of the token in the line (``line[start:end] == text``); −1 for an axis word of a plain
        block read by the interpreter's per-line fast path (``text`` is then the letter and digits, and
        :func:`word_spans` finds the offsets when the block is rewritten).
    key : str
        Upper-case address: the letter of a word (``X``), the name of an assignment,
        call or name (``TRAORI``, ``R1``, ``GOTOF``); empty for comments and strings.
    value : float or None
        Numeric value of a word or of a numeric assignment.
    value_start, value_end : int
        Offsets of the digits of ``value`` in the line (−1 without a value).
    function : str
        ``AC``/``IC``/``DC``/``ACP``/``ACN`` of an 840D assignment ``X=AC(…)``; ``=`` for ``X=10``;
        empty for plain words.
    """

    kind: str
    text: str
    start: int
    end: int
    key: str = ""
    value: float | None = None
    value_start: int = -1
    value_end: int = -1
    function: str = ""

    @property
    def has_point(self) -> bool:
        """True when the number is written with a decimal point (ISO/Fanuc: ``X120.`` ≠ ``X120``)."""
        if self.start < 0:  # a word without offsets (fast path): text is letter + digits
            return "." in self.text
        return self.value_start >= 0 and "." in self.text[self.value_start - self.start:self.value_end - self.start]

    @property
    def code(self) -> str:
        """Normalised G/M code of a word (``G01`` → ``G1``, ``G43.40`` → ``G43.4``); else the key."""
        if self.kind != "word" or self.value is None or self.key not in "GM":
            return self.key
        digits = self.text[self.value_start - self.start:self.value_end - self.start]
        cached = _CODES.get((self.key, digits))
        if cached is None:
            if digits.startswith(("+", "-")):
                cached = self.key + digits
            else:
                whole, _, frac = digits.partition(".")
                whole = whole.lstrip("0") or "0"
                frac = frac.rstrip("0")
                cached = f"{self.key}{whole}.{frac}" if frac else f"{self.key}{whole}"
            _CODES[(self.key, digits)] = cached
        return cached


def _number(text: str, column: int) -> float:
    value = float(text)
    if not math.isfinite(value):  # pragma: no cover - the grammar has no exponent
        raise LexError(column, f"number {text!r} is not finite")
    return value


def tokenize(line: str, *, siemens: bool) -> list[Token]:
    """Tokens of one line (without its line ending), comments and whitespace included.

    A line read again (a program's log statement, ``ENDIF``, ``STOPRE``: the same text at every pose) gets the
    same tokens from a cache of the latest :data:`REMEMBERED_LINES` (tokens are immutable; the list is new).

    Raises
    ------
    LexError
        Unterminated comment/string, exponent notation (``1e400``), a number with two points.
    """
    return list(_remembered(line, siemens))


#: Lines whose tokens :func:`tokenize` keeps (least recently read dropped first).
REMEMBERED_LINES = 512


@lru_cache(maxsize=REMEMBERED_LINES)
def _remembered(line: str, siemens: bool) -> tuple[Token, ...]:
    return tuple(_tokens(line, siemens))


def _tokens(line: str, siemens: bool) -> list[Token]:
    """:func:`tokenize` itself."""
    pattern = _SIEMENS if siemens else _ISO
    tokens: list[Token] = []
    append = tokens.append
    for m in pattern.finditer(line):
        kind = m.lastgroup
        if kind == "space":
            continue
        pos, end = m.span()
        if kind == "word":
            num = m.group("num")
            append(Token("word", m.group(), pos, end, m.group("letter").upper(), float(num), m.start("num"),
                         m.end("num")))
        elif kind == "semi" or kind == "paren":
            append(Token("comment", m.group(), pos, end))
        elif kind == "string":
            append(Token("string", m.group(), pos, end))
        elif kind == "assign":
            append(_assign(line, m, pos, end))
        elif kind == "call":
            append(Token("call", m.group(), pos, end, key=m.group("cname").upper()))
        elif kind == "name":
            append(Token("name", m.group(), pos, end, key=m.group().upper()))
        elif kind == "others":  # a macro expression's run of #, digits, brackets and operators (Fanuc IF[...])
            for k, ch in enumerate(m.group(), pos):
                append(Token("other", ch, k, k + 1, ch))
        elif kind == "bad":
            raise LexError(pos, f"malformed number in {m.group().strip()!r} (exponents such as 1e400 "
                           "and numbers with two points are not G-code)")
        else:
            ch = m.group()
            if ch == "(":
                raise LexError(pos, "unterminated comment '(' (no closing ')')")
            if ch == '"':
                raise LexError(pos, "unterminated string")
            append(Token("other", ch, pos, end, key=ch))
    return tokens


def _assign(line: str, m: re.Match[str], start: int, end: int) -> Token:
    name = m.group("aname").upper()
    if m.group("fnum") is not None:
        return Token("assign", m.group(), start, end, key=name, value=_number(m.group("fnum"), start),
                     value_start=m.start("fnum"), value_end=m.end("fnum"), function=m.group("fn").upper())
    if m.group("anum") is not None:
        rest = line[end:]
        if rest[:1] and not (rest[:1].isspace() or rest[:1] == ";"):
            # X=10+R1, X=10*2, X=1e4 ...: an expression, not a plain value
            return Token("assign", m.group(), start, end, key=name, function="expr")
        return Token("assign", m.group(), start, end, key=name, value=_number(m.group("anum"), start),
                     value_start=m.start("anum"), value_end=m.end("anum"), function="=")
    return Token("assign", m.group(), start, end, key=name, function="expr")


def word_spans(line: str, words: dict[str, Token]) -> dict[str, tuple[int, int, int, int]]:
    """Offsets ``(start, end, value_start, value_end)`` in ``line`` of each word in ``words`` (by letter).

    Tokens of the interpreter's per-line fast path carry no offsets (−1): they are found again here, in plain
    blocks whose words all have the form letter + number.
    """
    out = {k: (t.start, t.end, t.value_start, t.value_end) for k, t in words.items() if t.start >= 0}
    if len(out) < len(words):
        for m in _PLAIN_WORD.finditer(line):
            letter = m.group(1).upper()
            if letter in words and letter not in out:
                out[letter] = (m.start(), m.end(), m.start(2), m.end(2))
        if len(out) < len(words):
            raise ValueError(f"cannot locate the axis words of {line!r}")
    return out


def plain_words(axes: tuple[str, ...], match: re.Match[str]) -> dict[str, Token]:
    """The axis words of a plain block, with their offsets, by axis letter.

    ``match`` is the block's line matched by :func:`pige_sym.nc.plain_blocks.plain_pattern` for ``axes``
    (per axis ``i``: group ``3i + 4`` its letter, ``3i + 5`` its number).
    """
    line, regs = match.string, match.regs
    out: dict[str, Token] = {}
    for i, axis in enumerate(axes):
        ws = regs[3 * i + 4][0]
        if ws >= 0:
            vs, ve = regs[3 * i + 5]
            out[axis] = Token("word", line[ws:ve], ws, ve, axis, float(line[vs:ve]), vs, ve)
    return out
