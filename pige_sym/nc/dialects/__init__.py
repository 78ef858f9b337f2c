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

from pige_sym.nc.dialects.base import Dialect as Dialect


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


