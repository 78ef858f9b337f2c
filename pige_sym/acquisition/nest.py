"""Nest geometry: from three sensor readings to the ball-centre displacement.

Frame and sign
--------------
The nest is fixed to the table, so its sensors read in the workpiece frame W
(CONVENTIONS §4).  Sensor i has a unit vector ``n_i`` (row i of ``directions``)
pointing from the nominal ball centre towards its contact point: moving the ball
by ``d`` along ``+n_i`` pushes the probe in and the reading increases.

Probe models
------------
``flat``
    A flat-faced probe touches the ball on a plane normal to ``n_i``; its reading is
    exactly linear: ``r_i = n_i·d``.
``point``
    A probe with a spherical tip of radius ``r_tip`` (0 for a point) moves along its
    axis ``n_i`` through the nominal ball centre and touches a ball of radius ``R``.
    With ``ρ = R + r_tip`` the tip centre sits at distance ``s`` with
    ``|s·n_i − d| = ρ``, so the reading is the exact sphere-contact law::

        r_i = n_i·d + sqrt(ρ² − |d_⊥i|²) − ρ  ≈  n_i·d − |d_⊥i|² / (2ρ),
        d_⊥i = d − (n_i·d) n_i

    (the correction is second order in the lateral displacement: −0.39 µm for
    100 µm lateral on a 25.4 mm ball).

Inversion
---------
:meth:`NestGeometry.displacement` solves ``N d = r + c(d)`` with
``c_i = ρ_i − sqrt(ρ_i² − |d_⊥i|²)`` by fixed-point iteration from the linear
solution ``d = N⁻¹ r``; the contraction factor is about ``|d|/ρ`` (1e-2 for a
0.1 mm displacement), so a few iterations reach 1e-9 µm.  The sensor directions
need not be orthogonal; they must be linearly independent.

Specification (``--nest``)
--------------------------
``default``
    Cube-corner nest: three flat probes at azimuths 0°, 120°, 240° about the nest Z
    axis, each axis ``tilt`` = 35.264° below the horizontal (mutually orthogonal).
``key=value,...``
    Keys: ``tilt`` [deg] (angle of the sensor axes below the horizontal, default
    35.264), ``azimuth`` [deg] (of sensor 1; the others follow at +120° and +240°,
    default 0), ``probe`` (``flat`` or ``point``), ``ball_diameter`` [mm] (default
    25.4), ``tip_radius`` [mm] (default 0).  Example:
    ``tilt=45,probe=point,ball_diameter=25.4``.
a JSON file
    ``{"directions": [[x,y,z], [x,y,z], [x,y,z]], "probe": "flat" | "point" | [three],
    "ball_diameter_mm": 25.4, "tip_radius_mm": 0}`` (directions normalised).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import FileFormatError, InputError
from pige_sym.measurements.schema import read_json_file

CUBE_CORNER_TILT_DEG = math.degrees(math.atan(1 / math.sqrt(2)))  # 35.264°
PROBES = ("flat", "point")


@dataclass(frozen=True)
class NestDocument:
    """Schema of a nest JSON file (:mod:`pige_sym.measurements.schema`)."""

    directions: list[list[float]] = field(metadata={"length": 3, "max_abs": 1e6})
    probe: str | list[str] = field(default="flat", metadata={"length": 3})
    ball_diameter_mm: float = field(default=25.4, metadata={"max_abs": 1e3})
    tip_radius_mm: float = field(default=0.0, metadata={"max_abs": 1e3})


@dataclass(frozen=True)
class NestGeometry:
    """Sensor directions and probe model of a three-sensor nest.

    Attributes
    ----------
    directions : ndarray, shape=(3, 3)
        Unit vector of each sensor (rows), nest frame W.
    contact_radius_mm : ndarray, shape=(3,) [mm]
        ``ρ = R + r_tip`` of each point probe, ``inf`` for flat probes.
    description : str
        Text for the file's ``nest:`` metadata.
    """

    directions: np.ndarray
    contact_radius_mm: np.ndarray
    description: str = "custom"

    def __post_init__(self) -> None:
        n = np.asarray(self.directions, dtype=float)
        if n.shape != (3, 3) or not np.isfinite(n).all():
            raise InputError(f"nest: directions must be three finite 3-vectors, got shape {n.shape}")
        norms = np.linalg.norm(n, axis=1)
        if (norms < 1e-12).any():
            raise InputError("nest: a sensor direction is the zero vector")
        n = n / norms[:, None]
        if abs(np.linalg.det(n)) < 1e-3:
            raise InputError("nest: the three sensor directions are (nearly) coplanar; the ball position is "
                             "not determined")
        rho = np.broadcast_to(np.asarray(self.contact_radius_mm, dtype=float), (3,)).copy()
        if (rho <= 0).any() or np.isnan(rho).any():
            raise InputError("nest: contact radius (ball radius + tip radius) must be > 0 mm")
        object.__setattr__(self, "directions", n)
        object.__setattr__(self, "contact_radius_mm", rho)

    @property
    def linear(self) -> bool:
        """True when every probe is flat (readings exactly linear in d)."""
        return bool(np.isinf(self.contact_radius_mm).all())

    def _correction(self, d_um: np.ndarray) -> np.ndarray:
        """``c_i(d) = ρ_i − sqrt(ρ_i² − |d_⊥i|²)`` [µm], shape=(..., 3)."""
        proj = d_um @ self.directions.T  # (..., 3)
        lat2 = np.maximum((d_um**2).sum(axis=-1, keepdims=True) - proj**2, 0.0)
        rho = self.contact_radius_mm * 1000.0
        out = np.zeros_like(proj)
        point = np.isfinite(rho)
        if point.any():
            r = rho[point]
            lat = lat2[..., point]
            if (lat >= r**2).any():
                raise InputError("nest: displacement larger than the contact radius; the ball is off the probe")
            out[..., point] = lat / (r + np.sqrt(r**2 - lat))  # = ρ − sqrt(ρ² − lat²), without cancellation
        return out

    def readings(self, d_um: Any) -> np.ndarray:
        """Sensor readings of a ball-centre displacement (forward model).

        Parameters
        ----------
        d_um : array_like, shape=(..., 3) [µm]
            Ball centre minus nest centre, nest frame W.

        Returns
        -------
        ndarray, shape=(..., 3) [µm]
        """
        d = np.asarray(d_um, dtype=float)
        return d @ self.directions.T - self._correction(d)

    def displacement(self, readings_um: Any, *, tol_um: float = 1e-10, max_iter: int = 50) -> np.ndarray:
        """Ball-centre displacement from zeroed readings (inverse model).

        Parameters
        ----------
        readings_um : array_like, shape=(..., 3) [µm]
            Readings minus the readings at the reference pose.

        Returns
        -------
        ndarray, shape=(..., 3) [µm], nest frame W.
        """
        r = np.asarray(readings_um, dtype=float)
        inv = np.linalg.inv(self.directions)
        d = r @ inv.T
        if self.linear:
            return d
        for _ in range(max_iter):
            new = (r + self._correction(d)) @ inv.T
            step = np.abs(new - d).max() if new.size else 0.0
            d = new
            if step <= tol_um:
                return d
        raise InputError("nest: sensor-to-ball conversion did not converge (readings inconsistent with the geometry)")


def tripod(tilt_deg: float = CUBE_CORNER_TILT_DEG, azimuth_deg: float = 0.0, probe: str = "flat",
           ball_diameter_mm: float = 25.4, tip_radius_mm: float = 0.0, description: str | None = None) -> NestGeometry:
    """Three sensors 120° apart about the nest Z axis, tilted ``tilt_deg`` below the horizontal."""
    if probe not in PROBES:
        raise InputError(f"nest: probe must be 'flat' or 'point', got {probe!r}")
    if not 0 < tilt_deg < 90:
        raise InputError(f"nest: tilt must be between 0 and 90 degrees, got {tilt_deg:g}")
    if ball_diameter_mm <= 0 or tip_radius_mm < 0:
        raise InputError("nest: ball_diameter must be > 0 and tip_radius >= 0 mm")
    az = np.radians(azimuth_deg + np.array([0.0, 120.0, 240.0]))
    el = math.radians(tilt_deg)
    dirs = np.column_stack([math.cos(el) * np.cos(az), math.cos(el) * np.sin(az), np.full(3, -math.sin(el))])
    rho = ball_diameter_mm / 2 + tip_radius_mm if probe == "point" else math.inf
    desc = description or (f"tripod tilt={tilt_deg:g} azimuth={azimuth_deg:g} probe={probe}"
                           + (f" ball_diameter={ball_diameter_mm:g} tip_radius={tip_radius_mm:g}"
                              if probe == "point" else ""))
    return NestGeometry(dirs, np.full(3, rho), desc)


def default_nest() -> NestGeometry:
    """The cube-corner nest with flat probes."""
    return tripod(description="default (cube-corner, flat probes)")


def parse_nest(spec: str | None) -> NestGeometry:
    """Nest geometry from ``default``, ``key=value,...`` or a JSON file (module docstring)."""
    if spec is None or spec.strip() in ("", "default"):
        return default_nest()
    if os.path.exists(spec):
        doc = read_json_file(spec, NestDocument, "nest file")
        probes = list(doc.probe) if isinstance(doc.probe, list) else [doc.probe] * 3
        if any(p not in PROBES for p in probes):
            raise FileFormatError(spec, None, "probe must be 'flat', 'point' or a list of three of them")
        if not doc.ball_diameter_mm > 0 or doc.tip_radius_mm < 0:
            raise FileFormatError(spec, None, "ball_diameter_mm must be > 0 and tip_radius_mm >= 0")
        radius = doc.ball_diameter_mm / 2 + doc.tip_radius_mm
        rho = np.array([radius if p == "point" else math.inf for p in probes])
        return NestGeometry(np.array(doc.directions, dtype=float), rho, f"file {spec}")
    opts: dict[str, Any] = {}
    names = {"tilt": "tilt_deg", "azimuth": "azimuth_deg", "probe": "probe", "ball_diameter": "ball_diameter_mm",
             "tip_radius": "tip_radius_mm"}
    for part in filter(None, (p.strip() for p in spec.split(","))):
        key, eq, value = part.partition("=")
        key = key.strip()
        if not eq or key not in names:
            raise InputError(f"--nest: expected 'default', a JSON file or key=value with keys "
                             f"{', '.join(names)}; got {part!r}")
        if key == "probe":
            opts["probe"] = value.strip()
        else:
            try:
                opts[names[key]] = float(value)
            except ValueError:
                raise InputError(f"--nest: {key}={value!r} is not a number") from None
    return tripod(**opts, description=f"tripod {spec.strip()}")
