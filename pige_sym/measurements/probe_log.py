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

from pige_sym.constants import PROBE_FORMATS
from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import read_input_bytes
from pige_sym.measurements.decimal_fields import parse_decimal_fields
from pige_sym.measurements.measurement import LIMITS
from pige_sym.options import strict_float

LINUXCNC_AXES = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
INCH_MM = 25.4
_NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"  # an exponent too: the value is then checked (bounds)
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


def _read_lines(path: str | os.PathLike[str], raw: bytes | None = None) -> list[str]:
    if raw is None:
        raw = read_input_bytes(path, what="probe log")
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
        left = _PIGE_FIELD.sub(" ", rest).split()
        if left:
            raise FileFormatError(path, no, f"{left[0]!r} is not a field (a letter and an ASCII decimal); a contact "
                                            f"line has {' '.join(want)} in this order")
        if [f for f, _ in fields] != want:
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
    return parse_probe_log(str(path), read_input_bytes(path, what="probe log"), fmt, rotary_axes, units=units)


def parse_probe_log(path: str, raw: bytes, fmt: str, rotary_axes: tuple[str, ...], *, units: str = "mm") -> ProbeLog:
    """A probe log from its bytes (:func:`read_probe_log`; ``path`` names it in messages)."""
    scale = INCH_MM if units == "inch" else 1.0
    if fmt == "linuxcnc":
        fast = _linuxcnc_fast(str(path), raw, rotary_axes, scale)
        return fast if fast is not None else _read_linuxcnc(str(path), _read_lines(path, raw), rotary_axes, scale)
    return _read_pige(str(path), fmt, _read_lines(path, raw), rotary_axes, scale)


#: Bytes a LinuxCNC log written with ``%f`` holds: digits, sign, point, space, line ends.
_LINUXCNC_BYTES = b"0123456789.-+ \n\r"
_CHUNK_LINES = 16384


def _linuxcnc_fast(path: str, raw: bytes, rotary_axes: tuple[str, ...], scale: float) -> ProbeLog | None:
    """The LinuxCNC log read vectorised (the same values, bit for bit, as :func:`_read_linuxcnc`), or None when
    a line needs the strict path: a byte other than digits, sign, point, space and line ends, a lone ``\\r``,
    a line that is not nine fields separated by single spaces, or a field that is not a number.  Physical
    limits and axes of another machine are refused here with the strict path's messages."""
    if raw.translate(None, _LINUXCNC_BYTES):
        return None  # a byte other than digits, sign, point, space and line ends
    buf = np.frombuffer(raw, dtype=np.uint8)
    step = 1 << 23  # newlines found 8 MiB at a time: no file-sized temporary
    newline = np.concatenate([np.flatnonzero(buf[i:i + step] == 10) + i for i in range(0, max(buf.size, 1), step)])
    begin = np.concatenate([[0], newline + 1])
    end = np.concatenate([newline, [buf.size]])
    carriages = raw.count(b"\r")
    if carriages:
        at_end = (end > begin) & (buf[np.maximum(end - 1, 0)] == 13)
        if carriages != int(at_end.sum()):
            return None  # a carriage return inside a line
        end = end - at_end
    used = np.flatnonzero(end > begin)  # empty lines are skipped
    values = np.empty((used.size, 9))
    for first in range(0, used.size, _CHUNK_LINES):
        block = used[first:first + _CHUNK_LINES]
        parsed = _fields(buf, begin[block], end[block])
        if parsed is None:
            return None
        values[first:first + block.size] = parsed
    lines = used + 1
    _check_linuxcnc(path, values, lines, rotary_axes)
    idx = [LINUXCNC_AXES.index(a) for a in rotary_axes]
    return ProbeLog(path, "linuxcnc", rotary_axes, values[:, :3] * scale if scale != 1.0 else values[:, :3].copy(),
                    values[:, idx].reshape(used.size, -1), lines.astype(int), None) if used.size else None


def _fields(buf: np.ndarray, begin: np.ndarray, end: np.ndarray) -> np.ndarray | None:
    """The nine numbers of each line ``buf[begin:end]`` (L, 9); None when a line is not nine single-spaced numbers.

    Works on the lines' own bytes (a slice of ``buf``), so a chunk costs its size, not the file's.
    """
    lo, hi = int(begin[0]), int(end[-1])
    part = buf[lo:hi]
    begin, end = begin - lo, end - lo
    space = np.flatnonzero(part == 32)
    line = np.searchsorted(begin, space, side="right") - 1
    inside = space < end[line]  # spaces between lines (none: lines are contiguous up to their end) are refused
    if not inside.all() or not np.array_equal(np.bincount(line, minlength=begin.size), np.full(begin.size, 8)):
        return None
    if (space == begin[line]).any() or (space + 1 == end[line]).any() or (part[space + 1] == 32).any():
        return None  # an empty field
    per_line = space.reshape(-1, 8)  # eight spaces per line, in order (checked above)
    ends = np.column_stack([per_line, end]).ravel()
    starts = np.column_stack([begin, per_line + 1]).ravel()
    parsed = parse_decimal_fields(part, ends, starts)
    return None if parsed is None else parsed.reshape(-1, 9)


def _check_linuxcnc(path: str, values: np.ndarray, lines: np.ndarray, rotary_axes: tuple[str, ...]) -> None:
    """Physical limits and the machine's axes, as the strict path refuses them (first offence, located)."""
    limits = np.array([LIMITS["mm"]] * 3 + [LIMITS["deg"]] * 3 + [LIMITS["mm"]] * 3)
    beyond = np.abs(values) > limits
    others = [k for k in (3, 4, 5) if LINUXCNC_AXES[k] not in rotary_axes]
    moved = values[:, others] != 0.0
    first_beyond = int(np.argmax(beyond.any(axis=1))) if beyond.any() else values.shape[0]
    first_moved = int(np.argmax(moved.any(axis=1))) if moved.any() else values.shape[0]
    if first_beyond <= first_moved and first_beyond < values.shape[0]:
        r, k = first_beyond, int(np.argmax(beyond[first_beyond]))
        raise FileFormatError(path, int(lines[r]), f"{LINUXCNC_AXES[k]}: {values[r, k]:g} is beyond ±{limits[k]:g}: "
                              "not a physical value")
    if first_moved < values.shape[0]:
        r, j = first_moved, int(np.argmax(moved[first_moved]))
        raise FileFormatError(path, int(lines[r]), f"axis {LINUXCNC_AXES[others[j]]} = {values[r, others[j]]:g} moved, "
                              f"but the machine's rotary axes are {', '.join(rotary_axes)}: a log of another machine?")


def group_poses(log: ProbeLog, *, angle_tol_deg: float = 1e-4) -> list[np.ndarray]:
    """Contacts grouped by pose, in probing order: a list of row-index arrays (:func:`pose_starts`)."""
    starts = pose_starts(log, angle_tol_deg=angle_tol_deg)
    return [np.arange(s, e) for s, e in zip(starts[:-1], starts[1:], strict=True)]


def pose_starts(log: ProbeLog, *, angle_tol_deg: float = 1e-4) -> np.ndarray:
    """Where each pose begins among the contacts, in the order the poses were probed, shape=(n + 1,).

    Pose ``i`` is contacts ``starts[i]`` to ``starts[i + 1] - 1``.

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
    return np.append(np.flatnonzero(new), len(a)).astype(np.int64)
