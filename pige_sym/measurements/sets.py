"""Several measurement files of one machine, read for a joint identification or diagnosis.

Each path is read by its format: a file whose first line is ``# pige-ballbar 1`` as a
:class:`~pige_sym.measurements.ballbar.BallbarRun`, any other as a ``pige-rtest 1``
:class:`~pige_sym.measurements.measurement.Measurement` (R-test runs and probe imports).
A file given twice is refused: the same data would count double in a joint fit.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from pige_sym.errors import InputError
from pige_sym.measurements.ballbar import BallbarRun, is_ballbar_file, read_ballbar
from pige_sym.measurements.measurement import Measurement
from pige_sym.measurements.rtest import read_measurement


def read_files(paths: Sequence[str | os.PathLike[str]]) -> list[tuple[str, Measurement | BallbarRun]]:
    """(path, contents) of each file, in order.

    Raises
    ------
    InputError
        No file given, or one file given twice (also under another name).
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
    out: list[tuple[str, Measurement | BallbarRun]] = []
    for p in paths:
        out.append((os.fspath(p), read_ballbar(p) if is_ballbar_file(p) else read_measurement(p)))
    return out
