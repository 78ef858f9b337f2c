"""A run's result as operator messages (:class:`~pige_sym.cycle.messages.RunMessages`), most important first.

``M451 P0`` / ``P1``::

    PIGE M451 P1 optimise: FAIL against 10 um / 30 urad; 13 poses, 65 contacts; sphere radius found 7.8500 mm ...
    left with the values in force [um]: EY0A +12.30±0.21, EZ0A -9.87±0.25, EX0C +11.95±0.14, EY0C -8.02±0.13
    [urad], not held by xyzac-trt-kins: EB0A +59.8±3.1, EC0A -45.2±2.9, EA0C +40.3±2.2, EB0C -29.6±2.4
    in force: x-rot-point 0, y-rot-point 0, z-rot-point 0, :y-offset 20, :z-offset 10 [mm]
    proposal: setp xyzac-trt-kins.x-rot-point 0.0119523 (+0.0119523), ... ; enter with M451 P2 within 8 h
    predicted tool-point RMS error over the axes' travel: now 14.2 um (95 % <= 14.5); after entering 3.1 um ...

``M452``: the verdict (ok / drifted / out), each re-measured PIGE with its control limit, and the proposal when
there are changes to enter.
"""

from __future__ import annotations

from pige_sym.cycle.messages import RunMessages, fits, pack, relative_log, value_text
from pige_sym.cycle.proposal import Proposal, ProposedValue
from pige_sym.cycle.results import RunResult

MODE_WORDS = {"check": "P0 check", "optimise": "P1 optimise", "checkup": "check-up", "map": "P3 map test"}


def _head(r: RunResult, run_path: str) -> str:
    what = MODE_WORDS.get(r.mode, r.mode)
    return (f"PIGE {r.code} {what}: {r.verdict.upper()} {r.verdict_on}; {r.poses} poses, {r.contacts} contacts; "
            f"sphere radius found {r.r_eff_mm:.4f} mm (stated {r.stated_mm:g}); "
            + (f"history run {r.history_run}" if r.history_run is not None else "not in the history") + f"; log "
            f"{run_path}")


def row_lines(r: RunResult) -> list[str]:
    """The PIGEs: held ones by unit, then those the kinematics do not hold."""
    out = []
    for held in (True, False):
        for unit in ("um", "urad"):
            rows = [x for x in r.rows if x.held == held and x.unit == unit]
            if not rows:
                continue
            head = (f"left with the values in force [{unit}]: " if held else
                    f"[{unit}], not held by {r.module} (named, never entered): ")
            out += pack(head, [f"{x.name} {value_text(x.value, x.std)}"
                               + (f" (limit ±{x.limit:.2f}{'!' if x.outside else ''})" if x.limit is not None else "")
                               for x in rows])
    return out


def entry_items(entries: list[ProposedValue]) -> list[str]:
    """Each entry as its HAL line and change; the map pins of an axis as one item: how many values, the largest
    change in each unit, the grid (the lines are in the run's log and proposal.json)."""
    from pige_sym.cycle.map_pins import axis_of, is_map_pin

    items = [f"{e.line()} ({e.change:+.7g} {e.unit})" for e in entries if not is_map_pin(e)]
    for axis in dict.fromkeys(axis_of(e) for e in entries if is_map_pin(e)):
        mine = [e for e in entries if is_map_pin(e) and axis_of(e) == axis]
        values = [e for e in mine if e.unit in ("um", "urad")]
        largest = ", ".join(f"{max(abs(e.change) for e in values if e.unit == u):.3g} {u}" for u in ("um", "urad")
                            if any(e.unit == u for e in values))
        grid = ", ".join(f"{e.target.rsplit('-', 1)[-1]} {e.new:g}" for e in mine if e.unit in ("deg", "n"))
        items.append(f"{axis} map: {len(values)} values (largest change {largest or '-'})"
                     + (f", grid {grid}" if grid else ""))
    return items


def proposal_lines(p: Proposal, hours: float, beyond: list[str]) -> list[str]:
    if not p.entries:
        return ["proposal: nothing to enter (every change within its uncertainty)"]
    items = entry_items(p.entries)
    tail = ([f"BEYOND THE CHANGE LIMIT, M451 P2 will refuse it: {'; '.join(beyond)}"] if beyond else
            [f"enter with M451 P2 within {hours:g} h"])
    return pack("proposal: ", items + tail, sep="; ")


def _now_after(p: dict[str, object]) -> str:
    now, after = p["now"], p["after"]
    assert isinstance(now, dict) and isinstance(after, dict)
    return (f"now {now['expected']:.2f} um (95 % <= {now['p95']:.2f}), after entering {after['expected']:.2f} um "
            f"(95 % <= {after['p95']:.2f})")


def predicted_line(predicted: dict[str, object]) -> list[str]:
    """The predicted tool-point RMS error at the probed poses and over the axes' travel."""
    out = []
    probed = predicted.get("probed")
    if isinstance(probed, dict):
        out.append(f"predicted tool-point RMS error at the {probed['poses']} probed poses: {_now_after(probed)}")
    if isinstance(predicted.get("now"), dict) and isinstance(predicted.get("after"), dict):
        out.append(fits(f"over {predicted.get('over', 'the axes travel')}: {_now_after(predicted)}"))
    return out


def render_run(r: RunResult, run_path: str, hours: float) -> RunMessages:
    """The operator messages of a measuring run (module docstring)."""
    lines = [_head(r, run_path), *row_lines(r)]
    if r.in_force:
        lines += pack("in force: ", [f"{t} {v:g} [{u}]" for t, v, u in r.in_force])
    if r.proposal is not None:
        lines += proposal_lines(r.proposal, hours, r.beyond_limit)
        lines += predicted_line(r.predicted_um)
    lines += [f"note: {n}" for n in r.notes]
    return RunMessages(lines)


def render_stopped(code: str, mode: str, why: str, run: str) -> RunMessages:
    """A run a guard stopped: the operator error (nothing was changed, nothing stored)."""
    return RunMessages(error=f"PIGE {code} {MODE_WORDS.get(mode, mode)} stopped, nothing changed (log {run}): {why}")


def log_path(run: object) -> str:
    from pathlib import Path

    return relative_log(Path(str(run)))
