"""``pige demo``: the whole story on the default AC tilting table.

Stages that exist run in order; each prints what it did.
"""

from __future__ import annotations

import argparse

import numpy as np

from ..kernels import DEFAULT_MACHINE, load_kernels


def _run(args: argparse.Namespace) -> int:
    kern = load_kernels(args.machine)
    print(f"machine {kern.MACHINE_CODE}: rotary axes {', '.join(kern.ROTARY_AXES)}")
    print(f"parameters: {', '.join(f'{p} [{kern.UNITS[p]}]' for p in kern.PARAMETERS)}")
    sample = {"EY0A": 5.0, "EZ0A": -3.0, "EB0A": 8.0, "EC0A": -4.0, "EX0C": 2.0, "EY0C": 6.0, "EA0C": -7.0, "EB0C": 3.0}
    params = np.array([sample.get(p, 0.0) for p in kern.PARAMETERS])
    angles = np.array([[30.0, 45.0]])
    ball = np.array([120.0, 0.0, 80.0])
    dev = kern.deviation(angles, params, ball)[0]
    print("sample errors: " + ", ".join(f"{k}={v:g}" for k, v in sample.items()))
    pose = ", ".join(f"{a}={v:g}" for a, v in zip(kern.ROTARY_AXES, angles[0], strict=True))
    print(f"pose {pose} deg, ball {ball.tolist()} mm")
    print(f"deviation ball-nest (machine frame): dx={dev[0]:.3f} dy={dev[1]:.3f} dz={dev[2]:.3f} um")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the whole story on the default machine",
        description="Simulate, identify, diagnose and compensate on the default AC tilting table.",
    )
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="machine structure code")
    p.add_argument("--out", default="demo-out", help="output directory")
    p.set_defaults(handler=_run)
