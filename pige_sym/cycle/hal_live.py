"""The values in force in a running LinuxCNC, read and set with ``halcmd`` (``getp``/``gets``, ``setp``/``sets``).

pige's steps run as a process of LinuxCNC's task (:mod:`~pige_sym.cycle.linuxcnc_remap`), so ``halcmd`` reaches the
running HAL.  Without a running HAL (a step run by hand, the unit tests) :func:`hal_running` is False and the values
are the values file's.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable, Sequence

from pige_sym.cycle.kinematics import KinematicsSetup, ValuePin
from pige_sym.errors import InputError

#: how ``halcmd getp`` shows a bit pin (a map's ``full-turn``)
BITS = {"TRUE": 1.0, "FALSE": 0.0}
Runner = Callable[[Sequence[str]], "subprocess.CompletedProcess[str]"]


def _run(argv: Sequence[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(list(argv), capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)


def hal_running(run: Runner | None = None) -> bool:
    """Whether a HAL is running that ``halcmd`` reaches."""
    run = run or _run
    if shutil.which("halcmd") is None:
        return False
    try:
        return run(["halcmd", "-s", "show", "comp"]).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def read_live(setup: KinematicsSetup, run: Runner | None = None) -> dict[str, float]:
    """The value of every pin of ``setup`` in the running HAL (a netted pin: its signal).

    Raises
    ------
    InputError
        halcmd refuses (the pin or signal does not exist), naming it.
    """
    run = run or _run
    out = {}
    for p in setup.pins:
        verb = "gets" if p.signal else "getp"
        proc = run(["halcmd", "-s", verb, p.target])
        text = proc.stdout.strip()
        try:
            out[p.pin] = BITS[text] if text in BITS else float(text)
        except ValueError:
            raise InputError(f"halcmd {verb} {p.target}: {(proc.stdout + proc.stderr).strip()[:120]}: the running "
                             f"HAL has no such {'signal' if p.signal else 'pin'}; is this configuration's "
                             "kinematics loaded?") from None
    return out


def set_live(changes: list[tuple[ValuePin, float, float]], run: Runner | None = None) -> list[str]:
    """Set each pin from its old value to its new one (``(pin, old, new)``); on a refusal, the ones already set are
    put back to their old values and InputError is raised.  Returns the halcmd lines run.
    """
    run = run or _run
    done: list[tuple[ValuePin, float]] = []
    lines = []
    for p, old, new in changes:
        line = p.command(new)
        proc = run(["halcmd", *line.split()])
        if proc.returncode != 0:
            for q, old in reversed(done):
                run(["halcmd", *q.command(old).split()])
            raise InputError(f"halcmd {line}: {(proc.stdout + proc.stderr).strip()[:160]}; the values set before it "
                             "were put back")
        done.append((p, old))
        lines.append(line)
    return lines
