"""The proposal (``pige_cycle/proposal.json``, format ``pige-cycle-proposal 1``) and the rules ``M451 P2`` enters
it by.

``M451 P1`` writes it from the weighed entries ``pige compensate`` would print; ``M452`` from the check-up's changes
to enter.  Each entry is one value of the kinematics: its pin (or the signal it is set through), the value in force
when the proposal was made (``old``) and the value to enter (``new``).  ``M451 P2`` refuses it (:func:`refusal`),
changing nothing, when there is none, when it is older than ``limits.proposal_hours``, when the configuration's
fingerprint differs from the one it was made for (something was edited or entered since), or when an entry changes
its value by more than the change limit (``max_change_mm`` for positions, ``max_change_deg`` for orientations).
Once entered it moves into its run's folder (``proposal.entered.json``): a proposal is entered once.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from datetime import datetime
from typing import Any

from pige_sym.cycle.context import changed_parts
from pige_sym.cycle.kinematics import KinematicsSetup, ValuePin, format_value
from pige_sym.cycle.settings import Limits

FORMAT = "pige-cycle-proposal 1"
UM_PER_MM = 1000.0
URAD_PER_DEG = math.pi / 180.0 * 1e6


@dataclass(frozen=True)
class ProposedValue:
    """One value to enter: HAL ``target`` (a pin, or the signal it is set through: ``verb`` sets) of ``pin``,
    ``old`` → ``new`` [``unit``], what it ``holds``."""

    pin: str
    target: str
    verb: str
    old: float
    new: float
    unit: str
    holds: str

    @property
    def change(self) -> float:
        return self.new - self.old

    def line(self) -> str:
        return f"{self.verb} {self.target} {format_value(self.new, self.unit)}"


@dataclass(frozen=True)
class Proposal:
    """The proposal file (module docstring)."""

    format: str
    created: str
    run: str
    kind: str
    machine: str
    module: str
    fingerprint: dict[str, str]
    entries: list[ProposedValue]
    history_run: int | None = None
    not_entered: list[str] = field(default_factory=list)
    predicted_um: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def proposed_values(setup: KinematicsSetup, in_force: dict[str, float],
                    changes: dict[str, float]) -> list[ProposedValue]:
    """The setup's pins with their change (pin -> change in its unit), in the setup's order, each new value as it is
    written (:func:`~pige_sym.cycle.kinematics.format_value`); changes below that resolution left out."""
    out = []
    for p in setup.pins:
        d = changes.get(p.pin, 0.0)
        if d != 0.0:
            old = in_force[p.pin]
            new = float(format_value(old + d, p.unit))  # the value halcmd and the values file get
            if new != old:
                out.append(ProposedValue(p.pin, p.target, "sets" if p.signal else "setp", old, new, p.unit, p.holds))
    return out


def new_proposal(ctx: Any, run_name: str, kind: str, entered: Any, changes: dict[str, float],
                 parameters: list[str], fingerprint: dict[str, str], predicted: dict[str, Any]) -> Proposal:
    """The proposal of a measuring run (``kind`` ``full`` for ``M451 P1``, ``map`` for a map test): the changes
    (pin -> change) as :func:`proposed_values`, the identified ``parameters`` the kinematics do not hold named with
    their weighed value in ``entered`` (never entered), made now."""
    from datetime import timezone

    held = set(ctx.setup.held())
    not_entered = [f"{n} {entered.values.get(n, 0.0):+.3g}" for n in parameters if n not in held]
    return Proposal(FORMAT, datetime.now(timezone.utc).isoformat(timespec="seconds"), run_name, kind,
                    ctx.settings.machine, ctx.setup.module, fingerprint,
                    proposed_values(ctx.setup, ctx.in_force, changes), not_entered=not_entered, predicted_um=predicted)


def limit_of(unit: str, limits: Limits) -> float:
    """The change limit in ``unit`` (mm, µm or µrad; a map grid's pins, deg and n, have none: they say where the
    values lie)."""
    return {"mm": limits.max_change_mm, "um": limits.max_change_mm * UM_PER_MM,
            "urad": limits.max_change_deg * URAD_PER_DEG}.get(unit, math.inf)  # a map's grid: no geometry


def beyond_limit(entries: list[ProposedValue], limits: Limits) -> list[str]:
    """The entries whose change exceeds the change limit, in words."""
    return [f"{e.target} {e.change:+.4g} {e.unit} (limit {limit_of(e.unit, limits):.4g} {e.unit})" for e in entries
            if abs(e.change) > limit_of(e.unit, limits)]


def refusal(proposal: Proposal | None, now: datetime, fingerprint_now: dict[str, str], limits: Limits,
            setup: KinematicsSetup, in_force: dict[str, float]) -> str | None:
    """Why ``M451 P2`` must not enter ``proposal`` (module docstring), or None."""
    if proposal is None:
        return "no proposal to enter: run M451 P1 (or M452) first"
    age_h = (now - datetime.fromisoformat(proposal.created)).total_seconds() / 3600.0
    if age_h > limits.proposal_hours:
        return (f"the proposal of {proposal.run} is {age_h:.1f} h old, older than {limits.proposal_hours:g} h "
                "(limits.proposal_hours): run M451 P1 again")
    if age_h < -0.1:
        return f"the proposal of {proposal.run} is dated in the future ({proposal.created}): run M451 P1 again"
    changed = changed_parts(proposal.fingerprint, fingerprint_now)
    if changed or proposal.fingerprint.get("all") != fingerprint_now.get("all"):
        return (f"the configuration changed since the proposal of {proposal.run} ({', '.join(changed) or 'its parts'}"
                "): run M451 P1 again")
    pins = {p.pin: p for p in setup.pins}
    for e in proposal.entries:
        p: ValuePin | None = pins.get(e.pin)
        if p is None or p.target != e.target or abs(in_force[e.pin] - e.old) > 1e-9:
            return f"the proposal's {e.target} does not match the configuration in force: run M451 P1 again"
    beyond = beyond_limit(proposal.entries, limits)
    if beyond:
        return (f"an entry exceeds the change limit: {'; '.join(beyond)}: a change this large points to a set-up "
                "error (the sphere, the stylus, the machine's structure); nothing entered; check, then calibrate")
    if not proposal.entries:
        return f"the proposal of {proposal.run} enters nothing (every value within its uncertainty)"
    return None


def read_proposal(path: Any) -> Proposal | None:
    """The proposal file, or None when there is none."""
    from pige_sym.measurements.schema import read_json_file

    if not path.is_file():
        return None
    p = read_json_file(path, Proposal, "cycle proposal")
    if p.format != FORMAT:
        return None
    return p
