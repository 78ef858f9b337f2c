"""The dialect record (:class:`Dialect`) and the codes every supported controller shares.

The action vocabulary is documented in :mod:`pige_sym.nc.dialects`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field


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


def kinematics_switch_codes(dialect: Dialect | None, on: Iterable[str] = (),
                            off: Iterable[str] = ()) -> dict[str, str]:
    """Normalised code → ``rtcp:on`` / ``rtcp:off`` for the controller's own switch codes (``--rtcp-on M428``).

    Codes are compared as the lexer reads them (``M0429`` and ``m429`` are ``M429``).  One code cannot
    switch both ways (the program would leave the machine in whichever kinematics the controller gives
    it), nor one the dialect already gives another meaning (``M2`` ends the program, ``G1`` moves);
    ``dialect`` None: a language without a table here (HEIDENHAIN), only the first check.

    Raises
    ------
    InputError
        Not one G/M code or keyword, a code given for both switches, or a code that already means
        something else in the dialect; naming the options.
    """
    from pige_sym.errors import InputError, LexError
    from pige_sym.nc.lexer import tokenize

    out: dict[str, str] = {}
    given: dict[str, str] = {}
    for codes, action, flag in ((on, "rtcp:on", "--rtcp-on"), (off, "rtcp:off", "--rtcp-off")):
        for c in codes:
            try:
                toks = tokenize(c.strip(), siemens=dialect is not None and dialect.siemens)
            except LexError:
                toks = []
            if len(toks) != 1 or toks[0].kind not in ("word", "name"):
                raise InputError(f"{flag} {c!r}: give one G/M code or keyword, e.g. M428")
            code = toks[0].code
            if out.get(code, action) != action:
                raise InputError(f"{given[code]} {code} and {flag} {c}: one code cannot switch the kinematics both "
                                 "on and off; give the configuration's two codes (the shipped trt sims: --rtcp-on M428 "
                                 "--rtcp-off M429)")
            meaning = dialect.codes.get(code) if dialect is not None else None
            if dialect is not None and meaning is not None and meaning != action:
                raise InputError(f"{flag} {c}: {code} already means {meaning} in {dialect.name} programs; give the "
                                 "configuration's own kinematics switch code")
            out[code], given[code] = action, flag
    return out


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
