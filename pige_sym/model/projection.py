"""Excitation projection (CONVENTIONS §5): which direction(s) of the deviation are observed.

Specification grammar (``--projection``)::

    spec := "xyz"                       full 3-D deviation
          | "x" | "y" | "z"             one machine (measurement-frame) axis
          | NUM "," NUM "," NUM         a direction vector (normalised)
          | "htm:" NUM{9|16} ["@" AXES] the measurement frame transformed by a rotation (3x3,
                                        row-major) or HTM (4x4, row-major; translation ignored,
                                        deviations are differences): the data are expressed in
                                        the new frame, whose axes are the matrix columns; AXES
                                        (default "xyz") selects which new axes are observed.

A projection is a set of m unit directions n_i in the measurement frame; the
observation of a point is ``n_i · d`` for each i (m = 3 with the identity for ``xyz``).
The same projection is applied to the data and to the model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pige_sym.errors import InputError

_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class Projection:
    """Observed directions of the deviation.

    Attributes
    ----------
    name : str
        The specification it was parsed from (used in reports and JSON).
    directions : ndarray, shape=(m, 3)
        Unit directions in the measurement frame, one per observed component.
    """

    name: str
    directions: np.ndarray

    @property
    def is_full(self) -> bool:
        """True when the projection keeps the full 3-D information (rank 3)."""
        return self.directions.shape[0] == 3 and abs(np.linalg.det(self.directions)) > 1 - 1e-9

    def apply_data(self, deviation_um: np.ndarray) -> np.ndarray:
        """Project deviations, shape=(n, 3) → (n, m) [µm]."""
        return np.asarray(deviation_um) @ self.directions.T

    def apply_model(self, jacobian: np.ndarray) -> np.ndarray:
        """Project a Jacobian, shape=(n, 3, P) → (n, m, P)."""
        return np.einsum("mi,nip->nmp", self.directions, jacobian)


def _floats(text: str, what: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"projection {what!r}: expected comma-separated numbers") from None


def parse_projection(spec: str | Projection) -> Projection:
    """Parse a projection specification (see the module docstring)."""
    if isinstance(spec, Projection):
        return spec
    s = spec.strip().lower()
    if s == "xyz":
        return Projection("xyz", np.eye(3))
    if s in _AXES:
        return Projection(s, np.eye(3)[[_AXES[s]]])
    if s.startswith("htm:"):
        body, _, axes = s[4:].partition("@")
        vals = _floats(body, spec)
        if len(vals) == 16:
            mat = np.array(vals).reshape(4, 4)[:3, :3]
        elif len(vals) == 9:
            mat = np.array(vals).reshape(3, 3)
        else:
            raise InputError(f"projection {spec!r}: an HTM needs 9 (3x3) or 16 (4x4) numbers, got {len(vals)}")
        if not np.allclose(mat.T @ mat, np.eye(3), atol=1e-6):
            raise InputError(f"projection {spec!r}: the rotation part is not orthonormal")
        axes = axes or "xyz"
        if not axes or any(a not in _AXES for a in axes):
            raise InputError(f"projection {spec!r}: '@' must be followed by axes among x, y, z")
        return Projection(spec.strip(), np.array([mat[:, _AXES[a]] for a in axes]))
    if "," in s:
        vals = _floats(s, spec)
        if len(vals) != 3:
            raise InputError(f"projection {spec!r}: a direction needs 3 numbers")
        v = np.array(vals)
        norm = np.linalg.norm(v)
        if norm == 0:
            raise InputError(f"projection {spec!r}: the zero vector has no direction")
        return Projection(spec.strip(), (v / norm)[None, :])
    raise InputError(
        f"unknown projection {spec!r}: use x, y, z, xyz, a vector 'a,b,c' or 'htm:<9 or 16 numbers>[@axes]'"
    )


def direction_sweep(n: int = 12, plane: str = "xy") -> list[Projection]:
    """Projections on n directions evenly spread over 180° in a coordinate plane."""
    i, j = _AXES[plane[0]], _AXES[plane[1]]
    out = []
    for k in range(n):
        ang = np.pi * k / n
        v = np.zeros(3)
        v[i], v[j] = np.cos(ang), np.sin(ang)
        out.append(Projection(f"{plane}@{np.degrees(ang):.0f}deg", v[None, :]))
    return out
