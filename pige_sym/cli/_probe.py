"""Options shared by the sphere-probe commands (``program``, ``simulate``, ``import-probe``, ``demo``)."""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.cli._setup import finite_option, parse_vec3
from pige_sym.errors import InputError

INSTRUMENT_CHOICES = ("rtest", "sphere-probe", "ballbar")


def add_sphere_arguments(p: argparse.ArgumentParser) -> None:
    """Sphere and stylus: what every probe command needs."""
    p.add_argument("--sphere-radius", type=float, help="calibration sphere radius R [mm] (sphere-probe)")
    p.add_argument("--stylus-radius", type=float, help="stylus tip radius r [mm] (sphere-probe)")


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


def probe_pivot(items: list[str] | None) -> tuple[float, float, float]:
    """``--pivot x,y,z`` of the probe commands: the intersection of the rotary axis lines [mm]."""
    if not items:
        return (0.0, 0.0, 0.0)
    if len(items) > 1 or "=" in items[0]:
        raise InputError("sphere probing takes one --pivot x,y,z: the nominal intersection of the rotary axis lines "
                         "in the program's coordinates")
    v = parse_vec3(items[0], "--pivot")
    return (v[0], v[1], v[2])


def probe_tool(text: str | None) -> tuple[float, float, float] | None:
    """``--tool x,y,z`` of the probe commands: the stylus centre from the last tool-side pivot [mm], or None."""
    if not text:
        return None
    v = parse_vec3(text, "--tool")
    return (v[0], v[1], v[2])


def sphere_radii(args: argparse.Namespace) -> tuple[float, float]:
    """``--sphere-radius`` and ``--stylus-radius``, required and positive."""
    if args.sphere_radius is None or args.stylus_radius is None:
        raise InputError("sphere probing needs --sphere-radius R and --stylus-radius r [mm]")
    return (finite_option(args.sphere_radius, "--sphere-radius", positive=True),
            finite_option(args.stylus_radius, "--stylus-radius", positive=True))


def probe_setup(args: argparse.Namespace, machine: str) -> Any:
    """The :class:`~pige_sym.nc.probe_program.ProbeSetup` of the options."""
    import numpy as np

    from pige_sym.nc.probe_program import ProbeSetup

    if not args.sphere:
        raise InputError("sphere probing needs --sphere x,y,z: the sphere centre at the reference pose [mm]")
    radius, stylus = sphere_radii(args)
    for name in ("clearance", "overtravel", "probe_feed"):
        finite_option(getattr(args, name), "--" + name.replace("_", "-"), positive=True)
    return ProbeSetup(machine, np.array(parse_vec3(args.sphere, "--sphere")), np.array(probe_pivot(args.pivot)),
                      radius, stylus, clearance_mm=args.clearance, overtravel_mm=args.overtravel,
                      contacts=args.contacts, safe_z_mm=args.safe_z, probe_feed_mm_min=args.probe_feed,
                      pattern=args.pattern)
