"""The data body of an R-test file, read in chunks: vectorised where it can be, line by line where not.

A chunk of :data:`CHUNK_BYTES` whose lines all have the header's number of fields is parsed by
:mod:`pige_sym.measurements.decimal_fields` (bit-identical to the strict grammar), on up to
:data:`PARSE_THREADS` threads; any other chunk is parsed line by line with :func:`strict_float`, so a
refusal names the exact line and column.  A line longer than :data:`MAX_LINE_BYTES` is refused.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING

import numpy as np

from pige_sym.codegen.machine_code import MachineStructure
from pige_sym.errors import FileFormatError
from pige_sym.measurements.decimal_fields import field_ends, field_starts, parse_decimal_fields
from pige_sym.options import strict_float

if TYPE_CHECKING:
    from concurrent.futures import Future



CHUNK_BYTES = 4 * 2**20


#: Threads parsing chunks at once (NumPy releases the GIL; results are taken in file order).
PARSE_THREADS = 2


MAX_LINE_BYTES = 2**20


def bad_number(column: str, text: str) -> str:
    t = text.strip()
    if t.lower().lstrip("+-") in ("nan", "inf", "infinity"):
        kind = "NaN" if "nan" in t.lower() else "infinite value"
        return f"column {column}: {kind} {t!r} is not allowed"
    return f"column {column}: {t!r} is not a number (ASCII decimal, e.g. 12.5 or -3e-2)"


def check_numeric_block(
    path: str, first_line: int, rows: list[list[str]], names: list[str], numeric: list[int]
) -> np.ndarray:
    """Parse the numeric columns strictly (:func:`parse_number`); name the line and column of a bad value."""
    out = np.empty((len(rows), len(numeric)))
    for i, r in enumerate(rows):
        for q, j in enumerate(numeric):
            v = strict_float(r[j])
            if v is None:
                raise FileFormatError(path, first_line + i, bad_number(names[j], r[j]))
            out[i, q] = v
    return out


def separator_hint(line: str, fmt: str = "pige-rtest") -> str:
    """What a spreadsheet's regional settings did to a line of a ``fmt`` file, if anything (``;`` fields, tabs)."""
    if ";" in line:
        return (f"; the fields are separated by ';' (a spreadsheet's regional setting): {fmt} separates "
                "fields by ',' and writes decimals with '.'")
    if "\t" in line:
        return f"; the fields are separated by tabs: {fmt} separates fields by ','"
    return ""


@dataclass
class Header:
    """What the lines before the data say (validated)."""

    meta: dict[str, str]
    meta_line: dict[str, int]
    names: list[str]
    header_line: int
    structure: MachineStructure
    rotary: tuple[str, ...]
    numeric: list[int]
    extras: list[int]


#: A chunk's vectorised parse: its rows (n, numeric columns) and its text columns, or None.
FastResult = tuple[np.ndarray, dict[str, list[str]]] | None


class DataBody:
    """The data rows, read chunk by chunk: a vectorised path (:meth:`_fast`) for chunks whose lines all
    have the header's fields, a strict line-by-line path (:meth:`_strict`) that names the first bad line."""

    def __init__(self, path: str, header: Header) -> None:
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
        pending: deque[tuple[bytes, Future[FastResult] | None]] = deque()
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

    def _next_chunk(self, fh: IO[bytes], pending: deque[tuple[bytes, Future[FastResult] | None]]) -> bytes | None:
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

    def _take(self, chunk: bytes, parsed: Future[FastResult] | None) -> None:
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

    def _fast(self, chunk: bytes) -> FastResult:
        """Every line of the chunk with exactly the header's number of fields, the numeric ones
        parsed vectorised (:mod:`pige_sym.measurements.decimal_fields`, bit-identical to the strict grammar)
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
                hint = separator_hint(line) or ("; a decimal comma ('0,5') splits a number into two fields: write "
                                                "decimals with '.'" if len(fields) > len(names) else "")
                raise FileFormatError(p, ln, f"expected {len(names)} fields, got {len(fields)}{hint}")
            rows[n] = check_numeric_block(p, ln, [fields], names, numeric)[0]
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
