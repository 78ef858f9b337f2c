"""``pige check``: is the machine in tolerance?  ISO 14253-1 verdict per PIGE with its uncertainty.

Exit status: 0 only when every judged item passes; 1 when any fails or is undecided; 2 bad input.
"""

from __future__ import annotations

import argparse

ESTIMATES = ("diagnosis", "gauss-newton", "double-differential")


def _run(args: argparse.Namespace) -> int:
    from pige_sym import api
    from pige_sym.files import to_json
    from pige_sym.measurements.ballbar import is_ballbar_file

    if len(args.files) > 1 or is_ballbar_file(args.files[0]):
        # joint: R-test, probe and ballbar files of one machine; diagnosis: with the effects seen jointly
        estimate = (api.diagnose_files(args.files) if args.method == "diagnosis"
                    else api.identify_files(args.files).result)
        result = api.check(estimate, args.tolerances, rule=args.rule, k=args.k)
    else:
        result = api.check(args.files[0], args.tolerances, rule=args.rule, k=args.k, method=args.method)
    print(to_json(result.to_dict()) if args.json else result.format())
    return result.exit_status


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "check",
        help="in tolerance? pass/fail/undecided per PIGE (ISO 14253-1) from R-test, probe or ballbar files",
        description=(
            "Judge every parameter that has a limit: pass when |value| + k*u <= limit, fail when\n"
            "|value| - k*u > limit, undecided otherwise (guard rule, ISO 14253-1); a parameter that is not\n"
            "identifiable is undecided. FILE is a measurement (identified and diagnosed now) or the JSON of\n"
            "`pige identify --json` / `pige diagnose --json`. Exit status 0 only when every item passes,\n"
            "1 otherwise, 2 bad input.\n\n"
            "tolerance file (JSON):\n"
            '  {"format": "pige-tolerances 1", "machine": "...", "description": "...",\n'
            '   "defaults": {"um": 10, "urad": 20}, "limits": {"EX0C": 8, "angular_error_C.cos_urad": 25}}\n'
            "  limits bound |value| in the parameter's unit (um, urad); defaults apply to every location PIGE\n"
            "  of that unit. Example: examples/tolerances.json in the source tree."
        ),
        epilog=(
            "examples:\n"
            "  pige check run.csv --tolerances tolerances.json\n"
            "  pige check diagnosis.json --tolerances tolerances.json --json\n"
            "  pige check run.csv --tolerances tolerances.json --rule simple"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="pige-rtest 1 measurement, or identify/diagnose JSON; several files (or ballbar files) are "
                        "identified jointly")
    p.add_argument("--tolerances", required=True, metavar="TOL.json", help="tolerance file (format above)")
    p.add_argument("--rule", choices=("guard", "simple"), default="guard",
                   help="decision rule (default %(default)s: with the expanded uncertainty k*u)")
    p.add_argument("--k", type=float, default=2.0, help="coverage factor of the guard band (default %(default)s)")
    p.add_argument("--method", choices=ESTIMATES, default="diagnosis",
                   help="estimate of a measurement file (default %(default)s: the PIGEs fitted with the accepted "
                        "effects, i.e. those used for compensation)")
    p.add_argument("--json", action="store_true", help="print one JSON object {verdict, items, ...}")
    p.set_defaults(handler=_run)
