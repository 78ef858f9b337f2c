"""The cycle's remap code: runs inside LinuxCNC's task (its embedded Python), installed as
``pige_cycle/python/pige_cycle_remap.py`` by ``pige cycle install``.

It uses the standard library and LinuxCNC's ``interpreter`` and ``emccanon`` modules only, never pige: pige runs in
a separate process, so that its crash, hang or kill cannot take LinuxCNC down.  Each code is remapped as::

    REMAP = M451 modalgroup=10 argspec=pq prolog=pige_m451_prolog ngc=pige_m451 epilog=pige_m451_epilog
    REMAP = M452 modalgroup=10 argspec=p prolog=pige_m452_prolog ngc=pige_m452 epilog=pige_m452_epilog

and its NGC procedure (``pige_cycle/ngc/pige_m451.ngc``) saves the modal state (``M73``: coordinate system,
tool length compensation, units, feed, ...) and runs four steps, the first and third as the same code called again
with an internal ``P`` (only from inside the cycle: a call at the top level is refused)::

    M451 P[100 + mode]          prepare: pige cycle step prepare (writes the run's probing procedure; P3 Q<k>:
                                the map test's setup k, which the prolog keeps from the outer call)
    o<pige_cycle_probe> call    the probing program pige wrote for the configuration (P2: the switch to identity)
    M451 P[200 + mode]          analyse (P0, P1, M452) or enter (P2): pige cycle step analyse|enter
    o<pige_restore> call        the kinematics mode as it was found (``#<_pige_kins_before>``)

**An abort** (Esc, E-stop, an error: LinuxCNC's task runs ``[RS274NGC]ON_ABORT_COMMAND`` inside the interpreter
after every abort, ``O <pige_cycle_abort> call``) calls :func:`pige_cycle_abort`: it kills a step still running and
sets the kinematics mode the cycle found at once, as ``M68 E<n> Q<type>`` would, on the ``motion.analog-out-<n>``
that drives ``motion.switchkins-type`` (``pige_on_abort.ngc``, for a handler of the configuration's own, does it
with ``M68`` from the value returned).  A Python call and not an NGC procedure: after an E-stop reset LinuxCNC
executed the handler's last block a second time at call level 0, which for an ``endsub`` is an error.  Not the
configuration's own code (``M429``): the shipped procedure synchronises (``M66 E0 L0``), which at abort time
suspends the abort handler half-way and leaves ``o<pige_cycle_abort>`` unrun when it comes after.  LinuxCNC may run
the handler twice for one abort and drop what the first queued between the two (an interpreter error in MDI: task's
``EMC_ABORT_INTERPRETER_ERROR_MDI``, then ``EMC_ABORT_TASK_EXEC_ERROR``, which clears the queue first;
src/emc/task/emctaskmain.cc): so every abort within ``REASSERT_S`` of the first puts the mode back again until
``motion.switchkins-type`` shows it, at that abort or to the helper below (:data:`IN_FORCE`).  And what the
handler queues after such an error can wait behind the aborted interpreter until the next mode change drops it
(``emcTaskSetMode`` calls ``emcTaskAbort``): so ``o<pige_cycle_abort>`` also sends the value through LinuxCNC's
command channel, from a process of its own (:data:`PUT_BACK`).

The prepare and analyse steps run in the *epilog* of the inner call, as a generator that yields
``INTERP_EXECUTE_FINISH`` while pige's process runs: the interpreter stays responsive (Esc, E-stop, the GUI's
status) and no line after it is read before pige is done (LinuxCNC's restartable Python handlers).  Each step has a
timeout (``settings.json`` ``timeouts_s``): a process that runs longer is killed, and so is one still running when
LinuxCNC drops the cycle (Esc, E-stop: the generator is closed, and ``pige_on_abort`` calls ``o<pige_cycle_abort>``).
A step that fails (a refusal, a crash, a kill, a timeout) ends the cycle with an operator error naming the run's log;
the outer epilog shows the last step's messages (``analyse.messages.json``, ``enter.messages.json``) as operator
messages, or its error.

In the AXIS preview (``self.task`` 0) every handler returns at once and the NGC procedure skips its body.
"""

import json
import os
import subprocess
import time

try:  # inside LinuxCNC
    import emccanon
    from interpreter import INTERP_ERROR, INTERP_EXECUTE_FINISH, INTERP_OK
except ImportError:  # imported by pige's own tests: the values of src/emc/rs274ngc/interp_return.hh
    emccanon = None
    INTERP_OK, INTERP_EXECUTE_FINISH, INTERP_ERROR = 0, 2, 5

CONFIG = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROOT = os.path.join(CONFIG, "pige_cycle")
MODES = {"M451": {0: "check", 1: "optimise", 2: "enter", 3: "map"}, "M452": {0: "checkup"}}
#: LinuxCNC's operator messages hold at most LINELEN (255) bytes with the terminating NUL
MAX_MESSAGE = 254
#: the interpreter parameters the request records (src/emc/rs274ngc: tool, coordinate system, G92, positions)
PARAMETERS = {"tool": 5400, "tool_length": 5403, "system": 5220, "g92_on": 5210}


def _settings():
    with open(os.path.join(ROOT, "settings.json"), encoding="utf-8") as f:
        return json.load(f)


def _message(text):
    """One operator message (display), cut to what LinuxCNC carries."""
    if emccanon is not None:
        emccanon.MESSAGE(text.encode("utf-8")[:MAX_MESSAGE].decode("utf-8", "ignore"))


def _fail(self, text):
    """End the cycle with an operator error (the generator's next yield)."""
    self.set_errormsg(text.encode("utf-8")[:MAX_MESSAGE].decode("utf-8", "ignore"))
    return INTERP_ERROR


def _mode(code, words):
    p = words.get("p")
    step = int(round(p)) if p is not None else 0
    if p is not None and (abs(p - step) > 1e-9 or step < 0):
        return 0, None
    return step // 100, MODES[code].get(step % 100)


def _prolog(self, code, words):
    if not self.task:
        return INTERP_OK
    phase, mode = _mode(code, words)
    if mode is None or phase > 2:
        valid = ", ".join(f"P{k}" for k in MODES[code])
        return f"PIGE {code}: P{words.get('p', 0):g} is not a mode of the cycle ({valid})"
    if phase and self.remap_level < 2:
        return f"PIGE {code} P{words.get('p', 0):g} is a step of the cycle itself: call {code} with " + \
            ", ".join(f"P{k}" for k in MODES[code])
    if phase == 0:
        setup = _map_setup(mode, words)
        if isinstance(setup, str):
            return setup
        self.pige_setup = setup
        ABORTED.clear()
        self.params["_pige_phase"] = 0
        kins = _switchkins(self)
        self.params["_pige_kins_before"] = -1 if kins is None else kins
        self.pige_run = None
    else:
        self.params["_pige_phase"] = phase
    return INTERP_OK


def _map_setup(mode, words):
    """``M451 P3 Q<k>``: the map test's setup k (an integer from 1), else None; a message when Q is wrong."""
    q = words.get("q")
    if mode != "map":
        return None
    if q is None or abs(q - round(q)) > 1e-9 or round(q) < 1:
        return "PIGE M451 P3 probes one setup of the map test: give its number, M451 P3 Q1 (Q2, ...)"
    return int(round(q))


def _epilog(self, code, words):
    if not self.task:
        return INTERP_OK
    phase, mode = _mode(code, words)
    if phase == 1:
        return _step(self, code, mode, "prepare")
    if phase == 2:
        return _step(self, code, mode, "enter" if mode == "enter" else "analyse")
    return _finish(self, code, mode)


def _request(self, code, mode):
    """The run folder, with LinuxCNC's state at the start of the cycle (request.json) for pige to check."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    run = os.path.join(ROOT, "runs", f"{stamp}-{code}-{mode}")
    n = 1
    while os.path.exists(run):
        n += 1
        run = os.path.join(ROOT, "runs", f"{stamp}-{code}-{mode}-{n}")
    os.makedirs(run)
    system = int(round(self.params[PARAMETERS["system"]]))
    base = 5201 + 20 * (system - 1)
    request = {"format": "pige-cycle-request 1", "code": code, "mode": mode,
               "started": time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime()),
               "tool": int(round(self.params[PARAMETERS["tool"]])),
               "system": system, "offset": [float(self.params[base + k]) for k in range(9)],
               "rotation": float(self.params[base + 9]), "g92_on": float(self.params[PARAMETERS["g92_on"]]) != 0,
               "position": [float(self.params[5420 + k]) for k in range(6)],
               "switchkins_type": _switchkins(self), "setup": getattr(self, "pige_setup", None)}
    with open(os.path.join(run, "request.json"), "w", encoding="utf-8") as f:
        json.dump(request, f, indent=1)
    return run


def _switchkins(self):
    try:
        return int(round(self.params["_hal[motion.switchkins-type]"]))
    except Exception:  # no HAL_PIN_VARS, or no switchable kinematics
        return None


def _step(self, code, mode, step):
    """A generator: wait for the motion queue, run ``pige cycle step STEP``, wait for it without blocking."""
    yield INTERP_EXECUTE_FINISH  # the moves before are done: the machine is at rest, the probe log complete
    try:
        settings = _settings()
        if step == "prepare":
            self.pige_run = _request(self, code, mode)
        run = self.pige_run
        timeout = float(settings["timeouts_s"][step])
        command = list(settings["pige_command"]) + ["cycle", "step", step, "--run", run]
    except Exception as exc:
        yield _fail(self, f"PIGE {code}: the cycle cannot start ({exc}); run pige cycle install again")
        return
    try:
        proc = _start(command, run, step)
    except OSError as exc:
        yield _fail(self, f"PIGE {code}: cannot start pige ({exc}); run pige cycle install again")
        return
    end, timed_out = time.monotonic() + timeout, False
    try:
        while proc.poll() is None:
            if time.monotonic() >= end:
                timed_out = True
                break
            time.sleep(0.02)
            yield INTERP_EXECUTE_FINISH
    finally:  # a timeout, or LinuxCNC dropping the cycle (Esc, E-stop: GeneratorExit): the step never outlives it
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        RUNNING.pop("proc", None)
    if timed_out:
        yield _fail(self, f"PIGE {code}: pige's {step} step took longer than {timeout:g} s and was stopped, nothing "
                          f"changed (log {os.path.relpath(run, CONFIG)}/{step}.out)")
        return
    result = _read_messages(run, step)
    if step == "prepare" and result and result.get("error"):  # a refusal before anything moved: pige's own message
        yield _fail(self, result["error"])
        return
    if result is None:  # a crash, a kill: no result written
        why = f"ended by signal {-proc.returncode}" if proc.returncode < 0 else f"exit status {proc.returncode}"
        yield _fail(self, f"PIGE {code}: pige's {step} step failed ({why}), nothing changed (log "
                          f"{os.path.relpath(run, CONFIG)}/{step}.out){_first_line(run, step)}")
        return


#: the step process now running (at most one): pige_cycle_abort stops it after an abort
RUNNING: dict = {}


def _start(command, run, step):
    """pige's step as a process of its own (its own session: a signal to LinuxCNC does not reach it)."""
    with open(os.path.join(run, f"{step}.out"), "w") as output:
        proc = subprocess.Popen(command, cwd=CONFIG, stdout=output, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
    RUNNING["proc"] = proc
    with open(os.path.join(run, f"{step}.pid"), "w") as f:
        f.write(f"{proc.pid}\n")
    return proc


#: when the first abort of a cycle came (time.monotonic(), "at") and its token: the aborts that follow within
#: REASSERT_S put the kinematics mode back again until it shows, after that none does (module docstring)
ABORTED: dict = {}
REASSERT_S = 10.0
#: the command-channel helper (:data:`PUT_BACK`) writes the abort's token here once ``motion.switchkins-type`` shows
#: the mode: an abort after that (of the operator's own job, in a mode chosen since) puts nothing back
IN_FORCE = os.path.join(ROOT, "run", "abort.in_force")


def pige_cycle_abort(self, *args):
    """O-word procedure ``o<pige_cycle_abort>`` (pige_on_abort.ngc, LinuxCNC's ``ON_ABORT_COMMAND``): stop a step
    still running, and return (``#<_value>``) the ``motion.switchkins-type`` to put back, or -1 for none.

    A float always: an O-word procedure that returns nothing leaves ``#<_value>`` 0, an int is taken for an error.
    The mode to put back is the one the cycle found (``#<_pige_kins_before>``, -1 once ``o<pige_restore>`` ran);
    once ``motion.switchkins-type`` shows it (now, or as the helper saw it since: :data:`IN_FORCE`), or
    ``REASSERT_S`` after the cycle's first abort, nothing more is put back: a later abort (of the operator's own
    program, in a mode chosen since) never switches the kinematics.
    """
    proc = RUNNING.pop("proc", None)
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.wait()
    try:
        found = int(round(self.params["_pige_kins_before"]))
    except Exception:  # no cycle ran since LinuxCNC started
        return -1.0
    first = ABORTED.setdefault("at", time.monotonic())
    token = ABORTED.setdefault("token", f"{os.getpid()}-{time.time_ns()}")
    if found < 0 or _switchkins(self) == found or _seen_in_force(token) or time.monotonic() - first > REASSERT_S:
        self.params["_pige_kins_before"] = -1
        ABORTED.clear()
        return -1.0
    out = _switch_output()
    if out is not None and emccanon is not None:  # what M68 E<out> Q<found> queues
        emccanon.SET_AUX_OUTPUT_VALUE(out, float(found))
    _put_back_through_the_command_channel(found, getattr(self, "pige_run", None) or os.path.join(ROOT, "runs"), token)
    return float(found)


def _seen_in_force(token):
    """True when the helper of this abort (``token``) saw the mode in force (:data:`IN_FORCE`)."""
    try:
        with open(IN_FORCE, encoding="utf-8") as f:
            return f.read().strip() == token
    except OSError:
        return False


def _switch_output():
    """N of the motion.analog-out-N that drives motion.switchkins-type (settings.json), or None."""
    try:
        out = _settings()["kinematics_switch"]["analog_out"]
        return None if out is None else int(out)
    except Exception:
        return None


#: run by ``python3 -c`` (LinuxCNC's Python, its ``linuxcnc`` module) as a process of its own, arguments: the N of
#: motion.analog-out-N, the switchkins type to put back, the log file.  It waits until task has handled the abort
#: (interpreter idle, motion queue empty, in position), then, unless the output shows the type already, sends
#: EMC_MOTION_SET_AOUT through LinuxCNC's command channel (task takes it in MDI, MANUAL and E-stop; not in AUTO).
#: Once it has seen AUTO it sends nothing (an operator's later mode change is not its to undo) and only watches
#: until the output shows the type (the handler's own set) or 10 s pass: its note says which, and after how long.
#: Once the output shows the type it writes the abort's token into the file IN_FORCE (renamed into place)
PUT_BACK = """
import os, sys, time, linuxcnc
n, found, log, in_force, token = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
s, c = linuxcnc.stat(), linuxcnc.command()
t0 = time.monotonic()
end, sent, auto, why = t0 + 10.0, 0, False, "timed out"
while time.monotonic() < end:
    time.sleep(0.05)
    s.poll()
    auto = auto or s.task_mode == linuxcnc.MODE_AUTO
    if abs(s.aout[n] - found) < 1e-9:
        why = f"in force after {time.monotonic() - t0:.2f} s"
        break
    if not auto and s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0 and s.inpos and sent < 3:
        c.set_analog_output(n, found)
        c.wait_complete(2)
        sent += 1
try:  # a name of its own: the two helpers of one E-stop (the E-stop, its reset) write at once
    if why.startswith("in force"):
        with open(f"{in_force}.{os.getpid()}.new", "w") as f:
            f.write(token + "\\n")
        os.replace(f"{in_force}.{os.getpid()}.new", in_force)
except OSError as exc:
    why += f" (not noted for the next abort: {exc})"
if auto:
    why += " in AUTO mode (task takes no analog output command there: none sent)"
with open(log, "a") as f:
    f.write(f"{time.strftime('%Y-%m-%dT%H:%M:%S')} analog-out-{n:02d} {found:g}: {why}, sent {sent}\\n")
"""


def _put_back_through_the_command_channel(found, folder, token):
    """After an abort, the kinematics mode ``found`` also through LinuxCNC's command channel (:data:`PUT_BACK`, a
    process of its own: task is not held up): ``M68`` queued by the abort handler can wait behind the aborted
    interpreter and be dropped by the next mode change (after an interpreter error in MDI, measured: the kill).
    Its note goes to ``abort.log`` in ``folder`` (the aborted run's folder), the abort's ``token`` to
    :data:`IN_FORCE` once the mode shows."""
    try:
        out = _switch_output()
        if out is None:
            return
        subprocess.Popen(["python3", "-c", PUT_BACK, str(out), str(found), os.path.join(folder, "abort.log"),
                          IN_FORCE, token],
                         cwd=CONFIG, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    except Exception:  # never in the way of LinuxCNC's abort
        pass


def _read_messages(run, step):
    """What a step wrote (``<step>.messages.json``: lines and error), or None."""
    try:
        with open(os.path.join(run, f"{step}.messages.json"), encoding="utf-8") as f:
            out = json.load(f)
        return out if isinstance(out, dict) and isinstance(out.get("lines"), list) else None
    except (OSError, ValueError):
        return None


def _first_line(run, step):
    """The first error line of pige's output, for the message."""
    try:
        with open(os.path.join(run, f"{step}.out"), encoding="utf-8", errors="replace") as f:
            lines = [ln.strip() for ln in f if ln.strip()]
    except OSError:
        return ""
    return (": " + lines[-1][:160]) if lines else ""


def _finish(self, code, mode):
    """The messages of the run's last step (``analyse`` or ``enter``) as operator messages, or its error."""
    run = getattr(self, "pige_run", None)
    self.pige_run = None
    if run is None:
        return f"PIGE {code}: the cycle did not run (no run folder)"
    result = _read_messages(run, "enter" if mode == "enter" else "analyse")
    if result is None:
        return f"PIGE {code}: the run left no readable result, nothing changed (log {os.path.relpath(run, CONFIG)})"
    for line in result["lines"]:
        _message(str(line))
    error = result.get("error")
    if error:
        return str(error).encode("utf-8")[:MAX_MESSAGE].decode("utf-8", "ignore")
    return INTERP_OK


def pige_m451_prolog(self, **words):
    return _prolog(self, "M451", words)


def pige_m451_epilog(self, **words):
    return _epilog(self, "M451", words)


def pige_m452_prolog(self, **words):
    return _prolog(self, "M452", words)


def pige_m452_epilog(self, **words):
    return _epilog(self, "M452", words)
