"""Touch-probe logs: the contacts a probing program recorded, strictly read (CONVENTIONS §7).

Formats
-------
``linuxcnc``
    What LinuxCNC writes between ``(PROBEOPEN file)`` and ``(PROBECLOSE)``: one line per probe trip,
    ``X Y Z A B C U V W`` as ``"%f %f %f %f %f %f %f %f %f\\n"`` (``src/emc/task/emccanon.cc``, see
    ``docs/probe.md``): nine numbers, single spaces, six decimals, no header, program units, work
    coordinates.  The pose of a contact is its rotary angles (the line's A B C).
``fanuc``, ``siemens``, ``heidenhain``
    The layout ``pige program --instrument sphere-probe`` makes the controller write (DPRNT, WRITE,
    FN 16 F-PRINT), one line per contact::

        PIGE P<pose> K<contact> X<x> Y<y> Z<z> <axis1><angle1> <axis2><angle2>

    where a sign and spaces may stand between a letter and its number (DPRNT pads numbers with
    spaces) and numbers are ASCII decimals.  Blank lines and ``%`` lines (tape marks) are ignored.

Numbers are strict ASCII decimals (no NaN, no infinity, no exponent-only forms), within
:data:`~pige_sym.measurements.measurement.LIMITS`; every refusal is a
:class:`~pige_sym.errors.FileFormatError` naming the file and the 1-based line.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import open_regular_file
from pige_sym.measurements.measurement import LIMITS
from pige_sym.options import strict_float

PROBE_FORMATS = ("linuxcnc", "fanuc", "siemens", "heidenhain")
LINUXCNC_AXES = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
INCH_MM = 25.4
_NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)"
_PIGE_FIELD = re.compile(rf"([A-Z])\s*({_NUMBER})")


@dataclass
class ProbeLog:
    """The contacts of a probe log.

    Attributes
    ----------
    path : str
    format : str
    rotary_axes : tuple of str
        Column order of ``angles_deg``.
    xyz_mm : ndarray, shape=(N, 3) [mm]
        Controlled point at each contact, in the log's coordinates (inch logs converted).
    angles_deg : ndarray, shape=(N, k) [deg]
    lines : ndarray, shape=(N,) of int
        1-based line of each contact (for messages).
    pose_index : ndarray, shape=(N,) of int or None
        The pose number the program wrote (PIGE layout), None for LinuxCNC.
    """

    path: str
    format: str
    rotary_axes: tuple[str, ...]
    xyz_mm: np.ndarray
    angles_deg: np.ndarray
    lines: np.ndarray
    pose_index: np.ndarray | None = None


def _number(text: str, path: str, line: int, field: str, limit: float) -> float:
    value = strict_float(text)
    if value is None:
        raise FileFormatError(path, line, f"{field}: {text!r} is not a finite ASCII decimal number")
    if abs(value) > limit:
        raise FileFormatError(path, line, f"{field}: {value:g} is beyond ±{limit:g}: not a physical value")
    return value


def _read_lines(path: str | os.PathLike[str]) -> list[str]:
    with open_regular_file(path) as fh:
        raw = fh.read()
    try:
        return raw.decode("ascii").splitlines()
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise FileFormatError(str(path), line, "not an ASCII text file (a probe log is plain ASCII)") from None


def _read_linuxcnc(path: str, lines: list[str], rotary_axes: tuple[str, ...], scale: float) -> ProbeLog:
    idx = [LINUXCNC_AXES.index(a) for a in rotary_axes]
    xyz, ang, where = [], [], []
    for no, text in enumerate(lines, 1):
        if not text.strip():
            continue
        tokens = text.split(" ")
        if len(tokens) != 9 or not all(tokens):
            n = len(text.split())
            what = f"{n} fields" if n != 9 else "fields not separated by single spaces"
            raise FileFormatError(path, no, f"a LinuxCNC probe line holds nine numbers 'X Y Z A B C U V W' separated "
                                            f"by single spaces; this one has {what}: {text[:60]!r}")
        vals = [_number(t, path, no, LINUXCNC_AXES[k], LIMITS["mm"] if k < 3 or k > 5 else LIMITS["deg"])
                for k, t in enumerate(tokens)]
        xyz.append([v * scale for v in vals[:3]])
        ang.append([vals[i] for i in idx])
        others = [LINUXCNC_AXES[k] for k in (3, 4, 5) if k not in idx and vals[k] != 0.0]
        if others:
            raise FileFormatError(path, no, f"axis {others[0]} = {vals[LINUXCNC_AXES.index(others[0])]:g} moved, but "
                                            f"the machine's rotary axes are {', '.join(rotary_axes)}: a log of "
                                            "another machine?")
        where.append(no)
    return _log(path, "linuxcnc", rotary_axes, xyz, ang, where, None)


def _read_pige(path: str, fmt: str, lines: list[str], rotary_axes: tuple[str, ...], scale: float) -> ProbeLog:
    want = ["P", "K", "X", "Y", "Z", *rotary_axes]
    xyz, ang, where, poses = [], [], [], []
    for no, text in enumerate(lines, 1):
        body = text.strip()
        if not body or body.startswith("%"):
            continue
        if not body.startswith("PIGE"):
            raise FileFormatError(path, no, f"not a contact line (expected 'PIGE P.. K.. X.. Y.. Z.. "
                                            f"{' '.join(a + '..' for a in rotary_axes)}'): {body[:60]!r}")
        rest = body[4:]
        fields = _PIGE_FIELD.findall(rest)
        if _PIGE_FIELD.sub("", rest).strip() or [f for f, _ in fields] != want:
            got = " ".join(f for f, _ in fields) or "nothing"
            raise FileFormatError(path, no, f"fields {got}; a contact line has {' '.join(want)} in this order")
        vals = {f: _number(v, path, no, f, LIMITS["deg"] if f in rotary_axes else LIMITS["mm"]) for f, v in fields}
        for f in ("P", "K"):
            if vals[f] != int(vals[f]) or vals[f] < 0:
                raise FileFormatError(path, no, f"{f}: {vals[f]:g} is not a pose/contact number")
        xyz.append([vals["X"] * scale, vals["Y"] * scale, vals["Z"] * scale])
        ang.append([vals[a] for a in rotary_axes])
        poses.append(int(vals["P"]))
        where.append(no)
    return _log(path, fmt, rotary_axes, xyz, ang, where, poses)


def _log(path: str, fmt: str, rotary_axes: tuple[str, ...], xyz: list, ang: list, where: list[int],
         poses: list[int] | None) -> ProbeLog:
    if not xyz:
        raise FileFormatError(path, None, "no contact in the probe log")
    angles = np.array(ang, dtype=float).reshape(len(xyz), -1)
    return ProbeLog(path, fmt, rotary_axes, np.array(xyz, dtype=float), angles, np.array(where, dtype=int),
                    None if poses is None else np.array(poses, dtype=int))


def read_probe_log(path: str | os.PathLike[str], fmt: str, rotary_axes: tuple[str, ...], *,
                   units: str = "mm") -> ProbeLog:
    """Read a probe log (module docstring).

    Parameters
    ----------
    path : path-like
    fmt : {"linuxcnc", "fanuc", "siemens", "heidenhain"}
    rotary_axes : tuple of str
        The machine's rotary axes (the angle columns, in this order).
    units : {"mm", "inch"}
        Units of X Y Z in the log (LinuxCNC writes program units).

    Returns
    -------
    ProbeLog
    """
    if fmt not in PROBE_FORMATS:
        raise InputError(f"--format {fmt!r}: use one of {', '.join(PROBE_FORMATS)}")
    if units not in ("mm", "inch"):
        raise InputError(f"--units {units!r}: use mm or inch")
    scale = INCH_MM if units == "inch" else 1.0
    lines = _read_lines(path)
    if fmt == "linuxcnc":
        return _read_linuxcnc(str(path), lines, rotary_axes, scale)
    return _read_pige(str(path), fmt, lines, rotary_axes, scale)


def group_poses(log: ProbeLog, *, angle_tol_deg: float = 1e-4) -> list[np.ndarray]:
    """Contacts grouped by pose, in the order the poses were probed: a list of row-index arrays.

    A pose is a run of consecutive contacts with the same pose number (PIGE layout; its rotary angles must
    not change within it) or, in a LinuxCNC log, at the same rotary angles (within ``angle_tol_deg``: two
    consecutive poses at the same angles are one pose there).  Returning to an earlier pose's angles later
    is a new pose (a repeated pose is a measurement of drift).
    """
    a = log.angles_deg
    moved = np.ones(len(a), dtype=bool)
    moved[1:] = np.abs(np.diff(a, axis=0)).max(axis=1, initial=0) > angle_tol_deg
    new = moved
    if log.pose_index is not None:
        new = np.ones(len(a), dtype=bool)
        new[1:] = np.diff(log.pose_index) != 0
        bad = np.flatnonzero(moved & ~new)
        if bad.size:
            i = int(bad[0])
            raise FileFormatError(log.path, int(log.lines[i]), f"pose P{log.pose_index[i]}: the rotary angles changed "
                                                                "within one pose")
    starts = np.flatnonzero(new)
    return [np.arange(s, e) for s, e in zip(starts, [*starts[1:], len(a)], strict=True)]
