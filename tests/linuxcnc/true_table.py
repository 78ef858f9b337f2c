"""The true machine of the LinuxCNC loop: a tilting table with known PIGEs, written here from CONVENTIONS §2–3.

An oracle independent of pige_sym's model: each workpiece-side axis line is a point ``q = p + δ`` and a unit
direction ``u' = (u + ε × u)/|u + ε × u|``; the table point ``x`` stands at ``W(θ)x = M_o(M_i(x))`` with
``M(x) = q + R(u', −θ)(x − q)`` (the inner axis C is carried by the outer one, A or B, and its line is given at
the outer axis' reference pose), ``θ = σ·θ_cmd + E`` for the commanded joint angle ``θ_cmd``, the commanded
sense ``σ`` (CONVENTIONS §9) and the zero-position error ``E``.  The stylus-tip centre is ``tool_length``
below joint Z: ``y = (jx, jy, jz − L)`` in the machine frame, the table point under it ``W(θ)⁻¹ y``.

The same mathematics runs twice: in the realtime HAL component ``true_table.comp`` (C, one evaluation per
servo period, it drives ``motion.probe-input``), and in :meth:`TrueTable.tip_in_table` (NumPy) that the tests
use to check the component and the contacts LinuxCNC logged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from shared_runs import once

TEMPLATE = (Path(__file__).resolve().parent / "true_table.comp").read_text()
COMPONENT_NAME = "pige_true_table"
MODEL_PREFIX = "ptm"


def component_source(code: str) -> str:
    """The true machine's component for machine ``code``: the template with pige's emitted C model inlined (made
    once per test session: SymPy takes seconds, :func:`shared_runs.once`)."""
    return once(f"true table component {code}", lambda: _component_source(code))


def _component_source(code: str) -> str:
    from pige_sym.codegen.c_model import render_model_c
    from pige_sym.kernels import load_kernels

    kern = load_kernels(code)
    if tuple(kern.ROTARY_AXES)[1:] != ("C",) or len(kern.ROTARY_AXES) != 2:
        raise AssertionError(f"{code}: the true table is an A/B tilt with C on it")
    model = render_model_c(code, MODEL_PREFIX, include_math=False, header=True)
    return (TEMPLATE.replace("@MODEL@", model).replace("@PREFIX@", MODEL_PREFIX)
            .replace("@N_ERRORS@", str(len(kern.PARAMETERS))))


#: per outer axis: its direction and the PIGE names (position errors along the two other machine axes, then the
#: orientation errors about them, then the zero-position error); the inner axis is C
AXES = {
    "A": (np.array([1.0, 0.0, 0.0]), ("EY0A", "EZ0A"), ("EB0A", "EC0A"), "EA0A"),
    "B": (np.array([0.0, 1.0, 0.0]), ("EX0B", "EZ0B"), ("EA0B", "EC0B"), "EB0B"),
    "C": (np.array([0.0, 0.0, 1.0]), ("EX0C", "EY0C"), ("EA0C", "EB0C"), "EC0C"),
}
OTHER = {"A": (1, 2), "B": (0, 2), "C": (0, 1)}  # the machine axes of the position / orientation errors


def true_machine_hal(component: str, name: str, rotary_pins: tuple[str, str], values: dict[str, float]) -> list[str]:
    """HAL lines of a true machine: load ``component`` as ``name``, run it last in the servo thread, net the five
    joints' feedback (X, Y, Z, then ``rotary_pins``) and its ``probe`` output to motion, ``setp`` its inputs."""
    out = [f"loadrt {component} names={name}", f"addf {name} servo-thread"]
    for k, pin in enumerate(("joint-x", "joint-y", "joint-z", *rotary_pins)):
        out.append(f"net J{k}:pos-fb => {name}.{pin}")
    out.append(f"net pige:probe <= {name}.probe => motion.probe-input")
    return out + [f"setp {name}.{pin} {value!r}" for pin, value in values.items()]


def axis_line(axis: str, pivot_mm: np.ndarray, pige: dict[str, float]) -> tuple[np.ndarray, np.ndarray, float]:
    """The true line of a rotary axis: point [mm], unit direction, zero-position error [rad] (CONVENTIONS §3)."""
    u, pos, rot, zero = AXES[axis]
    i, j = OTHER[axis]
    q = np.asarray(pivot_mm, dtype=float).copy()
    q[i] += pige.get(pos[0], 0.0) * 1e-3
    q[j] += pige.get(pos[1], 0.0) * 1e-3
    eps = np.zeros(3)
    eps[i], eps[j] = pige.get(rot[0], 0.0) * 1e-6, pige.get(rot[1], 0.0) * 1e-6
    d = u + np.cross(eps, u)
    return q, d / np.linalg.norm(d), pige.get(zero, 0.0) * 1e-6


def rotate(y: np.ndarray, q: np.ndarray, u: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """``q + R(u, φ)(y − q)`` for rows ``y`` (n, 3) and angles ``φ`` (n,) [rad] (Rodrigues)."""
    v = y - q
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    return q + c * v + s * np.cross(u, v) + (1 - c) * (v @ u)[:, None] * u


@dataclass
class TrueTable:
    """The true machine: axis lines with PIGEs, senses, the stylus and the sphere.

    Attributes
    ----------
    code : str
        ISO 10791 code (the emitted model's machine).
    outer : {"A", "B"}
    pivot_mm : dict of str to (3,) [mm]
        Nominal point of each axis line ("A"/"B" and "C"), machine frame (joint coordinates).
    pige : dict of str to float [µm, µrad]
    sense : dict of str to int
        Commanded sense σ per axis (CONVENTIONS §9).
    tool_length_mm, sphere_mm (table coordinates), trip_radius_mm
    """

    code: str
    outer: str
    pivot_mm: dict[str, np.ndarray]
    pige: dict[str, float] = field(default_factory=dict)
    sense: dict[str, int] = field(default_factory=lambda: {"A": 1, "B": 1, "C": 1})
    tool_length_mm: float = 0.0
    sphere_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    trip_radius_mm: float = 1.0

    def lines(self) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
        """(axis, point, direction, zero) of the outer then the inner axis."""
        return [(ax, *axis_line(ax, self.pivot_mm[ax], self.pige)) for ax in (self.outer, "C")]

    def tip_in_table(self, joints: np.ndarray) -> np.ndarray:
        """Stylus-tip centre in table coordinates for joint rows (n, 5) [mm, deg] -> (n, 3) [mm]."""
        j = np.atleast_2d(np.asarray(joints, dtype=float))
        y = j[:, :3] - np.array([0.0, 0.0, self.tool_length_mm])
        for k, (ax, q, u, zero) in enumerate(self.lines()):  # undo the outer axis, then the inner one
            y = rotate(y, q, u, self.sense[ax] * np.radians(j[:, 3 + k]) + zero)
        return y

    def hal_lines(self, name: str = "ptt") -> list[str]:
        """Load the component, run it last in the servo thread, net it to the joints and the probe input."""
        return true_machine_hal(COMPONENT_NAME, name, ("joint-r1", "joint-r2"), self.pin_values())

    def pin_values(self) -> dict[str, float]:
        """Every input pin: the emitted model's (pivots, senses, errors) and the twin's (lines)."""
        from pige_sym.kernels import load_kernels

        vals: dict[str, float] = {}
        for k, ax in enumerate((self.outer, "C"), start=1):
            vals |= {f"pivot{k}-{c}": float(v) for c, v in zip("xyz", self.pivot_mm[ax], strict=True)}
            vals[f"sense{k}"] = float(self.sense[ax])
        unknown = set(self.pige) - set(load_kernels(self.code).PARAMETERS)
        if unknown:
            raise AssertionError(f"not parameters of {self.code}: {sorted(unknown)}")
        vals |= {f"err-{i}": float(self.pige.get(n, 0.0)) for i, n in enumerate(load_kernels(self.code).PARAMETERS)}
        for r, (_, q, u, zero) in zip(("r1", "r2"), self.lines(), strict=True):
            vals |= {f"{r}-p{c}": float(v) for c, v in zip("xyz", q, strict=True)}
            vals |= {f"{r}-u{c}": float(v) for c, v in zip("xyz", u, strict=True)}
            vals[f"{r}-zero"] = float(zero)
        vals |= {f"sphere-{c}": float(v) for c, v in zip("xyz", self.sphere_mm, strict=True)}
        return vals | {"tool-length": float(self.tool_length_mm), "trip-radius": float(self.trip_radius_mm)}
