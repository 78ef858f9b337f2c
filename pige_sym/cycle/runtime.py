"""One step of a running cycle, as LinuxCNC's task runs it: ``pige cycle step prepare|analyse|enter --run RUN``.

A step reads the configuration (:mod:`~pige_sym.cycle.context`) and the run's request, does its work
(:mod:`~pige_sym.cycle.prepare`, :mod:`~pige_sym.cycle.analyse`, :mod:`~pige_sym.cycle.checkup_step`,
:mod:`~pige_sym.cycle.enter`, :mod:`~pige_sym.cycle.map_analyse`) and writes, last, the run's ``messages.json``
(:mod:`~pige_sym.cycle.messages`).  A
refusal (any :class:`~pige_sym.errors.PigeError`: a guard, bad settings, a stage's own refusal) is written there as
the operator error, exit status 1; a crash or a kill leaves none (the remap then names the step's output).

Every step changes nothing before its end: the values, the values file, the proposal, the journal and the history
are written only once everything they hold has been computed.  ``status.txt`` says which stage is running (the
operator, and the tests, see it).

The stages are pige's own commands, run in this process as a user runs them (:func:`pige_command`): ``pige
program``, ``pige import-probe``; the rest through their functions (identify, weighing, check-up, history).
"""

from __future__ import annotations

from pathlib import Path

from pige_sym.cycle.messages import RunMessages, relative_log, write_messages
from pige_sym.cycle.steplog import RunLog, status
from pige_sym.errors import PigeError

STEPS = ("prepare", "analyse", "enter")


def run_step(step: str, run: Path, *, live: bool = True) -> int:
    """Run ``step`` on ``run`` (module docstring); the exit status.  ``live`` False: the values file stands for the
    running HAL (a dry run)."""
    run = run.resolve()
    config = run.parent.parent.parent
    log = RunLog(run)
    status(run, f"{step} started")
    try:
        messages = _dispatch(step, run, config, log, live)
    except PigeError as exc:
        code = (run.name.split("-")[2] if len(run.name.split("-")) > 2 else "M451")
        messages = RunMessages(error=f"PIGE {code} refused, nothing changed (log {relative_log(run)}): {exc}")
        log.add("refused", str(exc))
    status(run, f"{step} done")
    write_messages(run, step, messages)
    return 1 if messages.error else 0


def _dispatch(step: str, run: Path, config: Path, log: RunLog, live: bool) -> RunMessages:
    from pige_sym.cycle.context import read_context, read_request

    request = read_request(run)
    ctx = read_context(config, live=live)
    if step == "prepare":
        from pige_sym.cycle.prepare import prepare

        return prepare(ctx, request, run, log)
    if step == "enter":
        from pige_sym.cycle.enter import enter

        return enter(ctx, request, run, log)
    if request.mode == "map":
        from pige_sym.cycle.map_analyse import analyse_map

        return analyse_map(ctx, request, run, log)
    if request.mode == "checkup":
        from pige_sym.cycle.checkup_step import analyse_checkup

        return analyse_checkup(ctx, request, run, log)
    from pige_sym.cycle.analyse import analyse

    return analyse(ctx, request, run, log)
