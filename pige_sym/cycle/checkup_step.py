"""The analysis of ``M452``: the history's short run (``pige checkup``), its verdict, and its changes as a proposal.

The check-up program was written from the history by the prepare step, once the check-up's basis held (the last
full calibration made by the cycle with the configuration in force, less the check-ups' own entries:
:func:`~pige_sym.cycle.journal.checkup_basis`).  Here: ``pige import-probe`` of the log, the sphere-radius guard, then
``pige checkup``'s function (:func:`~pige_sym.verdict.checkup.routine.run_checkup`: the re-measured PIGEs fitted with
the others held, judged against their control limits and tolerance, stored in the history as a check-up), with
``corrected`` when the previous check-up's changes were entered since.  Its verdict: ``ok``, ``drifted`` or ``out``;
its changes to enter (weighed, within the change limit) become the proposal that ``M451 P2`` enters like any other.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pige_sym.cycle.analyse import in_force_list, measure, record, value_changes
from pige_sym.cycle.context import Context, Request
from pige_sym.cycle.messages import RunMessages, relative_log
from pige_sym.cycle.proposal import Proposal
from pige_sym.cycle.results import PigeRow, RunResult
from pige_sym.cycle.steplog import RunLog, status


def run_the_checkup(ctx: Context, req: Request, run: Path, corrected: bool, log: RunLog) -> Any:
    """``pige checkup``'s function on the run's measurement (stored in the history)."""
    from pige_sym.cli.checkup import format_checkup
    from pige_sym.verdict.checkup.routine import CheckupOptions, run_checkup
    from pige_sym.verdict.history.sqlite_fast import open_history

    status(run, "checkup")
    s = ctx.settings
    tol = run / "tolerances.json"
    tol.write_text(json.dumps(s.tolerances), encoding="utf-8")
    opts = CheckupOptions(tolerances=tol, corrected=corrected, date=req.started,
                          max_change=(s.limits.max_change_mm, s.limits.max_change_deg))
    result = run_checkup(open_history(s.db_url(ctx.layout.config)), run / "probe.csv", s.machine_id, opts)
    log.add(f"pige checkup{' --corrected' if corrected else ''}", format_checkup(result))
    return result


def checkup_proposal(ctx: Context, run: Path, result: Any, fingerprint: dict[str, str]) -> Proposal | None:
    """The check-up's changes to enter as a proposal (None when it is ``ok`` or enters nothing)."""
    from datetime import datetime, timezone

    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.cycle.proposal import FORMAT, proposed_values

    changes = {n: v for n, v in (result.changes.entered if result.changes else {}).items() if v}
    if result.verdict == "ok" or not changes:
        return None
    units = {i.name: i.unit for i in result.items}
    params = CompensationParameters(result.machine, changes, units, None, {}, "the check-up", [])
    entries = proposed_values(ctx.setup, ctx.in_force, value_changes(ctx, params))
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    not_entered = [f"{n} ({result.changes.why[n]})" for n, v in result.changes.entered.items() if v is None]
    return Proposal(FORMAT, created, run.name, "checkup", ctx.settings.machine, ctx.setup.module, fingerprint, entries,
                    result.run_id, not_entered)


def analyse_checkup(ctx: Context, req: Request, run: Path, log: RunLog) -> RunMessages:
    """The analysis of ``M452`` (module docstring)."""
    from pige_sym.cycle.proposal import beyond_limit
    from pige_sym.cycle.render import render_run

    measured = measure(ctx, req, run, log)
    if isinstance(measured, RunMessages):
        return measured
    info, m, (r_eff, stated) = measured
    result = run_the_checkup(ctx, req, run, bool(info["basis"]["corrected"]), log)
    proposal = checkup_proposal(ctx, run, result, info["fingerprint"])
    rows = [PigeRow(i.name, i.unit, i.value, i.std, True, None, i.status,
                    None if i.limit is None else i.limit.half_width, bool(i.limit and i.limit.outside))
            for i in result.items]
    flagged = [i.name for i in result.items if i.limit is not None and i.limit.outside]
    out = [i.name for i in result.items if i.status in ("fail", "undecided")]
    on = (f"({', '.join(out)} not shown within the tolerance)" if result.verdict == "out" else
          f"({', '.join(flagged)} outside their control limits)" if flagged else
          "against the control limits and the tolerances")
    res = RunResult(req.code, req.mode, run.name, ctx.setup.module, m.n_rows, int(m.optional["n_samples"].sum()),
                    r_eff, stated, rows, result.verdict, on, in_force_list(ctx), result.run_id, proposal,
                    beyond_limit(proposal.entries, ctx.settings.limits) if proposal else [],
                    notes=list(result.notes))
    record(ctx, req, run, info, res, proposal, log)
    return render_run(res, relative_log(run), ctx.settings.limits.proposal_hours)
