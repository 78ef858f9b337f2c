"""LinuxCNC rs274ngc: the codes the interpreter understands.

Comments ``( … )`` and ``;``; spaces may appear anywhere between a letter and its number.
No built-in RTCP G-code: a kinematics switch (``trtkins`` via ``M428``/``M429`` or similar
user M-codes) is declared with ``--rtcp-on``/``--rtcp-off``.  Inch ``G20``/metric ``G21``;
work offsets ``G54``–``G59.3``; ``G92`` (cancel ``G92.1``/``G92.2``), ``G10 L…`` (offsets
changed: nothing after is compensated); reference ``G28``/``G30``; machine ``G53``;
probing ``G38.x`` (end unknown); canned cycles ``G73 G76 G81–G89`` (cancel ``G80``);
``G5``/``G5.1``/``G5.2`` splines and ``G33`` threads are motions whose path is not tracked.
O-codes (subroutines, loops, conditionals), parameters ``#`` and expressions ``[ ]`` are
refused.  Dwell ``G4 P<s>`` (seconds).
"""

from __future__ import annotations

from pige_sym.nc.dialects.base import Dialect, common_codes

_CODES = common_codes() | {
    "G20": "units:inch", "G21": "units:mm", "G58": "offset", "G59": "offset", "G59.1": "offset",
    "G59.2": "offset", "G59.3": "offset", "G43": "benign", "G43.1": "benign", "G49": "benign",
    "G92": "frame:set", "G92.1": "frame:cancel", "G92.2": "frame:cancel", "G92.3": "frame:set",
    "G10": "frame:lock", "G28": "ref", "G30": "ref", "G28.1": "benign", "G30.1": "benign",
    "G80": "cycle:cancel", "G33": "motion:other", "G33.1": "motion:other", "G5": "motion:other",
    "G5.1": "motion:other", "G5.2": "motion:other", "G5.3": "motion:other", "G38.2": "motion:other",
    "G38.3": "motion:other", "G38.4": "motion:other", "G38.5": "motion:other", "G7": "benign", "G8": "benign",
    "G61.1": "benign", "G90.1": "benign", "G91.1": "benign", "G98": "benign", "G99": "benign", "G64": "benign",
    "G41.1": "comp:on", "G42.1": "comp:on", "G40": "comp:off", "M48": "benign", "M49": "benign", "M60": "stop",
}
for _c in ("G73", "G76", "G81", "G82", "G83", "G84", "G85", "G86", "G87", "G88", "G89"):
    _CODES[_c] = "cycle"

LINUXCNC = Dialect("linuxcnc", False, _CODES, decimal_point=False, dwell_letters={"P": 1.0},
                   comment_open="(", comment_close=")")
