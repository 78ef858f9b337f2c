"""Which contacts the stylus can reach at a pose: the sphere's stand, its stem and the table.

Geometry (machine frame, mm).  The sphere (centre ``c``, radius ``R``) stands on a stem of radius ``ρ``
along ``s``, the stem direction given in the table frame (default −z: below the sphere) and turned with the
table; the stem meets the table plane ``L`` from the centre.  The stylus is a ball of radius ``r`` whose
shank runs along the stylus axis ``k`` (the stylus frame's z, turned with a head); it is checked over
:attr:`Stem.shank_mm` from the ball centre (what lies beyond — probe body, spindle nose — is not).

A candidate contact of normal ``n`` is left out when

- ``n`` points within the stand cone of ``s`` (no probing move approaches from the stem side): ``stand``;
- anywhere along its path (the point over the start on the clearance plane, the start, the target; each leg
  sampled) the stylus comes within ``ρ + r + margin`` of the stem's axis segment: ``stem``;
- the stylus ball or the end of the checked shank comes within ``margin`` of the table plane: ``table``.

A pose whose stylus axis points below the table plane (``k·s > 0``: the head turns the probe towards the
stem) is refused as a whole (:func:`stylus_elevation_deg`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pige_sym.errors import InputError

REASONS = {"stand": "point at the stand", "stem": "would put the stylus on the stem",
           "table": "would put the stylus on the table"}


@dataclass(frozen=True)
class Stem:
    """The sphere's stem and the stylus shank checked against it.

    Attributes
    ----------
    direction : (3,)
        Stem direction from the sphere centre, in the table frame (unit after normalising; default −z).
    radius_mm : float [mm]
        Stem radius.
    length_mm : float [mm]
        From the sphere centre to the table plane along the stem.
    shank_mm : float [mm]
        Length of the stylus shank checked, from the ball centre along the stylus axis.
    margin_mm : float [mm]
        Clearance kept from the stem and the table.
    """

    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    radius_mm: float = 5.0
    length_mm: float = 100.0
    shank_mm: float = 30.0
    margin_mm: float = 0.5

    def unit(self) -> np.ndarray:
        """The stem direction as a unit vector (table frame); refuses a zero or non-finite one."""
        v = np.asarray(self.direction, dtype=float)
        norm = float(np.linalg.norm(v))
        if not np.isfinite(v).all() or norm == 0.0:
            raise InputError(f"--stem {self.direction}: give a non-zero direction x,y,z (the table frame)")
        return v / norm

    def check(self, sphere_radius_mm: float) -> None:
        """Refuse a stem that cannot hold the sphere or a table inside it (InputError)."""
        if not (0 < self.radius_mm < sphere_radius_mm and self.length_mm > sphere_radius_mm
                and 0 < self.shank_mm <= 500 and self.margin_mm >= 0):
            raise InputError(f"stem: radius {self.radius_mm:g} mm must be in (0, R), length {self.length_mm:g} mm "
                             "(sphere centre to table) more than R, stylus shank in (0, 500] mm")


def stylus_elevation_deg(axis: np.ndarray, stem_dir: np.ndarray) -> float:
    """Elevation of the stylus axis above the table plane [deg] (negative: it points below it)."""
    return float(np.degrees(np.arcsin(np.clip(-axis @ stem_dir, -1.0, 1.0))))


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances from points ``p`` (m, 3) to the segment a-b, shape (m,)."""
    d = b - a
    t = np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return np.asarray(np.linalg.norm(a + t[:, None] * d - p, axis=1))


@lru_cache(maxsize=16)
def _linspace(stop: float, samples: int) -> np.ndarray:
    """``samples + 1`` points evenly from 0 to ``stop``, read-only (:func:`blocked` samples every leg and the shank
    with the same few: a plan asks for them at every candidate contact)."""
    out = np.linspace(0.0, stop, samples + 1)
    out.flags.writeable = False
    return out


def blocked(path: list[np.ndarray], axis: np.ndarray, centre: np.ndarray, stem_dir: np.ndarray, stem: Stem,
            sphere_radius_mm: float, stylus_radius_mm: float, samples: int = 8) -> str | None:
    """``"stem"`` or ``"table"`` when the stylus along ``path`` (stylus-centre points, legs sampled) hits it."""
    points = np.array(path)
    a = points[:-1, None, :]
    tips = (a + _linspace(1.0, samples)[None, :, None] * (points[1:, None, :] - a)).reshape(-1, 3)
    shank = _linspace(stem.shank_mm, samples)
    stylus = (tips[:, None, :] + shank[None, :, None] * axis).reshape(-1, 3)
    below = (stylus - centre) @ stem_dir
    if below.max() > stem.length_mm - stylus_radius_mm - stem.margin_mm:
        return "table"
    # the stem from where it leaves the sphere to the table
    root = centre + stem_dir * np.sqrt(max(sphere_radius_mm**2 - stem.radius_mm**2, 0.0))
    foot = centre + stem_dir * stem.length_mm
    if _point_segment(stylus, root, foot).min() < stem.radius_mm + stylus_radius_mm + stem.margin_mm:
        return "stem"
    return None


def refusal(counts: dict[str, int]) -> str:
    """The candidates left out and why, e.g. ``"3 point at the stand, 1 would put the stylus on the stem"``."""
    return ", ".join(f"{n} {REASONS[k]}" for k, n in counts.items() if n) or "none left out"
