"""Reader and writer of R-test measurement files (format ``pige-rtest 1``, CONVENTIONS §6).

Grammar::

    file      := format_line meta_line* header_line data_line+ blank*
    format    := "# pige-rtest 1"
    meta_line := "#" key ":" value          (key: [A-Za-z0-9_]+; value: free text)
    header    := column ("," column)*       (t_s, <axis>_deg per rotary axis, dx_um, dy_um, dz_um,
                                             optional X_mm, Y_mm, Z_mm, temp_C, n_samples, sd_um,
                                             any other column, kept verbatim)
    data_line := value ("," value)*         (one value per column; finite numbers except in
                                             unknown columns, which are kept as text)

Required metadata: ``machine`` (ISO 10791 code) and ``ball_mm`` (three numbers).
Optional: ``frame`` (``machine`` or ``table``), ``tool_mm`` (required with a tool-side rotary
axis), ``pivot_<axis>_mm``, ``trajectory``, ``units``, ``source``, ``axis_sense`` (the axes commanded
in the reverse of CONVENTIONS' sense, ``A=-1, C=-1``: the angle columns hold θ_cmd and are read as
θ = σ·θ_cmd, CONVENTIONS §9); any other key is kept.  The first data row is
the reference pose (all angles 0, deviation 0); ``t_s`` never decreases.

Numbers are ASCII decimals (``[+-]digits[.digits][e[+-]digits]``): ``1_000``,
Arabic-Indic or full-width digits, ``nan`` and ``inf`` are not numbers.  Values must
be physical (:data:`LIMITS`: e.g. a deviation within ±1e5 µm, a ball position within
±1e5 mm).  A row that repeats an earlier row exactly (a duplicated record) is refused.
Only regular files are read (not FIFOs or devices).  The data body is read in chunks
of :data:`CHUNK_BYTES` after the header is validated, so large files stream; a chunk
whose lines all have the header's number of fields is parsed by the vectorised
:mod:`pige_sym.measurements.decimal_fields` (bit-identical to the strict grammar), any other chunk
line by line; a line longer than :data:`MAX_LINE_BYTES` is refused.

Every refusal is a :class:`~pige_sym.errors.FileFormatError` naming the file, the
1-based line and the problem.  Numbers are written with ``repr`` so that a
write → read round trip is lossless.
"""

from __future__ import annotations

import os
from typing import IO, TYPE_CHECKING

import numpy as np

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.errors import FileFormatError, PigeError
from pige_sym.files import open_regular_file, read_input_text
from pige_sym.measurements.axis_sense import METADATA_KEY, read_axis_sense, to_commanded, to_conventions

if TYPE_CHECKING:
    pass
from pige_sym.measurements.measurement import (
    DEVIATION_COLUMNS,
    FORMAT_LINE,
    FRAMES,
    LINEAR_COLUMNS,
    OPTIONAL_COLUMNS,
    REFERENCE_TOLERANCE,
    Measurement,
    column_limit,
    format_line_problem,
    missing_tool,
    parse_vec3,
)
from pige_sym.measurements.rtest_body import MAX_LINE_BYTES, DataBody, Header, check_numeric_block, separator_hint


class _Lines:
    """Numbered, length-bounded, UTF-8 lines of the header part of a file."""

    def __init__(self, fh: IO[bytes], path: str) -> None:
        self.fh = fh
        self.path = path
        self.number = 0

    def next(self) -> str | None:
        raw = self.fh.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return None
        self.number += 1
        if len(raw) > MAX_LINE_BYTES:
            raise FileFormatError(self.path, self.number, f"line longer than {MAX_LINE_BYTES} bytes")
        if self.number == 1:
            if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw:
                raise FileFormatError(self.path, 1, "UTF-16 text (what 'Unicode text' exports write): save the file "
                                                    "as UTF-8 (Excel: 'CSV UTF-8')")
            raw = raw.removeprefix(b"\xef\xbb\xbf")  # the byte-order mark Excel's 'CSV UTF-8' writes
        try:
            return raw.decode("utf-8").rstrip("\r\n")
        except UnicodeDecodeError as exc:
            raise FileFormatError(self.path, self.number, f"not UTF-8 text ({exc.reason})") from None


def _read_metadata(lines: _Lines, p: str) -> tuple[dict[str, str], dict[str, int], str | None]:
    """Format line and ``# key: value`` lines; returns them and the first line after them."""
    first = lines.next()
    if first is None or first.strip() != FORMAT_LINE:
        raise FileFormatError(p, 1, format_line_problem(first, FORMAT_LINE))
    meta: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    line = lines.next()
    while line is not None and line.startswith("#"):
        body = line[1:].strip()
        if body:
            if ":" not in body:
                raise FileFormatError(p, lines.number, f"metadata line must be '# key: value', got {line[:80]!r}")
            key, value = body.split(":", 1)
            key = key.strip()
            if not key or not all(ch.isascii() and (ch.isalnum() or ch == "_") for ch in key):
                raise FileFormatError(p, lines.number, f"bad metadata key {key[:40]!r}")
            if key in meta:
                raise FileFormatError(p, lines.number,
                                      f"metadata key {key!r} repeated (first on line {meta_line[key]})")
            meta[key] = value.strip()
            meta_line[key] = lines.number
        line = lines.next()
    while line is not None and not line.strip():
        line = lines.next()
    return meta, meta_line, line


def _read_header(fh: IO[bytes], p: str) -> Header:
    lines = _Lines(fh, p)
    meta, meta_line, header = _read_metadata(lines, p)
    for key in ("machine", "ball_mm"):
        if key not in meta:
            raise FileFormatError(p, lines.number, f"missing required metadata '# {key}: ...'")
    try:
        structure = parse_machine_code(meta["machine"])
    except PigeError as exc:
        raise FileFormatError(p, meta_line["machine"], f"unknown machine code: {exc}") from None
    rotary = tuple(a.name for a in structure.rotary_axes)
    if not rotary:
        raise FileFormatError(p, meta_line["machine"], f"machine {meta['machine']!r} has no rotary axis")
    if header is None:
        raise FileFormatError(p, lines.number, "no column header line after the metadata")
    if "," not in header and separator_hint(header):
        raise FileFormatError(p, lines.number, "in the column header" + separator_hint(header))
    names = [c.strip() for c in header.split(",")]
    numeric = _check_columns(p, lines.number, names, structure, rotary)
    extras = [j for j in range(len(names)) if j not in numeric]
    return Header(meta, meta_line, names, lines.number, structure, rotary, numeric, extras)


def _check_columns(p: str, header_line: int, names: list[str], structure: MachineStructure,
                   rotary: tuple[str, ...]) -> list[int]:
    """Validate the column header; returns the indices of the numeric (known) columns."""
    dupes = sorted({c for c in names if names.count(c) > 1})
    if dupes:
        raise FileFormatError(p, header_line, f"duplicated column(s): {', '.join(dupes)}")
    angle_cols = [f"{a}_deg" for a in rotary]
    required = ["t_s", *angle_cols, *DEVIATION_COLUMNS]
    missing = [c for c in required if c not in names]
    if missing:
        raise FileFormatError(
            p, header_line, f"missing column(s) {', '.join(missing)} for machine {structure.canonical} "
            f"(expected {', '.join(required)})"
        )
    unexpected = [c for c in names if c.endswith("_deg") and c not in angle_cols]
    if unexpected:
        raise FileFormatError(
            p, header_line, f"column(s) {', '.join(unexpected)} do not match the rotary axes {rotary} of "
            f"machine {structure.canonical}"
        )
    lin_present = [c for c in LINEAR_COLUMNS if c in names]
    if lin_present and len(lin_present) != 3:
        raise FileFormatError(p, header_line, f"give all of X_mm, Y_mm, Z_mm or none (found {', '.join(lin_present)})")
    known = set(required) | set(LINEAR_COLUMNS) | set(OPTIONAL_COLUMNS)
    return [j for j, c in enumerate(names) if c in known]


def _check_values(p: str, first_line: int, col: dict[str, np.ndarray], extras: dict[str, list[str]],
                  angle_cols: list[str]) -> None:
    """Physical magnitudes, the reference row, time order and duplicated rows (first offence, located)."""
    for name, values in col.items():
        limit, unit = column_limit(name)
        bad = np.abs(values) > limit
        if name in ("n_samples", "sd_um"):
            bad |= values < 0
        if bad.any():
            i = int(np.argmax(bad))
            sign = ", >= 0" if name in ("n_samples", "sd_um") else ""
            raise FileFormatError(p, first_line + i, f"column {name}: {values[i]:g} is not physical "
                                  f"(allowed: |value| <= {limit:g} {unit}{sign})")
    ref_bad = [(c, col[c][0]) for c in (*angle_cols, *DEVIATION_COLUMNS) if abs(col[c][0]) > REFERENCE_TOLERANCE]
    if ref_bad:
        what = ", ".join(f"{c}={v:g}" for c, v in ref_bad)
        raise FileFormatError(p, first_line,
                              f"first data row must be the reference pose (angles 0, deviation 0): {what}")
    t = col["t_s"]
    back = np.nonzero(np.diff(t) < 0)[0]
    if back.size:
        r = int(back[0]) + 1
        raise FileFormatError(p, first_line + r, f"t_s goes backwards ({t[r - 1]:g} then {t[r]:g})")
    dup = _first_duplicate(col, extras)
    if dup is not None:
        raise FileFormatError(p, first_line + dup[1], f"this row repeats line {first_line + dup[0]} exactly "
                              "(a duplicated record): remove one of them")


def _first_duplicate(col: dict[str, np.ndarray], extras: dict[str, list[str]]) -> tuple[int, int] | None:
    """Indices (first, repeat) of the first row equal to an earlier one in every field, or None.

    ``t_s`` never decreases, so equal rows share a time and sit in one run of equal times.
    """
    same = np.flatnonzero(np.diff(col["t_s"]) == 0)
    if not same.size:
        return None
    cand = np.unique(np.concatenate([same, same + 1]))
    block = np.column_stack([v[cand] for v in col.values()])
    seen: dict[tuple[bytes, tuple[str, ...]], int] = {}
    for k, i in enumerate(cand):
        key = (block[k].tobytes(), tuple(v[i] for v in extras.values()))
        if key in seen:
            return seen[key], int(i)
        seen[key] = int(i)
    return None


def read_measurement(path: str | os.PathLike[str]) -> Measurement:
    """Read and validate a ``pige-rtest 1`` file (module docstring: grammar and refusals).

    Raises
    ------
    FileFormatError
        Naming the file, the 1-based line and the problem.
    """
    p = str(path)
    with open_regular_file(path) as fh:
        h = _read_header(fh, p)
        body = DataBody(p, h)
        body.read(fh)
    ball, frame, tool, pivots, sense = _header_values(p, h)
    body.require_rows()
    angle_cols = [f"{a}_deg" for a in h.rotary]
    groups = {"t_s": body.gather(["t_s"]), "angles": body.gather(angle_cols),
              "deviation": body.gather(DEVIATION_COLUMNS)}
    names = {"t_s": ["t_s"], "angles": angle_cols, "deviation": list(DEVIATION_COLUMNS)}
    if "X_mm" in h.names:
        groups["linear"], names["linear"] = body.gather(LINEAR_COLUMNS), list(LINEAR_COLUMNS)
    for c in OPTIONAL_COLUMNS:
        if c in h.names:
            groups[c], names[c] = body.gather([c]), [c]
    col = {c: groups[g][:, i] for g, cs in names.items() for i, c in enumerate(cs)}
    _check_values(p, body.first_line, col, body.extras, angle_cols)
    meta = h.meta
    return Measurement(
        machine=meta["machine"], ball_mm=ball, t_s=groups["t_s"][:, 0],
        angles_deg=to_conventions(groups["angles"], sense, h.rotary), axis_sense=sense,
        deviation_um=groups["deviation"], rotary_axes=h.rotary, frame=frame, tool_mm=tool, pivots_mm=pivots,
        trajectory=meta.get("trajectory"), linear_mm=groups.get("linear"),
        optional={c: groups[c][:, 0] for c in OPTIONAL_COLUMNS if c in groups},
        extra_columns=body.extras, metadata=meta, path=p,
    )


def _header_values(p: str, h: Header) -> tuple[np.ndarray, str, np.ndarray | None, dict[str, np.ndarray],
                                                 dict[str, int]]:
    """Ball, frame, tool, pivots and axis sense from the metadata, validated (file and line in refusals)."""
    meta, meta_line = h.meta, h.meta_line
    ball = parse_vec3(meta["ball_mm"], p, meta_line["ball_mm"], "ball_mm")
    frame = meta.get("frame", "machine")
    if frame not in FRAMES:
        raise FileFormatError(p, meta_line.get("frame"), f"frame must be 'machine' or 'table', got {frame!r}")
    tool = parse_vec3(meta["tool_mm"], p, meta_line["tool_mm"], "tool_mm") if "tool_mm" in meta else None
    why = missing_tool(meta["machine"], tool, "'# tool_mm: x, y, z' (pige writes it when given --tool)")
    if why:
        raise FileFormatError(p, meta_line["machine"], why)
    pivots = _read_pivots(p, h)
    sense = read_axis_sense(meta.get(METADATA_KEY, ""), h.rotary, p, meta_line.get(METADATA_KEY))
    return ball, frame, tool, pivots, sense


def check_as_read(path: str | os.PathLike[str], m: Measurement) -> None:
    """What :func:`read_measurement` would refuse in the file ``path`` that ``m`` was just written to.

    The header is read from the file itself and validated as the reader validates it; it must name ``m``'s
    columns.  The rows are checked as the reader checks them (limits, reference row, time order, repeated
    rows) on ``m``'s arrays: the writer writes every number with ``repr``, whose text reads back to the same
    double, so the file's values are these (tested by the round trips), and a large file is not parsed twice.

    Raises
    ------
    FileFormatError
        As :func:`read_measurement` would (file, line, problem).
    """
    p = str(path)
    with open_regular_file(path) as fh:
        h = _read_header(fh, p)
    _header_values(p, h)
    if h.names != m.columns():
        raise FileFormatError(p, h.header_line, f"the columns written ({', '.join(h.names)}) are not the "
                              f"measurement's ({', '.join(m.columns())})")
    angle_cols = [f"{a}_deg" for a in h.rotary]
    commanded = to_commanded(m.angles_deg, m.axis_sense, m.rotary_axes)
    col = {"t_s": m.t_s, **{c: commanded[:, k] for k, c in enumerate(angle_cols)},
           **{c: m.deviation_um[:, k] for k, c in enumerate(DEVIATION_COLUMNS)},
           **({} if m.linear_mm is None else {c: m.linear_mm[:, k] for k, c in enumerate(LINEAR_COLUMNS)}),
           **{c: np.asarray(m.optional[c], dtype=float) for c in OPTIONAL_COLUMNS if c in m.optional}}
    _check_values(p, h.header_line + 1, col, {k: list(v) for k, v in m.extra_columns.items()}, angle_cols)


def _read_pivots(p: str, h: Header) -> dict[str, np.ndarray]:
    pivots: dict[str, np.ndarray] = {}
    for key, value in h.meta.items():
        if key.startswith("pivot_") and key.endswith("_mm"):
            ax = key[len("pivot_") : -len("_mm")]
            if ax not in h.rotary:
                raise FileFormatError(
                    p, h.meta_line[key], f"{key}: machine {h.structure.canonical} has no rotary axis {ax!r} "
                    f"(axes: {', '.join(h.rotary)})"
                )
            pivots[ax] = parse_vec3(value, p, h.meta_line[key], key)
    return pivots


def read_angle_file(path: str | os.PathLike[str]) -> tuple[tuple[str, ...], np.ndarray, np.ndarray | None]:
    """Read a plain CSV of rotary angles (``<axis>_deg`` columns, optional ``t_s``).

    Lines starting with ``#`` are comments.  Other columns are refused.

    Returns
    -------
    axes : tuple of str
    angles_deg : ndarray, shape=(n, k) [deg]
    t_s : ndarray, shape=(n,) [s] or None
    """
    p = str(path)
    lines = read_input_text(path, what="angle file").removeprefix("\ufeff").splitlines()
    body = [(n + 1, ln) for n, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    if not body:
        raise FileFormatError(p, None, "no header line with <axis>_deg columns")
    hline, header = body[0]
    if "," not in header and separator_hint(header):
        raise FileFormatError(p, hline, "in the column header" + separator_hint(header))
    names = [c.strip() for c in header.split(",")]
    bad = [c for c in names if not (c == "t_s" or (c.endswith("_deg") and len(c) > 4))]
    if bad:
        raise FileFormatError(p, hline, f"unexpected column(s) {', '.join(bad)}: an angle file has <axis>_deg and t_s")
    axes = tuple(c[:-4] for c in names if c.endswith("_deg"))
    if not axes:
        raise FileFormatError(p, hline, "no <axis>_deg column")
    rows = []
    for ln_no, ln in body[1:]:
        fields = ln.split(",")
        if len(fields) != len(names):
            raise FileFormatError(p, ln_no, f"expected {len(names)} fields, got {len(fields)}")
        rows.append(fields)
    if not rows:
        raise FileFormatError(p, hline, "no data rows")
    arr = check_numeric_block(p, body[1][0], rows, names, list(range(len(names))))
    # line numbers above assume contiguous rows; re-check precisely on error is done by the helper
    t = arr[:, names.index("t_s")] if "t_s" in names else None
    if t is not None:
        back = np.nonzero(np.diff(t) < 0)[0]
        if back.size:
            raise FileFormatError(p, body[int(back[0]) + 2][0], "t_s goes backwards")
    angles = np.column_stack([arr[:, names.index(f"{a}_deg")] for a in axes])
    return axes, angles, t
