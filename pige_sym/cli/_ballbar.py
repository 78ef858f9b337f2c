"""Options shared by the ballbar commands (``program`` and ``simulate`` with ``--instrument ballbar``)."""

from __future__ import annotations

import argparse
from typing import Any

from pige_sym.cli._setup import finite_option, parse_vec3


def add_ballbar_arguments(p: argparse.ArgumentParser) -> None:
    """One ISO 10791-6 style setup: kind, swept axis, geometry."""
    p.add_argument("--setup", choices=("radial", "tangential", "axial"), default="radial",
                   help="ballbar setup relative to the swept axis (ballbar; default %(default)s)")
    p.add_argument("--axis", help="the swept rotary axis, e.g. C or A (ballbar; default: the rotary table's)")
    p.add_argument("--tilt", type=float, default=0.0, help="tilt-axis angle held while C sweeps [deg] (ballbar)")
    p.add_argument("--tilt-range", type=float, default=-90.0, help="end of a tilt-axis sweep [deg] (ballbar)")
    p.add_argument("--table-ball", default="100,0,50", help="table ball at the reference pose x,y,z [mm] (ballbar)")
    p.add_argument("--length", type=float, default=100.0, help="bar length L0 [mm] (ballbar; default %(default)s)")
    p.add_argument("--zero", choices=("relative", "absolute"), default="relative",
                   help="relative: dL from the first reading (unknown constant); absolute: calibrated length")


def plan_pointer(result: Any, files: list[Any]) -> str:
    """What to do when ballbar setups alone leave PIGEs undetermined: the planner names the setups that do not.

    ``result`` is the joint :class:`~pige_sym.identification.result.IdentificationResult`, ``files`` its
    per-file summaries (with ``instrument``).  Empty when a PIGE-only set is determined or a file is no ballbar.
    """
    import numpy as np

    undetermined = [n for n, v in zip(result.parameters, result.values, strict=True) if not np.isfinite(v)]
    if not undetermined or any(f.instrument != "ballbar" for f in files):
        return ""
    count = "this ballbar setup determines" if len(files) == 1 else f"these {len(files)} ballbar setups determine"
    return (f"\nnext: {count} {len(result.parameters) - len(undetermined)} of {len(result.parameters)} PIGEs "
            f"(rank {result.rank}/{len(result.parameters)}); "
            f"pige plan --instrument ballbar --machine \"{result.machine}\" names the smallest set of setups that "
            "determines them all")


def ballbar_setup_of(args: argparse.Namespace, machine: str) -> Any:
    """The :class:`~pige_sym.simulation.ballbar.BallbarSetup` of the options."""
    from pige_sym.kernels import load_kernels
    from pige_sym.simulation.ballbar import ballbar_setup

    kern = load_kernels(machine)
    axis = args.axis or next((a for a in kern.ROTARY_AXES if a[0] == "C"), kern.ROTARY_AXES[-1])
    ball = parse_vec3(args.table_ball, "--table-ball")
    return ballbar_setup(machine, args.setup, axis, table_ball_mm=(ball[0], ball[1], ball[2]),
                         length_mm=finite_option(args.length, "--length", positive=True),
                         tilt_deg=finite_option(args.tilt, "--tilt"),
                         tilt_range_deg=finite_option(args.tilt_range, "--tilt-range"))
