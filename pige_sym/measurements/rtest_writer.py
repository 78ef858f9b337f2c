"""Writer of R-test measurement files (``pige-rtest 1``): whole files, or row by row with fsync.

Numbers are written with ``repr`` so that a write → read round trip is lossless; metadata keys and
columns follow the grammar in :mod:`pige_sym.measurements.rtest`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING

import numpy as np

from pige_sym.errors import FileFormatError, InputError
from pige_sym.files import atomic_write_text
from pige_sym.measurements.axis_sense import METADATA_KEY as SENSE_KEY
from pige_sym.measurements.axis_sense import format_axis_sense, to_commanded

if TYPE_CHECKING:
    pass
from pige_sym.measurements.measurement import (
    FORMAT_LINE,
    OPTIONAL_COLUMNS,
    Measurement,
    parse_vec3,
    validate_measurement,
)


def format_number(x: float) -> str:
    """Shortest text that reads back to exactly the same float."""
    return repr(float(x))


def format_vector(v: Iterable[float]) -> str:
    return ", ".join(format_number(x) for x in v)


def metadata_for(m: Measurement) -> dict[str, str]:
    """Metadata (text) of a measurement: known keys from its fields, unknown keys kept, file order kept.

    A known key keeps its original text when that text still reads as the field's value,
    so reading and writing a file does not reformat it.
    """

    def vec_text(key: str, value: np.ndarray) -> str:
        orig = m.metadata.get(key)
        if orig is not None:
            try:
                if np.array_equal(parse_vec3(orig, "", 0, key), value):
                    return orig
            except FileFormatError:
                pass
        return format_vector(value)

    known: dict[str, str] = {"machine": m.machine, "ball_mm": vec_text("ball_mm", m.ball_mm)}
    if m.frame != "machine" or "frame" in m.metadata:
        known["frame"] = m.frame
    if m.tool_mm is not None:
        known["tool_mm"] = vec_text("tool_mm", m.tool_mm)
    for ax, pv in m.pivots_mm.items():
        known[f"pivot_{ax}_mm"] = vec_text(f"pivot_{ax}_mm", pv)
    if m.trajectory is not None:
        known["trajectory"] = m.trajectory
    sense = format_axis_sense(m.axis_sense, m.rotary_axes)
    if sense:
        known[SENSE_KEY] = sense
    is_known = {"machine", "ball_mm", "frame", "tool_mm", "trajectory", SENSE_KEY}
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


def row_text(m: Measurement, i: int) -> str:
    commanded = to_commanded(m.angles_deg[i], m.axis_sense, m.rotary_axes)
    vals = [format_number(m.t_s[i]), *(format_number(a) for a in commanded),
            *(format_number(d) for d in m.deviation_um[i])]
    if m.linear_mm is not None:
        vals += [format_number(x) for x in m.linear_mm[i]]
    vals += [format_number(m.optional[c][i]) for c in OPTIONAL_COLUMNS if c in m.optional]
    vals += [v[i] for v in m.extra_columns.values()]
    return ",".join(vals)


#: Rows formatted at a time by :func:`measurement_chunks` (bounds the memory of a large file's text).
CHUNK_ROWS = 16384


def format_measurement(m: Measurement) -> str:
    """Render a measurement as ``pige-rtest 1`` text."""
    return "".join(measurement_chunks(m))


def measurement_chunks(m: Measurement, rows: int = CHUNK_ROWS) -> Iterator[str]:
    """The text of a measurement in pieces: the header, then ``rows`` rows at a time (exactly :func:`row_text`).

    Columns are formatted whole (``repr`` of each value, as :func:`format_number`), so a large file costs a
    few string operations per value and its text never needs to be held at once.
    """
    validate_measurement(m)
    yield header_text(m)
    commanded = to_commanded(m.angles_deg, m.axis_sense, m.rotary_axes)
    numeric = [m.t_s[:, None], commanded, m.deviation_um, *([] if m.linear_mm is None else [m.linear_mm]),
               *(np.asarray(m.optional[c])[:, None] for c in OPTIONAL_COLUMNS if c in m.optional)]
    table = np.column_stack([np.asarray(a, dtype=float).reshape(m.n_rows, -1) for a in numeric])
    extras = list(m.extra_columns.values())
    for start in range(0, m.n_rows, rows):
        block = table[start:start + rows]
        texts = [list(map(float.__repr__, block[:, j].tolist())) for j in range(block.shape[1])]
        texts += [[str(v) for v in column[start:start + rows]] for column in extras]
        yield "\n".join(map(",".join, zip(*texts, strict=True))) + "\n"


def write_measurement(m: Measurement, path: str | os.PathLike[str], *,
                      verify: Callable[[Path], None] | None = None) -> Path:
    """Write a measurement file (atomically: temp file then rename); missing parent folders are created.

    ``verify`` is called with the written temporary file before it replaces ``path`` (e.g. to read it back
    with the reader); when it raises, nothing is written.
    """
    return atomic_write_text(path, measurement_chunks(m), verify=verify)


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
        """Append one row and flush it to disk (``angles_deg`` θ in CONVENTIONS' sense: written as θ_cmd)."""
        t = self.template
        commanded = to_commanded(np.asarray(list(angles_deg), dtype=float), t.axis_sense, t.rotary_axes)
        vals = [format_number(t_s), *(format_number(a) for a in commanded), *(format_number(d) for d in deviation_um)]
        if self.template.linear_mm is not None:
            if linear_mm is None:
                raise InputError("this file has X_mm, Y_mm, Z_mm columns: give linear_mm")
            vals += [format_number(x) for x in linear_mm]
        for c in OPTIONAL_COLUMNS:
            if c in self.template.optional:
                vals.append(format_number((optional or {})[c]))
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
