"""Commanded sense of the rotary axes (CONVENTIONS §9): ``θ = σ·θ_cmd`` per axis, σ ∈ {+1, −1}.

pige computes in CONVENTIONS' angle θ (ISO 841, §2–3).  A controller may command an axis the other way
(LinuxCNC 2.9's ``xyzac-trt-kins`` and ``xyzbc-trt-kins`` turn the table right-handed for positive A/B and
C: σ = −1 for both axes).  Programs, logs and measurement files hold the *commanded* angle θ_cmd; every
reader turns it into θ with the file's σ, every writer turns θ back into θ_cmd and records σ.

Grammar (the ``--axis-sense`` option and the ``axis_sense`` metadata value)::

    axis_sense := "" | item ("," item)*        e.g. ``A=-1,C=-1``
    item       := AXIS "=" sign                 AXIS a rotary axis of the machine (``C``, ``C1``)
    sign       := "-1" | "+1" | "1"

An axis not named has σ = +1.  Files record only the axes with σ = −1 (``# axis_sense: A=-1, C=-1``);
a file without the key is in CONVENTIONS' sense.  A command given an ``--axis-sense`` that differs from
what its input file records refuses the file (:func:`reconcile`): the two would be mixed up.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from pige_sym.errors import FileFormatError, InputError

#: Metadata key of measurement files, program headers and parameter JSON.
METADATA_KEY = "axis_sense"
#: The sense the stock LinuxCNC 2.9 trt kinematics command (CONVENTIONS §9, measured).
LINUXCNC_TRT_SENSE = {"xyzac-trt-kins": "A=-1,C=-1", "xyzbc-trt-kins": "B=-1,C=-1"}

AxisSense = dict[str, int]


def parse_axis_sense(text: str, rotary_axes: Sequence[str], what: str = "--axis-sense") -> AxisSense:
    """The axes with σ = −1 of an ``axis_sense`` text (module grammar).

    Parameters
    ----------
    text : str
        ``A=-1,C=-1``; blank: every axis +1.
    rotary_axes : sequence of str
        The machine's rotary axes.
    what : str
        The option or field named in errors.

    Returns
    -------
    dict of str to int
        Axis → −1 for the reversed axes only (an empty dict: CONVENTIONS' sense).

    Raises
    ------
    InputError
        An unknown axis, a sign other than ±1, an axis given twice, or a malformed item.
    """
    out: dict[str, int] = {}
    seen: set[str] = set()
    for item in filter(None, (x.strip() for x in text.split(","))):
        axis, eq, sign = (part.strip() for part in item.partition("="))
        if not eq or not axis:
            raise InputError(f"{what}: expected AXIS=-1 or AXIS=+1 items (e.g. A=-1,C=-1), got {item!r}")
        if axis not in rotary_axes:
            raise InputError(f"{what}: {axis!r} is not a rotary axis of this machine (axes: {', '.join(rotary_axes)})")
        if axis in seen:
            raise InputError(f"{what}: {axis} is given twice")
        seen.add(axis)
        if sign not in ("-1", "+1", "1"):
            raise InputError(f"{what} {axis}: the sense is -1 (the reverse of CONVENTIONS' sense) or +1, got {sign!r}")
        if sign == "-1":
            out[axis] = -1
    return {a: -1 for a in rotary_axes if a in out}


def format_axis_sense(sense: Mapping[str, int], rotary_axes: Sequence[str] | None = None) -> str:
    """``A=-1, C=-1`` (the reversed axes, in ``rotary_axes`` order when given); ``""`` for CONVENTIONS' sense."""
    axes = [a for a in (rotary_axes if rotary_axes is not None else sense) if sense.get(a, 1) == -1]
    return ", ".join(f"{a}=-1" for a in axes)


def describe_axis_sense(sense: Mapping[str, int], rotary_axes: Sequence[str] | None = None) -> str:
    """Words for messages: ``A=-1, C=-1`` or ``CONVENTIONS' sense (every axis +1)``."""
    return format_axis_sense(sense, rotary_axes) or "CONVENTIONS' sense (every axis +1)"


def sense_vector(sense: Mapping[str, int], rotary_axes: Sequence[str]) -> np.ndarray:
    """σ of every axis in ``rotary_axes`` order, shape=(k,) of ±1.0."""
    return np.array([float(sense.get(a, 1)) for a in rotary_axes])


def to_conventions(commanded_deg: np.ndarray, sense: Mapping[str, int], rotary_axes: Sequence[str]) -> np.ndarray:
    """CONVENTIONS angles θ = σ·θ_cmd, same shape as ``commanded_deg`` ((n, k) or (k,)) [deg].

    The map is its own inverse, so it also turns θ into θ_cmd (:func:`to_commanded`).
    """
    a = np.asarray(commanded_deg, dtype=float)
    if not any(sense.get(x, 1) == -1 for x in rotary_axes):
        return a
    return a * sense_vector(sense, rotary_axes) + 0.0  # + 0.0: no -0.0 in written files


def to_commanded(conventions_deg: np.ndarray, sense: Mapping[str, int], rotary_axes: Sequence[str]) -> np.ndarray:
    """Commanded angles θ_cmd = σ·θ of CONVENTIONS angles [deg] (:func:`to_conventions`)."""
    return to_conventions(conventions_deg, sense, rotary_axes)


def read_axis_sense(text: str, rotary_axes: Sequence[str], path: str, line: int | None) -> AxisSense:
    """The ``axis_sense`` metadata of a file, refused with its file and line when malformed."""
    try:
        return parse_axis_sense(text, rotary_axes, METADATA_KEY)
    except InputError as exc:
        raise FileFormatError(path, line, str(exc)) from None


def reconcile(recorded: Mapping[str, int], given: Mapping[str, int] | None, source: str,
              rotary_axes: Sequence[str], *, given_by: str = "--axis-sense", fix: str | None = None) -> AxisSense:
    """The sense of an input (``recorded``), checked against ``given`` (None: not given).

    ``given`` is ``--axis-sense`` unless ``given_by`` names where it comes from (a parameter file, for a program
    compensated with it); ``fix`` then says what to do (a refusal never blames an option that was not given).

    Raises
    ------
    InputError
        The two disagree: they would be mixed up.
    """
    rec = {a: -1 for a in rotary_axes if recorded.get(a, 1) == -1}
    if given is None:
        return rec
    giv = {a: -1 for a in rotary_axes if given.get(a, 1) == -1}
    if giv != rec:
        said = "says" if given_by == "--axis-sense" else "records"
        raise InputError(f"{source} records the commanded axis sense {describe_axis_sense(rec, rotary_axes)}, but "
                         f"{given_by} {said} {describe_axis_sense(giv, rotary_axes)}: "
                         + (fix or "give the sense the file was made with (or leave --axis-sense out to take the "
                                   "file's)"))
    return rec
    giv = {a: -1 for a in rotary_axes if given.get(a, 1) == -1}
    if giv != rec:
        raise InputError(f"{source} records the commanded axis sense {describe_axis_sense(rec, rotary_axes)}, but "
                         f"--axis-sense says {describe_axis_sense(giv, rotary_axes)}: give the sense the file was "
                         "made with (or leave --axis-sense out to take the file's)")
    return rec
