"""ISO / Fanuc (0i, 30i) and Haas: the codes the interpreter understands.

Comments ``( … )``; every axis value must carry a decimal point (``X120`` would be 120
least increments = 0.120 mm with the default parameter DPI = 0, so it is refused on input
and never written).  RTCP: ``G43.4 H…``/``G43.5 H…`` (Fanuc TCP), ``G234 H…`` (Haas TCPC),
``M128`` (TNC-style ISO programs) on; ``G49``, ``G43``, ``M129`` off.  Inch ``G20``/metric
``G21``.  Work offsets ``G54``–``G59``, ``G54.1 P…``, ``G154 P…`` (Haas); frames
``G68``/``G68.2``/``G68.4`` (cancel ``G69``), scaling ``G51`` (``G50``), mirror ``G51.1``
(``G50.1``), local ``G52``, ``G92``/``G10`` (offsets changed: nothing after is compensated).
Reference ``G28``/``G30``, machine ``G53``.  Canned cycles ``G73 G74 G76 G81–G89`` (cancel
``G80``).  Calls ``M98``/``G65``/``G66`` and macro B (``#``, ``[``, ``IF``, ``GOTO``, ``WHILE``)
are refused.  Dwell ``G04 X<s>`` or ``G04 P<ms>``.
"""

from __future__ import annotations

from pige_sym.nc.dialects.base import Dialect, common_codes

_CODES = common_codes() | {
    "G20": "units:inch", "G21": "units:mm", "G58": "offset", "G59": "offset", "G54.1": "offset",
    "G154": "offset", "G43.4": "rtcp:on", "G43.5": "rtcp:on", "G234": "rtcp:on", "M128": "rtcp:on",
    "G43": "rtcp:off", "G44": "rtcp:off", "G49": "rtcp:off", "M129": "rtcp:off",
    "G68": "frame:set", "G68.2": "frame:set", "G68.3": "frame:set", "G68.4": "frame:set", "G69": "frame:cancel",
    "G51": "frame:set", "G50": "frame:cancel", "G51.1": "frame:set", "G50.1": "frame:cancel",
    "G52": "frame:set", "G92": "frame:lock", "G10": "frame:lock", "G254": "frame:set", "G255": "frame:cancel",
    "G28": "ref", "G30": "ref", "G80": "cycle:cancel", "G15": "benign", "G16": "refuse:polar coordinates",
    "G33": "motion:other", "G5": "refuse:high-speed machining data", "G6.2": "refuse:NURBS interpolation",
    "G5.1": "benign", "G8": "benign", "G187": "benign", "G98": "benign", "G99": "benign", "G40": "comp:off",
    "G61.1": "benign", "G63": "benign", "G94": "feed:G94", "G95": "feed:G95", "G93": "feed:G93",
    "M98": "refuse:subprogram call", "M99": "refuse:subprogram return", "M97": "refuse:subprogram call",
    "G65": "refuse:macro call", "G66": "refuse:macro call", "G67": "benign",
}
for _c in ("G73", "G74", "G76", "G81", "G82", "G83", "G84", "G85", "G86", "G87", "G88", "G89"):
    _CODES[_c] = "cycle"

FANUC = Dialect("fanuc", False, _CODES, decimal_point=True, dwell_letters={"X": 1.0, "U": 1.0, "P": 0.001},
                comment_open="(", comment_close=")")
