"""NC dialects: what each G/M code or 840D keyword means to the interpreter.

A dialect is a table, not code: :class:`Dialect` maps normalised codes (``G1``, ``G43.4``,
``M128``, ``TRAORI``) to an *action* the interpreter (:mod:`pige_sym.nc.interpreter`)
applies.  Actions::

    motion:G0 motion:G1 motion:G2 motion:G3   modal motion (G2/G3 arcs: end point tracked, never changed)
    motion:other                               other motion (thread, spline ...): end point unknown
    dist:abs dist:inc                          G90 / G91
    units:mm units:inch                        G21 G71 G710 / G20 G70 G700
    feed:G93 feed:G94 feed:G95                 feed mode (tracked; F words are never changed)
    plane:G17 plane:G18 plane:G19              working plane (tracked; arcs' end points do not depend on it)
    rtcp:on rtcp:off                           TRAORI G43.4 G43.5 M128 G234 / TRAFOOF G49 M129 ...
    offset                                     work offsets G54..G59, G54.1 P, G154 P, G505..G599, G500
    frame:set frame:cancel                     TRANS ROT SCALE MIRROR G68 G68.2 G51 G51.1 G52 G92 CYCLE800 ...
    frame:lock                                 G10, G92 (ISO): offsets changed for good -> nothing after is compensated
    ref                                        G28 G30 G74 G75 (end position in program coordinates unknown)
    machine                                    G53 G153 SUPA (non-modal machine coordinates)
    cycle cycle:cancel                         canned cycles G81..G89 / G80
    comp:on comp:off                           cutter radius compensation G41 G42 / G40
    dwell                                      G4 / G04
    stop end                                   M0 M1 / M2 M30
    benign                                     no effect on positions (G17, G64, M3, M8, CYCLE832 ...)
    refuse:<why>                               control flow, calls, expressions: refused unless --pass-through

Anything not in the table is refused with its line: the interpreter never guesses what an
unknown code does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pige_sym.constants import DIALECTS as DIALECTS


@dataclass(frozen=True)
class Dialect:
    """One controller family's codes and output rules.

    Attributes
    ----------
    name : str
        ``siemens``, ``fanuc`` or ``linuxcnc``.
    siemens : bool
        Lex with the 840D extensions (``X=AC(…)``, keywords, calls, strings).
    codes : dict of str to str
        Action per normalised G/M code or keyword (module docstring).
    decimal_point : bool
        Axis values must carry a decimal point (ISO/Fanuc: ``X120`` is 120 increments, not 120 mm);
        integers are refused on input and never written.
    dwell_letters : dict of str to float
        Address of the dwell time and its factor to seconds (``{"F": 1}``, ``{"X": 1, "P": 0.001}``).
    comment_open, comment_close : str
        How a comment line is written (header).
    """

    name: str
    siemens: bool
    codes: dict[str, str]
    decimal_point: bool
    dwell_letters: dict[str, float]
    comment_open: str
    comment_close: str = ""
    extra_codes: dict[str, str] = field(default_factory=dict)

    def action(self, code: str) -> str | None:
        """Action of a normalised code, or None when the dialect does not know it."""
        return self.extra_codes.get(code) or self.codes.get(code)

    def with_codes(self, extra: dict[str, str]) -> Dialect:
        """The dialect with controller-specific codes added (``--rtcp-on M428``)."""
        return Dialect(self.name, self.siemens, self.codes, self.decimal_point, self.dwell_letters,
                       self.comment_open, self.comment_close, {**self.extra_codes, **extra})

    def comment(self, text: str) -> str:
        """A comment line holding ``text`` (parentheses removed where they would end it)."""
        if self.comment_close:
            text = text.replace("(", "[").replace(")", "]")
        return f"{self.comment_open}{text}{self.comment_close}"


def common_codes() -> dict[str, str]:
    """G/M codes that mean the same on every supported controller."""
    codes = {"G0": "motion:G0", "G1": "motion:G1", "G2": "motion:G2", "G3": "motion:G3", "G4": "dwell",
             "G17": "plane:G17", "G18": "plane:G18", "G19": "plane:G19", "G40": "comp:off", "G41": "comp:on",
             "G42": "comp:on", "G90": "dist:abs", "G91": "dist:inc",
             "G93": "feed:G93", "G94": "feed:G94", "G95": "feed:G95",
             "G53": "machine", "G54": "offset", "G55": "offset", "G56": "offset", "G57": "offset",
             "G9": "benign", "G61": "benign", "G64": "benign", "G96": "benign", "G97": "benign",
             "M0": "stop", "M1": "stop", "M2": "end", "M30": "end"}
    for m in (3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 19, 31, 33, 34, 50, 51, 88, 89):
        codes[f"M{m}"] = "benign"
    return codes


def get_dialect(name: str) -> Dialect:
    """The dialect called ``name`` (``siemens``, ``fanuc``/``haas``/``iso``, ``linuxcnc``)."""
    from pige_sym.errors import InputError

    key = name.lower()
    if key == "siemens":
        from pige_sym.nc.dialects.siemens import SIEMENS
        return SIEMENS
    if key in ("fanuc", "haas", "iso"):
        from pige_sym.nc.dialects.fanuc import FANUC
        return FANUC
    if key == "linuxcnc":
        from pige_sym.nc.dialects.linuxcnc import LINUXCNC
        return LINUXCNC
    raise InputError(f"unknown dialect {name!r}: use siemens, fanuc (also Haas) or linuxcnc")


