"""Double-ballbar files (format ``pige-ballbar 1``, CONVENTIONS §8): reader and writer.

Grammar::

    file      := format_line meta_line* header_line data_line+ blank*
    format    := "# pige-ballbar 1"
    meta_line := "#" key ":" value           (key: [A-Za-z0-9_]+)
    header    := "t_s," <axis>_deg ("," <axis>_deg)* ",dL_um"   (the machine's rotary axes, in order)
    data_line := number ("," number)*         (finite ASCII decimals, one per column)

Required metadata: ``machine`` (ISO 10791 code), ``table_ball_mm`` (table ball centre at the reference
pose, machine frame, three numbers), ``offset_mm`` (tool ball minus table ball at the reference pose;
its length is the nominal bar length ``L0``, 10–1000 mm), ``zero`` (``relative``: ``dL_um`` is the change of
length since the first row, which must be 0, and carries an unknown constant; ``absolute``: the bar was
zeroed on its calibrator, ``dL_um = |T − P| − L0``).  Optional: ``setup`` (``radial``, ``tangential``,
``axial``), ``axis``, ``source``, ``trajectory``, ``axis_sense`` (commanded senses, CONVENTIONS §9: the angle
columns hold θ_cmd, read as θ = σ·θ_cmd); any other key is kept.  During the test the controller
(RTCP on) keeps the nominal tool ball on the nominal position of the table point
``table_ball + offset``.  ``t_s`` never decreases; ``|dL_um|`` is at most 1e5.  Every refusal is a
:class:`~pige_sym.errors.FileFormatError` naming the file and the 1-based line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.errors import FileFormatError, PigeError
from pige_sym.files import atomic_write_text, open_regular_file, peek_input
from pige_sym.measurements.axis_sense import METADATA_KEY as SENSE_KEY
from pige_sym.measurements.axis_sense import format_axis_sense, read_axis_sense, to_commanded, to_conventions
from pige_sym.measurements.measurement import LIMITS, format_line_problem
from pige_sym.measurements.rtest_body import separator_hint
from pige_sym.options import strict_float

FORMAT_LINE = "# pige-ballbar 1"
ZEROS = ("relative", "absolute")
SETUPS = ("radial", "tangential", "axial")
MIN_LENGTH_MM, MAX_LENGTH_MM = 10.0, 1000.0


@dataclass
class BallbarRun:
    """One ballbar setup: where the balls are and the length changes along the poses.

    Attributes
    ----------
    machine : str
    table_ball_mm, offset_mm : ndarray, shape=(3,) [mm]
    zero : {"relative", "absolute"}
    t_s : ndarray, shape=(n,) [s]
    angles_deg : ndarray, shape=(n, k) [deg]
    rotary_axes : tuple of str
    dl_um : ndarray, shape=(n,) [µm]
    metadata : dict of str to str
    path : str
    axis_sense : dict of str to int
        Axes commanded in the reverse of CONVENTIONS' sense (``angles_deg`` are θ; the file holds σ·θ).
    """

    machine: str
    table_ball_mm: np.ndarray
    offset_mm: np.ndarray
    zero: str
    t_s: np.ndarray
    angles_deg: np.ndarray
    rotary_axes: tuple[str, ...]
    dl_um: np.ndarray
    metadata: dict[str, str] = field(default_factory=dict)
    path: str = "<ballbar>"
    axis_sense: dict[str, int] = field(default_factory=dict)

    @property
    def length_mm(self) -> float:
        return float(np.linalg.norm(self.offset_mm))

    @property
    def n_rows(self) -> int:
        return int(self.dl_um.size)


def bar_directions(rotations: np.ndarray, offset_mm: np.ndarray) -> np.ndarray:
    """The bar's unit direction at each pose, ``n_i = R_w(θ_i)·offset/L0`` (CONVENTIONS §8), shape=(n, 3).

    Parameters
    ----------
    rotations : ndarray, shape=(n, 3, 3)
        Nominal workpiece rotation at each pose.
    offset_mm : ndarray, shape=(3,) [mm]
        Tool ball − table ball at the reference pose.
    """
    offset = np.asarray(offset_mm, dtype=float)
    return np.einsum("nij,j->ni", rotations, offset / np.linalg.norm(offset))


def is_ballbar_file(path: str | os.PathLike[str]) -> bool:
    """True when the file's first line is the ``pige-ballbar 1`` format line."""
    head = peek_input(path, 80).split(b"\n", 1)[0]
    return head.removeprefix(b"\xef\xbb\xbf").strip() == FORMAT_LINE.encode()


def _vec3(text: str, p: str, line: int, key: str) -> np.ndarray:
    parts = [strict_float(x.strip()) for x in text.split(",")]
    if len(parts) != 3 or any(v is None or abs(v) > LIMITS["mm"] for v in parts):
        raise FileFormatError(p, line, f"{key}: three finite numbers within ±{LIMITS['mm']:g} mm, got {text!r}")
    return np.array(parts, dtype=float)


def _metadata(lines: list[str], p: str) -> tuple[dict[str, str], dict[str, int], int]:
    if not lines or lines[0].removeprefix("\ufeff").strip() != FORMAT_LINE:
        raise FileFormatError(p, 1, format_line_problem(lines[0] if lines else None, FORMAT_LINE))
    meta: dict[str, str] = {}
    where: dict[str, int] = {}
    i = 1
    while i < len(lines) and lines[i].startswith("#"):
        body = lines[i][1:].strip()
        if body:
            key, sep, value = body.partition(":")
            key = key.strip()
            if not sep or not key.replace("_", "").isalnum() or not key.isascii():
                raise FileFormatError(p, i + 1, f"metadata line must be '# key: value', got {lines[i][:60]!r}")
            if key in meta:
                raise FileFormatError(p, i + 1, f"metadata key {key!r} repeated (first on line {where[key]})")
            meta[key], where[key] = value.strip(), i + 1
        i += 1
    for key in ("machine", "table_ball_mm", "offset_mm", "zero"):
        if key not in meta:
            raise FileFormatError(p, i, f"missing required metadata '# {key}: ...'")
    return meta, where, i


def _rows(lines: list[str], start: int, p: str, names: list[str]) -> np.ndarray:
    rows = []
    for no in range(start + 1, len(lines)):
        text = lines[no].strip()
        if not text:
            if any(ln.strip() for ln in lines[no:]):
                raise FileFormatError(p, no + 1, "blank line inside the data")
            break
        fields = text.split(",")
        if len(fields) != len(names):
            raise FileFormatError(p, no + 1, f"expected {len(names)} fields ({', '.join(names)}), got {len(fields)}")
        vals = [strict_float(f.strip()) for f in fields]
        for name, f, v in zip(names, fields, vals, strict=True):
            limit = LIMITS["deg"] if name.endswith("_deg") else LIMITS["um"] if name == "dL_um" else LIMITS["t_s"]
            if v is None or abs(v) > limit:
                raise FileFormatError(p, no + 1, f"{name}: {f.strip()!r} is not a finite number within ±{limit:g}")
        rows.append(vals)
    if not rows:
        raise FileFormatError(p, start + 1, "no data rows")
    return np.array(rows, dtype=float)


def read_ballbar(path: str | os.PathLike[str]) -> BallbarRun:
    """Read and validate a ``pige-ballbar 1`` file (module docstring)."""
    p = str(path)
    with open_regular_file(path) as fh:
        raw = fh.read()
    try:
        lines = raw.decode("utf-8").splitlines()
    except UnicodeDecodeError:
        raise FileFormatError(p, 1, "not UTF-8 text") from None
    meta, where, header_at = _metadata(lines, p)
    try:
        st = parse_machine_code(meta["machine"])
    except PigeError as exc:
        raise FileFormatError(p, where["machine"], f"machine: {exc}") from None
    axes = tuple(a.name for a in st.rotary_axes)
    head = [a.name for a in st.rotary_axes if a.side == "tool"]
    if head:
        raise FileFormatError(p, where["machine"], f"machine {st.canonical} has tool-side rotary axes "
                              f"({', '.join(head)}): {FORMAT_LINE[2:]} holds setups of table machines only (no tool "
                              "offset); measure a head with the R-test or the probe")
    table_ball = _vec3(meta["table_ball_mm"], p, where["table_ball_mm"], "table_ball_mm")
    offset = _vec3(meta["offset_mm"], p, where["offset_mm"], "offset_mm")
    if not MIN_LENGTH_MM <= np.linalg.norm(offset) <= MAX_LENGTH_MM:
        raise FileFormatError(p, where["offset_mm"], f"offset_mm: bar length {np.linalg.norm(offset):g} mm is not "
                                                     f"within {MIN_LENGTH_MM:g}-{MAX_LENGTH_MM:g} mm")
    if meta["zero"] not in ZEROS:
        raise FileFormatError(p, where["zero"], f"zero: {meta['zero']!r}; use relative or absolute")
    if header_at >= len(lines):
        raise FileFormatError(p, header_at, "no column header line after the metadata")
    if "," not in lines[header_at] and separator_hint(lines[header_at], "pige-ballbar"):
        raise FileFormatError(p, header_at + 1, "in the column header" + separator_hint(lines[header_at],
                                                                                         "pige-ballbar"))
    names = [c.strip() for c in lines[header_at].split(",")]
    want = ["t_s", *(f"{a}_deg" for a in axes), "dL_um"]
    if names != want:
        raise FileFormatError(p, header_at + 1, f"columns must be {','.join(want)} for {st.canonical}, got "
                                                f"{lines[header_at][:80]!r}")
    data = _rows(lines, header_at, p, names)
    first = header_at + 2
    if np.any(np.diff(data[:, 0]) < 0):
        raise FileFormatError(p, first + int(np.argmax(np.diff(data[:, 0]) < 0)) + 1, "t_s decreases")
    if meta["zero"] == "relative" and data[0, -1] != 0.0:
        raise FileFormatError(p, first, "zero: relative, but the first dL_um is not 0")
    sense = read_axis_sense(meta.get(SENSE_KEY, ""), axes, p, where.get(SENSE_KEY))
    return BallbarRun(st.canonical, table_ball, offset, meta["zero"], data[:, 0],
                      to_conventions(data[:, 1:-1], sense, axes), axes, data[:, -1], meta, p, axis_sense=sense)


def format_ballbar(run: BallbarRun) -> str:
    """The file text of a run (numbers with ``repr``: a write → read round trip is lossless)."""
    meta = {"machine": run.machine, "table_ball_mm": ", ".join(repr(float(x)) for x in run.table_ball_mm),
            "offset_mm": ", ".join(repr(float(x)) for x in run.offset_mm), "zero": run.zero}
    meta |= {k: v for k, v in run.metadata.items() if k not in meta and k != SENSE_KEY}
    if format_axis_sense(run.axis_sense, run.rotary_axes):
        meta[SENSE_KEY] = format_axis_sense(run.axis_sense, run.rotary_axes)
    lines = [FORMAT_LINE, *(f"# {k}: {v}" for k, v in meta.items()),
             ",".join(["t_s", *(f"{a}_deg" for a in run.rotary_axes), "dL_um"])]
    commanded = to_commanded(run.angles_deg, run.axis_sense, run.rotary_axes)
    for t, ang, dl in zip(run.t_s, commanded, run.dl_um, strict=True):
        lines.append(",".join(repr(float(x)) for x in (t, *ang, dl)))
    return "\n".join(lines) + "\n"


def write_ballbar(run: BallbarRun, path: str | os.PathLike[str]) -> Path:
    """Write a ``pige-ballbar 1`` file atomically."""
    return atomic_write_text(path, format_ballbar(run))
