"""``pige simulate``: write a synthetic R-test file and its truth sidecar."""

from __future__ import annotations

import argparse
import os

from pige_sym.cli._setup import (
    add_setup_arguments,
    finite_option,
    pige_values,
    setup_geometry,
    trajectory_options,
)
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text, check_output, to_json


def _run(args: argparse.Namespace) -> int:
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.rtest_writer import write_measurement
    from pige_sym.model.effects import parse_effect
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.simulation.simulator import simulate

    finite_option(args.noise, "--noise", minimum=0.0)
    kern = load_kernels(args.machine)
    traj = make_trajectory(kern.MACHINE_CODE, args.trajectory, **trajectory_options(args))
    ball, pivots, tool = setup_geometry(args)
    for axis in pivots:
        if axis not in kern.ROTARY_AXES:
            axes = ", ".join(kern.ROTARY_AXES)
            raise InputError(f"--pivot {axis}: not a rotary axis of {kern.MACHINE_CODE} ({axes})")
    pige = pige_values(args.pige, kern.MACHINE_CODE, args.seed)
    effects = [parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []]
    inputs = [x for x in (args.trajectory, args.pige) if os.path.isfile(x)]
    out = check_output(args.out, force=args.force, inputs=inputs, what="--out")
    truth_path = check_output(out.with_name(out.stem + ".truth.json"), force=args.force, inputs=inputs,
                              what="truth sidecar")
    result = simulate(
        kern.MACHINE_CODE, traj, pige=pige, ball_mm=ball, pivots_mm=pivots, tool_mm=tool, effects=effects,
        noise_um=args.noise, seed=args.seed, frame=args.frame,
    )
    csv = write_measurement(result.measurement, out)
    truth = atomic_write_text(truth_path, to_json(result.truth) + "\n")
    if args.json:
        print(to_json({"csv": str(csv), "truth_file": str(truth), "rows": result.measurement.n_rows,
                          "truth": result.truth}))
    else:
        print(f"wrote {csv} ({result.measurement.n_rows} rows) and {truth}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate an R-test measurement file",
        description="Simulate R-test data: machine, trajectory, PIGEs, effects and sensor noise.",
        epilog=(
            "examples:\n"
            "  pige simulate --machine \"wC'A'bXYZ(C1)t\" --trajectory cone-frustum --pige random \\\n"
            "      --seed 1 --out run.csv\n"
            "  pige simulate --machine \"wC'B'bXYZ(C1)t\" --trajectory figure-eight --pige EX0B=5,EA0C=-8 \\\n"
            "      --effect angular_error_C:harmonic=2,cos_urad=15 --noise 0.2 --out bc.csv"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_setup_arguments(p)
    p.add_argument("--pige", default="random", help="'random', NAME=VALUE,... [um|urad], or a JSON file")
    p.add_argument("--effect", action="append", metavar="NAME[:k=v,...]", help="add an unmodelled effect")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise sigma [um] (default %(default)s)")
    p.add_argument("--seed", type=int, default=None, help="random seed")
    p.add_argument("--frame", choices=["machine", "table"], default="machine", help="frame of the deviations")
    p.add_argument("--out", required=True, help="output CSV (a .truth.json sidecar is written beside it)")
    p.add_argument("--force", action="store_true", help="replace an existing output CSV and its sidecar")
    p.add_argument("--json", action="store_true", help="print the files written and the truth as one JSON object")
    p.set_defaults(handler=_run)
