"""Parser for ISO 10791 machine structure codes (CONVENTIONS §1).

Grammar (whitespace between any two tokens is ignored)::

    code       := "w" wp_axis* "b" tool_axis* spindle? "t"
    wp_axis    := LETTER SUFFIX? PRIME          (workpiece side, from the workpiece outward)
    tool_axis  := LETTER SUFFIX?                (tool side, from the bed towards the tool)
    spindle    := "(" LETTER SUFFIX? ")"        (spindle rotation: recorded, no errors)
    LETTER     := "X" | "Y" | "Z" | "U" | "V" | "W" | "A" | "B" | "C"
    SUFFIX     := DIGIT+
    PRIME      := "'" | "’" | "ʹ" | "′"

X Y Z (and U V W, parallel to them) are linear axes, A B C rotary axes about X Y Z.
An axis name is its letter plus suffix (``C``, ``C2``); a name may appear once.
Every violation raises :class:`~pige_sym.errors.MachineCodeError` naming the
offending character and its 0-based position in the string as given.

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
        raise MachineCodeError(str(code), 0, "a machine code must be a string")
    n = len(code)
    i = _skip_space(code, 0)
    if i >= n:
        raise MachineCodeError(code, i, "empty code; expected 'w' (workpiece) first, e.g. wC'A'bXYZ(C1)t")
    if code[i] != "w":
        raise MachineCodeError(code, i, "a code starts with 'w' (workpiece), e.g. wC'A'bXYZ(C1)t")
    i += 1
    seen: dict[str, int] = {}
    wp: list[Axis] = []
    tool: list[Axis] = []
    spindle: str | None = None
    side: Side = "workpiece"

    def read_axis(i: int) -> tuple[str, int, int]:
        start = i
        letter = code[i]
        i += 1
        while i < n and code[i].isdigit():
            i += 1
        return letter + code[start + 1 : i], start, i

    while True:
        i = _skip_space(code, i)
        if i >= n:
            expected = "'b' (bed)" if side == "workpiece" else "'t' (tool)"
            raise MachineCodeError(code, i, f"code ends too early; expected {expected}")
        ch = code[i]
        if ch in AXIS_LETTERS:
            name, start, i = read_axis(i)
            if name in seen:
                raise MachineCodeError(
                    code, start, f"axis {name} appears twice (first at position {seen[name]}); "
                    "give duplicates a digit suffix, e.g. C1 and C2"
                )
            j = _skip_space(code, i)
            primed = j < n and code[j] in PRIMES
            if side == "workpiece":
                if not primed:
                    raise MachineCodeError(
                        code, j, f"workpiece-side axis {name} (between 'w' and 'b') must be primed, e.g. {name}'"
                    )
                i = j + 1
            elif primed:
                raise MachineCodeError(
                    code, j, f"tool-side axis {name} (between 'b' and 't') must not be primed"
                )
            seen[name] = start
            (wp if side == "workpiece" else tool).append(Axis(name, side, start))
            continue
        if ch in PRIMES:
            raise MachineCodeError(code, i, "a prime must follow an axis letter")
        if ch == "b":
            if side == "tool":
                raise MachineCodeError(code, i, "'b' (bed) appears twice")
            side = "tool"
            i += 1
            continue
        if ch == "(":
            if side == "workpiece":
                raise MachineCodeError(code, i, "the spindle '(...)' belongs after 'b', just before 't'")
            if spindle is not None:
                raise MachineCodeError(code, i, "only one spindle '(...)' is allowed")
            j = _skip_space(code, i + 1)
            if j >= n or code[j] not in AXIS_LETTERS:
                raise MachineCodeError(code, j, "expected the spindle axis letter after '(', e.g. (C1)")
            name, _, j = read_axis(j)
            j = _skip_space(code, j)
            if j >= n or code[j] != ")":
                raise MachineCodeError(code, j, "unbalanced parenthesis: expected ')' after the spindle axis")
            spindle = name
            i = j + 1
            k = _skip_space(code, i)
            if k < n and code[k] != "t":
                raise MachineCodeError(code, k, "the spindle '(...)' must be followed by 't' (tool)")
            continue
        if ch == ")":
            raise MachineCodeError(code, i, "unbalanced parenthesis: ')' without '('")
        if ch == "t":
            if side == "workpiece":
                raise MachineCodeError(code, i, "'t' (tool) before 'b' (bed); the order is w ... b ... t")
            i = _skip_space(code, i + 1)
            if i < n:
                raise MachineCodeError(code, i, "unexpected text after 't' (tool), which ends the code")
            break
        if ch == "w":
            raise MachineCodeError(code, i, "'w' (workpiece) appears twice")
        if ch.upper() in AXIS_LETTERS:
            raise MachineCodeError(code, i, f"axis letters are upper case: write {ch.upper()!r}")
        raise MachineCodeError(
            code, i, "unknown character; expected an axis letter (X Y Z U V W A B C), a prime, 'b', '(' or 't'"
        )
    return MachineStructure(code=code, workpiece_axes=tuple(wp), tool_axes=tuple(tool), spindle=spindle)
