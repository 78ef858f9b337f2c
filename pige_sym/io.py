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
Optional: ``frame`` (``machine`` or ``table``), ``tool_mm``, ``pivot_<axis>_mm``,
``trajectory``, ``units``, ``source``; any other key is kept.  The first data row is
the reference pose (all angles 0, deviation 0); ``t_s`` never decreases.

Numbers are ASCII decimals (``[+-]digits[.digits][e[+-]digits]``): ``1_000``,
Arabic-Indic or full-width digits, ``nan`` and ``inf`` are not numbers.  Values must
be physical (:data:`LIMITS`: e.g. a deviation within ±1e5 µm, a ball position within
±1e5 mm).  A row that repeats an earlier row exactly (a duplicated record) is refused.
Only regular files are read (not FIFOs or devices).  The data body is read in chunks
of :data:`CHUNK_BYTES` after the header is validated, so large files stream; a chunk
whose lines all have the header's number of fields is parsed by the vectorised
:mod:`pige_sym.decimal_fields` (bit-identical to the strict grammar), any other chunk
line by line; a line longer than :data:`MAX_LINE_BYTES` is refused.

Every refusal is a :class:`~pige_sym.errors.FileFormatError` naming the file, the
1-based line and the problem.  Numbers are written with ``repr`` so that a
write → read round trip is lossless.
"""

from __future__ import annotations

import math
import os
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.decimal_fields import field_ends, field_starts, parse_decimal_fields
from pige_sym.errors import FileFormatError, InputError, PigeError
from pige_sym.files import atomic_write_text, open_regular_file
from pige_sym.options import strict_float

if TYPE_CHECKING:
    from concurrent.futures import Future

FORMAT_LINE = "# pige-rtest 1"
DEVIATION_COLUMNS = ("dx_um", "dy_um", "dz_um")
LINEAR_COLUMNS = ("X_mm", "Y_mm", "Z_mm")
OPTIONAL_COLUMNS = ("temp_C", "n_samples", "sd_um")
FRAMES = ("machine", "table")
REFERENCE_TOLERANCE = 1e-9
CHUNK_BYTES = 4 * 2**20
#: Threads parsing chunks at once (NumPy releases the GIL; results are taken in file order).
PARSE_THREADS = 2
MAX_LINE_BYTES = 2**20
#: Largest magnitude accepted per column or metadata kind (non-physical values are refused), in its unit.
LIMITS: dict[str, float] = {"t_s": 1e9, "deg": 1e5, "um": 1e5, "mm": 1e5, "temp_C": 1e3, "n_samples": 1e9,
                            "sd_um": 1e5}


@dataclass
class Measurement:
    """One R-test measurement: metadata and per-point data.

    Attributes
    ----------
    machine : str
        Machine structure code as written in the file.
    ball_mm : ndarray, shape=(3,) [mm]
        Ball centre at the reference pose, machine frame.
    t_s : ndarray, shape=(n,) [s]
        Time since the reference.
    angles_deg : ndarray, shape=(n, k) [deg]
        Commanded rotary angles, columns in ``rotary_axes`` order.
    deviation_um : ndarray, shape=(n, 3) [µm]
        Ball minus nest in ``frame``.
    rotary_axes : tuple of str
        Rotary-axis names in column order.
    frame : {"machine", "table"}
    tool_mm : ndarray, shape=(3,) [mm] or None
    pivots_mm : dict of str to ndarray, shape=(3,) [mm]
    trajectory : str or None
    linear_mm : ndarray, shape=(n, 3) [mm] or None
        Commanded X, Y, Z when present.
    optional : dict of str to ndarray, shape=(n,)
        Known optional numeric columns present (``temp_C``, ``n_samples``, ``sd_um``).
    extra_columns : dict of str to list of str
        Unknown columns, verbatim, in file order.
    metadata : dict of str to str
        Every metadata entry as text, in file order (known and unknown keys).
    path : str or None
    """

    machine: str
    ball_mm: np.ndarray
    t_s: np.ndarray
    angles_deg: np.ndarray
    deviation_um: np.ndarray
    rotary_axes: tuple[str, ...]
    frame: str = "machine"
    tool_mm: np.ndarray | None = None
    pivots_mm: dict[str, np.ndarray] = field(default_factory=dict)
    trajectory: str | None = None
    linear_mm: np.ndarray | None = None
    optional: dict[str, np.ndarray] = field(default_factory=dict)
    extra_columns: dict[str, list[str]] = field(default_factory=dict)
    metadata: dict[str, str] = field(default_factory=dict)
    path: str | None = None

    @property
    def n_rows(self) -> int:
        """Number of data rows (the reference row included)."""
        return int(self.t_s.shape[0])

    @property
    def structure(self) -> MachineStructure:
        """Parsed machine structure."""
        return parse_machine_code(self.machine)

    def columns(self) -> list[str]:
        """Column names in the order they are written."""
        cols = ["t_s", *(f"{a}_deg" for a in self.rotary_axes), *DEVIATION_COLUMNS]
        if self.linear_mm is not None:
            cols += list(LINEAR_COLUMNS)
        cols += [c for c in OPTIONAL_COLUMNS if c in self.optional]
        cols += list(self.extra_columns)
        return cols

    def deviation_machine_um(self, kernels: object | None = None) -> np.ndarray:
        """Deviation in the machine frame, shape=(n, 3) [µm].

        ``frame: table`` data are rotated with the nominal workpiece rotation of the
        commanded angles (CONVENTIONS §4); ``kernels`` defaults to the machine's.
        """
        if self.frame == "machine":
            return self.deviation_um
        from pige_sym.kernels import load_kernels

        kern: Any = kernels if kernels is not None else load_kernels(self.machine)
        rot = kern.workpiece_rotation(self.angles_deg)
        return np.einsum("nij,nj->ni", rot, self.deviation_um)


def _fmt(x: float) -> str:
    """Shortest text that reads back to exactly the same float."""
    return repr(float(x))


def _fmt_vec(v: Iterable[float]) -> str:
    return ", ".join(_fmt(x) for x in v)


def _parse_vec3(text: str, path: str, line: int, key: str) -> np.ndarray:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise FileFormatError(path, line, f"{key}: expected 3 comma-separated numbers, got {text!r}")
    out = []
    for p in parts:
        v = strict_float(p)
        if v is None:
            raise FileFormatError(path, line, f"{key}: {p!r} is not a number (ASCII decimal, e.g. 120.5 or -1e-3)")
        if abs(v) > LIMITS["mm"]:
            raise FileFormatError(path, line, f"{key}: {p} mm is not physical (|value| <= {LIMITS['mm']:g} mm)")
        out.append(v)
    return np.array(out)


def column_limit(name: str) -> tuple[float, str]:
    """Largest magnitude [unit] accepted in a known column, and the unit."""
    if name in LIMITS:
        return LIMITS[name], name.rsplit("_", 1)[-1]
    unit = name.rsplit("_", 1)[-1]
    return LIMITS.get(unit, math.inf), unit


def metadata_for(m: Measurement) -> dict[str, str]:
    """Metadata (text) of a measurement: known keys from its fields, unknown keys kept, file order kept.

    A known key keeps its original text when that text still reads as the field's value,
    so reading and writing a file does not reformat it.
    """

    def vec_text(key: str, value: np.ndarray) -> str:
        orig = m.metadata.get(key)
        if orig is not None:
            try:
                if np.array_equal(_parse_vec3(orig, "", 0, key), value):
                    return orig
            except FileFormatError:
                pass
        return _fmt_vec(value)

    known: dict[str, str] = {"machine": m.machine, "ball_mm": vec_text("ball_mm", m.ball_mm)}
    if m.frame != "machine" or "frame" in m.metadata:
        known["frame"] = m.frame
    if m.tool_mm is not None:
        known["tool_mm"] = vec_text("tool_mm", m.tool_mm)
    for ax, pv in m.pivots_mm.items():
        known[f"pivot_{ax}_mm"] = vec_text(f"pivot_{ax}_mm", pv)
    if m.trajectory is not None:
        known["trajectory"] = m.trajectory
    is_known = {"machine", "ball_mm", "frame", "tool_mm", "trajectory"}
    out: dict[str, str] = {}
    for k, v in m.metadata.items():
        if k in known:
            out[k] = known[k]
        elif k not in is_known and not (k.startswith("pivot_") and k.endswith("_mm")):
            out[k] = v
    for k, v in known.items():
        out.setdefault(k, v)
    return out


def header_text(m: Measurement) -> str:
    """Format line, metadata lines and the column header of a measurement."""
    lines = [FORMAT_LINE]
    for k, v in metadata_for(m).items():
        if "\n" in v:
            raise InputError(f"metadata value of {k!r} contains a newline")
        lines.append(f"# {k}: {v}")
    lines.append(",".join(m.columns()))
    return "\n".join(lines) + "\n"


def _row_text(m: Measurement, i: int) -> str:
    vals = [_fmt(m.t_s[i]), *(_fmt(a) for a in m.angles_deg[i]), *(_fmt(d) for d in m.deviation_um[i])]
    if m.linear_mm is not None:
        vals += [_fmt(x) for x in m.linear_mm[i]]
    vals += [_fmt(m.optional[c][i]) for c in OPTIONAL_COLUMNS if c in m.optional]
    vals += [v[i] for v in m.extra_columns.values()]
    return ",".join(vals)


def format_measurement(m: Measurement) -> str:
    """Render a measurement as ``pige-rtest 1`` text."""
    validate_measurement(m)
    body = "\n".join(_row_text(m, i) for i in range(m.n_rows))
    return header_text(m) + body + "\n"


def write_measurement(m: Measurement, path: str | os.PathLike[str]) -> Path:
    """Write a measurement file (atomically: temp file then rename); missing parent folders are created."""
    return atomic_write_text(path, format_measurement(m))


def validate_measurement(m: Measurement) -> None:
    """Check shapes and the reference row of an in-memory measurement (raises InputError)."""
    n = m.t_s.shape[0]
    k = len(m.rotary_axes)
    if n == 0:
        raise InputError("measurement has no rows")
    if m.angles_deg.shape != (n, k) or m.deviation_um.shape != (n, 3):
        raise InputError(f"shapes: t_s {m.t_s.shape}, angles_deg {m.angles_deg.shape}, deviation_um "
                         f"{m.deviation_um.shape}; expected (n,), (n, {k}), (n, 3)")
    if m.linear_mm is not None and m.linear_mm.shape != (n, 3):
        raise InputError(f"linear_mm has shape {m.linear_mm.shape}, expected ({n}, 3)")
    if m.frame not in FRAMES:
        raise InputError(f"frame must be 'machine' or 'table', got {m.frame!r}")
    arrays = {"t_s": m.t_s, "angles_deg": m.angles_deg, "deviation_um": m.deviation_um, "ball_mm": m.ball_mm,
              **({} if m.linear_mm is None else {"linear_mm": m.linear_mm}), **m.optional}
    for name, arr in arrays.items():
        if not np.isfinite(np.asarray(arr, dtype=float)).all():
            raise InputError(f"{name} holds NaN or infinite values: pige never writes them")


class MeasurementWriter:
    """Row-by-row writer: the header at open, then one flushed (fsynced) line per row.

    A crash leaves a valid partial file.  Use as a context manager.

    Parameters
    ----------
    path : path-like
    template : Measurement
        Supplies metadata and column layout (its rows are not written unless
        ``write_template_rows``).
    append : bool
        Continue an existing file (``--resume``): the header is not written again.
    """

    def __init__(self, path: str | os.PathLike[str], template: Measurement, *, append: bool = False) -> None:
        self.path = Path(path)
        self.template = template
        self._rows_at_open = self.rows_in_file() if append else 0
        self._fh: IO[str] = open(self.path, "a" if append else "w", encoding="utf-8")  # noqa: SIM115
        if not append:
            self._fh.write(header_text(template))
            self._sync()

    def _sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def write_row(
        self,
        t_s: float,
        angles_deg: Iterable[float],
        deviation_um: Iterable[float],
        linear_mm: Iterable[float] | None = None,
        optional: dict[str, float] | None = None,
        extra: dict[str, str] | None = None,
    ) -> None:
        """Append one row and flush it to disk."""
        vals = [_fmt(t_s), *(_fmt(a) for a in angles_deg), *(_fmt(d) for d in deviation_um)]
        if self.template.linear_mm is not None:
            if linear_mm is None:
                raise InputError("this file has X_mm, Y_mm, Z_mm columns: give linear_mm")
            vals += [_fmt(x) for x in linear_mm]
        for c in OPTIONAL_COLUMNS:
            if c in self.template.optional:
                vals.append(_fmt((optional or {})[c]))
        for c in self.template.extra_columns:
            vals.append((extra or {}).get(c, ""))
        bad = [v for v in vals[: len(vals) - len(self.template.extra_columns)] if not math.isfinite(float(v))]
        if bad:
            raise InputError(f"{self.path}: a row with {bad[0]} values is not written (pige never writes NaN or inf)")
        self._fh.write(",".join(vals) + "\n")
        self._sync()

    def close(self) -> None:
        self._fh.close()

    def rows_in_file(self) -> int:
        """Data rows the file holds now (lines after the column header), counted on disk."""
        with open(self.path, encoding="utf-8") as fh:
            body = [line for line in fh if line.strip() and not line.startswith("#")]
        return max(len(body) - 1, 0)

    def rows_written(self) -> int:
        """Rows this writer added, counted on disk: right even if an interrupt fell between a write and its caller."""
        return self.rows_in_file() - self._rows_at_open

    def __enter__(self) -> MeasurementWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _bad_number(column: str, text: str) -> str:
    t = text.strip()
    if t.lower().lstrip("+-") in ("nan", "inf", "infinity"):
        kind = "NaN" if "nan" in t.lower() else "infinite value"
        return f"column {column}: {kind} {t!r} is not allowed"
    return f"column {column}: {t!r} is not a number (ASCII decimal, e.g. 12.5 or -3e-2)"


def _check_numeric_block(
    path: str, first_line: int, rows: list[list[str]], names: list[str], numeric: list[int]
) -> np.ndarray:
    """Parse the numeric columns strictly (:func:`parse_number`); name the line and column of a bad value."""
    out = np.empty((len(rows), len(numeric)))
    for i, r in enumerate(rows):
        for q, j in enumerate(numeric):
            v = strict_float(r[j])
            if v is None:
                raise FileFormatError(path, first_line + i, _bad_number(names[j], r[j]))
            out[i, q] = v
    return out


@dataclass
class _Header:
    """What the lines before the data say (validated)."""

    meta: dict[str, str]
    meta_line: dict[str, int]
    names: list[str]
    header_line: int
    structure: MachineStructure
    rotary: tuple[str, ...]
    numeric: list[int]
    extras: list[int]


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
        try:
            return raw.decode("utf-8").rstrip("\r\n")
        except UnicodeDecodeError as exc:
            raise FileFormatError(self.path, self.number, f"not UTF-8 text ({exc.reason})") from None


def _read_metadata(lines: _Lines, p: str) -> tuple[dict[str, str], dict[str, int], str | None]:
    """Format line and ``# key: value`` lines; returns them and the first line after them."""
    first = lines.next()
    if first is None or first.strip() != FORMAT_LINE:
        got = first.strip() if first is not None else "an empty file"
        raise FileFormatError(p, 1, f"first line must be {FORMAT_LINE!r}, got {got[:80]!r}")
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


def _read_header(fh: IO[bytes], p: str) -> _Header:
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
    names = [c.strip() for c in header.split(",")]
    numeric = _check_columns(p, lines.number, names, structure, rotary)
    extras = [j for j in range(len(names)) if j not in numeric]
    return _Header(meta, meta_line, names, lines.number, structure, rotary, numeric, extras)


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


#: A chunk's vectorised parse: its rows (n, numeric columns) and its text columns, or None.
_FastResult = tuple[np.ndarray, dict[str, list[str]]] | None


class _Body:
    """The data rows, read chunk by chunk: a vectorised path (:meth:`_fast`) for chunks whose lines all
    have the header's fields, a strict line-by-line path (:meth:`_strict`) that names the first bad line."""

    def __init__(self, path: str, header: _Header) -> None:
        self.path = path
        self.h = header
        self.first_line = header.header_line + 1
        self.line = self.first_line  # number of the next line
        self.blank_at: int | None = None
        self.blocks: list[np.ndarray] = []
        self.extras: dict[str, list[str]] = {header.names[j]: [] for j in header.extras}

    def read(self, fh: IO[bytes]) -> None:
        """Read every chunk.  With more than one chunk the vectorised parses run in
        :data:`PARSE_THREADS` threads (NumPy releases the GIL); results are taken in file order, so
        lines, refusals and text columns are exactly those of a sequential read."""
        pending: deque[tuple[bytes, Future[_FastResult] | None]] = deque()
        first = self._next_chunk(fh, pending)
        if first is None:
            return
        pending.append((first, None))
        second = self._next_chunk(fh, pending)
        if second is None:  # one chunk (most files): no threads
            self._take(*pending.popleft())
            return
        from concurrent.futures import ThreadPoolExecutor  # here: its import costs 13 ms of start-up

        with ThreadPoolExecutor(max_workers=PARSE_THREADS) as pool:
            pending.append((second, pool.submit(self._fast, second)))
            while chunk := self._next_chunk(fh, pending):
                pending.append((chunk, pool.submit(self._fast, chunk)))
                if len(pending) > PARSE_THREADS:
                    self._take(*pending.popleft())
            while pending:
                self._take(*pending.popleft())

    def _next_chunk(self, fh: IO[bytes], pending: deque[tuple[bytes, Future[_FastResult] | None]]) -> bytes | None:
        """The next chunk, ending at a line end; a too-long line is refused with its number (after
        the chunks still ``pending`` are taken, so the count is exact)."""
        chunk = fh.read(CHUNK_BYTES)
        if not chunk:
            return None
        if not chunk.endswith(b"\n"):
            tail = fh.readline(MAX_LINE_BYTES + 1)
            if len(tail) > MAX_LINE_BYTES or (b"\n" not in chunk and len(chunk) > MAX_LINE_BYTES):
                while pending:
                    self._take(*pending.popleft())
                raise FileFormatError(self.path, self.line + chunk.count(b"\n"),
                                      f"line longer than {MAX_LINE_BYTES} bytes")
            chunk += tail
        return chunk

    def _take(self, chunk: bytes, parsed: Future[_FastResult] | None) -> None:
        """The next chunk in file order: its vectorised parse (done in a thread, or now), or the strict path."""
        result = self._fast(chunk) if parsed is None else parsed.result()
        if result is None or self.blank_at is not None:
            self.blocks.append(self._strict(chunk))
            return
        block, texts = result
        self.line += block.shape[0]
        for name, values in texts.items():
            self.extras[name] += values
        self.blocks.append(block)

    def _fast(self, chunk: bytes) -> _FastResult:
        """Every line of the chunk with exactly the header's number of fields, the numeric ones
        parsed vectorised (:mod:`pige_sym.decimal_fields`, bit-identical to the strict grammar)
        and text columns sliced as they are; or None (the strict path decides and names the line).
        Reads nothing but the header, so it can run in a thread."""
        if b"\r" in chunk:
            chunk = chunk.replace(b"\r\n", b"\n")
        if not chunk.endswith(b"\n"):
            chunk += b"\n"
        if b"\r" in chunk or (self.h.extras and not chunk.isascii()):
            return None
        buf = np.frombuffer(chunk, np.uint8)
        ends = field_ends(buf)
        ncols = len(self.h.names)
        line_ends = np.flatnonzero(buf[ends] == ord("\n"))
        if (np.diff(line_ends, prepend=-1) != ncols).any():
            return None
        if buf[0] == ord("#") or (buf[line_ends[:-1] + 1] == ord("#")).any():
            return None  # a comment line: the strict path names it
        if not self.h.extras:  # every field numeric: no per-column selection (it would copy the offsets)
            values = parse_decimal_fields(buf, ends)
            return None if values is None else (values.reshape(-1, ncols), {})
        numeric = self.h.numeric
        ends, starts = ends.reshape(-1, ncols), field_starts(ends).reshape(-1, ncols)
        values = parse_decimal_fields(buf, ends[:, numeric].ravel(), starts[:, numeric].ravel())
        if values is None:
            return None
        text = chunk.decode("ascii")
        texts = {}
        for j in self.h.extras:
            bounds = zip(starts[:, j].tolist(), ends[:, j].tolist(), strict=True)
            texts[self.h.names[j]] = [text[a:b] for a, b in bounds]
        return values.reshape(-1, len(numeric)), texts

    def _strict(self, chunk: bytes) -> np.ndarray:
        p, names, numeric = self.path, self.h.names, self.h.numeric
        raws = chunk.split(b"\n")
        if chunk.endswith(b"\n"):
            raws.pop()
        rows = np.empty((len(raws), len(numeric)))
        n = 0
        for raw in raws:
            ln = self.line
            self.line += 1
            if len(raw) > MAX_LINE_BYTES:
                raise FileFormatError(p, ln, f"line longer than {MAX_LINE_BYTES} bytes")
            try:
                line = raw.decode("utf-8").rstrip("\r")
            except UnicodeDecodeError as exc:
                raise FileFormatError(p, ln, f"not UTF-8 text ({exc.reason})") from None
            if not line.strip():
                self.blank_at = self.blank_at or ln
                continue
            if self.blank_at is not None:
                raise FileFormatError(p, self.blank_at, "blank line inside the data")
            if line.startswith("#"):
                raise FileFormatError(p, ln, "metadata line after the column header")
            fields = line.split(",")
            if len(fields) != len(names):
                raise FileFormatError(p, ln, f"expected {len(names)} fields, got {len(fields)}")
            rows[n] = _check_numeric_block(p, ln, [fields], names, numeric)[0]
            for j in self.h.extras:
                self.extras[names[j]].append(fields[j])
            n += 1
        return rows[:n]

    def require_rows(self) -> None:
        """Refuse a file without data rows."""
        if not self.blocks or sum(b.shape[0] for b in self.blocks) == 0:
            raise FileFormatError(self.path, self.h.header_line, "no data rows")

    def array(self) -> np.ndarray:
        self.require_rows()
        return np.concatenate(self.blocks) if len(self.blocks) > 1 else self.blocks[0]

    def gather(self, columns: Iterable[str]) -> np.ndarray:
        """The named numeric columns, shape (n_rows, len(columns)), copied once from the blocks."""
        positions = [self.h.numeric.index(self.h.names.index(c)) for c in columns]
        out = np.empty((sum(b.shape[0] for b in self.blocks), len(positions)))
        row = 0
        for block in self.blocks:
            np.take(block, positions, axis=1, out=out[row : row + block.shape[0]])
            row += block.shape[0]
        return out


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
        body = _Body(p, h)
        body.read(fh)
    meta, meta_line = h.meta, h.meta_line
    ball = _parse_vec3(meta["ball_mm"], p, meta_line["ball_mm"], "ball_mm")
    frame = meta.get("frame", "machine")
    if frame not in FRAMES:
        raise FileFormatError(p, meta_line.get("frame"), f"frame must be 'machine' or 'table', got {frame!r}")
    tool = _parse_vec3(meta["tool_mm"], p, meta_line["tool_mm"], "tool_mm") if "tool_mm" in meta else None
    pivots = _read_pivots(p, h)
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
    return Measurement(
        machine=meta["machine"], ball_mm=ball, t_s=groups["t_s"][:, 0], angles_deg=groups["angles"],
        deviation_um=groups["deviation"], rotary_axes=h.rotary, frame=frame, tool_mm=tool, pivots_mm=pivots,
        trajectory=meta.get("trajectory"), linear_mm=groups.get("linear"),
        optional={c: groups[c][:, 0] for c in OPTIONAL_COLUMNS if c in groups},
        extra_columns=body.extras, metadata=meta, path=p,
    )


def _read_pivots(p: str, h: _Header) -> dict[str, np.ndarray]:
    pivots: dict[str, np.ndarray] = {}
    for key, value in h.meta.items():
        if key.startswith("pivot_") and key.endswith("_mm"):
            ax = key[len("pivot_") : -len("_mm")]
            if ax not in h.rotary:
                raise FileFormatError(
                    p, h.meta_line[key], f"{key}: machine {h.structure.canonical} has no rotary axis {ax!r} "
                    f"(axes: {', '.join(h.rotary)})"
                )
            pivots[ax] = _parse_vec3(value, p, h.meta_line[key], key)
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
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise FileFormatError(p, None, "file not found") from None
    body = [(n + 1, ln) for n, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    if not body:
        raise FileFormatError(p, None, "no header line with <axis>_deg columns")
    hline, header = body[0]
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
    arr = _check_numeric_block(p, body[1][0], rows, names, list(range(len(names))))
    # line numbers above assume contiguous rows; re-check precisely on error is done by the helper
    t = arr[:, names.index("t_s")] if "t_s" in names else None
    if t is not None:
        back = np.nonzero(np.diff(t) < 0)[0]
        if back.size:
            raise FileFormatError(p, body[int(back[0]) + 2][0], "t_s goes backwards")
    angles = np.column_stack([arr[:, names.index(f"{a}_deg")] for a in axes])
    return axes, angles, t
