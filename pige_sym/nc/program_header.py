"""The machine-readable header pige writes into its NC programs, and its reader.

A program pige writes states what a later command must know to read it right: the machine, the commanded
axis sense (CONVENTIONS §9) and, for probing programs, the kinematics, pivots, sphere, stylus and work
offset.  Each item is one comment line, in the dialect's own comment form::

    (pige KEY: VALUE)            linuxcnc, fanuc
    ; pige KEY: VALUE            siemens, heidenhain (after the block number)

``KEY`` is ``[A-Za-z0-9_]+``; ``VALUE`` is free text without parentheses (a machine code's ``(C1)`` is
written ``[C1]`` and read back as ``(C1)``).  A key given twice with different values is refused (a
compensated program repeats its source's items: the same value twice is one item).  Other comments are ignored, so
the header survives any editor that keeps comments, and a program without one (a CAM program) reads as an
empty header.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

from pige_sym.errors import InputError, NCProgramError

_PAREN = re.compile(r"^\s*(?:N\d+\s+)?\(pige ([A-Za-z0-9_]+): (.*)\)\s*$")
_SEMI = re.compile(r"^\s*(?:\d+\s+|N\d+\s+)?; ?pige ([A-Za-z0-9_]+): (.*?)\s*$")


def header_lines(items: Mapping[str, str], dialect: str) -> list[str]:
    """The comment lines of ``items`` in ``dialect`` (module docstring)."""
    out = []
    for key, value in items.items():
        if not re.fullmatch(r"[A-Za-z0-9_]+", key) or "\n" in value:
            raise ValueError(f"header item {key!r}: a key of [A-Za-z0-9_] and a one-line value")
        text = value.replace("(", "[").replace(")", "]")
        out.append(f"; pige {key}: {text}" if dialect in ("siemens", "heidenhain") else f"(pige {key}: {text})")
    return out


def read_header(text: str, path: str = "<program>") -> dict[str, str]:
    """Every ``pige KEY: VALUE`` comment of a program (machine codes with ``[C1]`` given back as ``(C1)``).

    Raises
    ------
    NCProgramError
        A key given twice with different values (names both lines).
    """
    return {key: value for key, (value, _) in read_header_lines(text, path).items()}


def read_header_lines(text: str, path: str = "<program>") -> dict[str, tuple[str, int]]:
    """:func:`read_header` with the 1-based line of each item (its first line), for messages."""
    out: dict[str, tuple[str, int]] = {}
    for no, line in enumerate(text.splitlines(), 1):
        m = _PAREN.match(line) or _SEMI.match(line)
        if not m:
            continue
        key, value = m.group(1), m.group(2).strip()
        if key == "machine":
            value = value.replace("[", "(").replace("]", ")")
        if key in out and out[key][0] != value:
            raise NCProgramError(path, no, f"header item 'pige {key}: {value}' contradicts line {out[key][1]} "
                                           f"('{out[key][0]}')")
        out.setdefault(key, (value, no))
    return out


def program_axis_sense(text: str, rotary_axes: Sequence[str], path: str, given: Mapping[str, int] | None, *,
                       given_by: str = "--axis-sense", fix: str | None = None) -> dict[str, int]:
    """The commanded axis sense of a program: its header's, checked against ``given`` (``--axis-sense`` unless
    ``given_by`` names another source, :func:`~pige_sym.measurements.axis_sense.reconcile`).

    A program without the header item (a CAM program) takes ``given`` (None: CONVENTIONS' sense).
    """
    from pige_sym.measurements.axis_sense import METADATA_KEY, parse_axis_sense, reconcile

    header = read_header(text, path)
    if METADATA_KEY not in header:
        return {a: -1 for a in rotary_axes if (given or {}).get(a, 1) == -1}
    try:
        recorded = parse_axis_sense(header[METADATA_KEY], rotary_axes, f"{path}: pige {METADATA_KEY}")
    except InputError as exc:
        raise NCProgramError(path, None, str(exc)) from None
    return reconcile(recorded, given, path, rotary_axes, given_by=given_by, fix=fix)
