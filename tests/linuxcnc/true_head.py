"""The true head and mixed machines of the LinuxCNC head runs, written here from CONVENTIONS §2, §3 and §7 (head
paragraph), with no pige code.

Each axis line is a point ``q = p + δ`` and a unit direction ``u'`` (:func:`true_table.axis_line`), each
given in the frame of the body that carries it at that body's reference pose (§2).  With identity kinematics
the controller's X Y Z (the joints less the tool length along Z) are where the stylus-tip centre would be with
the head at its reference pose (§7).  The head axes turn the tip by ``+θ`` (tool side, §2), the axis that
carries the spindle first: the tip stands at ``X + T(θ)(b0) − b0`` in the machine frame, ``b0 = p + tool``.
The table axes turned the sphere by ``−θ``; turning the tip by ``+θ``, the axis on the bed first, takes it
into table coordinates.  ``θ = σ·θ_cmd + E`` (§9, the zero-position error E).

The same mathematics runs twice: in the realtime HAL component ``true_head.comp`` (C, once per servo period,
it drives ``motion.probe-input``), and in :meth:`TrueHead.tip_in_table` (NumPy), with which the test checks
the contacts LinuxCNC logged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from true_table import axis_line, rotate, true_machine_hal

SOURCE = (Path(__file__).resolve().parent / "true_head.comp").read_text()
COMPONENT_NAME = "pige_true_head"
READ_PINS = ["pth.trips", "pth.clock"]
#: the component's roles, in the order it applies them
ROLES = {"head inner": 1, "head outer": 2, "table outer": 3, "table inner": 4}


@dataclass
class TrueHead:
    """A head or mixed machine with PIGEs, senses, the stylus and the sphere.

    Attributes
    ----------
    roles : dict of str to str
        The rotary axis of joint 3, then of joint 4, and its role (a key of :data:`ROLES`).
    pivot_mm : (3,) [mm]
        Nominal point where the axis lines meet, machine frame at the reference pose.
    tool_mm : (3,) [mm]
        Stylus-tip centre relative to the nominal head pivot at the reference pose (CONVENTIONS §7).
    pige : dict of str to float [µm, µrad]
    sense : dict of str to int
        Commanded sense σ per axis (CONVENTIONS §9).
    tool_length_mm, sphere_mm (table coordinates), trip_radius_mm
    """

    roles: dict[str, str]
    pivot_mm: np.ndarray
    tool_mm: np.ndarray
    pige: dict[str, float] = field(default_factory=dict)
    sense: dict[str, int] = field(default_factory=dict)
    tool_length_mm: float = 0.0
    sphere_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    trip_radius_mm: float = 1.0

    @property
    def b0(self) -> np.ndarray:
        return np.asarray(self.pivot_mm, dtype=float) + np.asarray(self.tool_mm, dtype=float)

    def _turn(self, y: np.ndarray, joints: np.ndarray, roles: tuple[str, ...]) -> np.ndarray:
        for role in roles:
            for k, (axis, r) in enumerate(self.roles.items()):
                if r == role:
                    q, u, zero = axis_line(axis, self.pivot_mm, self.pige)
                    y = rotate(y, q, u, self.sense.get(axis, 1) * np.radians(joints[:, 3 + k]) + zero)
        return y

    def tip_in_table(self, joints: np.ndarray) -> np.ndarray:
        """Stylus-tip centre in table coordinates for joint rows (n, 5) [mm, deg] -> (n, 3) [mm]."""
        j = np.atleast_2d(np.asarray(joints, dtype=float))
        turned = self._turn(np.tile(self.b0, (len(j), 1)), j, ("head inner", "head outer"))
        y = j[:, :3] - np.array([0.0, 0.0, self.tool_length_mm]) + turned - self.b0
        return self._turn(y, j, ("table outer", "table inner"))

    def hal_lines(self, name: str = "pth") -> list[str]:
        """Load the component, run it last in the servo thread, net it to the joints and the probe input."""
        return true_machine_hal(COMPONENT_NAME, name, ("joint-r0", "joint-r1"), self.pin_values())

    def pin_values(self) -> dict[str, float]:
        vals: dict[str, float] = {}
        for k, (axis, role) in enumerate(self.roles.items()):
            q, u, zero = axis_line(axis, self.pivot_mm, self.pige)
            vals |= {f"p{c}{k}": float(v) for c, v in zip("xyz", q, strict=True)}
            vals |= {f"u{c}{k}": float(v) for c, v in zip("xyz", u, strict=True)}
            vals |= {f"zero{k}": float(zero), f"sense{k}": float(self.sense.get(axis, 1)), f"role{k}": ROLES[role]}
        vals |= {f"b0-{c}": float(v) for c, v in zip("xyz", self.b0, strict=True)}
        vals |= {f"sphere-{c}": float(v) for c, v in zip("xyz", self.sphere_mm, strict=True)}
        return vals | {"tool-length": float(self.tool_length_mm), "trip-radius": float(self.trip_radius_mm)}
