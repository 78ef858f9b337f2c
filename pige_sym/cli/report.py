"""``pige report``: a self-contained HTML calibration report of R-test measurement files."""

from __future__ import annotations

import argparse
import json
import sys

from pige_sym.report import PRIMARY_METHODS, findings_text, gather_report, write_report


def _run(args: argparse.Namespace) -> int:
    data = gather_report(args.files, studies=args.study or "", program=args.program, method=args.method,
                         projection=args.projection, with_zero=args.with_zero, presets=args.presets,
                         sobol_samples=args.samples, seed=args.seed, progress=not args.json and sys.stderr.isatty())
    path = write_report(data, args.out)
    if args.json:
        print(json.dumps(data.to_dict(), indent=1))
        return 0
    for rep in data.measurements:
        gn = rep.identification["gauss-newton"]
        found = findings_text(rep)
        comp = rep.compensation[0]
        print(f"{rep.path}: rank {gn.rank}/{len(gn.parameters)}, residual RMS {gn.rms_um:.3f} um; {found}; "
              f"RMSE {comp.rmse_before_um:.3f} -> {comp.rmse_after_um:.3f} um"
              f"{' (model-predicted)' if rep.compensation_basis == 'model' else ''}")
    print(f"wrote {path}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "report",
        help="write a self-contained HTML report of R-test files",
        description=(
            "Identify (Gauss-Newton and double-differential), diagnose and compensate each measurement and write\n"
            "DIR/report.html: one self-contained page (plots embedded as PNG, no external resources); the PNGs\n"
            "are kept in DIR/<file stem>/. A <stem>.truth.json beside a file (from pige simulate) is used as the\n"
            "machine of the before/after and compared with the estimates; without it the before/after is\n"
            "model-predicted."
        ),
        epilog=(
            "examples:\n"
            "  pige report run.csv --out report/\n"
            "  pige report ac.csv bc.csv --out report/ --study projection,sobol\n"
            "  pige report run.csv --out report/ --program rtest.mpf --method double-differential\n"
            "  pige report run.csv --out report/ --json > summary.json"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="pige-rtest 1 measurement file(s)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created)")
    p.add_argument("--study", metavar="LIST", help="also run studies on the measured trajectory: projection,sobol")
    p.add_argument("--program", metavar="NC-FILE", help="also compensate this 840D-style program (before/after)")
    p.add_argument("--method", choices=PRIMARY_METHODS, default="gauss-newton",
                   help="estimate used for the model overlay and the compensation; diagnosis = the PIGEs fitted "
                        "jointly with the accepted extensions (default %(default)s)")
    p.add_argument("--projection", default="xyz", help="projection of the identification tables (default xyz)")
    p.add_argument("--with-zero", action="store_true", help="also estimate the zero-position errors")
    p.add_argument("--presets", type=int, default=50, help="random presets of the projection study (default 50)")
    p.add_argument("--samples", type=int, default=2048, help="Sobol base sample size, a power of 2 (default 2048)")
    p.add_argument("--seed", type=int, default=0, help="seed of the studies")
    p.add_argument("--json", action="store_true", help="print one JSON object (the results and the report path)")
    p.set_defaults(handler=_run)
