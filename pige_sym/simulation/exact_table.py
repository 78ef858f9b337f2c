"""Exact rigid-body motion of a rotary table with PIGEs: no first-order approximation.

For machines whose rotary axes are all on the workpiece side (``wC'A'b…``, ``wC'B'b…``), a table point
``p`` (machine frame at the reference pose) is carried, from the workpiece towards the bed, by each axis in
turn: ``x ↦ c + R(u, −(θ + E₀))·(x − c)`` with the axis line through ``c = pivot + δ`` in direction
``u + ε × u`` (normalised) and the zero-position error ``E₀`` (CONVENTIONS §2–3: ``δ`` the position errors
[µm], ``ε`` the orientation errors [µrad] of that axis, the table turning by ``−θ`` so that the tool turns
by ``+θ`` relative to the workpiece).  The linear axes are perfect: a commanded position is reached.

:func:`table_point` gives where a table point really is; :func:`nominal_table_point` where the controller
thinks it is (no errors).  The difference of a tool point commanded onto a table point and that point's
true position is the R-test deviation without linearisation (``tests/test_ballbar.py`` checks it against the
generated kernels' first-order model).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from pige_sym.codegen.machine_code import MachineStructure, parse_machine_code
from pige_sym.errors import InputError

_DIRECTION = {"A": 0, "B": 1, "C": 2}


def _rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices about a unit ``axis`` by ``angle`` [rad], shape=(n, 3, 3) (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def _axis_line(axis: str, values: dict[str, float], pivot: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Point [mm], unit direction and zero-position error [rad] of an axis line with its errors."""
    d = _DIRECTION[axis[0]]
    u = np.eye(3)[d]
    delta = np.array([values.get(f"E{'XYZ'[k]}0{axis}", 0.0) if k != d else 0.0 for k in range(3)]) * 1e-3
    eps = np.array([values.get(f"E{'ABC'[k]}0{axis}", 0.0) if k != d else 0.0 for k in range(3)]) * 1e-6
    direction = u + np.cross(eps, u)
    return pivot + delta, direction / np.linalg.norm(direction), values.get(f"E{axis[0]}0{axis}", 0.0) * 1e-6


@lru_cache(maxsize=64)
def _structure(machine: str) -> MachineStructure:
    """The parsed machine code, remembered (immutable; a ballbar plan asks again for every setup it tries)."""
    return parse_machine_code(machine)


def table_point(machine: str, angles_deg: np.ndarray, point_mm: np.ndarray, values: dict[str, float] | None = None,
                pivots_mm: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """True machine position of a table point at each pose, shape=(n, 3) [mm] (module docstring).

    Parameters
    ----------
    machine : str
    angles_deg : ndarray, shape=(n, k) [deg]
        Commanded rotary angles, columns in the kernels' ``ROTARY_AXES`` order.
    point_mm : ndarray, shape=(3,) [mm]
        The table point at the reference pose, machine frame.
    values : dict of str to float
        PIGEs and zero-position errors [µm, µrad]; None: the nominal machine.
    pivots_mm : dict of axis to (3,) [mm], optional
        Nominal pivots (default: every axis line through the origin).
    """
    st = _structure(machine)
    if st.tool_axes and any(a.kind == "rotary" for a in st.tool_axes):
        raise InputError(f"{st.canonical}: the exact table model needs every rotary axis on the workpiece side")
    order = [a.name for a in st.rotary_axes]
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    x = np.empty((a.shape[0], 3))
    x[:] = np.asarray(point_mm, dtype=float)  # one row per pose (np.tile's bookkeeping cost more than the work)
    for ax in (w.name for w in st.workpiece_axes if w.kind == "rotary"):  # from the workpiece towards the bed
        pivot = np.asarray((pivots_mm or {}).get(ax, np.zeros(3)), dtype=float)
        c, u, zero = _axis_line(ax, values or {}, pivot) if values else (pivot, np.eye(3)[_DIRECTION[ax[0]]], 0.0)
        rot = _rotation(u, -(np.radians(a[:, order.index(ax)]) + zero))
        x = c + np.einsum("nij,nj->ni", rot, x - c)
    return x


def nominal_table_point(machine: str, angles_deg: np.ndarray, point_mm: np.ndarray,
                        pivots_mm: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Where the controller (nominal kinematics) puts a table point, shape=(n, 3) [mm]."""
    return table_point(machine, angles_deg, point_mm, None, pivots_mm)
