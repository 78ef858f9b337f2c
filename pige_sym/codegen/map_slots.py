"""The slots of a rotary axis' error maps in generated code (CONVENTIONS §10), for the C model and its pins.

Per axis seven slots: the six error motions of the body it carries in the order of CONVENTIONS §10's table
(radial translations, axial translation, tilts, positioning φ), then the reversal map of φ (φ⁺ − φ⁻).  Each slot
drives one of the kernels' motion columns (``dx dy dz rx ry rz``, the carried body's translation [µm] and small
rotation [µrad]); φ and its reversal drive the rotation about the axis' own direction.  This is the code
generator's copy of :func:`pige_sym.model.error_motions.axis_motions` (the model layer sits above codegen); the
tests check that the two agree.
"""

from __future__ import annotations

from pige_sym.errors import InputError

#: The kernels' motion columns of one rotary axis, in order.
MOTION_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")


def map_slots(axis: str) -> list[tuple[str, str, str]]:
    """``(name, component, kind)`` of each slot of ``axis`` (``C``, ``A``, ``C2``), e.g. ``("EXC", "dx", "radial")``.

    Raises
    ------
    InputError
        Not a rotary axis.
    """
    letter = axis[:1].upper()
    if letter not in ("A", "B", "C"):
        raise InputError(f"{axis!r} is not a rotary axis (A, B or C)")
    d = "ABC".index(letter)
    suffix = axis[1:]
    others = [j for j in range(3) if j != d]
    out = [(f"E{'XYZ'[j]}{letter}{suffix}", "d" + "xyz"[j], "radial") for j in others]
    out.append((f"E{'XYZ'[d]}{letter}{suffix}", "d" + "xyz"[d], "axial"))
    out += [(f"E{'ABC'[j]}{letter}{suffix}", "r" + "xyz"[j], "tilt") for j in others]
    out.append((f"E{letter}{letter}{suffix}", "r" + "xyz"[d], "positioning"))
    out.append((f"E{letter}{letter}{suffix}:reversal", "r" + "xyz"[d], "reversal"))
    return out
