"""The words of ``pige program`` for the configuration in force: what a probing run's program is written for.

The nominal axis lines are those the kinematics hold with the values in force (:func:`~pige_sym.cycle.kinematics.
lines_of`), the sphere and the lines in the active coordinate system (``--work-offset G5x=`` its X Y Z: the program
checks them), the stylus and the probing settings; ``--kinematics tcp``: the values in force act on every move.
:func:`probe_argv` leaves the poses to the caller (the cone of ``M451 P0``/``P1``, the map test's setups).
"""

from __future__ import annotations

from pathlib import Path

from pige_sym.cycle.context import Context, Request
from pige_sym.cycle.steplog import RunLog, pige_command
from pige_sym.errors import InputError


def word(v: float) -> str:
    """A number as a program option takes it: 9 decimals, no -0."""
    return repr(round(float(v), 9) + 0.0)


def probing_program(ctx: Context, req: Request, run: Path, log: RunLog) -> Path:
    """``pige program`` for the configuration in force (module docstring); the program's path."""
    p = ctx.settings.probing
    argv = probe_argv(ctx, req, run / "program.ngc") + ["--trajectory", "cone-frustum", "--points", str(p.poses)]
    return run_program(argv, run, log)


def program_point(v: list[float], req: Request) -> str:
    """A point in machine coordinates [mm] as the program takes it: in the active coordinate system."""
    return ",".join(word(x - req.offset[k]) for k, x in enumerate(v))


def probe_argv(ctx: Context, req: Request, out: Path) -> list[str]:
    """``pige program``'s words for the configuration in force, but the poses (module docstring)."""
    from pige_sym.cycle.kinematics import lines_of
    from pige_sym.nc.probe_safety import WORK_OFFSETS

    s, p = ctx.settings, ctx.settings.probing
    o = req.offset[:3]
    lines = lines_of(ctx.setup, ctx.in_force)
    pivots = [f"{a}=" + ",".join(word(v - o[k]) for k, v in enumerate(xyz)) for a, xyz in lines.items()]
    return ["program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", s.machine,
            "--axis-sense", ",".join(f"{a}={v}" for a, v in s.axis_sense.items()),
            *[w for piv in pivots for w in ("--pivot", piv)],
            "--sphere", program_point(s.sphere_mm, req),
            "--sphere-radius", word(s.sphere_radius_mm), "--stylus-radius", word(s.stylus_radius_mm),
            "--kinematics", "tcp", "--stylus-tool", str(s.stylus_tool), "--stylus-length", word(s.stylus_length_mm),
            "--work-offset", f"{WORK_OFFSETS[req.system - 1]}=" + ",".join(word(v) for v in o),
            "--contacts", str(p.contacts), "--clearance", word(p.clearance_mm), "--overtravel", word(p.overtravel_mm),
            "--probe-feed", word(p.probe_feed_mm_min), "--window", word(p.window_mm), "--out", str(out)]


def run_program(argv: list[str], run: Path, log: RunLog) -> Path:
    code, out = pige_command(argv)
    log.add("pige " + " ".join(argv), out)
    if code != 0:
        raise InputError(f"pige program refused: {out.strip().splitlines()[-1] if out.strip() else code}")
    return run / "program.ngc"
