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

from pige_sym.cli._probe import add_sphere_arguments, probe_pivot, probe_tool, sphere_radii
from pige_sym.constants import DEFAULT_MACHINE
from pige_sym.files import check_output


def _run(args: argparse.Namespace) -> int:
    from pige_sym.cli._setup import finite_option
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.probe_import import ProbeImport, import_probe_log
    from pige_sym.measurements.rtest_writer import write_measurement

    kern = load_kernels(args.machine)
    radius, stylus = sphere_radii(args)
    r_eff = None if args.radius is None else finite_option(args.radius, "--radius", positive=True)
    offset = finite_option(args.stylus_offset, "--stylus-offset")
    out = check_output(args.out, force=args.force, inputs=[args.log], what="--out")
    tool = probe_tool(args.tool)
    spec = ProbeImport(kern.MACHINE_CODE, probe_pivot(args.pivot), radius, stylus, r_eff, offset, args.units,
                       moves=args.moves, tool_mm=tool)
    m = import_probe_log(args.log, args.format, spec)
    write_measurement(m, out)
    print(f"wrote {out}: {m.n_rows} poses, {int(m.optional['n_samples'].sum())} contacts; R_eff "
          f"{m.metadata['r_eff_mm']} mm, contact sigma {float(m.metadata['contact_sigma_um']):.3f} um; largest "
          f"deviation {abs(m.deviation_um).max():.2f} um")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    from pige_sym.measurements.probe_log import PROBE_FORMATS

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
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--pivot", action="append", metavar="x,y,z",
                   help="nominal intersection of the rotary axis lines in the log's coordinates [mm] (default 0,0,0)")
    add_sphere_arguments(p)
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
