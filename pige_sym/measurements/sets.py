"""Several measurement files of one machine, read for a joint identification or diagnosis.

Each path is read by its format: a file whose first line is ``# pige-ballbar 1`` as a
:class:`~pige_sym.measurements.ballbar.BallbarRun`, any other as a ``pige-rtest 1``
:class:`~pige_sym.measurements.measurement.Measurement` (R-test runs and probe imports).
A file given twice is refused, under the same path or another (a link, a copy: compared by the SHA-256 of its
bytes): the same data would count double in a joint fit.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence

from pige_sym.errors import InputError
from pige_sym.files import open_regular_file
from pige_sym.measurements.ballbar import BallbarRun, is_ballbar_file, read_ballbar
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest import read_measurement


def read_files(paths: Sequence[str | os.PathLike[str]]) -> list[tuple[str, Measurement | BallbarRun]]:
    """(path, contents) of each file, in order.

    Raises
    ------
    InputError
        No file given, or one file given twice (also under another name, or a byte-identical copy).
    FileFormatError
        A file that violates its format (file, line, field).
    """
    if not paths:
        raise InputError("give at least one file")
    seen: dict[str, str] = {}
    for p in paths:
        key = os.path.realpath(p)
        if key in seen:
            raise InputError(f"{os.fspath(p)} is given twice (also as {seen[key]}): each file once, the same data "
                             "twice would count double in the joint fit")
        seen[key] = os.fspath(p)
    by_content: dict[str, str] = {}
    for p in paths:
        digest = content_digest(p)
        if digest in by_content:
            raise InputError(f"{os.fspath(p)} has the same content as {by_content[digest]} (SHA-256 {digest[:12]}…): "
                             "the same measurement under two names would count double in the joint fit; give it once")
        by_content[digest] = os.fspath(p)
    out: list[tuple[str, Measurement | BallbarRun]] = []
    for p in paths:
        out.append((os.fspath(p), read_ballbar(p) if is_ballbar_file(p) else read_measurement(p)))
    return out


def content_digest(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB pieces through the one safe opener (FIFOs and folders refused)."""
    h = hashlib.sha256()
    with open_regular_file(path) as fh:
        for piece in iter(lambda: fh.read(1 << 20), b""):
            h.update(piece)
    return h.hexdigest()
