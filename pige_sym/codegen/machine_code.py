"""Parser for ISO 10791 machine structure codes (CONVENTIONS §1).

Grammar (whitespace between any two tokens is ignored)::

    code       := "w" wp_axis* "b" tool_axis* spindle? "t"
    wp_axis    := LETTER SUFFIX? PRIME          (workpiece side, from the workpiece outward)
    tool_axis  := LETTER SUFFIX?                (tool side, from the bed towards the tool)
    spindle    := "(" LETTER SUFFIX? ")"        (spindle rotation: recorded, no errors)
    LETTER     := "X" | "Y" | "Z" | "U" | "V" | "W" | "A" | "B" | "C"
    SUFFIX     := DIGIT{1,3}                (ASCII 0-9 only; "²" or "١" are not digits here)
    PRIME      := "'" | "’" | "ʹ" | "′"

X Y Z (and U V W, parallel to them) are linear axes, A B C rotary axes about X Y Z.
An axis name is its letter plus suffix read as a number (``C``, ``C2``; ``C01`` is
``C1``); a name may appear once, and the spindle's name may not be one of the
positioning axes' (``wC1'bXYZ(C1)t`` is refused).  A code is at most
:data:`MAX_CODE_LENGTH` characters.  Every violation raises
:class:`~pige_sym.errors.MachineCodeError` naming the offending character and its
0-based position in the string as given.

The rotary axes of a machine are put in *column order*: sorted by name
(``A`` < ``B`` < ``C``, then by suffix).  Data files, kernels and parameter
vectors all use this order.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from pige_sym.errors import MachineCodeError

PRIMES = ("'", "\u2019", "\u02b9", "\u2032")
LINEAR_LETTERS = "XYZUVW"
ROTARY_LETTERS = "ABC"
AXIS_LETTERS = LINEAR_LETTERS + ROTARY_LETTERS
ASCII_DIGITS = "0123456789"
#: Longest code accepted [characters] (the longest real codes have about 20).
MAX_CODE_LENGTH = 64
MAX_SUFFIX_DIGITS = 3
#: Direction index (0 = X, 1 = Y, 2 = Z) of each axis letter.
DIRECTION_INDEX = {"X": 0, "Y": 1, "Z": 2, "U": 0, "V": 1, "W": 2, "A": 0, "B": 1, "C": 2}

Side = Literal["workpiece", "tool"]
Kind = Literal["linear", "rotary"]


@dataclass(frozen=True)
class Axis:
    """One positioning axis of the machine.

    Attributes
    ----------
    name : str
        Letter plus optional digit suffix, e.g. ``"C"`` or ``"C2"``.
    side : {"workpiece", "tool"}
        Chain the axis belongs to.
    position : int
        0-based position of its letter in the code string as given.
    """

    name: str
    side: Side
    position: int

    @property
    def letter(self) -> str:
        """Axis letter without suffix."""
        return self.name[0]

    @property
    def kind(self) -> Kind:
        """``"rotary"`` for A/B/C, ``"linear"`` for X/Y/Z/U/V/W."""
        return "rotary" if self.letter in ROTARY_LETTERS else "linear"

    @property
    def direction(self) -> int:
        """Index (0, 1, 2) of the machine axis X, Y, Z the axis moves along or about."""
        return DIRECTION_INDEX[self.letter]

    @property
    def sign(self) -> int:
        """ISO 841 sense: +1 for tool-side axes, -1 for workpiece-side (primed) axes."""
        return 1 if self.side == "tool" else -1


@dataclass(frozen=True)
class MachineStructure:
    """Typed description of a parsed machine structure code.

    Attributes
    ----------
    code : str
        The code exactly as given.
    workpiece_axes : tuple of Axis
        Workpiece-side axes from the workpiece outward (first carries the workpiece).
    tool_axes : tuple of Axis
        Tool-side axes from the bed towards the tool.
    spindle : str or None
        Name of the spindle rotation in parentheses, e.g. ``"C1"``.
    """

    code: str
    workpiece_axes: tuple[Axis, ...]
    tool_axes: tuple[Axis, ...]
    spindle: str | None

    @property
    def canonical(self) -> str:
        """Normalised code: no spaces, ASCII prime, e.g. ``wC'A'bXYZ(C1)t``."""
        wp = "".join(a.name + "'" for a in self.workpiece_axes)
        tl = "".join(a.name for a in self.tool_axes)
        sp = f"({self.spindle})" if self.spindle else ""
        return f"w{wp}b{tl}{sp}t"

    @property
    def axes(self) -> tuple[Axis, ...]:
        """All positioning axes, workpiece side then tool side."""
        return self.workpiece_axes + self.tool_axes

    @property
    def rotary_axes(self) -> tuple[Axis, ...]:
        """Rotary axes in column order (sorted by name)."""
        return tuple(sorted((a for a in self.axes if a.kind == "rotary"), key=_axis_sort_key))

    @property
    def linear_axes(self) -> tuple[Axis, ...]:
        """Linear axes in chain order (workpiece side, then tool side)."""
        return tuple(a for a in self.axes if a.kind == "linear")

    @property
    def module_name(self) -> str:
        """Python module name of the generated kernels for this machine."""
        out = []
        for ch in self.canonical:
            if ch == "'":
                out.append("p")
            elif ch in "()":
                out.append("_")
            else:
                out.append(ch)
        return "kin_" + "".join(out)


def _axis_sort_key(axis: Axis) -> tuple[str, int]:
    suffix = axis.name[1:]
    return (axis.letter, int(suffix) if suffix else -1)


def _skip_space(code: str, i: int) -> int:
    while i < len(code) and code[i].isspace():
        i += 1
    return i


def parse_machine_code(code: str) -> MachineStructure:
    """Parse an ISO 10791 machine structure code.

    Parameters
    ----------
    code : str
        E.g. ``"wC'A'bXYZ(C1)t"``; spaces are free, any of ``' ’ ʹ ′`` is a prime.

    Returns
    -------
    MachineStructure

    Raises
    ------
    MachineCodeError
        With the offending character and its 0-based position.
    """
    if not isinstance(code, str):
        raise MachineCodeError(str(code)[:MAX_CODE_LENGTH], 0, "a machine code must be a string")
    if len(code) > MAX_CODE_LENGTH:
        raise MachineCodeError(code, MAX_CODE_LENGTH, f"a machine code has at most {MAX_CODE_LENGTH} characters")
    return _CodeParser(code).parse()


class _CodeParser:
    """Recursive-descent parser of one code (module docstring grammar), one method per token kind."""

    def __init__(self, code: str) -> None:
        self.code = code
        self.n = len(code)
        self.i = 0
        self.seen: dict[str, int] = {}
        self.axes: dict[Side, list[Axis]] = {"workpiece": [], "tool": []}
        self.spindle: str | None = None
        self.spindle_at = 0
        self.side: Side = "workpiece"

    def fail(self, position: int, problem: str) -> MachineCodeError:
        return MachineCodeError(self.code, position, problem)

    def parse(self) -> MachineStructure:
        self._start()
        while not self._token():
            pass
        if self.spindle is not None and self.spindle in self.seen:
            raise self.fail(self.spindle_at, f"the spindle ({self.spindle}) has the name of a positioning axis "
                            f"(position {self.seen[self.spindle]}); give it another suffix, e.g. "
                            f"({self.spindle[0]}{_free_suffix(self.spindle[0], self.seen)})")
        return MachineStructure(code=self.code, workpiece_axes=tuple(self.axes["workpiece"]),
                                tool_axes=tuple(self.axes["tool"]), spindle=self.spindle)

    def _start(self) -> None:
        i = _skip_space(self.code, 0)
        if i >= self.n:
            raise self.fail(i, "empty code; expected 'w' (workpiece) first, e.g. wC'A'bXYZ(C1)t")
        if self.code[i] != "w":
            raise self.fail(i, "a code starts with 'w' (workpiece), e.g. wC'A'bXYZ(C1)t")
        self.i = i + 1

    def _token(self) -> bool:
        """Consume one token; True when the code has ended with 't'."""
        self.i = _skip_space(self.code, self.i)
        if self.i >= self.n:
            expected = "'b' (bed)" if self.side == "workpiece" else "'t' (tool)"
            raise self.fail(self.i, f"code ends too early; expected {expected}")
        ch = self.code[self.i]
        if ch in AXIS_LETTERS:
            self._axis()
        elif ch == "b":
            self._bed()
        elif ch == "(":
            self._spindle()
        elif ch == "t":
            self._tool_end()
            return True
        else:
            self._unexpected(ch)
        return False

    def _name(self, i: int) -> tuple[str, int]:
        """Axis letter and ASCII suffix at ``i`` (normalised: ``C01`` → ``C1``); returns (name, end)."""
        letter = self.code[i]
        j = i + 1
        while j < self.n and self.code[j] in ASCII_DIGITS:
            j += 1
        if j < self.n and self.code[j].isdigit() or j < self.n and self.code[j].isnumeric():
            raise self.fail(j, "axis suffixes are ASCII digits 0-9")
        digits = self.code[i + 1 : j]
        if len(digits) > MAX_SUFFIX_DIGITS:
            raise self.fail(i + 1, f"an axis suffix has at most {MAX_SUFFIX_DIGITS} digits")
        return letter + (str(int(digits)) if digits else ""), j

    def _axis(self) -> None:
        start = self.i
        name, i = self._name(start)
        if name in self.seen:
            raise self.fail(start, f"axis {name} appears twice (first at position {self.seen[name]}); "
                            "give duplicates a digit suffix, e.g. C1 and C2")
        j = _skip_space(self.code, i)
        primed = j < self.n and self.code[j] in PRIMES
        if self.side == "workpiece":
            if not primed:
                raise self.fail(j, f"workpiece-side axis {name} (between 'w' and 'b') must be primed, e.g. {name}'")
            i = j + 1
        elif primed:
            raise self.fail(j, f"tool-side axis {name} (between 'b' and 't') must not be primed")
        self.seen[name] = start
        self.axes[self.side].append(Axis(name, self.side, start))
        self.i = i

    def _bed(self) -> None:
        if self.side == "tool":
            raise self.fail(self.i, "'b' (bed) appears twice")
        self.side = "tool"
        self.i += 1

    def _spindle(self) -> None:
        if self.side == "workpiece":
            raise self.fail(self.i, "the spindle '(...)' belongs after 'b', just before 't'")
        if self.spindle is not None:
            raise self.fail(self.i, "only one spindle '(...)' is allowed")
        j = _skip_space(self.code, self.i + 1)
        if j >= self.n or self.code[j] not in AXIS_LETTERS:
            raise self.fail(j, "expected the spindle axis letter after '(', e.g. (C1)")
        self.spindle_at = j
        name, j = self._name(j)
        j = _skip_space(self.code, j)
        if j >= self.n or self.code[j] != ")":
            raise self.fail(j, "unbalanced parenthesis: expected ')' after the spindle axis")
        self.spindle = name
        self.i = j + 1
        k = _skip_space(self.code, self.i)
        if k < self.n and self.code[k] != "t":
            raise self.fail(k, "the spindle '(...)' must be followed by 't' (tool)")

    def _tool_end(self) -> None:
        if self.side == "workpiece":
            raise self.fail(self.i, "'t' (tool) before 'b' (bed); the order is w ... b ... t")
        i = _skip_space(self.code, self.i + 1)
        if i < self.n:
            raise self.fail(i, "unexpected text after 't' (tool), which ends the code")

    def _unexpected(self, ch: str) -> None:
        if ch in PRIMES:
            raise self.fail(self.i, "a prime must follow an axis letter")
        if ch == ")":
            raise self.fail(self.i, "unbalanced parenthesis: ')' without '('")
        if ch == "w":
            raise self.fail(self.i, "'w' (workpiece) appears twice")
        if ch.upper() in AXIS_LETTERS:
            raise self.fail(self.i, f"axis letters are upper case: write {ch.upper()!r}")
        raise self.fail(self.i, "unknown character; expected an axis letter (X Y Z U V W A B C), a prime, 'b', "
                        "'(' or 't'")


def _free_suffix(letter: str, seen: dict[str, int]) -> int:
    k = 1
    while f"{letter}{k}" in seen:
        k += 1
    return k
