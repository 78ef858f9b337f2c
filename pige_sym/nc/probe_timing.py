"""How long a probing program keeps the machine busy, from the moves it is made of.

The program is read back into its operations (:func:`~pige_sym.nc.probe_readback.probe_operations`, the statements
pige wrote, in any dialect) and each move is timed with a trapezoidal speed profile: a move of length ``L`` at top
speed ``v`` and acceleration ``a`` takes ``L/v + v/a`` when it reaches ``v`` (``L ≥ v²/a``), else ``2·√(L/a)``.

- rapid moves (``G0``, ``L … FMAX``): the linear axes at :attr:`MachineSpeeds.rapid_mm_s`, the rotary axes at
  :attr:`MachineSpeeds.rotary_deg_s` (a move of both takes the longer of the two);
- probing moves (``G38.2``, ``G31``, ``MEAS``, ``TCH PROBE``) and confirming contacts: at the block's feed (the
  probing feed of the set-up for a Heidenhain cycle, which states none) until the probe trips at the surface, the
  overtravel short of the target;
- guarded approaches (a contact would stop the program): their whole length at their feed.

Nothing else is counted (tool change, block processing, the probe's own trigger delay): the figure is the time the
axes move, a lower bound for a real machine.  ``tests/linuxcnc`` compares it with LinuxCNC's simulated time of the
same program (docs/checkup.md).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from pige_sym.nc.probe_program import ROUNDING_MARGIN_MM, ProbeSetup
from pige_sym.nc.probe_readback import probe_operations

_FEED = re.compile(r"\bF([\d.]+)")


@dataclass(frozen=True)
class MachineSpeeds:
    """Top speeds and accelerations of the axes (defaults: LinuxCNC's trt simulations with rapids of 6 m/min)."""

    rapid_mm_s: float = 100.0
    accel_mm_s2: float = 1000.0
    rotary_deg_s: float = 30.0
    rotary_accel_deg_s2: float = 1000.0


@dataclass(frozen=True)
class ProgramTime:
    """The program's machine time [s]: in total and by kind of move, and the number of moves."""

    seconds: float
    rapid_s: float
    rotary_s: float
    probing_s: float
    moves: int


def move_seconds(length: float, speed: float, accel: float) -> float:
    """Time of one move with a trapezoidal profile [s] (module docstring); 0 for no move."""
    if length <= 0:
        return 0.0
    if length >= speed * speed / accel:
        return length / speed + speed / accel
    return 2.0 * math.sqrt(length / accel)


def program_seconds(text: str, dialect: str, setup: ProbeSetup, rotary_axes: tuple[str, ...],
                    speeds: MachineSpeeds | None = None) -> ProgramTime:
    """Time the moves of a probing program (module docstring)."""
    sp = speeds or MachineSpeeds()
    lines = text.splitlines()
    pos = np.full(3, np.nan)
    ang = np.zeros(len(rotary_axes))
    rapid = rotary = probing = 0.0
    moves = 0
    trip_short = setup.overtravel_mm + ROUNDING_MARGIN_MM
    for op in probe_operations(text, dialect, rotary_axes=rotary_axes):
        if op.kind == "log":
            continue
        new = np.array([op.words.get(a, pos[k]) for k, a in enumerate("XYZ")])
        length = float(np.linalg.norm(np.nan_to_num(new - pos))) if np.isfinite(pos).all() else 0.0
        moves += 1
        if op.kind == "rapid":
            new_ang = np.array([op.words.get(a, ang[k]) for k, a in enumerate(rotary_axes)])
            turn = float(np.abs(new_ang - ang).max(initial=0.0))
            t_lin = move_seconds(length, sp.rapid_mm_s, sp.accel_mm_s2)
            t_rot = move_seconds(turn, sp.rotary_deg_s, sp.rotary_accel_deg_s2)
            rapid += t_lin if t_lin >= t_rot else 0.0
            rotary += t_rot if t_rot > t_lin else 0.0
            ang = new_ang
        else:
            found = _FEED.search(lines[op.line - 1]) if 0 < op.line <= len(lines) else None
            feed = float(found.group(1)) if found else setup.probe_feed_mm_min
            travel = length if op.kind == "guard" else max(length - trip_short, 0.0)
            probing += move_seconds(travel, feed / 60.0, sp.accel_mm_s2)
            if op.kind != "guard" and length > 0:  # the probe stops where it trips, short of the target
                new = pos + (new - pos) * (travel / length)
        pos = np.where(np.isnan(new), pos, new)
    return ProgramTime(rapid + rotary + probing, rapid, rotary, probing, moves)
