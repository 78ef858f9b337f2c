"""``pige rtest-sim``: a virtual R-test device on a pseudo-terminal or a TCP socket."""

from __future__ import annotations

import argparse
import secrets
import signal
import sys
from typing import Any

from ..effects import parse_effect
from ..kernels import DEFAULT_MACHINE, load_kernels
from ..nest import parse_nest
from ..rtest_program import DEFAULT_DWELL_S, DEFAULT_MOVE_S, load_test_program
from ..simulator import parse_pige
from ..virtual_device import FAULT_KINDS, DeviceConfig, parse_faults, run_device
from .simulate import parse_pivots, parse_vec3


def trajectory_options(args: argparse.Namespace) -> dict[str, Any]:
    """Trajectory options shared by ``rtest-sim`` and ``acquire`` (only those given)."""
    out: dict[str, Any] = {}
    if args.points is not None:
        out["points"] = args.points
    if args.turns is not None and args.trajectory == "cone-frustum":
        out["turns"] = args.turns
    return out


def _terminate(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _run(args: argparse.Namespace) -> int:
    kern = load_kernels(args.machine)
    program = load_test_program(
        kern.MACHINE_CODE, args.trajectory, ball_mm=parse_vec3(args.ball, "--ball"), pivots_mm=parse_pivots(args.pivot),
        tool_mm=parse_vec3(args.tool, "--tool") if args.tool else None, move_s=args.move, dwell_s=args.dwell,
        **trajectory_options(args),
    )
    seed = args.seed if args.seed is not None else secrets.randbits(31)
    cfg = DeviceConfig(
        program=program, pige=parse_pige(args.pige, kern.MACHINE_CODE, seed),
        effects=[parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []], seed=seed,
        noise_um=args.noise, repeatability_um=args.repeatability, rate_hz=args.rate, time_scale=args.time_scale,
        nest=parse_nest(args.nest), faults=parse_faults(args.faults), stall_s=args.stall_s, outage_s=args.outage_s,
        linger_s=args.linger,
    )
    signal.signal(signal.SIGTERM, _terminate)
    truth = run_device(cfg, tcp_port=args.tcp, truth_path=args.truth, announce=lambda url: print(url, flush=True),
                       connect_timeout_s=args.connect_timeout)
    inj = truth["injected"]
    faults = ", ".join(f"{k} {inj[k]}" for k in FAULT_KINDS if inj[k])
    print(f"rtest-sim: {'program finished' if truth['finished'] else truth.get('stop_reason', 'stopped')}: "
          f"{truth['sent']} records sent, {truth['unsent']} unsent"
          + (f"; injected {faults}" if faults else ""), file=sys.stderr)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "rtest-sim",
        help="run a virtual R-test device on a pseudo-terminal or TCP socket",
        description=(
            "Simulate a machine with chosen errors running an R-test program and stream the rtest device "
            "protocol (pige_sym.device) on a pseudo-terminal or a TCP socket.  The first line printed is the "
            "port to open; the device exits when the program ends.  See pige_sym/virtual_device.py for the "
            "machine, noise and fault models."
        ),
        epilog=(
            "examples:\n"
            "  pige rtest-sim --machine \"wC'A'bXYZ(C1)t\" --trajectory cone-frustum --pige random --seed 1\n"
            "  pige rtest-sim --trajectory cone-frustum --seed 1 --time-scale 50 --faults garbage,drop=5 \\\n"
            "      --truth dev.truth.json --tcp 5555\n"
            "  # in another terminal: pige acquire --port /dev/pts/N --program cone-frustum --out run.csv"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--trajectory", default="cone-frustum",
                   help="cone-frustum, figure-eight, steps, an angle CSV or an NC program file")
    p.add_argument("--ball", default="120,0,80", help="ball centre at the reference pose x,y,z [mm]")
    p.add_argument("--pivot", action="append", metavar="AXIS=x,y,z", help="nominal pivot of a rotary axis [mm]")
    p.add_argument("--tool", help="ball offset from the last tool-side pivot x,y,z [mm] (head machines)")
    p.add_argument("--pige", default="random", help="'random', NAME=VALUE,... [um|urad], or a JSON file")
    p.add_argument("--effect", action="append", metavar="NAME[:k=v,...]", help="add an unmodelled effect")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: random, written to the truth)")
    p.add_argument("--faults", metavar="KIND[=N],...",
                   help=f"inject faults: {', '.join(FAULT_KINDS)} (N of each, default 3)")
    p.add_argument("--truth", help="write the truth (PIGEs, faults injected) to this JSON file")
    p.add_argument("--tcp", type=int, metavar="PORT", help="listen on 127.0.0.1:PORT (0: any) instead of a pty")
    p.add_argument("--points", type=int, help="points per turn (cone, figure-eight)")
    p.add_argument("--turns", type=float, help="turns of the cone")
    p.add_argument("--nest", default="default", help="nest geometry: default, key=value,... or a JSON file")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise per sample [um] (default %(default)s)")
    p.add_argument("--repeatability", type=float, default=0.2,
                   help="positioning scatter per pose [um] (default %(default)s)")
    p.add_argument("--rate", type=float, default=20.0, help="samples per second of device time (default %(default)s)")
    p.add_argument("--time-scale", type=float, default=1.0,
                   help="device seconds per wall second (default %(default)s: real time)")
    p.add_argument("--move", type=float, default=DEFAULT_MOVE_S, help="move time between poses [s]")
    p.add_argument("--dwell", type=float, default=DEFAULT_DWELL_S,
                   help="dwell per pose [s] (NC programs: their G4 F values)")
    p.add_argument("--stall-s", type=float, default=2.0, help="length of an injected stall [wall s]")
    p.add_argument("--outage-s", type=float, default=0.5, help="device time lost by an injected disconnect [s]")
    p.add_argument("--linger", type=float, default=2.0, help="wait for a client that left [wall s]")
    p.add_argument("--connect-timeout", type=float, default=300.0, help="wait for the first client [wall s]")
    p.set_defaults(handler=_run)
