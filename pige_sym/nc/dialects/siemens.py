"""Siemens SINUMERIK 840D sl: G codes, keywords and calls the interpreter understands.

Comments ``;``; strings in ``MSG("…")``; ``X=AC(…)``/``X=IC(…)``/``C=DC(…)``/``ACP``/``ACN``
word forms; RTCP ``TRAORI``/``TRAORI(n)`` on, ``TRAFOOF`` off; inch ``G70``/``G700``,
metric ``G71``/``G710``; frames ``TRANS ROT SCALE MIRROR`` (and ``A…`` additive forms,
``CYCLE800``, ``G58``/``G59``) make the program coordinates unknown until ``TRANS``/``ROT``
… are programmed without axes (which clears the programmable frame); ``SUPA``/``G53``/
``G153`` are non-modal machine coordinates, ``G74``/``G75`` reference/fixed-point moves.
Calls (``L…``, ``CALL``, cycles other than the settings cycle ``CYCLE832``) and control flow
(``GOTO…``, ``IF``, loops) are refused.  Spline/polynomial motion (``BSPLINE``, ``POLY``,
``CIP``, ``CT``, ``G33``) are motions whose path the tool cannot follow: refused.
"""

from __future__ import annotations

from pige_sym.nc.dialects.base import Dialect, common_codes

_CODES = common_codes() | {
    "G70": "units:inch", "G700": "units:inch", "G71": "units:mm", "G710": "units:mm",
    "G153": "machine", "SUPA": "machine", "G74": "ref", "G75": "ref",
    "G500": "offset", "G58": "frame:set", "G59": "frame:set",
    "TRAORI": "rtcp:on", "TRAFOOF": "rtcp:off",
    "TRANS": "frame:set", "ATRANS": "frame:set", "ROT": "frame:set", "AROT": "frame:set",
    "SCALE": "frame:set", "ASCALE": "frame:set", "MIRROR": "frame:set", "AMIRROR": "frame:set",
    "ROTS": "frame:set", "AROTS": "frame:set", "CYCLE800": "frame:set", "G25": "refuse:working-area limits",
    "G26": "refuse:working-area limits", "G110": "refuse:polar coordinates", "G111": "refuse:polar coordinates",
    "G112": "refuse:polar coordinates", "TRACYL": "refuse:cylinder transformation",
    "TRANSMIT": "refuse:TRANSMIT transformation", "TRAANG": "refuse:inclined-axis transformation",
    "G33": "motion:other", "G331": "motion:other", "G332": "motion:other", "CIP": "motion:other",
    "CT": "motion:other", "BSPLINE": "motion:other", "ASPLINE": "motion:other", "CSPLINE": "motion:other",
    "POLY": "motion:other", "G60": "benign", "G601": "benign", "G602": "benign", "G603": "benign",
    "G641": "benign", "G642": "benign", "G643": "benign", "G644": "benign", "G645": "benign", "G450": "benign",
    "G451": "benign", "SOFT": "benign", "BRISK": "benign", "FFWON": "benign", "FFWOF": "benign",
    "COMPON": "benign", "COMPCURV": "benign", "COMPCAD": "benign", "COMPOF": "benign", "ORIWKS": "benign",
    "ORIMKS": "benign", "ORIAXES": "benign", "ORIVECT": "benign", "UPATH": "benign", "SPATH": "benign",
    "STOPRE": "benign", "DIAMOF": "benign", "FNORM": "benign", "FLIN": "benign", "FCUB": "benign",
    "CYCLE832": "benign", "MSG": "benign", "FGROUP": "benign",
    "M17": "end", "RET": "end", "CUT3DC": "comp:on", "CUT3DF": "comp:on", "CUT2D": "benign",
    "G40": "comp:off",
}
for _n in range(505, 600):
    _CODES[f"G{_n}"] = "offset"
for _kw in ("GOTO", "GOTOF", "GOTOB", "GOTOC", "IF", "ELSE", "ENDIF", "WHILE", "ENDWHILE", "FOR", "ENDFOR",
            "LOOP", "ENDLOOP", "REPEAT", "UNTIL", "CASE", "DEF", "PROC"):
    _CODES[_kw] = "refuse:control flow"
for _kw in ("CALL", "PCALL", "MCALL", "EXTCALL", "L"):
    _CODES[_kw] = "refuse:subprogram call"

SIEMENS = Dialect("siemens", True, _CODES, decimal_point=False, dwell_letters={"F": 1.0},
                  comment_open="; ")
