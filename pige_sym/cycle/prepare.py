"""The prepare step: check LinuxCNC's state, write the run's probing program and the procedure that runs it.

**Checks** (each refusal names what to do; nothing has moved): the stylus tool is the one loaded; no G92 offset;
the active coordinate system rotates nothing and offsets no rotary axis; the kinematics are in identity or TCP mode
(a configuration with a switch); for a probing run, the rotary axes stand at 0 (the program starts there).

**The program** is the one ``pige program --instrument sphere-probe --dialect linuxcnc`` writes for the configuration
as it is now, with its read-back: probed in the **TCP kinematics** (``--kinematics tcp``), so that the values in force
act and the PIGEs found are what is left with them (what a check shows, what an entry corrects); the nominal lines
are those the kinematics hold (the stock trt pins, or pige's component's pivots), in the active coordinate system
(``--work-offset G5x=`` its X Y Z: the sphere and the lines shifted by it; the program checks the values).
``M452`` takes the check-up program ``pige program --checkup`` writes from the history; ``M451 P3 Q<k>`` the
program of setup k that ``pige program --map`` writes (:mod:`~pige_sym.cycle.map_prepare`).  ``M451 P2`` probes nothing:
its procedure switches to identity kinematics, where the kinematics' pins act on nothing, so that entering them moves
no axis.

The procedure (``pige_cycle/run/pige_cycle_probe.ngc``) is the program wrapped as an NGC procedure
(:func:`~pige_sym.cycle.assets.probe_procedure`), after the switch to TCP when the kinematics were in identity.
"""

from __future__ import annotations

from pathlib import Path

from pige_sym.cycle.context import Context, Request
from pige_sym.cycle.messages import RunMessages
from pige_sym.cycle.program_words import probing_program, run_program, word
from pige_sym.cycle.steplog import RunLog, status
from pige_sym.errors import InputError

TOLERANCE_DEG = 5e-4


def check_state(ctx: Context, req: Request) -> None:
    """The module docstring's checks.

    Raises
    ------
    InputError
        With what to do.
    """
    s = ctx.settings
    if req.tool != s.stylus_tool:
        raise InputError(f"the spindle holds T{req.tool}; the cycle probes with the stylus T{s.stylus_tool}: load it "
                         f"(T{s.stylus_tool} M6) and call {req.code} again")
    sw = s.kinematics_switch
    if sw is not None and req.switchkins_type not in (sw.identity_type, sw.tcp_type):
        raise InputError(f"the kinematics are switched to type {req.switchkins_type}: select identity "
                         f"({sw.identity_code}) or TCP ({sw.tcp_code}) kinematics, then call {req.code} again")
    if req.mode == "enter":
        return
    from pige_sym.nc.probe_safety import WORK_OFFSETS

    system = WORK_OFFSETS[req.system - 1]
    if req.g92_on:
        raise InputError("G92 offsets are active: clear them (G92.1), then call the cycle again")
    if req.rotation != 0.0 or any(abs(v) > 0.0 for v in req.offset[3:6]):
        raise InputError(f"{system} rotates XY or offsets a rotary axis: the cycle probes in a coordinate system "
                         "without either; select another (G54 ... G59.3)")
    from pige_sym.kernels import load_kernels

    axes = tuple(load_kernels(s.machine).ROTARY_AXES)
    off = {a: req.position[3 + "ABC".index(a)] for a in axes}
    if any(abs(v) > TOLERANCE_DEG for v in off.values()):
        at = ", ".join(f"{a} {v:g}" for a, v in off.items())
        raise InputError(f"the rotary axes stand at {at}: turn them to 0 with the stylus clear above the sphere (the "
                         "probing program starts there), then call the cycle again")


def checkup_program(ctx: Context, req: Request, run: Path, log: RunLog) -> tuple[Path, dict[str, object]]:
    """``pige program --checkup`` from the history, once the check-up's basis holds (:mod:`~pige_sym.cycle.journal`);
    the program and the basis."""
    from pige_sym.cycle.journal import checkup_basis, read_journal
    from pige_sym.verdict.history import connect, list_runs

    s = ctx.settings
    basis = checkup_basis(read_journal(ctx.layout), ctx.fingerprint()["all"])
    db = s.db_url(ctx.layout.config)
    runs = list_runs(connect(db, create=False), s.machine_id, light=True)
    full = [r.id for r in runs if r.kind == "full"]
    if not full or full[-1] != basis.full_run:
        raise InputError(f"the history's last full calibration of {s.machine_id} is run {full[-1] if full else '-'}, "
                         f"not the cycle's (run {basis.full_run}): run M451 P0 first")
    p = s.probing
    argv = ["program", "--checkup", "--machine-id", s.machine_id, "--db", db, "--dialect", "linuxcnc",
            "--probe-feed", word(p.probe_feed_mm_min), "--clearance", word(p.clearance_mm), "--overtravel",
            word(p.overtravel_mm), "--out", str(run / "program.ngc")]
    program = run_program(argv, run, log)
    _same_work_offset(program, req)
    return program, {"full_run": basis.full_run, "corrected": basis.corrected}


def _same_work_offset(program: Path, req: Request) -> None:
    from pige_sym.nc.probe_header import header_setup
    from pige_sym.nc.probe_safety import WORK_OFFSETS

    ctrl = header_setup(program.read_text(encoding="utf-8"), str(program)).controller
    active = WORK_OFFSETS[req.system - 1]
    if ctrl.work_offset != active or max(abs(a - b) for a, b in zip(ctrl.work_offset_mm, req.offset[:3],
                                                                      strict=True)) > 5e-4:
        stated = ", ".join(f"{v:g}" for v in ctrl.work_offset_mm)
        raise InputError(f"the check-up repeats the full calibration in {ctrl.work_offset} ({stated}); {active} is "
                         f"active with {', '.join(f'{v:g}' for v in req.offset[:3])}: select the calibration's")


def prepare(ctx: Context, req: Request, run: Path, log: RunLog) -> RunMessages:
    """The prepare step (module docstring): writes the run's procedure and ``prepared.json``."""
    from pige_sym.cycle.assets import probe_procedure, switch_procedure
    from pige_sym.cycle.layout import PROBE_SUB
    from pige_sym.files import atomic_write_text, to_json

    check_state(ctx, req)
    sw = ctx.settings.kinematics_switch
    fp = ctx.fingerprint()
    info: dict[str, object] = {"fingerprint": fp, "in_force": ctx.in_force, "live": ctx.live,
                               "switchkins_type": req.switchkins_type}
    status(run, "program")
    if req.mode == "enter":
        before = [sw.identity_code] if sw is not None and req.switchkins_type != sw.identity_type else []
        text = switch_procedure(before)
    else:
        if req.mode == "checkup":
            program, basis = checkup_program(ctx, req, run, log)
            info["basis"] = basis
        elif req.mode == "map":
            from pige_sym.cycle.map_prepare import map_program

            program = map_program(ctx, req, run, log)
        else:
            program = probing_program(ctx, req, run, log)
        before = [sw.tcp_code] if sw is not None and req.switchkins_type != sw.tcp_type else []
        text = probe_procedure(program.read_text(encoding="utf-8"), run / "probe_log.txt", before)
    atomic_write_text(run / "prepared.json", to_json(info) + "\n")
    atomic_write_text(ctx.layout.current / f"{PROBE_SUB}.ngc", text)
    (run / "procedure.ngc").write_text(text, encoding="utf-8")
    log.add("prepared", f"mode {req.mode}; values in force ({'running HAL' if ctx.live else 'values file'}): "
            + ", ".join(f"{p.target} {ctx.in_force[p.pin]:g}" for p in ctx.setup.pins)
            + f"\nfingerprint {fp['all']}")
    return RunMessages()
