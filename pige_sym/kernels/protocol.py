"""The interface every generated kernel module provides (see :mod:`pige_sym.codegen.emit`).

Shapes: ``n`` poses, ``p`` error parameters, ``b`` basis functions; angles in degrees in the
order of ``ROTARY_AXES``, lengths in mm, deviations in µm, parameters in µm or µrad.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]
Pivots = Mapping[str, ArrayLike] | None


class KernelModule(Protocol):
    """A generated kernel module of one machine."""

    MACHINE_CODE: str
    ROTARY_AXES: tuple[str, ...]
    WORKPIECE_ROTARY: tuple[str, ...]
    TOOL_ROTARY: tuple[str, ...]
    PARAMETERS: tuple[str, ...]
    LOCATION_PARAMETERS: tuple[str, ...]
    ZERO_PARAMETERS: tuple[str, ...]
    MOTION_PARAMETERS: tuple[str, ...]
    UNITS: dict[str, str]
    BASIS: tuple[str, ...]
    SPINDLE_DIRECTION: int
    HAS_DIRECTION_SOLVER: bool
    GENERATOR_HASH: str

    def basis(self, angles_deg: ArrayLike) -> Array:
        """``(n, b)`` trigonometric basis of the rotary angles ``(n, 2)`` [deg]."""
        ...

    def coefficients(self, ball_mm: ArrayLike, pivots_mm: Pivots = None, tool_mm: ArrayLike | None = None) -> Array:
        """``(b, 3, p)`` coefficients with ``jacobian = basis @ coefficients``."""
        ...

    def jacobian(
        self,
        angles_deg: ArrayLike,
        params: ArrayLike | None = None,
        ball_mm: ArrayLike | None = None,
        pivots_mm: Pivots = None,
        tool_mm: ArrayLike | None = None,
    ) -> Array:
        """``(n, 3, p)`` Jacobian of the deviation [µm per µm or µrad]."""
        ...

    def deviation(
        self,
        angles_deg: ArrayLike,
        params: ArrayLike,
        ball_mm: ArrayLike,
        pivots_mm: Pivots = None,
        tool_mm: ArrayLike | None = None,
    ) -> Array:
        """``(n, 3)`` ball-minus-nest deviation [µm] (CONVENTIONS §4)."""
        ...

    def reference_jacobian(
        self, ball_mm: ArrayLike, pivots_mm: Pivots = None, tool_mm: ArrayLike | None = None
    ) -> Array:
        """``(3, p)`` Jacobian at the reference pose."""
        ...

    def motion_jacobian(
        self, angles_deg: ArrayLike, ball_mm: ArrayLike, pivots_mm: Pivots = None, tool_mm: ArrayLike | None = None
    ) -> Array:
        """``(n, 3, 12)`` deviation per error motion of each rotary axis."""
        ...

    def motion_orientation_jacobian(self, angles_deg: ArrayLike) -> Array:
        """``(n, 3, 6k)`` tool-orientation error per unit error motion [µrad per µm or µrad]."""
        ...

    def orientation_jacobian(self, angles_deg: ArrayLike) -> Array:
        """``(n, 3, p)`` tool-orientation error relative to the workpiece [µrad per parameter unit]."""
        ...

    def workpiece_rotation(self, angles_deg: ArrayLike) -> Array:
        """``(n, 3, 3)`` nominal rotation of the workpiece chain."""
        ...

    def tool_rotation(self, angles_deg: ArrayLike) -> Array:
        """``(n, 3, 3)`` nominal rotation of the tool chain."""
        ...

    def linear_commands(
        self, angles_deg: ArrayLike, ball_mm: ArrayLike, pivots_mm: Pivots = None, tool_mm: ArrayLike | None = None
    ) -> Array:
        """``(n, 3)`` X, Y, Z commands [mm] that keep the ball at ``ball_mm`` (RTCP)."""
        ...

    def tool_direction(self, angles_deg: ArrayLike) -> Array:
        """``(n, 3)`` tool direction in the workpiece frame."""
        ...

    def angles_for_direction(
        self, direction: ArrayLike, branch: int = 1, previous_deg: ArrayLike | None = None
    ) -> Array:
        """``(n, 2)`` rotary angles [deg] giving a tool direction."""
        ...
