"""``pige_cycle/journal.jsonl``: one JSON object per line, one line per measuring run of the cycle and per entry.

A line is appended at the end of a step that measured (``outcome: measured``, with the history's run id) or entered
values (``entered``, with the run whose proposal was entered and the configuration's fingerprint after); a run a
guard stopped or an entry refused leaves its own folder only.  The journal says what the history cannot: which
configuration each run was measured with.  ``M452`` reads it (:func:`checkup_basis`): a check-up compares with the
last full calibration only while the configuration is the one that calibration was made with, less the check-ups'
own entries.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from pige_sym.cycle.layout import Layout
from pige_sym.errors import FileFormatError, InputError


@dataclass(frozen=True)
class JournalEntry:
    """One line of the journal (module docstring); ``fingerprint`` is the configuration's when the step started."""

    time: str
    run: str
    code: str
    mode: str
    outcome: str
    fingerprint: str
    kind: str | None = None
    history_run: int | None = None
    verdict: str | None = None
    entered_from: str | None = None
    entered_kind: str | None = None
    fingerprint_after: str | None = None


def append_entry(layout: Layout, entry: JournalEntry) -> None:
    """Append one line (the file is opened for appending: earlier lines are never rewritten)."""
    layout.journal.parent.mkdir(parents=True, exist_ok=True)
    with open(layout.journal, "a", encoding="utf-8") as f:
        f.write(json.dumps(asdict(entry), sort_keys=True) + "\n")
        f.flush()


def read_journal(layout: Layout) -> list[JournalEntry]:
    """Every line, validated; none when the file does not exist.

    Raises
    ------
    FileFormatError
        A line that is not a journal entry (naming the line).
    """
    from pige_sym.measurements.schema import from_json
    from pige_sym.measurements.strict_json import strict_loads

    if not layout.journal.is_file():
        return []
    out = []
    for number, line in enumerate(layout.journal.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip():
            continue
        try:
            out.append(from_json(JournalEntry, strict_loads(line), f"{layout.journal}:{number}"))
        except ValueError as exc:
            raise FileFormatError(str(layout.journal), number, f"not a journal line: {exc}") from None
    return out


@dataclass(frozen=True)
class CheckupBasis:
    """What a check-up compares with: the last full calibration's history run, and whether the changes of the last
    check-up were entered since (``corrected``)."""

    full_run: int
    corrected: bool


def checkup_basis(entries: list[JournalEntry], fingerprint_now: str) -> CheckupBasis:
    """The basis of a new check-up (module docstring).

    Raises
    ------
    InputError
        No full calibration by the cycle, values entered from a full calibration since, or a configuration changed
        otherwise than by the check-ups' entries: run ``M451 P0`` first.
    """
    full = [i for i, e in enumerate(entries) if e.outcome == "measured" and e.kind == "full"]
    if not full:
        raise InputError("no full calibration by the cycle yet: run M451 P0 (or P1) first; the check-up compares "
                         "with it")
    last = entries[full[-1]]
    expected, corrected = last.fingerprint, False
    for e in entries[full[-1] + 1:]:
        if e.outcome == "entered":
            if e.entered_kind != "checkup":
                raise InputError(f"values were entered from a full calibration ({e.entered_from}) after the last one "
                                 f"measured: run M451 P0 first, so that the check-up compares with the values in force")
            expected, corrected = e.fingerprint_after or expected, True
        elif e.outcome == "measured" and e.kind == "checkup":
            corrected = False
    if fingerprint_now != expected:
        raise InputError(f"the configuration changed since the last full calibration ({last.run}) otherwise than by "
                         "entering a check-up's changes: run M451 P0 first")
    if last.history_run is None:  # pragma: no cover - a measured full run always has its history run
        raise InputError(f"{last.run} has no history run")
    return CheckupBasis(last.history_run, corrected)


def journal_path_note(path: Path) -> str:
    return f"the cycle's journal {path}"
