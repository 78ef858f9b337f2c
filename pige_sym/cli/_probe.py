"""Options shared by the sphere-probe commands (``program``, ``simulate``, ``import-probe``, ``demo``)."""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.cli._setup import finite_option, parse_vec3
from pige_sym.errors import InputError

INSTRUMENT_CHOICES = ("rtest", "sphere-probe", "ballbar")


def add_sphere_arguments(p: argparse.ArgumentParser, *, when: str = "with --instrument sphere-probe") -> None:
    """Sphere and stylus: what every probe command needs; ``when`` says when they are required."""
    p.add_argument("--sphere-radius", type=float, help=f"calibration sphere radius R [mm] (required {when})")
    p.add_argument("--stylus-radius", type=float, help=f"stylus tip radius r [mm] (required {when})")


def add_probe_program_arguments(p: argparse.ArgumentParser) -> None:
    """Where the sphere is and how to touch it (``program`` and ``simulate`` with ``--instrument sphere-probe``)."""
    add_sphere_arguments(p)
    p.add_argument("--sphere", help="nominal sphere centre at the reference pose x,y,z [mm] (sphere-probe)")
    p.add_argument("--contacts", type=int, default=5, help="contacts per pose, 4-9 (default %(default)s)")
    p.add_argument("--clearance", type=float, default=3.0, help="start of each probing move outside R + r [mm] "
                   "(default %(default)s)")
    p.add_argument("--overtravel", type=float, default=1.0, help="target of each probing move inside R + r [mm] "
                   "(default %(default)s)")
    p.add_argument("--safe-z", type=float, help="retract height before rotary moves [mm] (default: 20 mm above "
                   "the highest clearance plane)")
    p.add_argument("--probe-feed", type=float, default=100.0, help="probing feed [mm/min] (default %(default)s)")
    p.add_argument("--pattern", choices=("fixed", "alternate"), default="fixed",
                   help="contacts: the same pattern at every pose, or the rings (15 and 50 deg) taken in turn so a "
                        "direction-dependent trigger radius shows in the data (default %(default)s)")
    p.add_argument("--stem", default="0,0,-1", metavar="x,y,z",
                   help="sphere-probe: direction of the sphere's stem from its centre, table frame (default "
                        "%(default)s: below the sphere); no probing move comes from that side")
    p.add_argument("--stem-radius", type=float, default=5.0, help="sphere-probe: stem radius [mm] (default "
                   "%(default)s)")
    p.add_argument("--stem-length", type=float, default=100.0,
                   help="sphere-probe: sphere centre to the table along the stem [mm] (default %(default)s)")
    p.add_argument("--shank", type=float, default=30.0,
                   help="sphere-probe: stylus shank checked against stem and table, from the ball centre [mm] "
                        "(default %(default)s)")
    add_controller_arguments(p)


def add_controller_arguments(p: argparse.ArgumentParser) -> None:
    """What the probing program sets and checks on the controller (pige_sym.nc.probe_safety)."""
    g = p.add_argument_group("controller state the probing program sets and checks (sphere-probe)")
    g.add_argument("--kinematics", choices=("identity", "tcp"),
                   help="probe with RTCP off (identity: LinuxCNC needs --rtcp-off/--rtcp-on) or in LinuxCNC's TCP "
                        "kinematics (default: identity)")
    g.add_argument("--rtcp-off", metavar="CODE", help="LinuxCNC code that selects identity kinematics (M429 in the "
                   "shipped trt sims)")
    g.add_argument("--rtcp-on", metavar="CODE", help="LinuxCNC code that selects the TCP kinematics (M428); the "
                   "program ends with it")
    g.add_argument("--stylus-tool", type=int, help="tool number of the touch probe (required for a program)")
    g.add_argument("--stylus-length", type=float, help="its tool length: gauge line to the stylus-ball centre [mm] "
                   "(required for a program)")
    g.add_argument("--work-offset", default="G54", metavar="G54[=x,y,z]",
                   help="work offset the coordinates are in, and its X,Y,Z the program checks (default G54=0,0,0)")
    g.add_argument("--window", type=float, default=0.3, help="how far the confirming first contacts may lie from "
                   "the nominal sphere [mm] (default %(default)s)")


def probe_pivot(items: list[str] | None) -> tuple[float, float, float]:
    """``--pivot x,y,z`` of the probe commands: the intersection of the rotary axis lines [mm]."""
    if not items:
        return (0.0, 0.0, 0.0)
    if len(items) > 1 or "=" in items[0]:
        raise InputError("sphere probing takes one --pivot x,y,z (the nominal intersection of the rotary axis lines) "
                         "or one --pivot AXIS=x,y,z per rotary axis, in the program's coordinates")
    v = parse_vec3(items[0], "--pivot")
    return (v[0], v[1], v[2])


def probe_tool(text: str | None) -> tuple[float, float, float] | None:
    """``--tool x,y,z`` of the probe commands: the stylus centre from the last tool-side pivot [mm], or None."""
    if not text:
        return None
    v = parse_vec3(text, "--tool")
    return (v[0], v[1], v[2])


def probe_pivots(items: list[str] | None, rotary_axes: tuple[str, ...]) -> dict[str, list[float]] | None:
    """``--pivot AXIS=x,y,z`` for every rotary axis (their lines need not meet), or None for one ``x,y,z``."""
    from pige_sym.cli._setup import parse_pivots

    if not items or not any("=" in it for it in items):
        return None
    pivots = parse_pivots(items)
    unknown = [a for a in pivots if a not in rotary_axes]
    missing = [a for a in rotary_axes if a not in pivots]
    if unknown or missing or len(items) != len(pivots):
        raise InputError(f"--pivot AXIS=x,y,z: give each rotary axis once ({', '.join(rotary_axes)}); "
                         + (f"{unknown[0]} is not one" if unknown else f"{', '.join(missing) or 'an axis'} missing "
                            "or repeated"))
    return pivots


def probe_controller(args: argparse.Namespace, dialect: str, *, required: bool = True) -> Any:
    """The :class:`~pige_sym.nc.probe_safety.ProbeController` of the options (checked for ``dialect``)."""
    from pige_sym.nc.probe_safety import ProbeController

    if required and (args.stylus_tool is None or args.stylus_length is None):
        raise InputError("a probing program states its stylus: give --stylus-tool N and --stylus-length L (the "
                         "tool length to the stylus-ball centre, mm)")
    name, _, values = (args.work_offset or "G54").partition("=")
    offset = parse_vec3(values, "--work-offset") if values else [0.0, 0.0, 0.0]
    kinematics = args.kinematics or "identity"
    ctrl = ProbeController(kinematics, args.rtcp_off, args.rtcp_on,
                           args.stylus_tool if args.stylus_tool is not None else 1,
                           finite_option(args.stylus_length, "--stylus-length", positive=True)
                           if args.stylus_length is not None else 100.0,
                           name.strip().upper(), (offset[0], offset[1], offset[2]),
                           finite_option(args.window, "--window", positive=True))
    ctrl.check(dialect)
    return ctrl


def sphere_radii(args: argparse.Namespace) -> tuple[float, float]:
    """``--sphere-radius`` and ``--stylus-radius``, required and positive."""
    if args.sphere_radius is None or args.stylus_radius is None:
        raise InputError("sphere probing needs --sphere-radius R and --stylus-radius r [mm]")
    return (finite_option(args.sphere_radius, "--sphere-radius", positive=True),
            finite_option(args.stylus_radius, "--stylus-radius", positive=True))


def probe_setup(args: argparse.Namespace, machine: str, *, dialect: str | None = None,
                controller_required: bool = True) -> Any:
    """The :class:`~pige_sym.nc.probe_program.ProbeSetup` of the options.

    ``dialect`` None: no program is written (planning), the controller state is not needed; otherwise it is
    built from the options and checked for the dialect (:func:`probe_controller`).
    """
    import numpy as np

    from pige_sym.cli._setup import axis_sense_option
    from pige_sym.kernels import load_kernels
    from pige_sym.nc.probe_program import ProbeSetup
    from pige_sym.nc.probe_reach import Stem
    from pige_sym.nc.probe_safety import ProbeController

    if not args.sphere:
        raise InputError("sphere probing needs --sphere x,y,z: the sphere centre at the reference pose [mm]")
    radius, stylus = sphere_radii(args)
    for name in ("clearance", "overtravel", "probe_feed"):
        finite_option(getattr(args, name), "--" + name.replace("_", "-"), positive=True)
    axes = tuple(load_kernels(machine).ROTARY_AXES)
    per_axis = probe_pivots(args.pivot, axes)
    single = np.zeros(3) if per_axis is not None else np.array(probe_pivot(args.pivot))
    tool = probe_tool(getattr(args, "tool", None))
    v = parse_vec3(args.stem, "--stem")
    stem = (v[0], v[1], v[2])
    return ProbeSetup(machine, np.array(parse_vec3(args.sphere, "--sphere")), single,
                      radius, stylus, clearance_mm=args.clearance, overtravel_mm=args.overtravel,
                      contacts=args.contacts, safe_z_mm=args.safe_z, probe_feed_mm_min=args.probe_feed,
                      pattern=args.pattern,
                      pivots_mm=None if per_axis is None else {a: np.array(v) for a, v in per_axis.items()},
                      axis_sense=axis_sense_option(args, axes) or {},
                      controller=ProbeController() if dialect is None else
                      probe_controller(args, dialect, required=controller_required),
                      tool_mm=None if tool is None else np.array(tool),
                      stem=Stem(stem, finite_option(args.stem_radius, "--stem-radius", positive=True),
                                finite_option(args.stem_length, "--stem-length", positive=True),
                                finite_option(args.shank, "--shank", positive=True)))
