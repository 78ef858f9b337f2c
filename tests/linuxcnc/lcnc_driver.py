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
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import traceback

import hal  # type: ignore[import-not-found]
import linuxcnc  # type: ignore[import-not-found]

ERROR_KINDS = {linuxcnc.NML_ERROR: "error", linuxcnc.OPERATOR_ERROR: "error",
               linuxcnc.NML_TEXT: "text", linuxcnc.OPERATOR_TEXT: "text",
               linuxcnc.NML_DISPLAY: "display", linuxcnc.OPERATOR_DISPLAY: "display"}


class Driver:
    def __init__(self) -> None:
        self.stat = linuxcnc.stat()
        self.cmd = linuxcnc.command()
        self.err = linuxcnc.error_channel()
        self.messages: list[list[str]] = []
        self.hal_component = hal.component("pige-driver")  # hal.get_value needs a component of this process
        self.hal_component.ready()

    def drain(self) -> bool:
        """Collect the error channel; True when an error arrived."""
        bad = False
        while True:
            m = self.err.poll()
            if not m:
                return bad
            kind = ERROR_KINDS.get(m[0], str(m[0]))
            self.messages.append([kind, m[1]])
            bad = bad or kind == "error"

    def wait(self, done, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.stat.poll()
            if self.drain():
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


def run(job: dict) -> dict:
    drv = Driver()
    out: dict = {"steps": [], "ok": False}
    t0 = time.monotonic()
    try:
        drv.start()
        out["start_s"] = time.monotonic() - t0
        for step in job["steps"]:
            t = time.monotonic()
            clock = hal.get_value(step["clock"]) if "clock" in step else None
            if step["op"] == "read":
                res = {"readings": [{p: hal.get_value(p) for p in step["pins"]}]}
            else:
                res = getattr(drv, step["op"])(step)
            res |= {"op": step["op"], "wall_s": time.monotonic() - t}
            if clock is not None:
                res["sim_s"] = hal.get_value(step["clock"]) - clock
            out["steps"].append(res)
            drv.drain()
        out["ok"] = not any(kind == "error" for kind, _ in drv.messages)
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


def main() -> int:
    with open(os.environ["PIGE_LCNC_JOB"]) as f:
        job = json.load(f)
    result = run(job)
    with open(job["result"], "w") as f:
        json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
