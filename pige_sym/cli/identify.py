"""``pige identify``: PIGEs with uncertainty and identifiability from a measurement file, or jointly from several
(R-test runs, probe imports, ballbar setups: :mod:`pige_sym.identification.joint`)."""

from __future__ import annotations

import argparse

from pige_sym.constants import LOSSES, METHODS
from pige_sym.files import to_json


def _run(args: argparse.Namespace) -> int:
    from pige_sym import api
    from pige_sym.cli._setup import finite_option
    from pige_sym.identification.model_check import check_model
    from pige_sym.identification.result import format_result
    from pige_sym.measurements.ballbar import is_ballbar_file

    if args.map is not None:
        return _run_maps(args)
    if args.plots or args.map_step is not None or args.map_per_direction:
        from pige_sym.errors import InputError

        raise InputError("--plots, --map-step and --map-per-direction go with --map AXES")
    if len(args.files) > 1 or is_ballbar_file(args.files[0]):
        return _run_joint(args)
    if args.noise is not None:
        finite_option(args.noise, "--noise", positive=True)
    m = api.read(args.files[0])
    result = api.identify(m, method=args.method, projection=args.projection, loss=args.loss,
                          with_zero=args.with_zero)
    check = check_model(m, result, noise_um=args.noise)
    if args.json:
        print(to_json({**result.to_dict(), "model_check": None if check is None else check.to_dict()}))
    else:
        print(format_result(result) + ("" if check is None else "\n\n" + check.text()))
    return 0


def _run_joint(args: argparse.Namespace) -> int:
    """Several files (or a ballbar file): the joint identification with a per-file table."""
    from pige_sym import api
    from pige_sym.cli._ballbar import plan_pointer
    from pige_sym.errors import InputError
    from pige_sym.identification.joint import format_files
    from pige_sym.identification.result import format_result

    if args.noise is not None:
        raise InputError("--noise judges one R-test or probe file's residual: several files (or a ballbar file) are "
                         "each weighed by their own noise in the joint fit; identify that file alone")
    if args.method != "gauss-newton" or args.projection != "xyz" or args.loss != "linear":
        raise InputError("several files (or a ballbar file) are identified jointly: gauss-newton, each file with its "
                         "own projection (no --projection), loss linear")
    joint = api.identify_files(args.files, with_zero=args.with_zero)
    if args.json:
        print(to_json(joint.to_dict()))
    else:
        print(format_result(joint.result) + "\n" + format_files(joint.files) + plan_pointer(joint.result, joint.files))
    return 0


def _run_maps(args: argparse.Namespace) -> int:
    """``--map AXES``: the PIGEs, the zero-position errors and the error maps, jointly from every file."""
    from pige_sym.cli._maps import map_axes, map_step
    from pige_sym.errors import InputError
    from pige_sym.files import check_output
    from pige_sym.identification.joint import format_files
    from pige_sym.identification.map_output import format_maps, plot_maps, plot_paths
    from pige_sym.identification.maps import MapSpec, identify_maps
    from pige_sym.identification.result import format_result
    from pige_sym.measurements.sets import read_files

    if args.method != "gauss-newton" or args.projection != "xyz" or args.loss != "linear" or args.with_zero:
        raise InputError("--map fits every file jointly (gauss-newton, full 3-D, loss linear) and always with the "
                         "zero-position errors: leave out --method, --projection, --loss and --with-zero")
    axes, per_direction = map_axes(args)
    step = map_step(args.map_step, axes)
    if args.plots:
        for path in plot_paths(axes, args.plots):
            check_output(path, force=args.force, inputs=args.files, what="--plots")
    spec = MapSpec(axes, step, per_direction)
    result = identify_maps(read_files(args.files), spec)
    written = plot_maps(result, args.plots) if args.plots else []
    if args.json:
        print(to_json(result.to_dict() | ({"plots": written} if written else {})))
    else:
        print(format_result(result.result) + "\n" + format_files(result.joint.files) + "\n" + format_maps(result))
        for plot in written:
            print(f"wrote {plot}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "identify",
        help="identify the PIGEs from R-test, probe or ballbar files (several of one machine jointly)",
        description=("Least-squares identification of the rotary-axis PIGEs with uncertainty and identifiability,\n"
                     "from one file or jointly from several of one machine: R-test runs, probe imports, ballbar\n"
                     "setups.\n\n"
                     "model check (one R-test or probe file): chi2 = (residual sigma / noise)^2 * dof of the whitened\n"
                     "residual against its degrees of freedom; above its 99.9 % quantile the PIGE model misses\n"
                     "something in the file, and the next step is `pige diagnose FILE`. The noise: --noise, else a\n"
                     "probe import's centre covariances, else the R-test's nominal 0.25 um. JSON: \"model_check\"."),
        epilog=(
            "examples:\n"
            "  pige identify run.csv\n"
            "  pige identify run.csv --method double-differential --projection y\n"
            "  pige identify run.csv --loss soft_l1 --json > result.json\n"
            "  pige identify radial_C.csv tangential_C.csv axial_A.csv      # ballbar setups, jointly\n"
            "  pige identify s1.csv s2.csv s3.csv --map C,A --map-step 15   # error maps (CONVENTIONS §10)"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="pige-rtest 1 measurement (R-test, probe import) or pige-ballbar 1 file; several files of "
                        "one machine are identified jointly")
    p.add_argument("--method", choices=METHODS, default="gauss-newton")
    p.add_argument("--projection", default="xyz", help="x, y, z, xyz, a vector a,b,c or htm:... (default xyz)")
    p.add_argument("--loss", choices=LOSSES, default="linear", help="robust losses flag outlier rows")
    p.add_argument("--with-zero", action="store_true", help="also estimate the zero-position errors")
    p.add_argument("--noise", type=float, metavar="UM",
                   help="the instrument's noise per component [um] for the model check (default: the file's, else "
                        "the instrument's nominal)")
    p.add_argument("--map", metavar="AXES", help="also identify the error maps of these rotary axes (CONVENTIONS "
                   "§10), jointly from every file: probe setups, R-test runs, ballbar setups (docs/maps.md)")
    p.add_argument("--map-step", type=float, metavar="DEG", help="grid step of the maps [deg] (default 15)")
    p.add_argument("--map-per-direction", metavar="AXES",
                   help="map these axes' positioning error per approach direction (ECC+ and ECC-)")
    p.add_argument("--plots", metavar="DIR", help="with --map: draw each axis' maps with their ±2σ bands")
    p.add_argument("--force", action="store_true", help="replace existing plots")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_run)
