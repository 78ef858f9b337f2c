"""Where the cycle keeps its files in a LinuxCNC configuration folder.

Everything the cycle adds lives in one folder beside the INI, ``pige_cycle/``::

    pige_cycle/settings.json        the cycle's settings and limits (pige-cycle-settings 1; docs/linuxcnc-cycle.md)
    pige_cycle/values.hal           the values the kinematics hold, sourced by the INI (HALCMD = source ...)
    pige_cycle/values.hal.previous  the file as it was before the last entry (M451 P2)
    pige_cycle/python/              the remap's Python (toplevel.py, remap.py): runs inside LinuxCNC's task
    pige_cycle/ngc/                 the remaps' NGC procedures (pige_m451.ngc, pige_m452.ngc, pige_on_abort.ngc)
    pige_cycle/run/                 the current run's generated procedures (pige_cycle_probe/_restore.ngc); after
                                    an abort, abort.in_force (the mode found seen in force: linuxcnc_remap)
    pige_cycle/runs/<id>/           one folder per run: request, program, probe log, results, messages, log
    pige_cycle/proposal.json        the last proposal (M451 P1, M452), entered by M451 P2
    pige_cycle/journal.jsonl        one line per measuring run and per entry
    pige_cycle/history.db           the machine's history (default; ``--db`` names another)

The configuration's own files are the INI, its HAL files, ``settings.json``, ``values.hal`` and the remap code;
``run/``, ``runs/``, ``proposal.json``, ``journal.jsonl`` and the history are the cycle's record of what it did.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

FOLDER = "pige_cycle"
#: The record of what the cycle did: never part of the configuration's fingerprint or of "nothing changed".
RECORD = ("run", "runs", "proposal.json", "journal.jsonl", "history.db", "values.hal.previous")
#: Procedure names LinuxCNC looks up in SUBROUTINE_PATH (the generated ones are rewritten for every run).
PROBE_SUB = "pige_cycle_probe"
RESTORE_SUB = "pige_cycle_restore"
#: The remapped codes and their NGC procedures.
CODES = {"M451": "pige_m451", "M452": "pige_m452"}
ON_ABORT_SUB = "pige_on_abort"


@dataclass(frozen=True)
class Layout:
    """The cycle's paths in the configuration folder ``config`` (module docstring)."""

    config: Path

    @property
    def root(self) -> Path:
        return self.config / FOLDER

    @property
    def settings(self) -> Path:
        return self.root / "settings.json"

    @property
    def values(self) -> Path:
        return self.root / "values.hal"

    @property
    def values_previous(self) -> Path:
        return self.root / "values.hal.previous"

    @property
    def python(self) -> Path:
        return self.root / "python"

    @property
    def ngc(self) -> Path:
        return self.root / "ngc"

    @property
    def current(self) -> Path:
        return self.root / "run"

    @property
    def runs(self) -> Path:
        return self.root / "runs"

    @property
    def proposal(self) -> Path:
        return self.root / "proposal.json"

    @property
    def journal(self) -> Path:
        return self.root / "journal.jsonl"

    @property
    def default_db(self) -> Path:
        return self.root / "history.db"

    def relative(self, path: Path) -> str:
        """``path`` as the INI names it: relative to the configuration folder, with ``./``."""
        return "./" + path.relative_to(self.config).as_posix()
