"""The files ``pige cycle install`` puts into a configuration besides the INI edits: the remaps' NGC procedures and
the remap's Python, rendered to strings (an NGC procedure holds the configuration's kinematics codes).

``pige_m451.ngc`` / ``pige_m452.ngc`` run the steps of :mod:`~pige_sym.cycle.linuxcnc_remap` (its docstring);
``pige_restore.ngc`` puts the kinematics mode back to the one found at the start (``#<_pige_kins_before>``, the
``motion.switchkins-type`` the prolog read); ``pige_on_abort.ngc`` puts it back after an abort
(:func:`on_abort_procedure`).  The generated probing
procedure ``pige_cycle_probe.ngc`` is written for every run (:func:`probe_procedure`); until the first run it aborts.
"""

from __future__ import annotations

from pathlib import Path

from pige_sym.cycle.layout import CODES, ON_ABORT_SUB, PROBE_SUB, Layout
from pige_sym.cycle.settings import CycleSettings, Switch
from pige_sym.errors import InputError

RESTORE_SUB = "pige_restore"
MODULE = "pige_cycle_remap"
HEADER = "; pige cycle ({what}): written by pige cycle install, replaced by the next install; do not edit"


def code_procedure(code: str) -> str:
    """The NGC procedure of ``M451`` or ``M452`` (module docstring)."""
    name = CODES[code]
    return "\n".join([
        HEADER.format(what=f"{code}: {'P0 check, P1 optimise, P2 enter' if code == 'M451' else 'check-up'}"),
        f"o<{name}> sub",
        "M73 (the modal state comes back at endsub: coordinate system, tool length compensation, units, feed)",
        "o100 if [#<_task> EQ 1]",
        "o101 if [#<_pige_phase> EQ 0]",
        "o102 if [EXISTS[#<p>]]",
        "#<mode> = #<p>",
        "o102 else",
        "#<mode> = 0",
        "o102 endif",
        f"{code} P[100 + #<mode>] (prepare: pige writes the probing procedure)",
        f"o<{PROBE_SUB}> call",
        f"{code} P[200 + #<mode>] (analyse, or enter)",
        f"o<{RESTORE_SUB}> call",
        "o101 endif",
        "o100 endif",
        f"o<{name}> endsub",
        "M2", ""])


def restore_procedure(switch: Switch | None) -> str:
    """``o<pige_restore>``: the kinematics mode the cycle found, by the configuration's own codes."""
    body = ["(no kinematics switch: nothing to put back)"] if switch is None else [
        f"o101 if [#<_pige_kins_before> EQ {switch.identity_type}]", switch.identity_code,
        f"o101 elseif [#<_pige_kins_before> EQ {switch.tcp_type}]", switch.tcp_code, "o101 endif"]
    return "\n".join([
        HEADER.format(what="the kinematics mode found at the start"),
        f"o<{RESTORE_SUB}> sub", "o100 if [EXISTS[#<_pige_kins_before>]]", "o103 if [#<_pige_kins_before> GE 0]",
        *body, "#<_pige_kins_before> = -1", "o103 endif", "o100 endif", f"o<{RESTORE_SUB}> endsub", "M2", ""])


def on_abort_procedure(switch: Switch | None) -> str:
    """``[RS274NGC]ON_ABORT_COMMAND``: after any abort, no step of pige still running, and the kinematics mode the
    cycle found (:func:`~pige_sym.cycle.linuxcnc_remap.pige_cycle_abort` says which, or -1): set at once on the
    output that drives ``motion.switchkins-type`` (no synchronisation, so the handler runs to its end), or, when the
    install found no such output, by the configuration's code (``o<pige_restore>``)."""
    put_back = "o100 if [[#<_value_returned> EQ 1] AND [#<_value> GE 0]]"
    if switch is None:
        body = ["(no kinematics switch: nothing to put back)"]
    elif switch.analog_out is not None:
        body = [put_back, f"(motion.analog-out-{switch.analog_out:02d} drives motion.switchkins-type)",
                f"M68 E{switch.analog_out} Q#<_value>", "o100 endif"]
    else:
        body = [put_back, "#<_pige_kins_before> = #<_value>", f"o<{RESTORE_SUB}> call", "o100 endif"]
    return "\n".join([HEADER.format(what="after an abort"), f"o<{ON_ABORT_SUB}> sub",
                      "(stop pige's step; the kinematics mode to put back in _value, or -1)",
                      "o<pige_cycle_abort> call", *body, f"o<{ON_ABORT_SUB}> endsub", "M2", ""])


def placeholder_procedure() -> str:
    """The probing procedure before the first run: it refuses to run."""
    return "\n".join([HEADER.format(what="no run prepared yet"), f"o<{PROBE_SUB}> sub",
                      "(abort, PIGE: no probing program was prepared for this run: call M451 or M452)",
                      f"o<{PROBE_SUB}> endsub", "M2", ""])


def toplevel_text() -> str:
    return "\n".join(["# pige cycle: written by pige cycle install; LinuxCNC's [PYTHON]TOPLEVEL", "import oword",
                      "import remap", ""])


def oword_text() -> str:
    """``oword.py``: the O-word procedures LinuxCNC looks up (``o<pige_cycle_abort> call``)."""
    return "\n".join([f"# pige cycle: written by pige cycle install; the procedures are in {MODULE}.py",
                      f"from {MODULE} import pige_cycle_abort  # noqa: F401", ""])


def remap_text() -> str:
    """``remap.py``: the module LinuxCNC looks the handlers up in."""
    return "\n".join([f"# pige cycle: written by pige cycle install; the handlers are in {MODULE}.py",
                      f"from {MODULE} import *  # noqa: F401,F403", ""])


def remap_module_text() -> str:
    """The cycle's remap code (:mod:`~pige_sym.cycle.linuxcnc_remap`), as the file LinuxCNC imports."""
    source = (Path(__file__).parent / "linuxcnc_remap.py").read_text(encoding="utf-8")
    return "# pige cycle: written by pige cycle install from pige_sym/cycle/linuxcnc_remap.py; do not edit\n" + source


def asset_files(layout: Layout, settings: CycleSettings) -> dict[Path, str]:
    """Every file of the cycle's code with its text."""
    out = {layout.ngc / f"{CODES[c]}.ngc": code_procedure(c) for c in CODES}
    out[layout.ngc / f"{RESTORE_SUB}.ngc"] = restore_procedure(settings.kinematics_switch)
    out[layout.ngc / f"{ON_ABORT_SUB}.ngc"] = on_abort_procedure(settings.kinematics_switch)
    out[layout.python / "toplevel.py"] = toplevel_text()
    out[layout.python / "remap.py"] = remap_text()
    out[layout.python / "oword.py"] = oword_text()
    out[layout.python / f"{MODULE}.py"] = remap_module_text()
    return out


def switch_procedure(before: list[str]) -> str:
    """The run's procedure of ``M451 P2``: the switch to identity kinematics (``before``), nothing else."""
    return "\n".join([f"o<{PROBE_SUB}> sub", *before, f"o<{PROBE_SUB}> endsub", "M2", ""])


def probe_procedure(program: str, probe_log: Path, before: list[str]) -> str:
    """The run's probing procedure: ``before`` (the switch to the probing kinematics), then the program pige wrote,
    its last line ``M2`` replaced by the end of the procedure and its probe log written into ``probe_log``.

    Only those two lines change (checked: the program must have exactly one ``(PROBEOPEN ...)`` and end with ``M2``);
    the program itself was read back before it was written.

    Raises
    ------
    InputError
        A program of another shape, or a log path LinuxCNC cannot take in a comment.
    """
    lines = program.rstrip("\n").split("\n")
    opens = [i for i, ln in enumerate(lines) if ln.startswith("(PROBEOPEN ")]
    if not lines or lines[-1].strip() != "M2" or len(opens) > 1:
        raise InputError("the probing program does not end with M2 or opens its log more than once: not one pige "
                         "wrote")
    if any(c in str(probe_log) for c in "()\n") or len(str(probe_log)) > 200:
        raise InputError(f"{probe_log}: LinuxCNC takes the probe log's path in a comment: the configuration's path "
                         "must not hold '(' or ')' and be shorter than 200 characters")
    if opens:
        lines[opens[0]] = f"(PROBEOPEN {probe_log})"
    return "\n".join([f"o<{PROBE_SUB}> sub", *before, *lines[:-1], f"o<{PROBE_SUB}> endsub", "M2", ""])
