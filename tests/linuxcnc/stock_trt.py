"""LinuxCNC 2.9's stock trt inverse kinematics, transcribed here as the test's oracle of what the controller does.

``xyzacKinematicsInverse`` and ``xyzbcKinematicsInverse`` of ``src/emc/kinematics/trtfuncs.c`` at commit
f1270d6ed7 (Debian's 2.9.0~pre1): world (the program's point plus the tool length along Z) -> joints, with the
HAL pins ``x|y|z-rot-point``, ``y-offset``/``x-offset``, ``z-offset`` and ``tool-offset`` (added to
``z-offset``).  Used to turn the work coordinates LinuxCNC logs in TCP mode back into the joint positions the
true table saw.
"""

from __future__ import annotations

import numpy as np


def trt_inverse(kind: str, world: np.ndarray, angles_deg: np.ndarray, pins: dict[str, float]) -> np.ndarray:
    """Joints X, Y, Z [mm] of world rows (n, 3) [mm] at commanded (tilt, C) rows (n, 2) [deg]."""
    p = np.atleast_2d(np.asarray(world, dtype=float))
    t, c = (np.radians(np.atleast_2d(angles_deg)[:, k]) for k in (0, 1))
    xr, yr, zr = (pins.get(f"{a}-rot-point", 0.0) for a in "xyz")
    dz = pins.get("z-offset", 0.0) + pins.get("tool-offset", 0.0)
    x, y, z = p[:, 0] - xr, p[:, 1] - yr, p[:, 2] - zr
    if kind == "xyzac":
        dy = pins.get("y-offset", 0.0)
        return np.column_stack([
            np.cos(c) * x - np.sin(c) * y + xr,
            np.sin(c) * np.cos(t) * x + np.cos(c) * np.cos(t) * y - np.sin(t) * z
            - np.cos(t) * dy + np.sin(t) * dz + dy + yr,
            np.sin(c) * np.sin(t) * x + np.cos(c) * np.sin(t) * y + np.cos(t) * z
            - np.sin(t) * dy - np.cos(t) * dz + dz + zr])
    dx = pins.get("x-offset", 0.0)
    dpx = -np.cos(t) * dx - np.sin(t) * dz + dx
    dpz = np.sin(t) * dx - np.cos(t) * dz + dz
    return np.column_stack([
        np.cos(c) * np.cos(t) * x - np.sin(c) * np.cos(t) * y + np.sin(t) * z + dpx + xr,
        np.sin(c) * x + np.cos(c) * y + yr,
        -np.cos(c) * np.sin(t) * x + np.sin(c) * np.sin(t) * y + np.cos(t) * z + dpz + zr])


def stock_pins(kind: str) -> dict[str, float]:
    """The pins the shipped INIs set (``sets :y-offset 20``, ``sets :z-offset 10``; ``-20``, ``-15``)."""
    if kind == "xyzac":
        return {"y-offset": 20.0, "z-offset": 10.0}
    return {"x-offset": -20.0, "z-offset": -15.0}
