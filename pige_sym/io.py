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

Every refusal is a :class:`~pige_sym.errors.FileFormatError` naming the file, the
1-based line and the problem.  Numbers are written with ``repr`` so that a
write → read round trip is lossless.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.errors import FileFormatError, InputError, PigeError
from pige_sym.files import atomic_write_text

FORMAT_LINE = "# pige-rtest 1"
DEVIATION_COLUMNS = ("dx_um", "dy_um", "dz_um")
LINEAR_COLUMNS = ("X_mm", "Y_mm", "Z_mm")
OPTIONAL_COLUMNS = ("temp_C", "n_samples", "sd_um")
FRAMES = ("machine", "table")
REFERENCE_TOLERANCE = 1e-9


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

    def with_rows(self, rows: np.ndarray) -> Measurement:
        """A copy holding only the given rows (boolean mask or indices)."""
        idx = np.arange(self.n_rows)[rows]
        return Measurement(
            machine=self.machine, ball_mm=self.ball_mm.copy(), t_s=self.t_s[idx], angles_deg=self.angles_deg[idx],
            deviation_um=self.deviation_um[idx], rotary_axes=self.rotary_axes, frame=self.frame,
            tool_mm=None if self.tool_mm is None else self.tool_mm.copy(),
            pivots_mm={k: v.copy() for k, v in self.pivots_mm.items()}, trajectory=self.trajectory,
            linear_mm=None if self.linear_mm is None else self.linear_mm[idx],
            optional={k: v[idx] for k, v in self.optional.items()},
            extra_columns={k: [v[i] for i in idx] for k, v in self.extra_columns.items()},
            metadata=dict(self.metadata), path=self.path,
        )


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
        try:
            v = float(p)
        except ValueError:
            raise FileFormatError(path, line, f"{key}: {p!r} is not a number") from None
        if not math.isfinite(v):
            raise FileFormatError(path, line, f"{key}: {p!r} is not a finite number")
        out.append(v)
    return np.array(out)


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
        self._fh.write(",".join(vals) + "\n")
        self._sync()

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> MeasurementWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _check_numeric_block(
    path: str, first_line: int, rows: list[list[str]], names: list[str], numeric: list[int]
) -> np.ndarray:
    """Parse the numeric columns; on failure scan to report the exact line and column."""
    try:
        arr = np.array([[r[j] for j in numeric] for r in rows], dtype=float)
        if np.isfinite(arr).all():
            return arr
    except ValueError:
        pass
    for i, r in enumerate(rows):
        for j in numeric:
            text = r[j].strip()
            try:
                v = float(text)
            except ValueError:
                raise FileFormatError(path, first_line + i, f"column {names[j]}: {text!r} is not a number") from None
            if math.isnan(v):
                raise FileFormatError(path, first_line + i, f"column {names[j]}: NaN is not allowed")
            if math.isinf(v):
                raise FileFormatError(path, first_line + i, f"column {names[j]}: infinite value {text!r}")
    raise FileFormatError(path, first_line, "could not parse the numeric block")  # pragma: no cover


def read_measurement(path: str | os.PathLike[str]) -> Measurement:
    """Read and validate a ``pige-rtest 1`` file.

    Raises
    ------
    FileFormatError
        Naming the file, the 1-based line and the problem.
    """
    p = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileFormatError(p, None, "file not found") from None
    except UnicodeDecodeError as exc:
        raise FileFormatError(p, None, f"not a UTF-8 text file ({exc.reason})") from None
    lines = text.splitlines()
    if not lines or lines[0].strip() != FORMAT_LINE:
        got = lines[0].strip() if lines else "an empty file"
        raise FileFormatError(p, 1, f"first line must be {FORMAT_LINE!r}, got {got!r}")
    meta: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    i = 1
    while i < len(lines) and lines[i].startswith("#"):
        body = lines[i][1:].strip()
        if body:
            if ":" not in body:
                raise FileFormatError(p, i + 1, f"metadata line must be '# key: value', got {lines[i]!r}")
            key, value = body.split(":", 1)
            key = key.strip()
            if not key or not all(ch.isalnum() or ch == "_" for ch in key):
                raise FileFormatError(p, i + 1, f"bad metadata key {key!r}")
            if key in meta:
                raise FileFormatError(p, i + 1, f"metadata key {key!r} repeated (first on line {meta_line[key]})")
            meta[key] = value.strip()
            meta_line[key] = i + 1
        i += 1
    for key in ("machine", "ball_mm"):
        if key not in meta:
            where = i + 1 if i < len(lines) else len(lines)
            raise FileFormatError(p, where, f"missing required metadata '# {key}: ...'")
    try:
        structure = parse_machine_code(meta["machine"])
    except PigeError as exc:
        raise FileFormatError(p, meta_line["machine"], f"unknown machine code: {exc}") from None
    rotary = tuple(a.name for a in structure.rotary_axes)
    if not rotary:
        raise FileFormatError(p, meta_line["machine"], f"machine {meta['machine']!r} has no rotary axis")
    ball = _parse_vec3(meta["ball_mm"], p, meta_line["ball_mm"], "ball_mm")
    frame = meta.get("frame", "machine")
    if frame not in FRAMES:
        raise FileFormatError(p, meta_line.get("frame"), f"frame must be 'machine' or 'table', got {frame!r}")
    tool = _parse_vec3(meta["tool_mm"], p, meta_line["tool_mm"], "tool_mm") if "tool_mm" in meta else None
    pivots: dict[str, np.ndarray] = {}
    for key, value in meta.items():
        if key.startswith("pivot_") and key.endswith("_mm"):
            ax = key[len("pivot_") : -len("_mm")]
            if ax not in rotary:
                raise FileFormatError(
                    p, meta_line[key], f"{key}: machine {structure.canonical} has no rotary axis {ax!r} "
                    f"(axes: {', '.join(rotary)})"
                )
            pivots[ax] = _parse_vec3(value, p, meta_line[key], key)

    # header
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines):
        raise FileFormatError(p, len(lines), "no column header line after the metadata")
    header_line = i + 1
    names = [c.strip() for c in lines[i].split(",")]
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
    numeric = [j for j, c in enumerate(names) if c in known]

    rows: list[list[str]] = []
    first_data = i + 2
    for j in range(i + 1, len(lines)):
        line = lines[j]
        if not line.strip():
            if any(x.strip() for x in lines[j:]):
                raise FileFormatError(p, j + 1, "blank line inside the data")
            break
        if line.startswith("#"):
            raise FileFormatError(p, j + 1, "metadata line after the column header")
        fields = line.split(",")
        if len(fields) != len(names):
            raise FileFormatError(p, j + 1, f"expected {len(names)} fields, got {len(fields)}")
        rows.append(fields)
    if not rows:
        raise FileFormatError(p, header_line, "no data rows")
    arr = _check_numeric_block(p, first_data, rows, names, numeric)
    col = {names[j]: arr[:, q] for q, j in enumerate(numeric)}
    t = col["t_s"]
    angles = np.column_stack([col[c] for c in angle_cols])
    dev = np.column_stack([col[c] for c in DEVIATION_COLUMNS])
    ref_bad = [(c, col[c][0]) for c in (*angle_cols, *DEVIATION_COLUMNS) if abs(col[c][0]) > REFERENCE_TOLERANCE]
    if ref_bad:
        what = ", ".join(f"{c}={v:g}" for c, v in ref_bad)
        raise FileFormatError(
            p, first_data, f"first data row must be the reference pose (angles 0, deviation 0): {what}"
        )
    back = np.nonzero(np.diff(t) < 0)[0]
    if back.size:
        r = int(back[0]) + 1
        raise FileFormatError(p, first_data + r, f"t_s goes backwards ({t[r - 1]:g} then {t[r]:g})")
    return Measurement(
        machine=meta["machine"], ball_mm=ball, t_s=t, angles_deg=angles, deviation_um=dev, rotary_axes=rotary,
        frame=frame, tool_mm=tool, pivots_mm=pivots, trajectory=meta.get("trajectory"),
        linear_mm=np.column_stack([col[c] for c in LINEAR_COLUMNS]) if lin_present else None,
        optional={c: col[c] for c in OPTIONAL_COLUMNS if c in col},
        extra_columns={names[j]: [r[j] for r in rows] for j in range(len(names)) if j not in numeric},
        metadata=meta, path=p,
    )


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
