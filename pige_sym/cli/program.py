"""``pige program``: write the R-test NC program of a test trajectory (to run on the machine).

One positioning block per pose followed by a dwell, written natively in the chosen
dialect (Siemens 840D, ISO/Fanuc/Haas with decimal points and ``G04 X``, or LinuxCNC with
``G4 P``; :func:`pige_sym.nc.program.make_rtest_program`).  In machine coordinates
(``TRAFOOF``, default) X/Y/Z are the RTCP commands of the nominal kinematics for the
ball at ``--ball`` (honouring ``--pivot``/``--tool``); with ``--rtcp`` (``TRAORI``)
they are the workpiece coordinates of the ball and the controller's RTCP moves the
linear axes.  The same file is what ``pige acquire --program`` and ``pige rtest-sim
--trajectory`` read, and what ``pige compensate`` rewrites.
"""

from __future__ import annotations

import argparse

from pige_sym.cli._setup import add_setup_arguments, setup_geometry, trajectory_options
from pige_sym.constants import DEFAULT_DWELL_S
from pige_sym.files import atomic_write_text, check_output


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from pige_sym.kernels import load_kernels
    from pige_sym.nc.program import make_rtest_program
    from pige_sym.nc.rtest_program import load_test_program

    out = check_output(args.out, force=args.force, what="--out")
    kern = load_kernels(args.machine)
    ball, pivots, tool = setup_geometry(args)
    program = load_test_program(kern.MACHINE_CODE, args.trajectory, ball_mm=ball, pivots_mm=pivots, tool_mm=tool,
                                dwell_s=args.dwell, **trajectory_options(args))
    if args.rtcp:
        xyz = np.tile(program.ball_mm, (program.n_poses, 1))
    else:
        xyz = program.linear_mm()
    text = make_rtest_program(program.angles_deg, xyz, tuple(kern.ROTARY_AXES), rtcp=args.rtcp, dwell_s=args.dwell,
                              feed=args.feed, title=f"R-test {program.description}, {kern.MACHINE_CODE}, "
                              f"ball {', '.join(f'{x:g}' for x in program.ball_mm)} mm", dialect=args.dialect)
    atomic_write_text(out, text)
    print(f"wrote {out}: {program.n_poses} poses ({program.description}), {'TRAORI' if args.rtcp else 'TRAFOOF'}, "
          f"{args.dwell:g} s dwell per pose, {args.dialect}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "program",
        help="write the R-test NC program of a test trajectory",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        epilog=(
            "examples:\n"
            "  pige program --machine \"wC'A'bXYZ(C1)t\" --trajectory cone-frustum --ball 120,0,80 --out rtest.mpf\n"
            "  pige program --machine \"wC'B'bXYZ(C1)t\" --trajectory figure-eight --rtcp --out fig8.mpf\n"
            "  pige program --trajectory steps --dialect fanuc --out steps.nc"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_setup_arguments(p)
    p.add_argument("--dwell", type=float, default=DEFAULT_DWELL_S,
                   help="dwell per pose [s] (default %(default)s: ~1 s to settle, then a 5 s average)")
    p.add_argument("--feed", type=float, default=2000.0, help="feed of the positioning blocks (default %(default)s)")
    p.add_argument("--rtcp", action="store_true", help="workpiece coordinates with TRAORI instead of machine ones")
    p.add_argument("--dialect", choices=["siemens", "fanuc", "linuxcnc"], default="siemens", help="output dialect")
    p.add_argument("--out", required=True, help="program file to write")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(handler=_run)
