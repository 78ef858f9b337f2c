"""``pige program``: write the NC program of a test (R-test, sphere probing or ballbar), to run on the machine.

One positioning block per pose followed by a dwell, written natively in the chosen
dialect (Siemens 840D, ISO/Fanuc/Haas with decimal points and ``G04 X``, or LinuxCNC with
``G4 P``; :func:`pige_sym.nc.program.make_rtest_program`).  In machine coordinates
(``TRAFOOF``, default) X/Y/Z are the RTCP commands of the nominal kinematics for the
ball at ``--ball`` (honouring ``--pivot``/``--tool``); with ``--rtcp`` (``TRAORI``)
they are the workpiece coordinates of the ball and the controller's RTCP moves the
linear axes.  The same file is what ``pige acquire --program`` and ``pige rtest-sim
--trajectory`` read, and what ``pige compensate`` rewrites.

With ``--instrument sphere-probe`` it writes the sphere-probing program instead
(:mod:`pige_sym.nc.probe_program`): per pose the rotary axes positioned (RTCP off), k contacts
probed along machine axes (G38.2 / G31 / MEAS / TCH PROBE) and logged; the program is read back and
replayed against the nominal sphere before it is written (:mod:`pige_sym.nc.probe_readback`).
Heidenhain programs print with FN 16: the format file is written beside the program (``.A``).

With ``--instrument sphere-probe --map AXES`` it writes one probing program per setup of the map test
``pige plan --map`` plans (``--out map.ngc``: ``map_1.ngc``, ``map_2.ngc``, …), each covering the map grid (every
grid angle of each rotary axis, the inner axis swept at each outer angle; with ``--map-per-direction`` every
angle met from both sides), each read back and checked as above.

With ``--instrument ballbar`` it writes one ballbar setup (``--setup``, ``--axis``, ``--tilt``) as an RTCP
program (Siemens ``TRAORI`` or Fanuc ``G43.4``), checked to keep the nominal bar length at every pose.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from pige_sym.cli._ballbar import add_ballbar_arguments
from pige_sym.cli._maps import add_map_arguments
from pige_sym.cli._probe import INSTRUMENT_CHOICES, add_probe_program_arguments
from pige_sym.cli._setup import (
    add_setup_arguments,
    axis_sense_option,
    finite_option,
    setup_geometry,
    trajectory_options,
)
from pige_sym.constants import DEFAULT_DWELL_S
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text, check_output

#: The contact scatter a map test's programs are planned with when ``--noise`` is not given [µm].
MAP_NOISE_UM = 0.5


def _run_probe(args: argparse.Namespace) -> int:
    from pige_sym.cli._probe import probe_setup
    from pige_sym.kernels import load_kernels
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.nc.probe_program import plan_probing

    kern = load_kernels(args.machine)
    setup = probe_setup(args, kern.MACHINE_CODE, dialect=args.dialect)
    if args.map is not None:
        return _run_probe_maps(args, kern, setup)
    traj = make_trajectory(kern.MACHINE_CODE, args.trajectory, **trajectory_options(args))
    plan = plan_probing(setup, traj.angles_deg, traj.description)
    return _write_probe(args, setup, plan, [args.trajectory])


def _write_probe(args: argparse.Namespace, setup: Any, plan: Any, inputs: list[str]) -> int:
    """Render a probing plan in ``--dialect``, read it back (proof of safety), write it and say what it holds."""
    from pige_sym.identification.result import per_pose
    from pige_sym.nc.probe_readback import verify_rendered_program
    from pige_sym.nc.probe_render import heidenhain_format_file, render_probe_program

    text = render_probe_program(plan, args.dialect)
    check = verify_rendered_program(text, args.dialect, setup, plan.rotary_axes, out=args.out)
    out = check_output(args.out, force=args.force, inputs=inputs, what="--out")
    fmt = check_output(out.with_suffix(".A"), force=args.force, inputs=inputs, what="format file") \
        if args.dialect == "heidenhain" else None
    atomic_write_text(out, text)
    if fmt is not None:
        atomic_write_text(fmt, heidenhain_format_file(plan))
    print(f"wrote {out}: {check.poses} poses ({plan.description}), {sum(check.contacts)} contacts "
          f"({per_pose(min(check.contacts), max(check.contacts))}), {args.dialect}"
          + (f", format file {fmt}" if fmt is not None else ""))
    print(f"read back: rapid moves at least {check.min_rapid_clearance_mm:.2f} mm from the sphere, rotary moves "
          f"{check.min_rotary_clearance_mm:.1f} mm above it, every probing move {check.min_overtravel_mm:.2f} mm past "
          f"its surface; safe Z {plan.safe_z_mm:.3f} mm; the sphere confirmed by {check.confirmations} contacts "
          f"within {setup.controller.window_mm:g} mm before the log opens")
    return 0


def _run_checkup(args: argparse.Namespace) -> int:
    """The check-up program of a machine (``--checkup``): poses planned from its last full calibration, its set-up."""
    from dataclasses import replace

    from pige_sym.cli._checkup import checkup_controller, plan_from_history
    from pige_sym.nc.probe_program import plan_probing

    if args.instrument != "rtest" or args.trajectory != "cone-frustum":
        raise InputError("--checkup takes the instrument and the poses from the history: leave out --instrument and "
                         "--trajectory")
    pc = plan_from_history(args, budget_s=args.budget, controller=checkup_controller(args, args.dialect),
                           dialect=args.dialect)
    p = pc.plan
    said = f"check-up of {pc.machine_id}, {p.poses} poses, {', '.join(p.free)}"
    if pc.probe is not None:
        setup = replace(pc.probe, contacts=p.contacts, checkup=tuple(p.free), machine_id=pc.machine_id)
        code = _write_probe(args, setup, plan_probing(setup, p.angles_deg, said), [])
    else:
        code = _write_rtest_checkup(args, pc, said)
    print(f"predicted: {p.seconds:.0f} s of machine time; std " + ", ".join(f"{n} {s:.3f}" for n, s in p.std.items()))
    return code


def _write_rtest_checkup(args: argparse.Namespace, pc: Any, said: str) -> int:
    """An R-test check-up program: the plan's poses with the full calibration's ball, pivots, tool and sense."""
    import tempfile
    from pathlib import Path

    import numpy as np

    from pige_sym.nc.program import make_rtest_program
    from pige_sym.nc.rtest_program import load_test_program

    if args.dialect == "heidenhain":
        raise InputError("R-test programs are written for siemens, fanuc or linuxcnc (heidenhain: sphere-probe)")
    out = check_output(args.out, force=args.force, what="--out")
    s = pc.setup
    with tempfile.TemporaryDirectory() as tmp:
        angles = Path(tmp) / "checkup.csv"
        angles.write_text(pc.plan.angle_file_text(said))
        program = load_test_program(s.machine, str(angles), ball_mm=s.ball_mm, pivots_mm=s.pivots_mm or None,
                                    tool_mm=s.tool_mm, dwell_s=args.dwell, axis_sense=s.axis_sense)
    xyz = np.tile(program.ball_mm, (program.n_poses, 1)) if args.rtcp else program.linear_mm()
    text = make_rtest_program(program.angles_deg, xyz, tuple(pc.plan.rotary_axes), rtcp=args.rtcp, dwell_s=args.dwell,
                              feed=args.feed, title=f"R-test {said}, {s.machine}", dialect=args.dialect,
                              axis_sense=program.axis_sense)
    atomic_write_text(out, text)
    print(f"wrote {out}: {program.n_poses} poses ({said}), {'TRAORI' if args.rtcp else 'TRAFOOF'}, {args.dialect}")
    return 0


def _map_noise(args: argparse.Namespace) -> float:
    """``--noise`` of a map test (> 0), :data:`MAP_NOISE_UM` when not given [µm]."""
    return MAP_NOISE_UM if args.noise is None else finite_option(args.noise, "--noise", positive=True)


def _run_probe_maps(args: argparse.Namespace, kern: Any, setup: Any) -> int:
    """``--map AXES``: one probing program per setup of the map test (``pige plan --map``), each planned, read back
    and checked as a single program is; nothing is written unless every one passes."""
    import dataclasses

    from pige_sym.cli._maps import map_request, numbered
    from pige_sym.nc.probe_readback import verify_probe_program
    from pige_sym.nc.probe_render import heidenhain_format_file, render_probe_program
    from pige_sym.planning.map_plan import plan_map_test

    plan = plan_map_test(map_request(args, kern, "sphere-probe", point=setup.sphere_mm, tool=setup.tool_mm,
                                     probe=setup, noise_um=_map_noise(args), pose_s=args.pose_time,
                                     contact_s=args.contact_time), fewer=False)
    outs = numbered(args.out, len(plan.setups))
    written = []
    for s, out in zip(plan.setups, outs, strict=True):
        assert s.probe is not None and s.probe_plan is not None
        grid = f"{s.label}: maps of {args.map} every {args.map_step:g} deg"
        probe_plan = dataclasses.replace(s.probe_plan, description=grid)
        text = render_probe_program(probe_plan, args.dialect)
        check = verify_probe_program(text, args.dialect, s.probe, probe_plan.rotary_axes, path=str(out))
        path = check_output(out, force=args.force, what="--out")
        fmt = check_output(path.with_suffix(".A"), force=args.force, what="format file") \
            if args.dialect == "heidenhain" else None
        written.append((s, path, fmt, text, probe_plan, check))
    for s, path, fmt, text, probe_plan, check in written:
        atomic_write_text(path, text)
        if fmt is not None:
            atomic_write_text(fmt, heidenhain_format_file(probe_plan))
        where = f"sphere {', '.join(f'{x:g}' for x in s.point_mm)} mm" + (
            "" if s.tool_mm is None else f", tool {', '.join(f'{x:g}' for x in s.tool_mm)} mm")
        print(f"wrote {path}: {s.label}, {where}; {check.poses} poses, {sum(check.contacts)} contacts, "
              f"{args.dialect}, {s.seconds / 60:.0f} min; read back: rapid moves at least "
              f"{check.min_rapid_clearance_mm:.2f} mm from the sphere, probing moves {check.min_overtravel_mm:.2f} mm "
              f"past it" + (f"; format file {fmt}" if fmt is not None else ""))
    done, total = plan.prediction.counts()
    print(f"together: {done} of {total} map values determined (the map test's plan gives their predicted standard "
          "errors)")
    print(map_next_steps(args, [path for _, path, *_ in written]))
    return 0


def map_next_steps(args: argparse.Namespace, programs: list[Any]) -> str:
    """What to run after the map programs, as commands that run as printed: each log's import (LinuxCNC, SINUMERIK
    and HEIDENHAIN write a log of a fixed name, imported before the next program writes it again), then ``pige
    identify`` with the map options the programs were written for (grid, per direction)."""
    from pige_sym.nc.probe_program import HEIDENHAIN_LOG
    from pige_sym.nc.probe_render import LINUXCNC_LOG, SIEMENS_LOG

    log = {"linuxcnc": LINUXCNC_LOG, "siemens": SIEMENS_LOG, "heidenhain": HEIDENHAIN_LOG.rsplit("\\", 1)[-1]}.get(
        args.dialect)
    csvs = [Path(p).with_suffix(".csv") for p in programs]
    if log is None:
        lines = [f"next: run each program in turn and import its {args.dialect} output (the file its DPRNT writes, "
                 "named on the control) with the import command, --format " + args.dialect
                 + ", --program and --out as below:"]
        lines += [f"  {p} -> {c}" for p, c in zip(programs, csvs, strict=True)]
    else:
        lines = [f"next: run each program in turn; each writes the log {log}: import it before the next program "
                 "writes it again:"]
        lines += [f"  pige import-probe {log} --format {args.dialect} --program {p} --out {c}"
                  for p, c in zip(programs, csvs, strict=True)]
    options = f"--map {args.map} --map-step {args.map_step:g}"
    if args.map_per_direction:
        options += f" --map-per-direction {args.map_per_direction}"
    lines += ["then identify the maps from every setup:",
              f"  pige identify {' '.join(str(c) for c in csvs)} {options}"]
    return "\n".join(lines)


def _run_ballbar(args: argparse.Namespace) -> int:
    """One ballbar setup as an RTCP program: the tool ball on the nominal table point table_ball + offset."""
    import numpy as np

    from pige_sym.cli._ballbar import ballbar_setup_of
    from pige_sym.errors import InputError
    from pige_sym.kernels import load_kernels
    from pige_sym.nc.program import make_rtest_program
    from pige_sym.simulation.exact_table import nominal_table_point

    if args.dialect not in ("siemens", "fanuc"):
        raise InputError("a ballbar program needs RTCP (TRAORI / G43.4): --dialect siemens or fanuc")
    kern = load_kernels(args.machine)
    setup = ballbar_setup_of(args, kern.MACHINE_CODE)
    tool_point = setup.table_ball_mm + setup.offset_mm
    n = setup.angles_deg.shape[0]
    # read the geometry back: the nominal bar length is L0 at every pose (the bar's travel, ±1 mm, takes the errors)
    lengths = np.linalg.norm(nominal_table_point(kern.MACHINE_CODE, setup.angles_deg, tool_point)
                             - nominal_table_point(kern.MACHINE_CODE, setup.angles_deg, setup.table_ball_mm), axis=1)
    if np.abs(lengths - np.linalg.norm(setup.offset_mm)).max() > 1e-9:  # pragma: no cover - rigid table
        raise InputError("the nominal bar length varies along the program: refusing it")
    out = check_output(args.out, force=args.force, what="--out")
    text = make_rtest_program(setup.angles_deg, np.tile(tool_point, (n, 1)), tuple(kern.ROTARY_AXES), rtcp=True,
                              dwell_s=args.dwell, feed=args.feed, dialect=args.dialect,
                              axis_sense=axis_sense_option(args, tuple(kern.ROTARY_AXES)),
                              title=f"ballbar {setup.label}, {kern.MACHINE_CODE}, table ball "
                              f"{', '.join(f'{x:g}' for x in setup.table_ball_mm)} mm, tool ball "
                              f"{', '.join(f'{x:g}' for x in tool_point)} mm "
                              f"(L0 {np.linalg.norm(setup.offset_mm):g} mm)")
    atomic_write_text(out, text)
    print(f"wrote {out}: {n} poses ({setup.label} sweep), RTCP on; nominal bar length "
          f"{np.linalg.norm(setup.offset_mm):g} mm at every pose")
    return 0


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from pige_sym.cli._checkup import checkup_requested

    if checkup_requested(args, "write different programs", "write a check-up program"):
        return _run_checkup(args)
    if args.instrument == "sphere-probe":
        return _run_probe(args)
    if args.map is not None:
        raise InputError("--map writes the probing programs of a map test (--instrument sphere-probe); for an R-test "
                         "or ballbar map test, pige plan --map names each setup's ball and tool")
    if args.instrument == "ballbar":
        return _run_ballbar(args)
    if args.dialect == "heidenhain":
        raise InputError("R-test programs are written for siemens, fanuc or linuxcnc (heidenhain: sphere-probe)")

    from pige_sym.kernels import load_kernels
    from pige_sym.nc.program import make_rtest_program
    from pige_sym.nc.rtest_program import load_test_program

    out = check_output(args.out, force=args.force, what="--out")
    kern = load_kernels(args.machine)
    ball, pivots, tool = setup_geometry(args)
    program = load_test_program(kern.MACHINE_CODE, args.trajectory, ball_mm=ball, pivots_mm=pivots, tool_mm=tool,
                                dwell_s=args.dwell, axis_sense=axis_sense_option(args, tuple(kern.ROTARY_AXES)),
                                **trajectory_options(args))
    if args.rtcp:
        xyz = np.tile(program.ball_mm, (program.n_poses, 1))
    else:
        xyz = program.linear_mm()
    text = make_rtest_program(program.angles_deg, xyz, tuple(kern.ROTARY_AXES), rtcp=args.rtcp, dwell_s=args.dwell,
                              feed=args.feed, title=f"R-test {program.description}, {kern.MACHINE_CODE}, "
                              f"ball {', '.join(f'{x:g}' for x in program.ball_mm)} mm", dialect=args.dialect,
                              axis_sense=program.axis_sense)
    atomic_write_text(out, text)
    print(f"wrote {out}: {program.n_poses} poses ({program.description}), {'TRAORI' if args.rtcp else 'TRAFOOF'}, "
          f"{args.dwell:g} s dwell per pose, {args.dialect}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "program",
        help="write the NC program of a test: R-test trajectory, touch-probe cycles on the sphere, or ballbar setup",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        epilog=(
            "examples:\n"
            "  pige program --machine \"wC'A'bXYZ(C1)t\" --trajectory cone-frustum --ball 120,0,80 --out rtest.mpf\n"
            "  pige program --machine \"wC'B'bXYZ(C1)t\" --trajectory figure-eight --rtcp --out fig8.mpf\n"
            "  pige program --trajectory steps --dialect fanuc --out steps.nc\n"
            "  pige program --instrument sphere-probe --dialect linuxcnc --sphere 100,20,60 --sphere-radius 12.7 \\\n"
            "      --stylus-radius 1.5 --trajectory plan.csv --out probe.ngc\n"
            "  pige program --instrument sphere-probe --map C,A --dialect linuxcnc --sphere 100,20,60 \\\n"
            "      --sphere-radius 12.7 --stylus-radius 1.5 --stylus-tool 9 --stylus-length 120 --out map.ngc\n"
            "  pige program --instrument ballbar --setup tangential --axis C --tilt -45 --dialect siemens \\\n"
            "      --out tangential_C45.mpf\n"
            "  pige program --checkup --machine-id DMU50-2 --db history.db --dialect fanuc --out checkup.nc"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_setup_arguments(p)
    p.add_argument("--dwell", type=float, default=DEFAULT_DWELL_S,
                   help="dwell per pose [s] (default %(default)s: ~1 s to settle, then a 5 s average)")
    p.add_argument("--feed", type=float, default=2000.0, help="feed of the positioning blocks (default %(default)s)")
    p.add_argument("--rtcp", action="store_true", help="workpiece coordinates with TRAORI instead of machine ones")
    p.add_argument("--dialect", choices=["siemens", "fanuc", "linuxcnc", "heidenhain"], default="siemens",
                   help="output dialect (heidenhain: sphere-probe only)")
    p.add_argument("--instrument", choices=INSTRUMENT_CHOICES, default="rtest", help="the test's instrument")
    add_probe_program_arguments(p)
    add_ballbar_arguments(p)
    from pige_sym.cli._checkup import add_checkup_arguments

    add_checkup_arguments(p)
    add_map_arguments(p)
    p.add_argument("--budget", type=float, help="with --checkup: machine-time budget [s] (default 120)")
    p.add_argument("--noise", type=float, help=f"--map: contact scatter the plan weighs [um] (default {MAP_NOISE_UM}); "
                   "--checkup: only when the history holds none for the last full calibration")
    p.add_argument("--pose-time", type=float, default=20.0, help="--map: time per pose (retract, rotate) [s]")
    p.add_argument("--contact-time", type=float, default=8.0, help="--map: time per contact [s]")
    p.add_argument("--out", required=True, help="program file to write (--map: map.ngc writes map_1.ngc, map_2.ngc, "
                   "...)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(handler=_run)
