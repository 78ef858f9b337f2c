"""``pige rtest-sim``: a virtual R-test device on a pseudo-terminal or a TCP socket."""

from __future__ import annotations

import argparse
import os
import secrets
import signal
import sys
from typing import Any

from pige_sym.cli._setup import (
    add_setup_arguments,
    axis_sense_option,
    finite_option,
    pige_values,
    setup_geometry,
    trajectory_options,
)
from pige_sym.constants import DEFAULT_DWELL_S, DEFAULT_MOVE_S, FAULT_KINDS
from pige_sym.files import check_output


def _terminate(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _run(args: argparse.Namespace) -> int:
    from pige_sym.acquisition.nest import parse_nest
    from pige_sym.acquisition.virtual_device import DeviceConfig, parse_faults
    from pige_sym.acquisition.virtual_run import run_device
    from pige_sym.kernels import load_kernels
    from pige_sym.model.effects import parse_effect
    from pige_sym.nc.rtest_program import load_test_program

    if args.truth:
        inputs = [x for x in (args.trajectory, args.pige, args.nest) if os.path.isfile(x)]
        check_output(args.truth, force=args.force, inputs=inputs, what="--truth")
    kern = load_kernels(args.machine)
    ball, pivots, tool = setup_geometry(args)
    program = load_test_program(kern.MACHINE_CODE, args.trajectory, ball_mm=ball, pivots_mm=pivots, tool_mm=tool,
                                move_s=finite_option(args.move, "--move", minimum=0.0),
                                dwell_s=finite_option(args.dwell, "--dwell", positive=True),
                                axis_sense=axis_sense_option(args, tuple(kern.ROTARY_AXES)), **trajectory_options(args))
    seed = args.seed if args.seed is not None else secrets.randbits(31)
    cfg = DeviceConfig(
        program=program, pige=pige_values(args.pige, kern.MACHINE_CODE, seed),
        effects=[parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []], seed=seed,
        noise_um=args.noise, repeatability_um=args.repeatability, rate_hz=args.rate, time_scale=args.time_scale,
        nest=parse_nest(args.nest), faults=parse_faults(args.faults), stall_s=args.stall_s, outage_s=args.outage_s,
        linger_s=args.linger,
    )
    signal.signal(signal.SIGTERM, _terminate)
    truth = run_device(cfg, tcp_port=args.tcp, truth_path=args.truth, announce=lambda url: print(url, flush=True),
                       connect_timeout_s=args.connect_timeout, await_hello=args.await_hello)
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
            "Simulate a machine with chosen errors running an R-test program and stream the rtest "
            "device protocol (pige_sym.acquisition.device) on a pseudo-terminal or a TCP socket.  "
            "The first line printed is the port to open; the device exits when the program ends.  "
            "See pige_sym/acquisition/virtual_device.py for the machine, noise and fault models."
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
    add_setup_arguments(p, program_help="cone-frustum, figure-eight, steps, an angle CSV or an NC program file")
    p.add_argument("--pige", default="random", help="'random', NAME=VALUE,... [um|urad], or a JSON file")
    p.add_argument("--effect", action="append", metavar="NAME[:k=v,...]", help="add an unmodelled effect")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: random, written to the truth)")
    p.add_argument("--faults", metavar="KIND[=N],...",
                   help=f"inject faults: {', '.join(FAULT_KINDS)} (N of each, default 3)")
    p.add_argument("--truth", help="write the truth (PIGEs, faults injected) to this JSON file")
    p.add_argument("--force", action="store_true", help="replace an existing --truth file")
    p.add_argument("--tcp", type=int, metavar="PORT", help="listen on 127.0.0.1:PORT (0: any) instead of a pty")
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
    p.add_argument("--await-hello", action="store_true",
                   help="send nothing on a connection until the client has sent a byte (a client that says it has "
                        "opened the port; pyserial discards what arrives while it opens)")
    p.set_defaults(handler=_run)
