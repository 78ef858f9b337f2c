"""Modal state of an NC program and one interpreted block.

Positions are kept in millimetres and degrees whatever the program's units (an inch
program's words are converted on reading and back on writing); ``None`` means the
position of that axis is not known at this point of the program.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from pige_sym.nc.lexer import Token, plain_words

MM_PER_INCH = 25.4


@dataclass(frozen=True, slots=True)
class ModalState:
    """What the controller remembers between blocks (only what matters to positions).

    Attributes
    ----------
    incremental : bool
        G91 (True) or G90.
    inch : bool
        G20/G70/G700 (True) or G21/G71/G710.
    units_programmed : bool
        Whether the program said which units it uses (otherwise mm, the power-on default, is assumed).
    motion : str
        ``G0``, ``G1``, ``G2``, ``G3``, ``other`` or ``""`` (not programmed yet: a linear move).
    rtcp : bool
        Tool centre point control (TRAORI, G43.4 …) on.
    rtcp_programmed : bool
        Whether the program switched RTCP on or off (otherwise off, the reset state, is assumed).
    offset : str
        Active work offset (``G54``, ``G54.1P3`` …), ``""`` before one is programmed.
    frame : str
        Non-empty while a programmable frame / rotation / scaling is active: why coordinates are unknown.
    locked : str
        Non-empty once offsets were changed for good (G10, ISO G92): why nothing after is compensated.
    cutter_comp : bool
        Cutter radius compensation (G41/G42, CUT3DC) active.
    cycle : bool
        A canned cycle is modal (G81 …, until G80).
    lost : str
        Non-empty after a block passed through whose effect is unknown (a call, a jump): why.
    plane : str
        ``G17``/``G18``/``G19`` (``""`` before one is programmed).
    feed : str
        Feed mode ``G93`` (inverse time), ``G94``, ``G95`` (``""`` before one is programmed).
    """

    incremental: bool = False
    inch: bool = False
    units_programmed: bool = False
    motion: str = ""
    rtcp: bool = False
    rtcp_programmed: bool = False
    offset: str = ""
    frame: str = ""
    locked: str = ""
    cutter_comp: bool = False
    cycle: bool = False
    lost: str = ""
    plane: str = ""
    feed: str = ""

    @property
    def unit_mm(self) -> float:
        """Millimetres per program unit of length."""
        return MM_PER_INCH if self.inch else 1.0


@dataclass(slots=True)
class Block:
    """One line of a program as the interpreter understood it.

    Attributes
    ----------
    line_no : int
        1-based line number in the file.
    text, ending : str
        The line without / with only its line ending (``\\n``, ``\\r\\n``, ``""`` for the last line).
    tokens : list of Token
        Empty for a plain block read in a batch (:meth:`Interpreter.run`), only the axis words for one
        read by the per-line fast path.
    state : ModalState
        Modal state in force for this block's motion (after its own modal codes).
    before, after : tuple of float or None
        Position of every axis (``axes`` order) before and after the block [mm, deg].
    axis_words : dict of str to Token
        The block's axis words by axis letter (property: for a plain block read in a batch they are
        made on first use from ``plain_``, with :func:`pige_sym.nc.lexer.plain_words`).
    plain_ : re.Match or None
        A plain block read in a batch: its line cut by :func:`pige_sym.nc.plain_blocks.plain_pattern`.
    incremental_axes : frozenset of str
        Axes whose word is incremental (G91 or ``=IC()``).
    kind : str
        ``""`` (no motion), ``move`` (G0/G1 linear move), ``pass`` (any other block that moves
        axes: arcs, reference and machine-coordinate moves, cycles …).
    reason : str
        Why a ``move`` cannot be compensated, or what a ``pass`` block is; empty for a compensable move.
    dwell_s : float or None
        Dwell time [s] of a dwell block (None: no dwell or a dwell not given in seconds).
    dwell : bool
    stop : bool
        M0/M1 programmed stop.
    skip : bool
        The block starts with the block-skip ``/``.
    axes : tuple of str
        Axis letters of ``before``/``after`` (X, Y, Z and the machine's rotary axes).
    """

    line_no: int
    text: str
    ending: str
    tokens: list[Token]
    state: ModalState
    before: tuple[float | None, ...]
    after: tuple[float | None, ...]
    axes: tuple[str, ...]
    words_: dict[str, Token] | None = field(default=None, repr=False, compare=False)
    plain_: re.Match[str] | None = field(default=None, repr=False, compare=False)
    incremental_axes: frozenset[str] = frozenset()
    kind: str = ""
    reason: str = ""
    dwell_s: float | None = None
    dwell: bool = False
    stop: bool = False
    skip: bool = False

    @property
    def axis_words(self) -> dict[str, Token]:
        """The block's axis words by axis letter (class docstring)."""
        words = self.words_
        if words is None:
            words = {} if self.plain_ is None else plain_words(self.axes, self.plain_)
            self.words_ = words
        return words

    @axis_words.setter
    def axis_words(self, words: dict[str, Token]) -> None:
        self.words_ = words

    @property
    def position(self) -> dict[str, float | None]:
        """Position after the block by axis [mm, deg]."""
        return dict(zip(self.axes, self.after, strict=True))

    @property
    def is_motion(self) -> bool:
        """A linear (G0/G1) move."""
        return self.kind == "move"

    @property
    def rtcp(self) -> bool:
        return self.state.rtcp

    @property
    def compensable(self) -> bool:
        """A linear move whose full pose before and after is known, with nothing that forbids changing it."""
        return self.kind == "move" and not self.reason
