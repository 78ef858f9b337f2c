"""``pige acquire``: measure every pose of an R-test program from a device into a ``pige-rtest 1`` file."""

from __future__ import annotations

import argparse
import os
import re
import signal
from typing import Any

from pige_sym.cli._setup import (
    add_setup_arguments,
    axis_sense_option,
    finite_option,
    setup_geometry,
    show_progress,
    trajectory_options,
)
from pige_sym.constants import DEFAULT_DWELL_S, DEFAULT_MOVE_S, DEVICE_PROTOCOLS, TRIGGERS
from pige_sym.errors import InputError
from pige_sym.files import to_json


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt  # SIGTERM ends the run like Ctrl-C: summary written, partial file valid


_SIZE = re.compile(r"([0-9]{1,15})([kKmMgG]?)[bB]?")


def parse_size(text: str) -> int:
    """``500M``, ``2G``, ``65536`` → bytes (k, M, G are powers of 1024)."""
    m = _SIZE.fullmatch(text.strip())
    if not m:
        raise InputError(f"--max-raw-log: expected a size like 65536, 500M or 2G, got {text!r}")
    return int(m.group(1)) * 1024 ** " kmg".index(m.group(2).lower() or " ")


def _run(args: argparse.Namespace) -> int:
    from pige_sym.acquisition.device import make_adapter
    from pige_sym.acquisition.engine import acquire
    from pige_sym.acquisition.nest import parse_nest
    from pige_sym.acquisition.options import AcquisitionOptions
    from pige_sym.acquisition.outputs import summary_path
    from pige_sym.acquisition.transport import PortSettings
    from pige_sym.kernels import load_kernels
    from pige_sym.nc.rtest_program import load_test_program

    signal.signal(signal.SIGTERM, _interrupt)
    kern = load_kernels(args.machine)
    ball, pivots, tool = setup_geometry(args)
    program = load_test_program(kern.MACHINE_CODE, args.trajectory, ball_mm=ball, pivots_mm=pivots, tool_mm=tool,
                                move_s=finite_option(args.move, "--move", minimum=0.0),
                                dwell_s=finite_option(args.dwell, "--dwell", positive=True),
                                axis_sense=axis_sense_option(args, tuple(kern.ROTARY_AXES)), **trajectory_options(args))
    settings = PortSettings(baudrate=args.baud, bytesize=args.bytesize, parity=args.parity, stopbits=args.stopbits,
                            timeout_s=args.timeout)
    options = AcquisitionOptions(
        trigger=args.trigger, window_s=args.window, settle_s=args.settle, tolerance_um=args.tolerance,
        delay_s=args.delay, min_samples=args.min_samples, max_gap_s=args.max_gap,
        reconnect_timeout_s=args.reconnect_timeout, frame=args.frame, replay_tol_um=args.replay_tol,
        timing_check=not args.no_timing_check, max_reconnects=args.max_reconnects,
        max_bytes=parse_size(args.max_raw_log) if args.max_raw_log else None,
    )
    inputs = [x for x in (args.trajectory, args.nest) if os.path.isfile(x)]
    summary = acquire(
        args.port, program, args.out, options=options, settings=settings, nest=parse_nest(args.nest),
        adapter=make_adapter(args.protocol), resume=args.resume, force=args.force, inputs=inputs,
        raw_log=args.raw_log if args.raw_log else (None if args.no_raw_log else True),
        progress=show_progress(args.no_progress, args.json),
    )
    if args.json:
        print(to_json({**summary.to_dict(), "summary_file": str(summary_path(args.out))}))
    else:
        print(summary.format())
        print(f"summary: {summary_path(args.out)}")
    return 0 if summary.completed else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    from pige_sym.acquisition.transport import PARITIES, STOPBITS

    p = subparsers.add_parser(
        "acquire",
        help="acquire an R-test measurement from a device over a serial port",
        description=(
            "Read a three-sensor R-test nest over a serial port (any pyserial URL), wait for each pose of the "
            "program to settle, average over the dwell window and write a pige-rtest 1 file row by row.  The raw "
            "byte stream goes to a log first; bad records are counted and skipped; the link is reopened after a "
            "timeout or disconnect.  Exit status 1 when the run stopped before the last pose (the file is valid: "
            "continue with --resume)."
        ),
        epilog=(
            "examples:\n"
            "  pige acquire --port /dev/ttyUSB0 --program cone-frustum --machine \"wC'A'bXYZ(C1)t\" \\\n"
            "      --ball 120,0,80 --out run.csv\n"
            "  pige acquire --port socket://127.0.0.1:5555 --program rtest.mpf --out run.csv --resume\n"
            "  pige acquire --port /dev/pts/3 --program cone-frustum --trigger key --out run.csv"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", required=True, help="device path or URL: /dev/ttyUSB0, socket://host:port, rfc2217://...")
    add_setup_arguments(p, program_flag="--program", program_help="cone-frustum, figure-eight, steps, an angle CSV, "
                        "or an NC program (G4 F<s> / M00 per pose)")
    p.add_argument("--out", required=True, help="measurement file (pige-rtest 1), written row by row")
    p.add_argument("--resume", action="store_true", help="continue a partial --out file (run the program again)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --out (and its raw log and summary) with a new run")
    p.add_argument("--raw-log", help="raw byte log (default: <out stem>.raw.log)")
    p.add_argument("--no-raw-log", action="store_true", help="do not keep the raw byte log")
    p.add_argument("--max-raw-log", metavar="SIZE",
                   help="stop after reading this many bytes (e.g. 200M; default sized for the program: "
                        "16 MiB + 128 kB per program second)")
    p.add_argument("--frame", choices=["machine", "table"], default="machine", help="frame of the deviations")
    p.add_argument("--nest", default="default", help="nest geometry: default, key=value,... or a JSON file")
    p.add_argument("--protocol", choices=DEVICE_PROTOCOLS, default="rtest", help="device protocol")
    g = p.add_argument_group("port settings")
    g.add_argument("--baud", type=int, default=115200, help="baud rate (default %(default)s)")
    g.add_argument("--bytesize", type=int, default=8, choices=[5, 6, 7, 8])
    g.add_argument("--parity", default="N", choices=sorted(PARITIES))
    g.add_argument("--stopbits", default="1", choices=sorted(STOPBITS))
    g.add_argument("--timeout", type=float, default=1.0, help="stall timeout: no byte for this long [s]")
    g.add_argument("--reconnect-timeout", type=float, default=30.0,
                   help="stop (exit 1, summary) after this long without a valid record [s]")
    g.add_argument("--max-reconnects", type=int, default=20,
                   help="stop after this many reconnections in a row without a valid record")
    a = p.add_argument_group("points")
    a.add_argument("--trigger", choices=TRIGGERS, default="stable",
                   help="stable: settle detection; schedule: program times; key: Enter per pose")
    a.add_argument("--window", type=float, default=5.0, help="averaging window per pose [s] (default %(default)s)")
    a.add_argument("--settle", type=float, default=0.5, help="stability test length [s] (default %(default)s)")
    a.add_argument("--tolerance", type=float, default=2.0, help="settled band / motion threshold [um]")
    a.add_argument("--delay", type=float, default=1.0, help="schedule trigger: wait after arrival [s]")
    a.add_argument("--min-samples", type=int, default=20, help="fewer valid samples flag the pose (no row)")
    a.add_argument("--max-gap", type=float, default=1.0, help="a longer data gap ends a window [s of device time]")
    a.add_argument("--move", type=float, default=DEFAULT_MOVE_S, help="program move time between poses [s]")
    a.add_argument("--dwell", type=float, default=DEFAULT_DWELL_S, help="program dwell per pose [s]")
    a.add_argument("--no-timing-check", action="store_true",
                   help="stable trigger: do not cross-check settles with the program timing (operator-paced runs)")
    a.add_argument("--replay-tol", type=float, default=1.0, help="resume: allowed difference of a replayed pose [um]")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object (no progress bars)")
    p.set_defaults(handler=_run)
