"""``pige compensate``: corrected NC programs and controller corrections; ``pige study compensation``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from pige_sym.compensation import (
    compensate_program,
    compensation_study,
    controller_corrections,
    format_controller,
    load_parameters,
    plot_compensation,
    read_program,
)
from pige_sym.errors import InputError
from pige_sym.identification import identify
from pige_sym.kernels import DEFAULT_MACHINE, load_kernels
from pige_sym.simulator import random_pige, simulate
from pige_sym.trajectories import cone_frustum, figure_eight


def _run(args: argparse.Namespace) -> int:
    params = load_parameters(args.params, args.machine, allow_unidentifiable=args.allow_unidentifiable)
    if args.controller and not args.json:
        print(format_controller(params, args.controller))
    if args.controller and not args.program:
        if args.json:
            print(json.dumps({"machine": params.machine, "parameters_from": params.source,
                              "axes": controller_corrections(params)}, indent=1))
        return 0
    if not args.program:
        raise InputError("give a PROGRAM to compensate (or --controller to print the corrected kinematics)")
    if not args.out:
        raise InputError("give --out NEW_PROGRAM")
    text = compensate_program(read_program(args.program), params, path=args.program, dialect=args.dialect,
                              pass_through=args.pass_through)
    with open(args.out, "w", encoding="utf-8", newline="") as fh:
        fh.write(text)
    if args.json:
        print(json.dumps({"program": args.program, "out": args.out, "dialect": args.dialect,
                          "machine": params.machine, "parameters_from": params.source, "pige": params.values,
                          "extensions": [{"effect": e.spec.id, "options": e.spec.options, "params": e.params}
                                         for e in params.extensions],
                          "not_compensated": params.ignored}, indent=1))
        return 0
    print(f"wrote {args.out} ({args.dialect}); parameters from {params.source}")
    for ext in params.extensions:
        print(f"compensated extension: {ext.spec.id} " + ", ".join(f"{k}={v:.4g}" for k, v in ext.params.items()))
    if params.ignored:
        print("not compensated: " + ", ".join(params.ignored))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "compensate",
        help="write a compensated NC program / print controller corrections",
        description="Rewrite an 840D-style program so the tool lands where the nominal program intended.",
        epilog=(
            "examples:\n"
            "  pige identify run.csv --json > result.json\n"
            "  pige compensate rtest.mpf --params result.json --out rtest_comp.mpf\n"
            "  pige compensate rtest.mpf --params result.json --dialect fanuc --out rtest_comp.nc\n"
            "  pige compensate --params result.json --controller siemens"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("program", nargs="?", help="Siemens 840D-style program (TRAORI or TRAFOOF)")
    p.add_argument("--params", required=True, help="JSON printed by pige identify --json or pige diagnose --json")
    p.add_argument("--machine", help="machine code (default: from the JSON)")
    p.add_argument("--out", help="compensated program to write")
    p.add_argument("--dialect", choices=["siemens", "fanuc"], default="siemens")
    p.add_argument("--pass-through", action="store_true", help="keep unsupported blocks verbatim (uncompensated)")
    p.add_argument("--allow-unidentifiable", action="store_true", help="use 0 for parameters without a value")
    p.add_argument("--controller", choices=["table", "siemens"], help="print the corrected kinematic chain")
    p.add_argument("--json", action="store_true", help="print what was compensated as one JSON object")
    p.set_defaults(handler=_run)


def _study(args: argparse.Namespace) -> int:
    kern = load_kernels(args.machine)
    code = kern.MACHINE_CODE
    incl = "X" if kern.ROTARY_AXES[0] == "A" else "Y"
    trajs = [cone_frustum(code, incl_axis=incl), figure_eight(code)]
    truth = random_pige(code, args.seed)
    sim = simulate(code, trajs[0], pige=truth, noise_um=args.noise, seed=args.seed)
    res = identify(sim.measurement)
    ident = {p: v for p, v in zip(res.parameters, res.values, strict=True)}
    rows = compensation_study(code, trajs, truth=truth, identified=ident, covariance=res.covariance)
    paths = plot_compensation(rows, args.plots) if args.plots else []
    if args.json:
        print(json.dumps({"machine": code, "truth": truth, "identified": ident, "rows": [r.to_dict() for r in rows],
                          "plots": paths}, indent=1))
        return 0
    print(f"compensation study on {code}: PIGEs identified from a simulated cone test (noise {args.noise} um)")
    for r in rows:
        print(f"  {r.trajectory}: RMSE {r.rmse_before_um:.3f} -> {r.rmse_after_um:.3f} um "
              f"({r.reduction:.1%} reduction; {r.predicted_after_um:.3f} um expected from the std); "
              f"commands moved by {r.command_change_rmse_mm * 1e3:.2f} um RMS")
    for pth in paths:
        print(f"  plot: {Path(pth)}")
    return 0


def register_study_compensation(sub: argparse._SubParsersAction) -> None:
    """Add ``pige study compensation`` to the study subcommands."""
    p = sub.add_parser("compensation", help="before/after compensation on a simulated machine",
                       epilog="example:\n  pige study compensation --seed 3 --plots plots/",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the true errors and the noise (default %(default)s)")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise sigma [um] (default %(default)s)")
    p.add_argument("--plots", metavar="DIR", help="write before/after plots (PNG) into DIR")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_study)
