"""``pige identify``: PIGEs with uncertainty and identifiability from a measurement file."""

from __future__ import annotations

import argparse

from pige_sym.constants import LOSSES, METHODS
from pige_sym.files import to_json


def _run(args: argparse.Namespace) -> int:
    from pige_sym import api
    from pige_sym.identification.result import format_result

    result = api.identify(args.file, method=args.method, projection=args.projection, loss=args.loss,
                          with_zero=args.with_zero)
    if args.json:
        print(to_json(result.to_dict()))
    else:
        print(format_result(result))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "identify",
        help="identify the PIGEs from an R-test file",
        description="Least-squares identification of the rotary-axis PIGEs with uncertainty and identifiability.",
        epilog=(
            "examples:\n"
            "  pige identify run.csv\n"
            "  pige identify run.csv --method double-differential --projection y\n"
            "  pige identify run.csv --loss soft_l1 --json > result.json"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", help="pige-rtest 1 measurement file")
    p.add_argument("--method", choices=METHODS, default="gauss-newton")
    p.add_argument("--projection", default="xyz", help="x, y, z, xyz, a vector a,b,c or htm:... (default xyz)")
    p.add_argument("--loss", choices=LOSSES, default="linear", help="robust losses flag outlier rows")
    p.add_argument("--with-zero", action="store_true", help="also estimate the zero-position errors")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_run)
