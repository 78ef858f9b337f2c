"""``pige cycle``: calibrate at the machine, one LinuxCNC cycle that probes, identifies, checks and corrects.

``pige cycle install INI ...`` adds the cycle to a LinuxCNC configuration: ``M451 P0`` check, ``M451 P1``
optimise, ``M451 P2`` enter the last proposal, ``M451 P3 Q<k>`` setup k of a map test (``--map``), ``M452``
check-up (docs/linuxcnc-cycle.md).  Without ``--force`` it
prints the changes as a diff and writes nothing; with ``--force`` it writes them, keeping a backup of every file it
changes.  ``pige cycle step prepare|analyse|enter --run RUN`` are the steps LinuxCNC runs during the cycle (not
for the command line).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def _vec3(text: str, what: str) -> tuple[float, float, float]:
    from pige_sym.cli._setup import parse_vec3

    v = parse_vec3(text, what)
    return (v[0], v[1], v[2])


def _positive(value: float, what: str) -> float:
    from pige_sym.cli._setup import finite_option

    return float(finite_option(value, what, positive=True))


def _install_options(args: argparse.Namespace) -> Any:
    from dataclasses import replace

    from pige_sym.cli.compensate import _max_change
    from pige_sym.cycle.install import InstallOptions
    from pige_sym.cycle.settings import Limits, Probing

    max_mm, max_deg = _max_change(args.max_change)
    tolerances = None
    if args.tolerances:
        from pige_sym.measurements.strict_json import load_json
        from pige_sym.verdict.check import read_tolerances

        read_tolerances(args.tolerances)  # refused here when it is not a tolerance file
        tolerances = load_json(args.tolerances, "tolerance file")
    probing = replace(Probing(), poses=args.poses, contacts=args.contacts,
                      probe_feed_mm_min=_positive(args.probe_feed, "--probe-feed"),
                      clearance_mm=_positive(args.clearance, "--clearance"))
    limits = Limits(max_mm, max_deg, _positive(args.radius_tolerance, "--radius-tolerance"),
                    _positive(args.proposal_hours, "--proposal-hours"))
    return InstallOptions(_vec3(args.sphere, "--sphere"), _positive(args.sphere_radius, "--sphere-radius"),
                          _positive(args.stylus_radius, "--stylus-radius"), args.stylus_tool,
                          _positive(args.stylus_length, "--stylus-length"), [sys.executable, "-m", "pige_sym"],
                          kinematics=args.kinematics, machine=args.machine, machine_id=args.machine_id, db=args.db,
                          rtcp_on=args.rtcp_on, rtcp_off=args.rtcp_off, probing=probing, limits=limits,
                          tolerances=tolerances, map=_map_test(args))


def _map_test(args: argparse.Namespace) -> Any:
    """``--map AXES`` and its options: the map test's settings (None without ``--map``)."""
    from pige_sym.cli._maps import axes_option
    from pige_sym.cycle.settings import MapTest
    from pige_sym.errors import InputError

    if args.map is None:
        if args.map_sphere or args.map_range or args.map_per_direction:
            raise InputError("--map-sphere, --map-range and --map-per-direction go with --map AXES")
        return None
    spheres = [list(_vec3(v, "--map-sphere")) for v in args.map_sphere or []]
    return MapTest(list(axes_option(args.map, "--map")), _positive(args.map_step, "--map-step"), args.map_setups,
                   list(axes_option(args.map_per_direction, "--map-per-direction")), list(args.map_range or []),
                   spheres)


def _install(args: argparse.Namespace) -> int:
    from pige_sym.cycle.install import apply_plan, plan_install

    plan = plan_install(Path(args.ini), _install_options(args))
    for note in plan.notes:
        print(f"note: {note}")
    if not plan.files:
        print(f"{args.ini}: the cycle is installed as these options ask: nothing to change")
        return 0
    if not args.force:
        print(plan.diff(), end="")
        print(f"nothing written: {len(plan.files)} file(s) would change; pass --force to write them (each changed "
              "file is backed up first)")
        return 0
    for line in apply_plan(plan):
        print(line)
    print(f"installed: M451 P0/P1/P2 and M452 on machine {plan.settings.machine_id} ({plan.settings.machine}, "
          f"{plan.settings.module}); restart LinuxCNC, load the stylus (T{plan.settings.stylus_tool} M6) and call "
          "M451 P0 (docs/linuxcnc-cycle.md)")
    return 0


def _step(args: argparse.Namespace) -> int:
    from pige_sym.cycle.runtime import run_step

    return run_step(args.step, Path(args.run), live=not args.no_hal)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "cycle", help="calibrate at the machine: install LinuxCNC's M451 (check, optimise, enter) and M452 (check-up)",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        epilog="examples:\n"
               "  pige cycle install xyzac-trt.ini --sphere 20,10,15 --sphere-radius 6.35 --stylus-radius 1.5 \\\n"
               "      --stylus-tool 9 --stylus-length 30            # prints the diff, writes nothing\n"
               "  pige cycle install xyzac-trt.ini --sphere 20,10,15 --sphere-radius 6.35 --stylus-radius 1.5 \\\n"
               "      --stylus-tool 9 --stylus-length 30 --force    # writes, with backups",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cycle_command", metavar="ACTION", parser_class=type(p))
    sub.required = True
    _register_install(sub)
    st = sub.add_parser("step", help="one step of a running cycle (LinuxCNC calls it; not for the command line)",
                        description="One step of a running cycle: LinuxCNC's remap runs it in a process of its own "
                                    "(docs/linuxcnc-cycle.md); --no-hal runs it at a desk on the values file.",
                        epilog="example: a dry run of a run folder the remap made\nexamples:\n"
                               "  pige cycle step prepare --run pige_cycle/runs/20261128-120000-M451-check --no-hal",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    st.add_argument("step", choices=("prepare", "analyse", "enter"))
    st.add_argument("--run", required=True, help="the run's folder (pige_cycle/runs/<id>)")
    st.add_argument("--no-hal", action="store_true", help="read the values file, not the running HAL, and set no "
                    "pin (a dry run at a desk)")
    st.set_defaults(handler=_step)


def _register_install(sub: argparse._SubParsersAction) -> None:
    from pige_sym.cli.history import DB_HELP

    p = sub.add_parser("install", help="add M451/M452 to a LinuxCNC configuration (a diff; --force writes)",
                       description="Add the cycle to the LinuxCNC configuration INI: the remaps, their procedures "
                                   "and Python, the values file, the settings, the history's location "
                                   "(docs/linuxcnc-cycle.md).  Without --force: the diff, nothing written.",
                       epilog="examples:\n"
                              "  pige cycle install xyzac-trt.ini --sphere 20,10,15 --sphere-radius 6.35 \\\n"
                              "      --stylus-radius 1.5 --stylus-tool 9 --stylus-length 30\n"
                              "  pige cycle install my.ini --sphere 100,20,60 --sphere-radius 12.7 --stylus-radius 1.5 "
                              "\\\n      --stylus-tool 99 --stylus-length 120 --kinematics pige --machine-id DMU50-2 "
                              "--force",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("ini", metavar="INI", help="the configuration's INI file")
    p.add_argument("--sphere", required=True, metavar="X,Y,Z",
                   help="the sphere centre in machine coordinates, every rotary axis at 0 [mm]")
    p.add_argument("--sphere-radius", required=True, type=float, help="calibration sphere radius R [mm]")
    p.add_argument("--stylus-radius", required=True, type=float, help="stylus ball radius r [mm]")
    p.add_argument("--stylus-tool", required=True, type=int, help="the stylus' tool number")
    p.add_argument("--stylus-length", required=True, type=float,
                   help="its length in the tool table: gauge line to the stylus-ball centre [mm]")
    p.add_argument("--kinematics", choices=("stock", "pige"),
                   help="stock trt kinematics or pige's component (default: the INI's KINEMATICS)")
    p.add_argument("--machine", help="ISO 10791 code (default: from the kinematics)")
    p.add_argument("--machine-id", metavar="ID", help="the machine's name in the history (default: [EMC] MACHINE)")
    p.add_argument("--db", metavar="URL", help="the history (default pige_cycle/history.db in the configuration "
                   "folder); " + DB_HELP.split(": ", 1)[1].split(" (default")[0])
    p.add_argument("--rtcp-on", metavar="CODE", help="the code that selects the TCP kinematics (default: found in "
                   "the INI's remaps, e.g. M428)")
    p.add_argument("--rtcp-off", metavar="CODE", help="the code that selects identity kinematics (e.g. M429)")
    p.add_argument("--poses", type=int, default=12, help="probed poses after the reference (default %(default)s)")
    p.add_argument("--probe-feed", type=float, default=50.0, help="probing feed [mm/min] (default %(default)s)")
    p.add_argument("--clearance", type=float, default=1.0,
                   help="start of each probing move outside the sphere [mm] (default %(default)s)")
    p.add_argument("--max-change", default="0.2,0.1", metavar="MM[,DEG]",
                   help="largest change M451 P2 enters per value (default %(default)s)")
    p.add_argument("--radius-tolerance", type=float, default=0.02,
                   help="how far the radius the probe finds may lie from R + r [mm] (default %(default)s)")
    p.add_argument("--proposal-hours", type=float, default=8.0,
                   help="how old a proposal M451 P2 still enters [h] (default %(default)s)")
    p.add_argument("--tolerances", metavar="TOL.json", help="tolerances of the verdict (default 10 um, 30 urad)")
    p.add_argument("--contacts", type=int, default=5, help="contacts per probed pose, 4..9 (default %(default)s)")
    g = p.add_argument_group("the map test at the machine, M451 P3 Q<k> (pige's component only; "
                             "docs/linuxcnc-cycle.md)")
    g.add_argument("--map", metavar="AXES", help="the axes whose error maps the map test measures, e.g. C,A")
    g.add_argument("--map-step", type=float, default=15.0, metavar="DEG", help="grid step [deg] (default %(default)s)")
    g.add_argument("--map-setups", type=int, default=3, metavar="N", help="sphere setups (default %(default)s)")
    g.add_argument("--map-per-direction", metavar="AXES", help="map these axes' positioning per approach direction")
    g.add_argument("--map-range", action="append", metavar="AXIS=lo:hi",
                   help="range of an axis that does not turn fully [deg] (default 0:90 on a table)")
    g.add_argument("--map-sphere", action="append", metavar="X,Y,Z",
                   help="the sphere of setups 2, 3, ... in machine coordinates at the reference pose [mm] "
                        "(repeatable; default: pige program --map's, --sphere turned about C)")
    p.add_argument("--force", action="store_true", help="write the changes (each changed file backed up first)")
    p.set_defaults(handler=_install)


