"""What every step of a run shares: its log (``log.txt``), its stage (``status.txt``), and pige's commands run in
this process as a user runs them (:func:`pige_command`)."""

from __future__ import annotations

import contextlib
import io
import time
from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class RunLog:
    """The run's log (``log.txt``): sections appended as the step goes."""

    run: Path
    parts: list[str] = field(default_factory=list)

    def add(self, title: str, text: str) -> None:
        """Append a section (the file grows as the step goes: a step that dies leaves what it did)."""
        part = f"== {title}\n{text.rstrip()}\n"
        self.parts.append(part)
        with open(self.run / "log.txt", "a", encoding="utf-8") as f:
            f.write(part)


def status(run: Path, stage: str) -> None:
    """Append the stage now running to ``status.txt`` (with the wall time)."""
    with open(run / "status.txt", "a", encoding="utf-8") as f:
        f.write(f"{time.strftime('%H:%M:%S')} {stage}\n")


def pige_command(argv: list[str]) -> tuple[int, str]:
    """``pige ARGV`` run in this process: (exit status, what it printed)."""
    from pige_sym.cli.main import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = main(argv)
    return code, out.getvalue()
