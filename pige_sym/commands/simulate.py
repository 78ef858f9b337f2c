"""``pige simulate``: write a synthetic R-test file and its truth sidecar."""

from __future__ import annotations

import argparse
import json

from ..effects import parse_effect
from ..errors import InputError
from ..kernels import DEFAULT_MACHINE, load_kernels
from ..simulator import parse_pige, simulate
from ..trajectories import make_trajectory


def parse_vec3(text: str, what: str) -> list[float]:
    """Three comma-separated numbers, or a clear InputError."""
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"{what}: expected x,y,z numbers, got {text!r}") from None
    if len(vals) != 3:
        raise InputError(f"{what}: expected 3 numbers x,y,z, got {len(vals)}")
    return vals


def parse_pivots(items: list[str] | None) -> dict[str, list[float]]:
    out = {}
    for item in items or []:
        axis, eq, vec = item.partition("=")
        if not eq:
            raise InputError(f"--pivot: expected AXIS=x,y,z, got {item!r}")
        out[axis.strip()] = parse_vec3(vec, f"--pivot {axis.strip()}")
    return out


def _run(args: argparse.Namespace) -> int:
    kern = load_kernels(args.machine)
    options: dict[str, float | int | str] = {}
    if args.points is not None:
        options["points"] = args.points
    if args.turns is not None and args.trajectory == "cone-frustum":
        options["turns"] = args.turns
    if args.incl_axis is not None and args.trajectory == "cone-frustum":
        options["incl_axis"] = args.incl_axis
    traj = make_trajectory(kern.MACHINE_CODE, args.trajectory, **options)
    pivots = parse_pivots(args.pivot)
    for axis in pivots:
        if axis not in kern.ROTARY_AXES:
            axes = ", ".join(kern.ROTARY_AXES)
            raise InputError(f"--pivot {axis}: not a rotary axis of {kern.MACHINE_CODE} ({axes})")
    pige = parse_pige(args.pige, kern.MACHINE_CODE, args.seed)
    effects = [parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []]
    result = simulate(
        kern.MACHINE_CODE, traj, pige=pige, ball_mm=parse_vec3(args.ball, "--ball"), pivots_mm=pivots,
        tool_mm=parse_vec3(args.tool, "--tool") if args.tool else None, effects=effects, noise_um=args.noise,
        seed=args.seed, frame=args.frame,
    )
    csv, truth = result.write(args.out)
    if args.json:
        print(json.dumps({"csv": str(csv), "truth_file": str(truth), "rows": result.measurement.n_rows,
                          "truth": result.truth}, indent=1))
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
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--trajectory", default="cone-frustum",
                   help="cone-frustum, figure-eight, steps, or a CSV of <axis>_deg angles")
    p.add_argument("--ball", default="120,0,80", help="ball centre at the reference pose x,y,z [mm]")
    p.add_argument("--pivot", action="append", metavar="AXIS=x,y,z", help="nominal pivot of a rotary axis [mm]")
    p.add_argument("--tool", help="ball offset from the last tool-side pivot x,y,z [mm] (head machines)")
    p.add_argument("--pige", default="random", help="'random', NAME=VALUE,... [um|urad], or a JSON file")
    p.add_argument("--effect", action="append", metavar="NAME[:k=v,...]", help="add an unmodelled effect")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise sigma [um] (default %(default)s)")
    p.add_argument("--seed", type=int, default=None, help="random seed")
    p.add_argument("--points", type=int, help="points per turn (cone, figure-eight)")
    p.add_argument("--turns", type=float, help="turns of the cone")
    p.add_argument("--incl-axis", choices=["X", "Y", "x", "y"], help="cone inclination axis")
    p.add_argument("--frame", choices=["machine", "table"], default="machine", help="frame of the deviations")
    p.add_argument("--out", required=True, help="output CSV (a .truth.json sidecar is written beside it)")
    p.add_argument("--json", action="store_true", help="print the files written and the truth as one JSON object")
    p.set_defaults(handler=_run)
