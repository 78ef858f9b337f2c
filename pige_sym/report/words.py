"""The words of the report: the instrument's own vocabulary, counts, and numbers a reader can read.

- :class:`Vocabulary` (:func:`vocabulary`): what a file's rows are called and what they measure.  An R-test
  records the ball's deviation from the nest at timed points (seconds); a probe import records, per pose,
  the sphere centre's deviation from its nominal motion, fitted from contacts, with the pose's order as
  its only clock (docs/conventions.md §7).
- :func:`count`: ``1 file``, ``9 files`` (never ``file(s)``); :func:`per_pose`: ``5 per pose``, ``4–9 per pose``.
- :func:`value_std` (from :mod:`pige_sym.identification.result`): a value and its standard error with the
  same decimals (the std to two significant digits): ``11.95 ± 0.42``, never ``12 ± 0.42``.
- :func:`small_um`: an RMS that is numerically zero reads ``< 0.001 µm``, not ``1.52e-11 µm``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pige_sym.identification.result import per_pose as per_pose
from pige_sym.identification.result import value_std as value_std
from pige_sym.measurements.measurement import Measurement


@dataclass(frozen=True)
class Vocabulary:
    """How the report speaks of one file's rows."""

    instrument: str  # "R-test", "touch probe"
    row: str  # one row: "point" or "pose"
    rows: str
    measurand: str  # title of the deviation plot
    deviation_axis: str  # y label of the deviation [µm]
    reference_point: str  # what sits at the reference pose
    time_axis: str  # x label of a time plot
    time_unit: str  # unit of t and of a drift's time constant
    tool_point: str  # the point the spindle carries: the R-test's ball, the probe's stylus tip
    table_point: str  # the point on the table: the R-test's ball (in its nest), the calibration sphere


RTEST = Vocabulary("R-test", "point", "points", "R-test deviation d = ball − nest", "deviation ball − nest [µm]",
                   "ball at the reference pose", "t [s]", "s", "ball", "ball")
PROBE = Vocabulary("touch probe", "pose", "poses", "probe deviation d = −(sphere centre − its nominal motion)",
                   "deviation d = −(c − c_nom) [µm]", "sphere centre at the reference pose",
                   "pose (its order in the log: a probe log holds no clock)", "poses", "stylus tip centre",
                   "sphere")


def vocabulary(m: Measurement) -> Vocabulary:
    """The vocabulary of a measurement file (probe import or R-test)."""
    return PROBE if m.metadata.get("instrument") == "sphere-probe" else RTEST


def count(n: int, word: str, plural: str | None = None) -> str:
    """``n`` and the word in the right number (``plural`` defaults to word + "s")."""
    return f"{n} {word if n == 1 else (plural or word + 's')}"


def small_um(x: float, fmt: str = ".3g") -> str:
    """An RMS [µm] for a title or a sentence: below 0.001 µm it is numerical noise, and says so."""
    if not math.isfinite(x):
        return "—"
    return "< 0.001" if abs(x) < 1e-3 else format(x, fmt)
