#!/usr/bin/python3
"""The DISPLAY program of tests/linuxcnc: drives a headless LinuxCNC through its Python module, then exits.

LinuxCNC starts an INI's ``[DISPLAY]DISPLAY`` program as ``PROGRAM -ini INIFILE`` once HAL, motion, task
and io are up, and shuts everything down when it exits.  This one runs under the system Python
(``/usr/bin/python3``: the ``linuxcnc`` and ``hal`` modules are Debian's, not the virtual environment's)
and uses only the standard library besides them.

The job is a JSON file named by the environment variable ``PIGE_LCNC_JOB``::

    {"result": "result.json",                      # written on exit, whatever happened
     "steps": [{"op": "mdi", "lines": ["M429", "G0 X0"], "read": ["ptt.tip-x"]},
               {"op": "program", "file": "probe.ngc", "timeout": 900, "clock": "ptt.clock"},
               {"op": "hal", "commands": ["setp ptt.trip-radius 0"]},
               {"op": "read", "pins": ["ptt.trips"]}]}

Before the steps: estop reset, machine on, every joint homed (the shipped sims home in place).  ``mdi``
runs each line in MDI mode, waits until the interpreter is idle, the motion queue empty and the axes in
position, and reads
``read`` HAL pins after each line; ``program`` opens the file and runs it in AUTO until the interpreter is
idle again; ``hal`` runs ``halcmd`` commands; ``read`` reads pins.  ``clock`` (any step) names a HAL pin
that counts simulated seconds: the step's simulated time is its change.  A step that raises an error
message stops the job.  The result holds per step its wall time, the error channel's messages (kind,
text), the readings, and the final joint and axis positions.

Steps for runs that are meant to be interrupted or refused (tests/linuxcnc/test_linuxcnc_cycle.py):
``mdi_start`` issues one MDI line and returns once the interpreter has taken it; ``wait_for`` waits until a file
exists (and holds ``contains``) or a pin reaches ``at_least``; ``abort`` is the GUI's Esc (task abort), ``estop``
the E-stop button and ``machine_on`` its reset (the joints stay homed); ``kill`` sends SIGKILL to the process whose
id a file holds; ``idle`` waits for the interpreter and motion to rest; ``files`` returns the SHA-256 of every file
under a folder.  A ``glob`` finds only files written since the last ``mdi_start``.  A step with ``"allow_error":
true`` records the errors that arrive while it runs instead of stopping the job; errors outside such steps make the
job fail.  ``label`` (any step) comes back with its result.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
import traceback

import hal  # type: ignore[import-not-found]
import linuxcnc  # type: ignore[import-not-found]

#: ops that a copy of this file adds (name -> function(step) -> result dict): tests/linuxcnc/axis_screenshot.py's
#: wait for AXIS and its screen shot
EXTRA_OPS: dict = {}
#: False when another program reads LinuxCNC's error channel (AXIS: it shows the operator messages itself)
READ_ERRORS = True

ERROR_KINDS = {linuxcnc.NML_ERROR: "error", linuxcnc.OPERATOR_ERROR: "error",
               linuxcnc.NML_TEXT: "text", linuxcnc.OPERATOR_TEXT: "text",
               linuxcnc.NML_DISPLAY: "display", linuxcnc.OPERATOR_DISPLAY: "display"}


class Driver:
    def __init__(self) -> None:
        self.stat = linuxcnc.stat()
        self.cmd = linuxcnc.command()
        self.err = linuxcnc.error_channel()
        self.messages: list[list[str]] = []
        self.tolerate = False  # a step that expects errors records them instead of stopping the job
        self.started = 0.0  # when the last mdi_start was issued: a glob finds only files written since
        self.at_start: dict[str, float] = {}  # the pins it was told to watch, as they were then
        self.hal_component = hal.component("pige-driver")  # hal.get_value needs a component of this process
        self.hal_component.ready()

    def drain(self) -> bool:
        """Collect the error channel; True when an error arrived."""
        bad = False
        while READ_ERRORS:
            m = self.err.poll()
            if not m:
                break
            kind = ERROR_KINDS.get(m[0], str(m[0]))
            self.messages.append([kind, m[1]])
            bad = bad or kind == "error"
        return bad

    def wait(self, done, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.stat.poll()
            if self.drain() and not self.tolerate:
                raise RuntimeError(f"{what}: {self.messages[-1][1]}")
            if done(self.stat):
                return
            time.sleep(0.02)
        raise RuntimeError(f"{what}: not done after {timeout:g} s")

    def mode(self, mode: int) -> None:
        self.cmd.mode(mode)
        self.cmd.wait_complete(10)
        self.wait(lambda s: s.task_mode == mode, 10, f"mode {mode}")

    def start(self) -> None:
        self.wait(lambda s: True, 30, "stat")
        self.cmd.state(linuxcnc.STATE_ESTOP_RESET)
        self.cmd.wait_complete(10)
        self.cmd.state(linuxcnc.STATE_ON)
        self.cmd.wait_complete(10)
        self.wait(lambda s: s.task_state == linuxcnc.STATE_ON, 10, "machine on")
        self.mode(linuxcnc.MODE_MANUAL)
        self.cmd.home(-1)
        self.cmd.wait_complete(10)
        self.wait(lambda s: all(s.homed[: s.joints]), 60, "homing")

    def idle(self, timeout: float, what: str) -> None:
        self.wait(lambda s: s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0 and not s.queue_full
                  and s.state != linuxcnc.RCS_EXEC and s.inpos, timeout, what)

    def mdi(self, step: dict) -> dict:
        self.mode(linuxcnc.MODE_MDI)
        readings = []
        for line in step["lines"]:
            self.cmd.mdi(line)
            self.cmd.wait_complete(10)
            self.idle(step.get("timeout", 120), f"MDI {line!r}")
            readings.append({p: hal.get_value(p) for p in step.get("read", [])})
        return {"readings": readings}

    def program(self, step: dict) -> dict:
        self.mode(linuxcnc.MODE_AUTO)
        self.cmd.program_open(os.path.abspath(step["file"]))
        self.cmd.wait_complete(10)
        self.cmd.auto(linuxcnc.AUTO_RUN, 0)
        self.cmd.wait_complete(10)
        self.wait(lambda s: s.interp_state != linuxcnc.INTERP_IDLE or s.state == linuxcnc.RCS_DONE, 10,
                  "program start")
        self.idle(step.get("timeout", 900), f"program {step['file']}")
        return {}

    def mdi_start(self, step: dict) -> dict:
        """One MDI line, not waited for: returns once the interpreter has left idle (or 10 s)."""
        self.mode(linuxcnc.MODE_MDI)
        self.started = time.time()
        self.at_start = {pin: hal.get_value(pin) for pin in step.get("watch", [])}
        self.cmd.mdi(step["line"])
        self.cmd.wait_complete(10)
        try:
            self.wait(lambda s: s.interp_state != linuxcnc.INTERP_IDLE, 10, f"MDI {step['line']!r} start")
        except RuntimeError:
            pass  # a line refused at once leaves the interpreter idle: its error is recorded
        return {}

    def wait_for(self, step: dict) -> dict:
        """Until ``file`` (or the newest match of ``glob``) exists, holding ``contains`` when given, or ``pin`` >=
        ``at_least``, or ``pin`` has grown by ``increase`` since the last ``mdi_start`` (which ``watch``-ed it)."""
        def done(_s) -> bool:
            if "file" in step or "glob" in step:
                path = step["file"] if "file" in step else _newest(step["glob"], self.started)
                if path is None or not os.path.isfile(path):
                    return False
                with open(path, errors="replace") as f:
                    return step.get("contains", "") in f.read()
            if "increase" in step:
                return hal.get_value(step["pin"]) >= self.at_start[step["pin"]] + step["increase"]
            return hal.get_value(step["pin"]) >= step["at_least"]
        what = step.get("file", step.get("glob", step.get("pin")))
        self.wait(done, step.get("timeout", 600), f"wait for {what}")
        return {}

    def abort(self, step: dict) -> dict:
        """The GUI's Esc: task abort, then wait until the interpreter rests."""
        self.cmd.abort()
        self.cmd.wait_complete(10)
        self.wait(lambda s: s.interp_state == linuxcnc.INTERP_IDLE, 30, "abort")
        return {}

    def estop(self, step: dict) -> dict:
        self.cmd.state(linuxcnc.STATE_ESTOP)
        self.cmd.wait_complete(10)
        self.wait(lambda s: s.task_state == linuxcnc.STATE_ESTOP, 30, "E-stop")
        return {}

    def machine_on(self, step: dict) -> dict:
        """E-stop reset and machine on (the joints stay homed)."""
        self.cmd.state(linuxcnc.STATE_ESTOP_RESET)
        self.cmd.wait_complete(10)
        self.cmd.state(linuxcnc.STATE_ON)
        self.cmd.wait_complete(10)
        self.wait(lambda s: s.task_state == linuxcnc.STATE_ON, 30, "machine on")
        return {}

    def kill(self, step: dict) -> dict:
        """SIGKILL to the process whose id the file ``pid_file`` (or the newest match of ``pid_glob``) holds: a
        process of this run, named by its id."""
        path = step["pid_file"] if "pid_file" in step else _newest(step["pid_glob"], self.started)
        with open(path) as f:
            pid = int(f.read().split()[0])
        os.kill(pid, signal.SIGKILL)
        return {"pid": pid, "pid_file": path}

    def sleep(self, step: dict) -> dict:
        """Wait ``seconds``, collecting messages."""
        end = time.monotonic() + step["seconds"]
        while time.monotonic() < end:
            self.drain()
            time.sleep(0.05)
        return {}

    def status(self, step: dict) -> dict:
        """The task's and the interpreter's state as the status channel gives them."""
        self.stat.poll()
        s = self.stat
        return {"status": {"task_mode": s.task_mode, "task_state": s.task_state, "interp_state": s.interp_state,
                           "exec_state": s.exec_state, "call_level": s.call_level, "queue": s.queue,
                           "state": s.state}}

    def idle_step(self, step: dict) -> dict:
        self.idle(step.get("timeout", 600), "idle")
        return {}

    def files(self, step: dict) -> dict:
        """SHA-256 of every file under ``root`` (relative paths), leaving out those under ``exclude`` and the
        temporary files LinuxCNC's interpreter writes its parameter file through (``*.new``, renamed at once)."""
        out = {}
        skip = tuple(step.get("exclude", []))
        for folder, _, names in os.walk(step["root"]):
            for name in names:
                path = os.path.join(folder, name)
                rel = os.path.relpath(path, step["root"])
                if rel.startswith(skip) or name.endswith(".new"):
                    continue
                try:
                    with open(path, "rb") as f:
                        out[rel] = hashlib.sha256(f.read()).hexdigest()
                except FileNotFoundError:  # renamed meanwhile: read what replaced it
                    continue
        return {"files": out}

    def hal(self, step: dict) -> dict:
        """``halcmd`` commands (``setp``, ``sets``, ...), each must succeed."""
        for command in step["commands"]:
            proc = subprocess.run(["halcmd", *command.split()], capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"halcmd {command}: {proc.stdout}{proc.stderr}")
        return {}

    def positions(self) -> dict:
        self.stat.poll()
        return {"joint": list(self.stat.joint_actual_position[: self.stat.joints]),
                "axis": list(self.stat.actual_position), "g5x_offset": list(self.stat.g5x_offset),
                "tool_offset": list(self.stat.tool_offset), "tool_in_spindle": self.stat.tool_in_spindle,
                "read_line": self.stat.read_line, "motion_line": self.stat.motion_line,
                "current_line": self.stat.current_line}


def _newest(pattern: str, since: float) -> str | None:
    """The newest file matching ``pattern`` written since ``since`` (seconds since the epoch), or None."""
    found = [f for f in glob.glob(pattern) if os.path.getmtime(f) >= since - 0.5]
    return max(found, key=os.path.getmtime) if found else None


def run(job: dict) -> dict:
    drv = Driver()
    out: dict = {"steps": [], "ok": False}
    unexpected: list[list[str]] = []
    t0 = time.monotonic()
    try:
        drv.start()
        out["start_s"] = time.monotonic() - t0
        for step in job["steps"]:
            t = time.monotonic()
            clock = hal.get_value(step["clock"]) if "clock" in step else None
            drv.tolerate = bool(step.get("allow_error"))
            first = len(drv.messages)
            if step["op"] == "read":
                res = {"readings": [{p: hal.get_value(p) for p in step["pins"]}]}
            elif step["op"] in EXTRA_OPS:
                res = EXTRA_OPS[step["op"]](step)
            else:
                res = getattr(drv, "idle_step" if step["op"] == "idle" else step["op"])(step)
            drv.drain()
            res |= {"op": step["op"], "wall_s": time.monotonic() - t,
                    "messages": drv.messages[first:], "label": step.get("label")}
            if not drv.tolerate:
                unexpected += [m for m in drv.messages[first:] if m[0] == "error"]
            drv.tolerate = False
            if clock is not None:
                res["sim_s"] = hal.get_value(step["clock"]) - clock
            out["steps"].append(res)
        out["ok"] = not unexpected
    except Exception as exc:  # the result must be written whatever happened
        out["exception"] = f"{exc}\n{traceback.format_exc()}"
    try:
        drv.drain()
        out["final"] = drv.positions()
    except Exception as exc:
        out["exception_final"] = str(exc)
    out["messages"] = drv.messages
    out["wall_s"] = time.monotonic() - t0
    return out


def program_start(self: Driver, step: dict) -> dict:
    """The program ``file`` run in AUTO, not waited for (the op ``program_start``, :meth:`Driver.mdi_start`'s
    counterpart): returns once the interpreter has left idle (or 10 s); ``watch`` as there."""
    self.mode(linuxcnc.MODE_AUTO)
    self.started = time.time()
    self.at_start = {pin: hal.get_value(pin) for pin in step.get("watch", [])}
    self.cmd.program_open(os.path.abspath(step["file"]))
    self.cmd.wait_complete(10)
    self.cmd.auto(linuxcnc.AUTO_RUN, 0)  # not wait_complete: task holds the run command until the program ends
    try:
        self.wait(lambda s: s.interp_state != linuxcnc.INTERP_IDLE, 10, f"program {step['file']} start")
    except RuntimeError:
        pass  # a program refused at once leaves the interpreter idle: its error is recorded
    return {}


Driver.program_start = program_start  # type: ignore[attr-defined]


def main() -> int:
    with open(os.environ["PIGE_LCNC_JOB"]) as f:
        job = json.load(f)
    result = run(job)
    with open(job["result"], "w") as f:
        json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
