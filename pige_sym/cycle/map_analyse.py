"""The analysis of ``M451 P3 Q<k>``: one setup of the map test measured; after the last, the maps identified.

1. As every measuring run (:func:`~pige_sym.cycle.analyse.measure`): ``pige import-probe`` of the setup's probe log,
   and the **sphere-radius guard** of this setup (a stopped setup is not part of the map test).
2. The setup's record ``map_setup.json`` in its run folder (:class:`SetupRecord`), and a journal line.
3. The map test's setups (:func:`collect_setups`): for each k of 1..N the latest setup measured with the
   configuration's fingerprint of this run and within ``limits.proposal_hours``; a setup measured again replaces the
   earlier one; an entry (``M451 P2``) or any edit of the configuration starts the test afresh.  With one missing,
   the message says where the sphere of the next missing setup goes (:func:`~pige_sym.cycle.map_prepare.
   setup_sphere`) and which code to call.
4. With all N: ``pige identify --map`` (:func:`~pige_sym.identification.maps.identify_maps`, PIGEs, zero-position
   errors and maps jointly from every setup's file) and the verdict of the PIGEs left against the tolerances; the
   **proposal**: the parameters in machine coordinates, weighed as ``pige compensate`` weighs them
   (:func:`~pige_sym.compensation.controllers.entered_for_controller`), their 8 PIGE pins (the value in force plus
   the change, :func:`~pige_sym.cycle.analyse.value_changes`) and their map pins (:func:`map_changes`: the maps as
   ``pige compensate --controller linuxcnc`` gives them to the component, :func:`~pige_sym.compensation.
   controllers.tables.linuxcnc_kins_maps.component_maps`, each value held to the change limit by ``M451 P2``), the
   predicted tool-point error over the axes' travel before and after.  The zero-position errors are named, not
   entered (the cycle enters the location errors and the maps; a zero-position error is the homing's).

The map test is not stored in the machine's history (the history holds single-file PIGE runs): its record is the
run folders, ``result.json`` and the journal.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.cycle.context import Context, Request
from pige_sym.cycle.messages import RunMessages, pack, relative_log
from pige_sym.cycle.proposal import Proposal
from pige_sym.cycle.steplog import RunLog, status
from pige_sym.errors import InputError

RECORD = "map_setup.json"


@dataclass(frozen=True)
class SetupRecord:
    """One measured setup of the map test (``map_setup.json``): setup ``k`` of ``n``, the configuration's
    fingerprint it was measured with, when it started, its poses and contacts, the radius found [mm]."""

    setup: int
    setups: int
    fingerprint: str
    started: str
    run: str
    poses: int
    contacts: int
    r_eff_mm: float


def collect_setups(ctx: Context, fingerprint: str, now: datetime) -> dict[int, tuple[Path, SetupRecord]]:
    """The map test's setups (module docstring, step 3): setup k → (its run folder, its record)."""
    m = ctx.settings.map
    assert m is not None
    out: dict[int, tuple[Path, SetupRecord]] = {}
    for path in sorted(ctx.layout.runs.glob(f"*/{RECORD}")):  # named by their start time: the latest last
        try:
            r = SetupRecord(**json.loads(path.read_text(encoding="utf-8")))
            age_h = (now - datetime.fromisoformat(r.started)).total_seconds() / 3600.0
        except (OSError, ValueError, TypeError):
            continue  # not a record of this version: not part of the test
        if r.fingerprint == fingerprint and r.setups == m.setups and 1 <= r.setup <= m.setups and \
                -0.1 <= age_h <= ctx.settings.limits.proposal_hours:
            out[r.setup] = (path.parent, r)
    return out


def analyse_map(ctx: Context, req: Request, run: Path, log: RunLog) -> RunMessages:
    """The analysis of ``M451 P3 Q<k>`` (module docstring)."""
    from pige_sym.cycle.analyse import measure
    from pige_sym.cycle.map_prepare import check_map_request
    from pige_sym.files import atomic_write_text, to_json

    k = check_map_request(ctx, req)
    measured = measure(ctx, req, run, log)
    if isinstance(measured, RunMessages):
        return measured
    info, m, radius = measured
    s = ctx.settings.map
    assert s is not None
    record = SetupRecord(k, s.setups, info["fingerprint"]["all"], req.started, run.name, int(m.n_rows),
                         int(m.optional["n_samples"].sum()), radius[0])
    atomic_write_text(run / RECORD, to_json(asdict(record)) + "\n")
    _journal(ctx, req, run, info["fingerprint"]["all"], "map-setup", None)
    setups = collect_setups(ctx, record.fingerprint, datetime.now(timezone.utc))
    missing = [i for i in range(1, s.setups + 1) if i not in setups]
    if missing:
        return _next_setup(ctx, req, run, record, setups, missing[0])
    return conclude_map(ctx, req, run, log, info, setups)


def _next_setup(ctx: Context, req: Request, run: Path, record: SetupRecord,
                setups: dict[int, tuple[Path, SetupRecord]], nxt: int) -> RunMessages:
    from pige_sym.cycle.map_prepare import setup_sphere

    where = ", ".join(f"{v:.4g}" for v in setup_sphere(run, nxt, req))
    done = ", ".join(str(i) for i in sorted(setups))
    return RunMessages([
        f"PIGE M451 P3 map setup {record.setup} of {record.setups} measured: {record.poses} poses, {record.contacts} "
        f"contacts; sphere radius found {record.r_eff_mm:.4f} mm; log {relative_log(run)}",
        f"setups measured: {done}; next: clamp the sphere at X, Y, Z = {where} mm (machine coordinates, rotary axes "
        f"at 0), move the stylus clear above it and call M451 P3 Q{nxt}"])


def identify_setups(ctx: Context, run: Path, log: RunLog, setups: dict[int, tuple[Path, SetupRecord]]) -> Any:
    """``pige identify --map`` of every setup's file (module docstring, step 4)."""
    from pige_sym.identification.joint import format_files
    from pige_sym.identification.map_output import format_maps
    from pige_sym.identification.maps import MapSpec, identify_maps
    from pige_sym.identification.result import format_result
    from pige_sym.measurements.sets import read_files

    s = ctx.settings.map
    assert s is not None
    status(run, "identify")
    files = [setups[k][0] / "probe.csv" for k in sorted(setups)]
    result = identify_maps(read_files(files), MapSpec(tuple(s.axes), float(s.step_deg), tuple(s.per_direction)))
    log.add("pige identify " + " ".join(str(f) for f in files) + f" --map {','.join(s.axes)} --map-step "
            f"{s.step_deg:g}", format_result(result.result) + "\n" + format_files(result.joint.files) + "\n"
            + format_maps(result))
    return result


def map_changes(ctx: Context, entered: Any) -> dict[str, float]:
    """pin → change of the map pins that enters the weighed maps of ``entered`` (module docstring): the grid set to
    the map test's, each value the one found plus the one in force when the axis' map is in force (the setups
    were probed with it acting), else the one found.

    Raises
    ------
    InputError
        An identified grid that is not the map test's, or a map in force on another grid.
    """
    from pige_sym.codegen.targets.linuxcnc_pins import map_pin, map_slot_names
    from pige_sym.compensation.controllers.tables.linuxcnc_kins_maps import component_maps
    from pige_sym.cycle.map_pins import check_grid, grid_targets, map_grids

    s = ctx.settings.map
    assert s is not None
    grids = map_grids(ctx.setup.machine, s)
    module, now = ctx.setup.module, ctx.in_force
    out: dict[str, float] = {}
    for cm in component_maps(entered):
        g = check_grid(grids, cm.axis, cm.axis_maps.grid.angles_deg, cm.axis_maps.grid.full_turn)
        targets = grid_targets(module, g)
        in_force = now[f"{module}.map-{g.axis.lower()}-nodes"] != 0.0
        if in_force and any(abs(now[pin] - v) > 1e-9 for pin, v in targets.items()):
            grid = ", ".join(f"{pin.rsplit('-', 1)[-1]} {now[pin]:g}" for pin in targets)
            raise InputError(f"a map of {g.axis} on another grid is in force ({grid}); the map test adds to a map on "
                             f"its own grid ({g.step_deg:g} deg, {g.nodes} angles) only: install with that map's grid, "
                             f"or set map-{g.axis.lower()}-nodes 0 in values.hal with LinuxCNC stopped")
        out |= {pin: v - now[pin] for pin, v in targets.items()}
        for stem, values in zip(map_slot_names(cm.axis), cm.slots, strict=True):
            for node, v in enumerate(np.nan_to_num(values)):
                pin = map_pin(module, stem, node)
                out[pin] = float(v) if in_force else float(v) - now[pin]
    return out


def map_proposal(ctx: Context, req: Request, run: Path, result: Any, fingerprint: dict[str, str]
                 ) -> tuple[Proposal, dict[str, Any]]:
    """The proposal and the predicted tool-point error (module docstring, step 4)."""
    from pige_sym.compensation.controllers import entered_for_controller
    from pige_sym.compensation.controllers.entry_checks import check_parameters
    from pige_sym.compensation.controllers.scope import tool_point_summary
    from pige_sym.cycle.analyse import machine_parameters, value_changes
    from pige_sym.cycle.proposal import new_proposal

    status(run, "weigh")
    entered = entered_for_controller(machine_parameters(result, req.offset), "weighed")
    check_parameters(entered)  # the physical bounds every controller entry is held to (the change limit: M451 P2)
    scope = tool_point_summary(entered, "linuxcnc")
    predicted = {"over": scope.judged_on, "now": scope.before.to_dict() if scope.before else None,
                 "after": scope.complete.to_dict() if scope.complete else None}
    changes = value_changes(ctx, entered) | map_changes(ctx, entered)
    return new_proposal(ctx, run.name, "map", entered, changes, result.result.parameters, fingerprint,
                        predicted), predicted


def conclude_map(ctx: Context, req: Request, run: Path, log: RunLog, info: dict[str, Any],
                 setups: dict[int, tuple[Path, SetupRecord]]) -> RunMessages:
    """Steps 4 of the module docstring with every setup measured: identify, judge, propose, record; the messages."""
    from pige_sym import api
    from pige_sym.cycle.analyse import in_force_list, pige_rows
    from pige_sym.cycle.proposal import beyond_limit
    from pige_sym.cycle.render import render_run
    from pige_sym.cycle.results import RunResult
    from pige_sym.files import atomic_write_text, to_json

    result = identify_setups(ctx, run, log, setups)
    verdict = api.check(result.result, ctx.settings.tolerances)
    log.add("pige check (the PIGEs left with the values in force, against the settings' tolerances)", verdict.format())
    proposal, predicted = map_proposal(ctx, req, run, result, info["fingerprint"])
    tol = ctx.settings.tolerances.get("defaults", {})
    recs = [r for _, r in setups.values()]
    res = RunResult(req.code, req.mode, run.name, ctx.setup.module, sum(r.poses for r in recs),
                    sum(r.contacts for r in recs), float(np.mean([r.r_eff_mm for r in recs])),
                    ctx.settings.sphere_radius_mm + ctx.settings.stylus_radius_mm, pige_rows(ctx, result.result),
                    verdict.verdict, f"against {tol.get('um', '?')} um / {tol.get('urad', '?')} urad",
                    in_force_list(ctx), None, proposal, beyond_limit(proposal.entries, ctx.settings.limits), predicted,
                    map_notes(result, setups))
    atomic_write_text(ctx.layout.proposal, to_json(proposal.to_dict()) + "\n")
    atomic_write_text(run / "result.json", to_json(res.to_dict()) + "\n")
    _journal(ctx, req, run, info["fingerprint"]["all"], "map", res.verdict)
    log.add("recorded", "proposal written (the map test is not stored in the history)")
    return render_run(res, relative_log(run), ctx.settings.limits.proposal_hours)


def map_notes(result: Any, setups: dict[int, tuple[Path, SetupRecord]]) -> list[str]:
    """What the message adds for a map test: the setups, each axis' largest map value found, the values left
    undetermined (entered as 0: nothing corrected there)."""
    out = [f"map test of the setups {', '.join(f'{k} ({r.run})' for k, (_, r) in sorted(setups.items()))}"]
    for axis, amap in result.maps.items():
        largest = []
        for mo in amap.motions:
            v = np.asarray(amap.value[mo.name], dtype=float)
            if np.isfinite(v).any():
                largest.append(f"{mo.name} {np.nanmax(np.abs(v)):.3g}")
        out += pack(f"{axis} map every {amap.grid.angles_deg[1] - amap.grid.angles_deg[0]:g} deg, largest |value| "
                    "[um, urad]: ", largest)
    if result.undetermined:
        said = [u.motion if u.angle_deg is None else f"{u.motion}@{u.angle_deg:g}" for u in result.undetermined]
        out += pack("undetermined by these setups (a whole motion, or motion@angle; entered as 0, nothing corrected "
                    "there; the log says why): ", said)
    return out


def _journal(ctx: Context, req: Request, run: Path, fingerprint: str, kind: str, verdict: str | None) -> None:
    """A journal line: a setup measured (``map-setup``), or the map test concluded (``map``, with its verdict)."""
    from pige_sym.cycle.journal import JournalEntry, append_entry

    append_entry(ctx.layout, JournalEntry(datetime.now(timezone.utc).isoformat(timespec="seconds"), run.name, req.code,
                                          req.mode, "measured", fingerprint, kind, None, verdict))

