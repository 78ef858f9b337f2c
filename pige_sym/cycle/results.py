"""What a run of the cycle found, as data (the analysis steps fill it, :mod:`~pige_sym.cycle.render` renders it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from pige_sym.cycle.proposal import Proposal


@dataclass(frozen=True)
class PigeRow:
    """One PIGE as a run found it: what is left with the values in force (``value`` ± ``std`` [``unit``]), whether
    the kinematics hold it (``held``), and the value in force (pige's component: its pin; None: the stock kinematics
    hold it as the lines' pins, or hold nothing of it)."""

    name: str
    unit: str
    value: float
    std: float
    held: bool
    in_force: float | None = None
    status: str = ""
    limit: float | None = None
    outside: bool = False


@dataclass
class RunResult:
    """A measuring run (``M451 P0``/``P1``, ``M452``): the rows, the verdict, the proposal, the record."""

    code: str
    mode: str
    run: str
    module: str
    poses: int
    contacts: int
    r_eff_mm: float
    stated_mm: float
    rows: list[PigeRow]
    verdict: str
    verdict_on: str
    in_force: list[tuple[str, float, str]]
    history_run: int | None = None
    proposal: Proposal | None = None
    beyond_limit: list[str] = field(default_factory=list)
    predicted_um: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        from pige_sym.files import json_ready

        out = asdict(self)
        out["proposal"] = None if self.proposal is None else self.proposal.to_dict()
        return dict(json_ready(out))
