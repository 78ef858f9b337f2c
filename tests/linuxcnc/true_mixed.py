"""The true mixed machine of the LinuxCNC head run: a swivel head B over a rotary table C, written here from
CONVENTIONS §2, §3 and §7 (head paragraph), with no pige code.

Each axis line is a point ``q = p + δ`` and a unit direction ``u'`` (:func:`true_table.axis_line`).  With
identity kinematics the controller's X Y Z (the joints less the tool length along Z) are where the
stylus-tip centre would be with the head at its reference pose (§7); the head turns the tip about its true
line by ``+θ_B`` (a tool-side axis, §2), so the tip stands at ``X + T(θ_B)(b0) − b0`` in the machine frame,
``b0 = p_B + tool``.  The table turned the sphere by ``−θ_C``; turning the tip by ``+θ_C`` about the C line takes
it into table coordinates.  ``θ = σ·θ_cmd + E`` (§9, the zero-position error E).

The same mathematics runs twice: in the realtime HAL component ``true_mixed.comp`` (C, once per servo period,
it drives ``motion.probe-input``), and in :meth:`TrueMixed.tip_in_table` (NumPy), with which the test checks
the contacts LinuxCNC logged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from true_table import axis_line, rotate, true_machine_hal

SOURCE = (Path(__file__).resolve().parent / "true_mixed.comp").read_text()
COMPONENT_NAME = "pige_true_mixed"
READ_PINS = ["ptm.trips", "ptm.clock"]


@dataclass
class TrueMixed:
    """A C table and a B head with PIGEs, senses, the stylus and the sphere.

    Attributes
    ----------
    pivot_mm : (3,) [mm]
        Nominal point where both axis lines meet, machine frame at the reference pose.
    tool_mm : (3,) [mm]
        Stylus-tip centre relative to the nominal head pivot at the reference pose (CONVENTIONS §7).
    pige : dict of str to float [µm, µrad]
    sense : dict of str to int
        Commanded sense σ of "B" and "C" (CONVENTIONS §9).
    tool_length_mm, sphere_mm (table coordinates), trip_radius_mm
    """

    pivot_mm: np.ndarray
    tool_mm: np.ndarray
    pige: dict[str, float] = field(default_factory=dict)
    sense: dict[str, int] = field(default_factory=lambda: {"B": 1, "C": 1})
    tool_length_mm: float = 0.0
    sphere_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    trip_radius_mm: float = 1.0

    @property
    def b0(self) -> np.ndarray:
        return np.asarray(self.pivot_mm, dtype=float) + np.asarray(self.tool_mm, dtype=float)

    def tip_in_table(self, joints: np.ndarray) -> np.ndarray:
        """Stylus-tip centre in table coordinates for joint rows (n, 5) ``X Y Z B C`` [mm, deg] -> (n, 3) [mm]."""
        j = np.atleast_2d(np.asarray(joints, dtype=float))
        qb, ub, zb = axis_line("B", self.pivot_mm, self.pige)
        qc, uc, zc = axis_line("C", self.pivot_mm, self.pige)
        turned = rotate(np.tile(self.b0, (len(j), 1)), qb, ub, self.sense["B"] * np.radians(j[:, 3]) + zb)
        y = j[:, :3] - np.array([0.0, 0.0, self.tool_length_mm]) + turned - self.b0
        return rotate(y, qc, uc, self.sense["C"] * np.radians(j[:, 4]) + zc)

    def hal_lines(self, name: str = "ptm") -> list[str]:
        """Load the component, run it last in the servo thread, net it to the joints and the probe input."""
        return true_machine_hal(COMPONENT_NAME, name, ("joint-head", "joint-table"), self.pin_values())

    def pin_values(self) -> dict[str, float]:
        vals: dict[str, float] = {}
        for axis, side in (("B", "head"), ("C", "table")):
            q, u, zero = axis_line(axis, self.pivot_mm, self.pige)
            vals |= {f"{side}-p{c}": float(v) for c, v in zip("xyz", q, strict=True)}
            vals |= {f"{side}-u{c}": float(v) for c, v in zip("xyz", u, strict=True)}
            vals |= {f"{side}-zero": float(zero), f"{side}-sense": float(self.sense[axis])}
        vals |= {f"b0-{c}": float(v) for c, v in zip("xyz", self.b0, strict=True)}
        vals |= {f"sphere-{c}": float(v) for c, v in zip("xyz", self.sphere_mm, strict=True)}
        return vals | {"tool-length": float(self.tool_length_mm), "trip-radius": float(self.trip_radius_mm)}
