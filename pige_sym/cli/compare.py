"""``pige compare``: measured before/after of two R-test files of the same program."""

from __future__ import annotations

import argparse


def _run(args: argparse.Namespace) -> int:
    from pige_sym.files import to_json
    from pige_sym.verdict.compare import compare_measurements

    result = compare_measurements(args.before, args.after, explain=not args.no_explain)
    print(to_json(result.to_dict()) if args.json else result.format())
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "compare",
        help="measured before/after of two runs of the same test program (R-test or probe files)",
        description=(
            "Two measurements of the same program (before and after compensation, or two dates): |d| per pose,\n"
            "RMS and max before and after, the improvement, and what is left: each file is diagnosed and its\n"
            "deviation split into the PIGE part, one part per accepted effect and the unexplained rest.\n"
            "The files must have the same machine, axes and points, angles within 0.05 deg."
        ),
        epilog=("examples:\n  pige compare before.csv after.csv\n  pige compare before.csv after.csv --json"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("before", metavar="BEFORE", help="pige-rtest 1 file measured first (e.g. before compensation)")
    p.add_argument("after", metavar="AFTER", help="pige-rtest 1 file of the same program measured later")
    p.add_argument("--no-explain", action="store_true", help="skip the diagnosis of what is left")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_run)
