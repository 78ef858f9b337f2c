"""``M451 P3 Q<k>``'s program: setup k of the map test, as ``pige program --instrument sphere-probe --map`` writes it.

The map test (docs/maps.md) measures the sphere at ``settings.map.setups`` places on the table; its programs are the
ones ``pige program --map AXES --map-step S --map-setups N`` writes for the configuration in force (the same words
as ``M451 P0``'s program, :func:`~pige_sym.cycle.program_words.probe_argv`: TCP kinematics, the values in force act, the
active coordinate system), with ``--map-point`` the settings' spheres (``sphere_mm`` for setup 1, ``map.spheres_mm``
for the others; none given: the program's own).  All N programs are written into the run's folder
(``map_1.ngc`` … ``map_N.ngc``, each read back by pige program); setup k's becomes the run's ``program.ngc``, and the
next setup's header says where its sphere goes (:func:`setup_sphere`).

Refused, before anything moves: the stock kinematics (they hold no map: the map test at the desk, with the
positioning maps as ``COMP_FILE``s), no map test in the settings, a setup number outside 1..N.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from pige_sym.cycle.context import Context, Request
from pige_sym.cycle.steplog import RunLog
from pige_sym.errors import InputError

#: at most 254 bytes with the operator error's head (LinuxCNC's limit)
STOCK_REFUSAL = ("{module} holds no error map (trt: the axis lines only); the map test needs pige's component; else "
                 "map at the desk and enter COMP_FILEs (docs/maps.md)")


def check_map_request(ctx: Context, req: Request) -> int:
    """The setup number k of ``M451 P3 Q<k>``, once the configuration can run a map test.

    Raises
    ------
    InputError
        The module docstring's refusals, naming what to do.
    """
    s = ctx.settings
    if ctx.setup.kinematics != "pige":
        raise InputError(STOCK_REFUSAL.format(module=ctx.setup.module))
    if s.map is None:
        raise InputError("no map test in pige_cycle/settings.json: install the cycle again with --map AXES "
                         "--map-step DEG (docs/linuxcnc-cycle.md)")
    k = req.setup
    if k is None or not 1 <= k <= s.map.setups:
        raise InputError(f"M451 P3 Q{k if k is not None else ''}: the map test has setups 1..{s.map.setups}: call "
                         "M451 P3 Q1 (Q2, ...)")
    return k


def map_argv(ctx: Context, req: Request, out: Path) -> list[str]:
    """``pige program --map``'s words for every setup of the settings' map test (module docstring)."""
    from pige_sym.cycle.program_words import probe_argv, program_point

    m = ctx.settings.map
    assert m is not None
    argv = probe_argv(ctx, req, out) + ["--map", ",".join(m.axes), "--map-step", repr(float(m.step_deg)),
                                        "--map-setups", str(m.setups)]
    if m.per_direction:
        argv += ["--map-per-direction", ",".join(m.per_direction)]
    for r in m.ranges:
        argv += ["--map-range", r]
    if m.spheres_mm:
        for v in [ctx.settings.sphere_mm, *m.spheres_mm]:
            argv += ["--map-point", program_point(list(v), req)]
    return argv


def map_program(ctx: Context, req: Request, run: Path, log: RunLog) -> Path:
    """Every setup's program into ``run`` (``map_<i>.ngc``), setup k's as ``program.ngc``; that path."""
    from pige_sym.cycle.program_words import run_program

    k = check_map_request(ctx, req)
    run_program(map_argv(ctx, req, run / "map.ngc"), run, log)
    program = run / "program.ngc"
    shutil.copyfile(run / f"map_{k}.ngc", program)
    return program


def setup_sphere(run: Path, k: int, req: Request) -> list[float]:
    """Where the sphere of setup ``k`` goes [mm]: machine coordinates at the reference pose, from the header of the
    program ``pige program --map`` wrote for it into ``run`` (its coordinates are the active system's)."""
    from pige_sym.nc.probe_header import header_setup

    path = run / f"map_{k}.ngc"
    sphere = header_setup(path.read_text(encoding="utf-8"), str(path)).sphere_mm
    return [float(v) + req.offset[i] for i, v in enumerate(sphere)]
