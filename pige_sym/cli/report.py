"""``pige report``: a self-contained HTML calibration report of R-test, probe and ballbar files."""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.cli._setup import show_progress
from pige_sym.files import to_json

#: estimates a report can compensate with (pige_sym.report.PRIMARY_METHODS, kept here so --help stays light)
METHODS = ("diagnosis", "gauss-newton", "double-differential")


def _graded_plan(args: argparse.Namespace, data: Any) -> Any:
    """The predicted figures of ``--plan`` (angle file or NC program) for the first measurement's set-up."""
    import numpy as np

    from pige_sym.constants import DEFAULT_BALL_MM, DEFAULT_MACHINE
    from pige_sym.nc.rtest_program import load_test_program
    from pige_sym.planning import Setup, grade_test

    if data.measurements:
        m = data.measurements[0].measurement
        setup = Setup(m.machine, np.asarray(m.ball_mm, dtype=float), m.tool_mm, m.pivots_mm or None,
                      noise_um=args.plan_noise)
    else:
        setup = Setup(DEFAULT_MACHINE, np.asarray(DEFAULT_BALL_MM, dtype=float), None, None, noise_um=args.plan_noise)
    prog = load_test_program(setup.machine, args.plan, ball_mm=setup.ball_mm, pivots_mm=setup.pivots_mm,
                             tool_mm=setup.tool_mm)
    return grade_test(setup, prog.angles_deg, prog.arrive_s, description=prog.description,
                      duration_s=prog.duration_s)


def _map_spec(args: argparse.Namespace) -> Any:
    """``--map AXES [--map-step DEG] [--map-per-direction AXES]`` as a MapSpec (None without --map)."""
    from pige_sym.cli._maps import map_spec_option
    from pige_sym.identification.maps import DEFAULT_MAP_STEP_DEG

    return map_spec_option(args, DEFAULT_MAP_STEP_DEG)


def _run(args: argparse.Namespace) -> int:
    from pige_sym.files import check_output_folder
    from pige_sym.report import findings_text, gather_report, write_report

    inputs = [*args.files, *(args.compare or []), *(x for x in (args.program, args.tolerances, args.plan) if x)]
    check_output_folder(args.out, force=args.force, inputs=inputs, names=("report.html",))  # before the long work
    data = gather_report(args.files, studies=args.study or "", program=args.program, method=args.method,
                         projection=args.projection, with_zero=args.with_zero, presets=args.presets,
                         sobol_samples=args.samples, seed=args.seed, progress=show_progress(args.json),
                         tolerances=args.tolerances, rule=args.rule, k=args.k,
                         compare=tuple(args.compare) if args.compare else None, history=args.history, db=args.db,
                         joint=args.joint, maps=_map_spec(args))
    if args.plan:
        data.plan = _graded_plan(args, data)
    path = write_report(data, args.out, force=args.force, inputs=inputs, figures=not args.no_figures)
    if args.json:
        print(to_json(data.to_dict()))
        return 0
    for jr in data.joints:
        d = jr.diagnosis
        agree = ("agreement not testable" if d.agreement is None else
                 f"{'files DISAGREE' if d.agreement_status == 'disagree' else 'files agree'} "
                 f"(p = {d.agreement.p_value:.2g})")
        verdict = f"verdict {jr.check.verdict}; " if jr.check is not None else ""
        print(f"joint ({len(jr.paths)} files of {jr.machine}): {verdict}{agree}; rank {d.final.rank}/"
              f"{len(d.final.parameters)}, residual RMS {d.final.rms_um:.3f} um")
    for rep in data.measurements:
        gn = rep.identification["gauss-newton"]
        found = findings_text(rep)
        comp = rep.compensation[0]
        verdict = f"verdict {rep.check.verdict}; " if rep.check is not None else ""
        if rep.compensation_basis == "model":
            before_after = f"RMSE {comp.rmse_before_um:.3f} um (model-predicted; measure after compensating)"
        else:
            before_after = f"RMSE {comp.rmse_before_um:.3f} -> {comp.rmse_after_um:.3f} um (simulated on the truth)"
        print(f"{rep.path}: {verdict}rank {gn.rank}/{len(gn.parameters)}, residual RMS {gn.rms_um:.3f} um; "
              f"{found}; {before_after}")
    if data.comparison is not None:
        c = data.comparison
        print(f"measured before/after: RMS {c.rms_before_um:.3f} -> {c.rms_after_um:.3f} um ({c.improvement:.1%} less)")
    if data.history is not None:
        n_sig = sum(ch.significant is True for comp in data.history.comparisons for ch in comp.changes)
        changes = "change" if n_sig == 1 else "changes"
        print(f"history of {data.history.machine_id}: {len(data.history.runs)} runs, {n_sig} significant {changes}")
    print(f"wrote {path}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "report",
        help="write a self-contained HTML report of R-test, probe and ballbar files",
        description=(
            "Identify (Gauss-Newton and double-differential), diagnose and compensate each measurement and write\n"
            "DIR/report.html: one self-contained page (plots embedded as PNG, no external resources); the PNGs\n"
            "are also kept in DIR/<file stem>/ (not with --no-figures). A <stem>.truth.json beside a file (from\n"
            "pige simulate) is used as the machine of the before/after and compared with the estimates; without\n"
            "it the before/after is model-predicted. The page leads with the answer: machine, date, verdict\n"
            "(--tolerances), the PIGEs used for compensation, the main finding and the improvement (measured\n"
            "with --compare).\n"
            "Ballbar setups (with --joint: also two R-test/probe files or more of one machine) get a joint\n"
            "section: one set of PIGEs for all files (as pige identify F1 F2 ...), whether the files agree\n"
            "(as pige diagnose F1 F2 ...) and, with --tolerances, the verdict of the joint estimate."
        ),
        epilog=(
            "examples:\n"
            "  pige report run.csv --out report/\n"
            "  pige report ac.csv bc.csv --out report/ --study projection,sobol\n"
            "  pige report radial_C.csv tangential_C.csv axial_A.csv --out report/ --tolerances tol.json\n"
            "  pige report run.csv --out report/ --program rtest.mpf --method double-differential\n"
            "  pige report run.csv --out report/ --json > summary.json\n"
            "  pige report after.csv --out report/ --tolerances tol.json --compare before.csv after.csv\n"
            "  pige report --history DMU50-2 --tolerances tol.json --out report/"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="pige-rtest 1 (R-test, probe) or pige-ballbar 1 file(s) (optional with --compare or --history)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created)")
    p.add_argument("--force", action="store_true",
                   help="replace the report already in --out (report.html and its folders; nothing else is touched)")
    p.add_argument("--study", metavar="LIST", help="also run studies on the measured trajectory: projection,sobol")
    p.add_argument("--program", metavar="NC-FILE", help="also compensate this 840D-style program (before/after)")
    p.add_argument("--tolerances", metavar="TOL.json", help="judge every measurement (pige check) and lead with it")
    p.add_argument("--rule", choices=("guard", "simple"), default="guard", help="decision rule (default %(default)s)")
    p.add_argument("--k", type=float, default=2.0, help="coverage factor of the guard band (default %(default)s)")
    p.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"),
                   help="two measurements of the same program: the measured before/after section")
    p.add_argument("--joint", action="store_true",
                   help="also identify two or more R-test/probe files of one machine jointly (ballbar files always "
                        "are): one set of PIGEs, whether the files agree")
    p.add_argument("--map", metavar="AXES", help="also fit the error maps of these rotary axes jointly from every file "
                   "(conventions §10): plots, what they leave, what the setups do not determine (docs/maps.md)")
    p.add_argument("--map-step", type=float, metavar="DEG", help="grid step of the maps [deg] (default 15)")
    p.add_argument("--map-per-direction", metavar="AXES",
                   help="map these axes' positioning error per approach direction, as pige identify does")
    p.add_argument("--history", metavar="ID", help="machine id: trend plots of its runs (pige history)")
    p.add_argument("--db", metavar="URL", help="history database (default: as pige history)")
    p.add_argument("--plan", metavar="TRAJECTORY",
                   help="grade a test (pige plan's angle file, an NC program, or cone-frustum/figure-eight/steps) "
                        "for the first file's set-up: predicted std per PIGE against the default cone")
    p.add_argument("--plan-noise", type=float, default=0.25, help="sensor noise for --plan [um] (default 0.25)")
    p.add_argument("--method", choices=METHODS, default="diagnosis",
                   help="estimate used for the model overlay and the compensation; diagnosis = the PIGEs fitted "
                        "jointly with the accepted extensions (default %(default)s)")
    p.add_argument("--projection", default="xyz", help="projection of the identification tables (default xyz)")
    p.add_argument("--with-zero", action="store_true", help="also estimate the zero-position errors")
    p.add_argument("--presets", type=int, default=50, help="random presets of the projection study (default 50)")
    p.add_argument("--samples", type=int, default=None,
                   help="Sobol indices estimated by Monte-Carlo on this base sample size (a power of 2) instead of "
                        "the exact closed form (default: exact)")
    p.add_argument("--seed", type=int, default=0, help="seed of the studies")
    p.add_argument("--no-figures", action="store_true",
                   help="write the page only: its figures are embedded in it, no PNG files beside it")
    p.add_argument("--json", action="store_true", help="print one JSON object (the results and the report path)")
    p.set_defaults(handler=_run)
