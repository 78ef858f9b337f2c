"""``M451 P2``: enter the last proposal, or refuse it and change nothing.

The proposal is checked first (:func:`~pige_sym.cycle.proposal.refusal`: it exists, is not older than the window,
was made for the configuration in force, no entry beyond the change limit).  Then, with the kinematics in identity
mode (the procedure the prepare step wrote switched there: the pins act on nothing, no axis moves):

1. the pins are set in the running HAL (``halcmd setp``/``sets``); a refusal puts back those already set; map pins
   in the safe order (:func:`~pige_sym.cycle.map_pins.safe_order`: an axis' node count to 0 first, to its size
   last);
2. the values file is rewritten atomically, the one before kept as ``values.hal.previous`` (a failure here puts the
   pins back too): the values hold again at the next start of LinuxCNC;
3. the proposal moves into its run's folder (``proposal.entered.json``: entered once), and the journal records the
   entry with the configuration's new fingerprint.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

from pige_sym.cycle.context import Context, Request, read_context
from pige_sym.cycle.messages import RunMessages, pack, relative_log
from pige_sym.cycle.steplog import RunLog, status
from pige_sym.errors import InputError


def enter(ctx: Context, req: Request, run: Path, log: RunLog) -> RunMessages:
    """The entry (module docstring)."""
    from pige_sym.cycle.analyse import prepared_info
    from pige_sym.cycle.hal_live import set_live
    from pige_sym.cycle.map_pins import safe_order
    from pige_sym.cycle.proposal import read_proposal, refusal
    from pige_sym.cycle.render import entry_items
    from pige_sym.cycle.values import values_text, write_values

    info = prepared_info(ctx, run)
    proposal = read_proposal(ctx.layout.proposal)
    why = refusal(proposal, datetime.now(timezone.utc), ctx.fingerprint(), ctx.settings.limits, ctx.setup,
                  ctx.in_force)
    if why is not None or proposal is None:
        log.add("refused", str(why))  # nothing written but the run's own folder
        return RunMessages(error=f"PIGE M451 P2 refused, nothing changed (log {relative_log(run)}): {why}")
    if not ctx.live:
        raise InputError("halcmd does not reach the running HAL: the values cannot take effect now")
    status(run, "enter")
    pins = {p.pin: p for p in ctx.setup.pins}
    changes = safe_order(ctx.setup, ctx.in_force, [(pins[e.pin], e.old, e.new) for e in proposal.entries])
    values = dict(ctx.in_force) | {e.pin: e.new for e in proposal.entries}
    lines = set_live(changes)
    try:
        write_values(ctx.layout.values, ctx.layout.values_previous, values_text(ctx.setup, values))
    except BaseException:
        set_live([(p, new, old) for p, old, new in reversed(changes)])
        raise
    entered = run / "proposal.entered.json"
    ctx.layout.proposal.replace(entered)
    after = read_context(ctx.layout.config, live=ctx.live).fingerprint()["all"]
    _journal(ctx, req, run, info, "entered", proposal.run, proposal.kind, after)
    log.add("entered", "\n".join(lines) + f"\nvalues file {ctx.layout.values} rewritten (previous: "
            f"{ctx.layout.values_previous.name}); proposal of {proposal.run} moved to {entered}")
    nxt = ("call M451 P0 to check the machine with them" if proposal.kind in ("full", "map") else
           "the next M452 compares with them")
    return RunMessages(pack(f"PIGE M451 P2: entered from {proposal.run}: ", entry_items(proposal.entries)
                            + [f"values.hal rewritten, the one before kept as values.hal.previous; {nxt}"], sep="; "))


def _journal(ctx: Context, req: Request, run: Path, info: dict[str, object], outcome: str, source: str | None = None,
             kind: str | None = None, after: str | None = None) -> None:
    from pige_sym.cycle.journal import JournalEntry, append_entry

    fp = info["fingerprint"]
    assert isinstance(fp, dict)
    append_entry(ctx.layout, JournalEntry(datetime.now(timezone.utc).isoformat(timespec="seconds"), run.name, req.code,
                                          req.mode, outcome, str(fp["all"]), entered_from=source, entered_kind=kind,
                                          fingerprint_after=after))
