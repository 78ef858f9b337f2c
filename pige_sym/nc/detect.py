"""Which controller a program is written for, from the program itself.

Each dialect has markers that only its programs contain (840D: ``%_N_`` headers, ``;``
comments at the start of a line, ``TRAORI``, ``=AC(``, ``MSG(``, ``CYCLE8…``, ``G64x``;
ISO/Fanuc/Haas: ``O1234`` program numbers, ``G43.4``/``G43.5``/``G234``, ``G54.1``/``G154``,
``G68.2``, ``M98``, ``#100``; LinuxCNC: ``o100 sub``, ``#<name>``, ``(MSG,``, ``G64 P``,
``G59.1``, ``G92.1``, ``G38.2``, an ``.ngc`` file name).  The dialect with the most marker
lines wins; the file name is a hint (``.ngc`` LinuxCNC, whose ``;`` comments then do not count for
840D; ``.mpf``/``.spf`` Siemens) that also breaks a tie; any other tie, or a program with no marker, is
refused: give ``--dialect``.
"""

from __future__ import annotations

import re

from pige_sym.errors import InputError

_MARKERS = {
    "siemens": re.compile(
        r"^\s*%_N_|^\s*;|\bTRAORI\b|\bTRAFOOF\b|=\s*(?:AC|IC|DC|ACP|ACN)\s*\(|\bMSG\s*\(|\bCYCLE\d+\s*\("
        r"|\bG64[1-5]\b|\bSUPA\b|\bG500\b|\bG70[01]?\b|\bG71[0]?\b|\bM17\b|\bSOFT\b|\bFFWON\b|\bORIWKS\b"
        r"|\bGOTO[FBC]\b|\bDEF\s|\bT\s*=\s*\"", re.IGNORECASE | re.MULTILINE),
    "fanuc": re.compile(
        r"^\s*O\d{1,5}\b|\bG43\.[45]\b|\bG234\b|\bG54\.1\b|\bG154\b|\bG68\.[234]\b|\bM98\b|\bG65\b|#\d+\s*="
        r"|\bG0?5\.1\b|\bG187\b|\bM128\b|\bG0?4\s*X", re.IGNORECASE | re.MULTILINE),
    "linuxcnc": re.compile(
        r"^\s*o\d+\s+(?:sub|call|if|while|do)\b|#<|\(\s*(?:MSG|DEBUG|PRINT|LOGOPEN)\s*,|\bG64\s*P|\bG59\.[123]\b"
        r"|\bG92\.[123]\b|\bG38\.[2-5]\b|\bG0?4\s*P\s*\d+\.\d", re.IGNORECASE | re.MULTILINE),
}


_SEMICOLON_COMMENT = re.compile(r"^\s*;", re.MULTILINE)


def _extension_hint(path: str) -> str | None:
    """The dialect a file name suggests: ``.ngc`` LinuxCNC, ``.mpf``/``.spf`` Siemens, none otherwise."""
    low = path.lower()
    if low.endswith(".ngc"):
        return "linuxcnc"
    if low.endswith((".mpf", ".spf")):
        return "siemens"
    return None


def detect_dialect(text: str, path: str = "<program>") -> str:
    """``siemens``, ``fanuc`` or ``linuxcnc`` (module docstring).

    Raises
    ------
    InputError
        No marker, or two dialects with as many markers.
    """
    scores = {name: len(rx.findall(text)) for name, rx in _MARKERS.items()}
    hint = _extension_hint(path)
    if hint == "linuxcnc":  # LinuxCNC reads ';' comments too: in an .ngc file they are not 840D markers
        scores["siemens"] -= len(_SEMICOLON_COMMENT.findall(text))
    if hint is not None:
        scores[hint] += 1
    ranked = sorted(scores.items(), key=lambda kv: (-kv[1], kv[0] != hint))
    (best, n1), (second, n2) = ranked[0], ranked[1]
    if n1 == n2 and best == hint:
        return best  # a tie: the file name decides
    if n1 == 0:
        raise InputError(f"{path}: cannot tell which controller the program is for (no dialect-specific code "
                         "found): give --dialect siemens, fanuc or linuxcnc")
    if n1 == n2:
        raise InputError(f"{path}: the program looks like {best} and like {second} ({n1} marker lines each): "
                         "give --dialect")
    return best
