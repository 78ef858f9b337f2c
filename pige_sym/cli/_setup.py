"""Options shared by the commands that describe a test set-up (simulate, program, rtest-sim, acquire).

``--machine``, the test program (``--trajectory`` or ``--program``), ``--ball``,
``--pivot AXIS=x,y,z`` (repeatable), ``--tool``, and the trajectory shape options
``--points``, ``--turns`` and ``--incl-axis`` (the last two only for the cone frustum), and the commanded
sense of the rotary axes ``--axis-sense`` (CONVENTIONS §9).
Also :func:`show_progress`, the one rule for progress bars of every command.
Not a subcommand: the leading underscore keeps it out of the registry.
"""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.constants import DEFAULT_MACHINE
from pige_sym.errors import InputError


def show_progress(*suppressed: bool) -> bool:
    """Progress bars only on a terminal: never into a redirected stderr (a log file would fill with ``\\r``
    frames), and not when any of ``suppressed`` (``--json``, ``--quiet``, ``--no-progress``) is set."""
    import sys

    return not any(suppressed) and sys.stderr.isatty()


def parse_vec3(text: str, what: str) -> list[float]:
    """Three comma-separated ASCII decimals within ±1e5 mm, or a clear InputError naming the option."""
    from pige_sym.measurements.measurement import LIMITS
    from pige_sym.options import parse_vector

    out = parse_vector(text, what, 3)
    if max(abs(v) for v in out) > LIMITS["mm"]:
        raise InputError(f"{what}: {text} is not physical (|x|, |y|, |z| <= {LIMITS['mm']:g} mm)")
    return out


def parse_pivots(items: list[str] | None) -> dict[str, list[float]]:
    """``AXIS=x,y,z`` items of ``--pivot`` as axis -> [x, y, z] [mm]."""
    out = {}
    for item in items or []:
        axis, eq, vec = item.partition("=")
        if not eq:
            raise InputError(f"--pivot: expected AXIS=x,y,z, got {item!r}")
        out[axis.strip()] = parse_vec3(vec, f"--pivot {axis.strip()}")
    return out


def add_setup_arguments(p: argparse.ArgumentParser, *, program_flag: str = "--trajectory",
                        program_help: str = "cone-frustum, figure-eight, steps, or a CSV of <axis>_deg angles") -> None:
    """Add the set-up options; the test program lands in ``args.trajectory`` whatever its flag."""
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument(program_flag, dest="trajectory", default="cone-frustum",
                   help=program_help + " (default %(default)s)")
    p.add_argument("--ball", default="120,0,80",
                   help="ball centre at the reference pose x,y,z [mm] (default %(default)s)")
    p.add_argument("--pivot", action="append", metavar="AXIS=x,y,z", help="nominal pivot of a rotary axis [mm]")
    p.add_argument("--tool", help="ball offset from the last tool-side pivot x,y,z [mm] (head machines)")
    p.add_argument("--points", type=int, help="points per turn (cone, figure-eight)")
    p.add_argument("--turns", type=float, help="turns of the cone")
    p.add_argument("--incl-axis", choices=["X", "Y", "x", "y"], help="cone inclination axis (default X)")
    add_axis_sense_argument(p)


def trajectory_options(args: argparse.Namespace) -> dict[str, Any]:
    """The trajectory shape options that were given (cone-only ones only for the cone)."""
    out: dict[str, Any] = {}
    if args.points is not None:
        out["points"] = args.points
    if args.trajectory == "cone-frustum":
        if args.turns is not None:
            out["turns"] = args.turns
        if args.incl_axis is not None:
            out["incl_axis"] = args.incl_axis.upper()
    return out


def setup_geometry(args: argparse.Namespace) -> tuple[list[float], dict[str, list[float]], list[float] | None]:
    """Ball [mm], nominal pivots by axis [mm] and tool offset [mm] (None when not given)."""
    return (parse_vec3(args.ball, "--ball"), parse_pivots(args.pivot),
            parse_vec3(args.tool, "--tool") if args.tool else None)


def pige_values(spec: str, machine: str, seed: int | None) -> dict[str, float]:
    """``--pige``: ``random``, ``NAME=VALUE,...`` or a parameter file [µm, µrad].

    A file goes through :func:`pige_sym.measurements.schema.read_params_file` (strict JSON, finite physical
    numbers, the machine must agree); PIGEs it does not give are 0, as with ``NAME=VALUE``.
    """
    import os

    from pige_sym.measurements.schema import read_params_file
    from pige_sym.simulation.simulator import parse_pige

    if not os.path.isfile(spec):
        return parse_pige(spec, machine, seed)
    params = read_params_file(spec, machine=machine, allow_missing=True)
    if params.effect_values:
        raise InputError(f"--pige {spec}: effect parameters ({', '.join(params.effect_values)}) are not PIGEs; "
                         "give effects with --effect")
    return dict(params.pige)


def add_axis_sense_argument(p: argparse.ArgumentParser) -> None:
    """``--axis-sense AXIS=-1,...``: the sense in which the controller commands each rotary axis (CONVENTIONS §9)."""
    p.add_argument("--axis-sense", metavar="AXIS=-1,...",
                   help="rotary axes the controller commands in the reverse of CONVENTIONS' sense, e.g. A=-1,C=-1 "
                        "(LinuxCNC 2.9's xyzac-trt-kins; docs/linuxcnc.md); default: every axis +1")


def axis_sense_option(args: argparse.Namespace, rotary_axes: tuple[str, ...]) -> dict[str, int] | None:
    """``--axis-sense`` as axis -> -1 for the reversed axes; None when the option was not given."""
    from pige_sym.measurements.axis_sense import parse_axis_sense

    text = getattr(args, "axis_sense", None)
    return None if text is None else parse_axis_sense(text, rotary_axes)


def finite_option(value: float, name: str, *, minimum: float | None = None, positive: bool = False) -> float:
    """A numeric option that must be finite (and >= ``minimum`` / > 0); InputError naming it otherwise."""
    import math

    if not math.isfinite(value):
        raise InputError(f"{name}: {value!r} is not a finite number")
    if positive and not value > 0:
        raise InputError(f"{name} must be > 0, got {value:g}")
    if minimum is not None and value < minimum:
        raise InputError(f"{name} must be >= {minimum:g}, got {value:g}")
    return value
