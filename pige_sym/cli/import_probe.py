"""``pige import-probe``: a touch-probe log (LinuxCNC, Fanuc, Siemens, Heidenhain) to a measurement file.

Contacts are grouped by pose (the rotary angles of the log), every pose's sphere centre is fitted
(one effective radius for all poses unless ``--radius`` gives it), and the deviation of the centre from
the nominal motion of the reference pose's centre (on a head or mixed machine the log's points are first turned
with the head about ``--tool``, CONVENTIONS §7) is written as a ``pige-rtest 1`` file with
``instrument: sphere-probe`` and per-row centre covariances
(:mod:`pige_sym.measurements.probe_import`).  Every command reads it: identify, diagnose, check,
report, history, compare, plan --grade.
"""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.cli._probe import add_sphere_arguments, probe_pivot, probe_tool, sphere_radii
from pige_sym.constants import DEFAULT_MACHINE
from pige_sym.files import check_output


def _run(args: argparse.Namespace) -> int:
    from pige_sym.measurements.probe_import import import_probe_log, verify_written
    from pige_sym.measurements.rtest_writer import write_measurement

    spec = _spec(args)
    out = check_output(args.out, force=args.force, inputs=[x for x in (args.log, args.program) if x], what="--out")
    m = import_probe_log(args.log, args.format, spec)
    write_measurement(m, out, verify=verify_written(out, m))  # read back before it replaces anything
    r_eff_text, _, how = m.metadata["r_eff_mm"].partition(" ")
    print(f"wrote {out}: {m.n_rows} poses, {int(m.optional['n_samples'].sum())} contacts; R_eff "
          f"{float(r_eff_text):.4f} mm {how}, contact sigma {float(m.metadata['contact_sigma_um']):.3f} um; largest "
          f"deviation {abs(m.deviation_um).max():.2f} um")
    return 0


def _spec(args: argparse.Namespace) -> Any:
    """The import's :class:`~pige_sym.measurements.probe_import.ProbeImport`: the options, or the program's header
    checked against them (``--program``)."""
    from pige_sym.cli._probe import probe_pivots
    from pige_sym.cli._setup import axis_sense_option, finite_option
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.probe_import import ProbeImport

    if args.program:
        return _spec_from_program(args)
    kern = load_kernels(args.machine or DEFAULT_MACHINE)
    axes = tuple(kern.ROTARY_AXES)
    radius, stylus = sphere_radii(args)
    r_eff = None if args.radius is None else finite_option(args.radius, "--radius", positive=True)
    per_axis = probe_pivots(args.pivot, axes)
    pivots = None if per_axis is None else {a: (v[0], v[1], v[2]) for a, v in per_axis.items()}
    return ProbeImport(kern.MACHINE_CODE, (0.0, 0.0, 0.0) if pivots else probe_pivot(args.pivot), radius, stylus,
                       r_eff, finite_option(args.stylus_offset, "--stylus-offset"), args.units, moves=args.moves,
                       pivots_mm=pivots, axis_sense=axis_sense_option(args, axes) or {},
                       kinematics=args.kinematics or "identity", tool_mm=probe_tool(args.tool),
                       sphere_mm=_sphere(args))


def _spec_from_program(args: argparse.Namespace) -> Any:
    """What the probing program's header states; every option given must agree with it."""
    from pige_sym.cli._setup import axis_sense_option, finite_option
    from pige_sym.errors import InputError
    from pige_sym.measurements.axis_sense import reconcile
    from pige_sym.measurements.probe_import import ProbeImport
    from pige_sym.nc.probe_header import header_setup
    from pige_sym.nc.program_file import read_program
    from pige_sym.nc.program_header import read_header

    text = read_program(args.program)
    h = header_setup(text, args.program)
    axes = tuple(h.pivots_mm)
    given = {"--machine": (args.machine, h.machine), "--format": (args.format, h.dialect),
             "--kinematics": (args.kinematics, h.controller.kinematics),
             "--sphere-radius": (args.sphere_radius, h.sphere_radius_mm),
             "--stylus-radius": (args.stylus_radius, h.stylus_radius_mm)}
    for flag, (value, stated) in given.items():
        if value is not None and not _same(value, stated, flag):
            raise InputError(f"{flag} {value}: the program {args.program} states {stated}; leave the option out "
                             "(the program's header gives it) or import the log of the right program")
    if args.pivot:
        raise InputError(f"--pivot: the program {args.program} states the pivots; leave --pivot out")
    sense = reconcile(h.axis_sense, axis_sense_option(args, axes), args.program, axes)
    r_eff = None if args.radius is None else finite_option(args.radius, "--radius", positive=True)
    pivots: dict[str, tuple[float, float, float]] | None = {a: (float(v[0]), float(v[1]), float(v[2]))
                                                             for a, v in h.pivots_mm.items()}
    tool = probe_tool(args.tool)
    import numpy as np

    if tool is not None and (h.tool_mm is None or not np.allclose(h.tool_mm, tool, rtol=2e-6, atol=2e-6)):
        raise InputError(f"--tool {args.tool}: the program {args.program} states "
                         f"{'no tool' if h.tool_mm is None else ', '.join(f'{v:g}' for v in h.tool_mm)}; leave "
                         "--tool out (the program's header gives it)")
    single: tuple[float, float, float] = (0.0, 0.0, 0.0)
    if h.tool_mm is not None:  # a head is probed about one pivot (the axis lines meet)
        first = next(iter(h.pivots_mm.values()))
        single, pivots = (float(first[0]), float(first[1]), float(first[2])), None
    return ProbeImport(h.machine, single, h.sphere_radius_mm, h.stylus_radius_mm, r_eff,
                       finite_option(args.stylus_offset, "--stylus-offset"), args.units, moves=args.moves,
                       pivots_mm=pivots, axis_sense=sense, kinematics=h.controller.kinematics,
                       program=read_header(text, args.program),
                       tool_mm=None if h.tool_mm is None else (h.tool_mm[0], h.tool_mm[1], h.tool_mm[2]),
                       sphere_mm=_sphere(args, h.sphere_mm, args.program))


def _sphere(args: argparse.Namespace, stated: Any = None, program: str | None = None
            ) -> tuple[float, float, float] | None:
    """``--sphere`` [mm], or the program's sphere (which ``--sphere`` must then agree with)."""
    from pige_sym.cli._setup import parse_vec3
    from pige_sym.errors import InputError

    given = parse_vec3(args.sphere, "--sphere") if args.sphere else None
    if given is not None and stated is not None and max(abs(a - float(b)) for a, b in zip(given, stated,
                                                                                          strict=True)) > 1e-6:
        said = ", ".join(f"{float(v):g}" for v in stated)
        raise InputError(f"--sphere {args.sphere}: the program {program} states {said}; leave the option out (the "
                         "program's header gives it)")
    v = given if given is not None else stated
    return None if v is None else (float(v[0]), float(v[1]), float(v[2]))


def _same(value: object, stated: object, flag: str) -> bool:
    if flag == "--machine":
        from pige_sym.kernels import load_kernels

        return bool(load_kernels(str(value)).MACHINE_CODE == stated)
    if isinstance(stated, float):
        return abs(float(value) - stated) <= 1e-6 * max(1.0, abs(stated))  # type: ignore[arg-type]
    return value == stated


def register(subparsers: argparse._SubParsersAction) -> None:
    from pige_sym.constants import PROBE_FORMATS

    p = subparsers.add_parser(
        "import-probe",
        help="turn a touch-probe log into a measurement file",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        epilog=(
            "examples:\n"
            "  pige import-probe probe.txt --format linuxcnc --machine \"wC'A'bXYZ(C1)t\" --pivot 0,0,0 \\\n"
            "      --sphere-radius 12.7 --stylus-radius 1.5 --out probe.csv\n"
            "  pige import-probe probe.txt --format siemens --machine \"wC'bXYZB(C1)t\" --tool 0,0,-180 \\\n"
            "      --sphere-radius 12.7 --stylus-radius 1.5 --out head.csv\n"
            "  pige identify probe.csv"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("log", help="probe log (LinuxCNC PROBEOPEN file, or the log a pige probing program wrote)")
    p.add_argument("--format", choices=PROBE_FORMATS, required=True, help="the controller that wrote the log")
    p.add_argument("--program", help="the probing program that wrote the log: its header gives the machine, axis "
                   "sense, pivots, radii and kinematics (options given must agree)")
    p.add_argument("--machine", help=f"ISO 10791 machine code (default {DEFAULT_MACHINE})")
    p.add_argument("--pivot", action="append", metavar="x,y,z",
                   help="nominal intersection of the rotary axis lines in the log's coordinates [mm] (default "
                        "0,0,0), or AXIS=x,y,z once per rotary axis")
    p.add_argument("--axis-sense", metavar="AXIS=-1,...", help="rotary axes the controller commands in the reverse "
                   "of CONVENTIONS' sense (e.g. A=-1,C=-1 for LinuxCNC 2.9's trt kinematics)")
    p.add_argument("--kinematics", choices=("identity", "tcp"), help="the kinematics the log was probed in "
                   "(tcp: work coordinates, mapped back through --pivot and --axis-sense; default identity)")
    add_sphere_arguments(p, when="without --program, whose header states them")
    p.add_argument("--sphere", metavar="x,y,z", help="where the probing program put the sphere centre at the reference "
                   "pose [mm]: the fitted reference centre must be within 0.5 mm of it (default: the program's header "
                   "with --program, else not checked)")
    p.add_argument("--tool", metavar="x,y,z",
                   help="head and mixed machines: the stylus centre from the last tool-side pivot at the reference "
                        "pose [mm] (CONVENTIONS 7; required there)")
    p.add_argument("--radius", type=float, help="calibrated effective radius R + r - pre-travel [mm] (default: fit)")
    p.add_argument("--stylus-offset", type=float, default=0.0,
                   help="stylus centre above the controlled point along the spindle axis [mm] (default 0)")
    p.add_argument("--units", choices=["mm", "inch"], default="mm", help="units of X Y Z in the log")
    p.add_argument("--moves", choices=["axes", "normal"], default="axes",
                   help="how the contacts were probed: along machine axes, vertical onto the top and horizontal "
                        "elsewhere (pige's programs), or along the surface normal; weighs each contact by the "
                        "share of the probe's scatter that lands on the radius (default %(default)s)")
    p.add_argument("--out", required=True, help="measurement file to write")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(handler=_run)
