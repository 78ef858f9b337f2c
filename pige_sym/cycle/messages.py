"""What the operator reads: a step's operator messages (``<step>.messages.json``) and the run's log (``log.txt``).

LinuxCNC carries an operator message of at most 254 bytes (``LINELEN``, NUL included), so a result is a few lines,
each :func:`pack`-ed under that, most important first; the log holds everything (the stages' own output).  The
remap shows ``lines`` as operator messages (``emccanon.MESSAGE``: a notification in AXIS) and ``error``, when there
is one, as the operator error that ends the cycle.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

MAX_BYTES = 254


@dataclass
class RunMessages:
    """The operator messages of a run and, when the cycle ends with an error, that error."""

    lines: list[str] = field(default_factory=list)
    error: str | None = None

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def fits(text: str) -> str:
    """``text`` cut to what LinuxCNC carries (whole characters)."""
    return text.encode("utf-8")[:MAX_BYTES].decode("utf-8", "ignore")


def pack(head: str, items: list[str], sep: str = ", ") -> list[str]:
    """``head`` then ``items`` joined by ``sep``, in as few lines of at most :data:`MAX_BYTES` bytes as they take
    (a continued line starts with ``... ``)."""
    lines: list[str] = []
    current = head
    for item in items:
        joined = current + ("" if current in (head, "... ") else sep) + item
        if len(joined.encode("utf-8")) <= MAX_BYTES:
            current = joined
            continue
        lines.append(current)
        current = "... " + item
    lines.append(current)
    return [fits(line) for line in lines]


def value_text(value: float, std: float | None = None, decimals: int = 2) -> str:
    """``+1.23±0.45`` (no std: ``+1.23``; undetermined: ``n/d``)."""
    if not math.isfinite(value):
        return "n/d"
    text = f"{value:+.{decimals}f}"
    return text if std is None or not math.isfinite(std) else f"{text}±{std:.{decimals}f}"


def write_messages(run: Path, step: str, messages: RunMessages) -> None:
    """``<step>.messages.json`` of the run (written last: the remap reads it once the step has ended; a step killed
    before leaves none)."""
    from pige_sym.files import atomic_write_text

    lines = [fits(line) for line in messages.lines]
    error = None if messages.error is None else fits(messages.error)
    atomic_write_text(run / f"{step}.messages.json", json.dumps({"lines": lines, "error": error}, indent=1) + "\n")


def relative_log(run: Path) -> str:
    """The run's log as a message names it: ``pige_cycle/runs/<id>/log.txt``."""
    return f"pige_cycle/runs/{run.name}/log.txt"
