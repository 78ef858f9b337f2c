"""The analysis of ``M451 P0`` (check) and ``M451 P1`` (optimise): import, the sphere-radius guard, identify, judge,
propose, store.

1. ``pige import-probe`` of LinuxCNC's probe log with the run's program (its header gives the machine, sense,
   pivots, radii, kinematics), as a user runs it.
2. **Sphere radius** (the guard, before identifying): the radius the probe finds (the import's fitted R + r −
   pre-travel) against the stated ``sphere_radius_mm + stylus_radius_mm``; beyond ``limits.sphere_radius_mm`` the
   run stops (dirt on the sphere, a wrong stylus or sphere): nothing stored, nothing proposed.
3. ``identify`` and its model check: the PIGEs left with the values in force (the program probed in the TCP
   kinematics), each with its standard error; the verdict against the tolerances (``pige check``'s rule).
4. ``P1``: the weighed entries ``pige compensate --controller linuxcnc`` would print (each estimate weighed by its
   uncertainty over the axes' travel), as new values of the kinematics' pins (the values in force plus the
   change), and the predicted tool-point error before and after with its 95 % bound: the **proposal**.
5. The run is stored in the machine's history (``pige history add``'s function, the Gauss-Newton estimate), then
   the proposal, the journal line and the run's result.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from pige_sym.cycle.context import Context, Request
from pige_sym.cycle.messages import RunMessages, relative_log
from pige_sym.cycle.proposal import Proposal
from pige_sym.cycle.results import PigeRow, RunResult
from pige_sym.cycle.steplog import RunLog, pige_command, status
from pige_sym.errors import GuardStopped, InputError


def prepared_info(ctx: Context, run: Path) -> dict[str, Any]:
    """What the prepare step recorded; refused when the configuration changed since."""
    from pige_sym.cycle.context import changed_parts
    from pige_sym.measurements.strict_json import load_json

    info = load_json(run / "prepared.json", "prepared run")
    now = ctx.fingerprint()
    if info["fingerprint"]["all"] != now["all"]:
        parts = ", ".join(changed_parts(info["fingerprint"], now))
        raise InputError(f"the configuration changed during the run ({parts}): call the cycle again")
    return dict(info)


def import_log(run: Path, req: Request, log: RunLog) -> Any:
    """``pige import-probe`` of the run's probe log: the measurement, dated when the run started and named by the run
    (``date``, ``cycle_run`` metadata: the history's time of the run, and two runs that logged the same contacts, as
    an exact simulation does, are still two files)."""
    from pige_sym.measurements.probe_import import verify_written
    from pige_sym.measurements.rtest import read_measurement
    from pige_sym.measurements.rtest_writer import write_measurement

    status(run, "import")
    argv = ["import-probe", str(run / "probe_log.txt"), "--format", "linuxcnc", "--program", str(run / "program.ngc"),
            "--out", str(run / "probe.csv")]
    code, out = pige_command(argv)
    log.add("pige " + " ".join(argv), out)
    if code != 0:
        raise InputError(f"pige import-probe refused the probe log: {out.strip().splitlines()[-1] if out else code}")
    csv = run / "probe.csv"
    m = read_measurement(csv)
    m.metadata["date"], m.metadata["cycle_run"] = req.started, run.name
    write_measurement(m, csv, verify=verify_written(csv, m))
    return read_measurement(csv)


def radius_guard(ctx: Context, m: Any) -> tuple[float, float]:
    """(radius found, radius stated) [mm]; :class:`~pige_sym.errors.GuardStopped` beyond the limit (module
    docstring)."""
    s = ctx.settings
    found = float(m.metadata["r_eff_mm"].split()[0])
    stated = s.sphere_radius_mm + s.stylus_radius_mm
    if abs(found - stated) > s.limits.sphere_radius_mm:
        raise GuardStopped(f"sphere radius found {found:.4f} mm, {found - stated:+.4f} from R + r = {stated:g} (limit "
                      f"±{s.limits.sphere_radius_mm:g}): dirt on the sphere or stylus, or a wrong one; clean them or "
                      "correct the radii in settings.json")
    return found, stated


def pige_rows(ctx: Context, result: Any) -> list[PigeRow]:
    """The identified PIGEs as rows: held or not by the kinematics, with the pin value in force for pige's component."""
    import math

    held = set(ctx.setup.held())
    pins = {p.holds: ctx.in_force[p.pin] for p in ctx.setup.pins} if ctx.setup.kinematics == "pige" else {}
    rows = []
    for i, name in enumerate(result.parameters):
        std = float(result.std[i])
        rows.append(PigeRow(name, result.units[name], float(result.values[i]), std if math.isfinite(std) else math.nan,
                            name in held, pins.get(name)))
    return rows


def in_force_list(ctx: Context) -> list[tuple[str, float, str]]:
    """The values in force, by the name an operator reads (a pin without its module's prefix); the map pins left out
    (their node counts are in the proposal's lines)."""
    from pige_sym.cycle.map_pins import is_map_pin

    module = ctx.setup.module + "."
    return [(p.target.removeprefix(module), ctx.in_force[p.pin], p.unit) for p in ctx.setup.pins if not is_map_pin(p)]


def machine_parameters(result: Any, offset: list[float]) -> Any:
    """Compensation parameters of ``result`` in machine coordinates: its pivots and point shifted by the work offset
    the program was written in (a translation: the PIGEs do not change)."""
    from pige_sym.compensation.parameters import parameters_from_result

    params = parameters_from_result(result)
    o = offset[:3]
    pivots = {a: [float(v) + o[k] for k, v in enumerate(xyz)] for a, xyz in params.pivots_mm.items()}
    ball = None if params.ball_mm is None else [float(v) + o[k] for k, v in enumerate(params.ball_mm)]
    return replace(params, pivots_mm=pivots, ball_mm=ball)


def value_changes(ctx: Context, entered: Any) -> dict[str, float]:
    """pin -> change of the kinematics' values that enters ``entered`` (its values: the changes in PIGEs)."""
    from pige_sym.codegen.targets.linuxcnc_pins import error_pin
    from pige_sym.compensation.controllers.linuxcnc import linuxcnc_trt_deltas

    setup = ctx.setup
    if setup.kinematics == "pige":
        return {error_pin(setup.module, n): float(entered.values.get(n, 0.0)) for n in setup.held()}
    module, deltas = linuxcnc_trt_deltas(entered)
    return {f"{module}.{pin}": d for pin, d in deltas.items()}


def hal_config(ctx: Context) -> Any:
    """The values in force as ``pige compensate --current`` reads a configuration (for its text in the log)."""
    from pige_sym.compensation.controllers.hal_config import HalConfig

    cfg = HalConfig(str(ctx.layout.values), module=ctx.setup.module, module_where=str(ctx.ini))
    for p in ctx.setup.pins:
        short = p.pin.split(".", 1)[1]
        if p.signal:
            cfg.nets[short], cfg.signals[p.signal] = p.signal, ctx.in_force[p.pin]
        else:
            cfg.pins[short] = ctx.in_force[p.pin]
    return cfg


def probed_prediction(params: Any, angles_deg: Any, entered: dict[str, float]) -> dict[str, Any] | None:
    """The predicted RMS tool-point error at the probed poses (the sphere centre at each), now and after entering
    ``entered`` (what the kinematics hold), with their 95 % bounds (compensate's weighing on the program's poses)."""
    import numpy as np

    from pige_sym.compensation.weighing import program_poses, weigh

    if params.ball_mm is None:
        return None
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    w = weigh(params, program_poses(angles, np.tile(np.asarray(params.ball_mm, dtype=float), (angles.shape[0], 1))))
    now, after = w.predicted_for({}), w.predicted_for(entered)
    if now is None or after is None:
        return None
    return {"now": now.to_dict(), "after": after.to_dict(), "poses": int(angles.shape[0])}


def full_proposal(ctx: Context, req: Request, run: Path, result: Any, log: RunLog,
                  fingerprint: dict[str, str], m_angles: Any) -> tuple[Proposal, dict[str, Any]]:
    """The proposal of ``P1`` and the predicted tool-point error (module docstring, step 4)."""
    from pige_sym.compensation.controllers import entered_for_controller
    from pige_sym.compensation.controllers.scope import tool_point_summary
    from pige_sym.compensation.stage import format_controller
    from pige_sym.cycle.proposal import new_proposal

    status(run, "weigh")
    params = machine_parameters(result, req.offset)
    entered = entered_for_controller(params, "weighed")
    scope = tool_point_summary(entered, "linuxcnc")
    after = scope.complete if ctx.setup.kinematics == "pige" else scope.controller_only
    held = set(ctx.setup.held())
    predicted = {"over": scope.judged_on, "now": scope.before.to_dict() if scope.before else None,
                 "after": after.to_dict() if after else None,
                 "probed": probed_prediction(params, m_angles, {n: v for n, v in entered.values.items() if n in held})}
    if ctx.setup.kinematics == "stock":
        try:
            text = format_controller(entered, "linuxcnc", current=hal_config(ctx))
        except InputError as exc:  # a change beyond --max-change: the proposal says so, M451 P2 refuses it
            text = f"refused: {exc}"
        log.add("pige compensate --controller linuxcnc (the values in force as --current)", text)
    return new_proposal(ctx, run.name, "full", entered, value_changes(ctx, entered), result.parameters, fingerprint,
                        predicted), predicted


def store_full(ctx: Context, req: Request, run: Path, csv: Path, m: Any, result: Any) -> int:
    """The run in the machine's history (``pige history add``'s function, with the identification ``result`` of the
    measurement ``m`` read from ``csv``, made already); its run id."""
    import json

    from pige_sym.verdict.history import add_run, connect

    status(run, "store")
    tol = run / "tolerances.json"
    tol.write_text(json.dumps(ctx.settings.tolerances), encoding="utf-8")
    record = add_run(connect(ctx.settings.db_url(ctx.layout.config)), csv, ctx.settings.machine_id,
                     method="gauss-newton", tolerances=tol, date=req.started, identified=(m, result))
    return int(record.id)


def measure(ctx: Context, req: Request, run: Path, log: RunLog) -> tuple[dict[str, Any], Any, tuple[float, float]] | \
        RunMessages:
    """Steps 1-2 of every analysis (``M451 P0``/``P1`` and ``M452``): the prepared run's record, the import of its
    probe log and the sphere-radius guard: ``(prepared info, measurement, (radius found, stated) [mm])``, or the
    messages of a run the guard stopped (recorded in its folder only)."""
    from pige_sym.cycle.render import render_stopped

    info = prepared_info(ctx, run)
    m = import_log(run, req, log)
    try:
        radius = radius_guard(ctx, m)
    except GuardStopped as exc:
        record_stopped(ctx, req, run, info, str(exc), log)
        return render_stopped(req.code, req.mode, str(exc), relative_log(run))
    return info, m, radius


def analyse(ctx: Context, req: Request, run: Path, log: RunLog) -> RunMessages:
    """The analysis of ``P0``/``P1`` (module docstring)."""
    measured = measure(ctx, req, run, log)
    if isinstance(measured, RunMessages):
        return measured
    info, m, radius = measured
    result = identify(m, run, log)
    return conclude(ctx, req, run, log, info, m, result, radius)


def identify(m: Any, run: Path, log: RunLog) -> Any:
    from pige_sym import api
    from pige_sym.identification.model_check import check_model
    from pige_sym.identification.result import format_result

    status(run, "identify")
    result = api.identify(m)
    check = check_model(m, result)
    log.add("pige identify", format_result(result) + ("" if check is None else "\n\n" + check.text()))
    return result


def conclude(ctx: Context, req: Request, run: Path, log: RunLog, info: dict[str, Any], m: Any, result: Any,
             radius: tuple[float, float]) -> RunMessages:
    """Verdict, proposal, the record (module docstring, steps 3-5), the messages."""
    from pige_sym import api
    from pige_sym.cycle.proposal import beyond_limit
    from pige_sym.cycle.render import render_run

    verdict = api.check(result, ctx.settings.tolerances)
    log.add("pige check (the PIGEs left with the values in force, against the settings' tolerances)", verdict.format())
    proposal, predicted = (full_proposal(ctx, req, run, result, log, info["fingerprint"], m.angles_deg)
                           if req.mode == "optimise" else (None, {}))
    history_run = store_full(ctx, req, run, run / "probe.csv", m, result)
    tol = ctx.settings.tolerances.get("defaults", {})
    res = RunResult(req.code, req.mode, run.name, ctx.setup.module, m.n_rows, int(m.optional["n_samples"].sum()),
                    radius[0], radius[1], pige_rows(ctx, result), verdict.verdict,
                    f"against {tol.get('um', '?')} um / {tol.get('urad', '?')} urad", in_force_list(ctx),
                    history_run, proposal, beyond_limit(proposal.entries, ctx.settings.limits) if proposal else [],
                    predicted)
    record(ctx, req, run, info, res, proposal, log)
    return render_run(res, relative_log(run), ctx.settings.limits.proposal_hours)


def record(ctx: Context, req: Request, run: Path, info: dict[str, Any], res: RunResult, proposal: Proposal | None,
           log: RunLog) -> None:
    """The proposal, the run's result and its journal line (the history holds the run already)."""
    from datetime import datetime, timezone

    from pige_sym.cycle.journal import JournalEntry, append_entry
    from pige_sym.files import atomic_write_text, to_json

    if proposal is not None:
        atomic_write_text(ctx.layout.proposal, to_json(proposal.to_dict()) + "\n")
    atomic_write_text(run / "result.json", to_json(res.to_dict()) + "\n")
    kind = "checkup" if req.mode == "checkup" else "full"
    append_entry(ctx.layout, JournalEntry(datetime.now(timezone.utc).isoformat(timespec="seconds"), run.name, req.code,
                                          req.mode, "measured", info["fingerprint"]["all"], kind, res.history_run,
                                          res.verdict))
    log.add("recorded", f"history run {res.history_run}; proposal {'written' if proposal else 'none'}")


def record_stopped(ctx: Context, req: Request, run: Path, info: dict[str, Any], why: str, log: RunLog) -> None:
    log.add("stopped", why)  # the run's folder holds it; the journal, the history and the proposal stay as they were
