"""The positioning error of a rotary axis in its commanded angle and sense: what every positioning table holds.

CONVENTIONS §10: commanded θ, the axis stands at ``θ + E + φ(θ)`` (θ = σ·θ_cmd, §9; E the zero-position error,
φ the positioning map, mean left out).  Per direction of approach φ± = φ ± r/2 with r the reversal map
(``φ⁺ − φ⁻``): φ⁺ when θ increases.  In the controller's commanded angle the axis stands at

    θ_cmd + e(θ_cmd, d),   e = σ·(E + φ^{σ·d}(σ·θ_cmd))      [deg]

for a commanded direction of motion d (+1: θ_cmd increasing).  A table that *adds* a value to the commanded
position (LinuxCNC) enters −e; a table that holds the *error* (ISG ``kw.ssfk``) enters +e; SINUMERIK's LEC moves
the axis against the sign of its value, so it enters +e too.  Each table module cites its page.

The map values are the ones to enter (weighed by their uncertainty, :func:`~pige_sym.compensation.controllers.
entered_for_controller`).  A grid angle without a value (the data did not determine it) gets 0 there, which is
what the NC rewrite does with it (no correction at that angle), and every table says so.  E enters only where
the parameter file gives it a value: a probe or an R-test cannot separate the inner axis' E from the set-up
(CONVENTIONS §10), and the file then leaves it without one.  A table whose controller enters E in another entry
(SINUMERIK: the swivel data record's offset angle, :mod:`.siemens_lec`) holds φ alone, so E is entered once.

Nodes: the map's grid angles in the commanded angle, over the travel of a full-turn axis (its grid repeats every
360°) or the grid itself (outside it the nearest end value holds, §10, as in every table here).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pige_sym.compensation.controllers.axis_lines import axis_sense
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.model.error_motions import MapGrid, axis_motions

URAD_TO_DEG = 1e-6 * 180.0 / math.pi


@dataclass(frozen=True)
class PositioningMap:
    """The positioning error of one rotary axis (module docstring).

    Attributes
    ----------
    axis : str
    sense : int
        σ (CONVENTIONS §9).
    grid : MapGrid
        In the CONVENTIONS angle θ [deg].
    mean_urad : (n,) [µrad]
        φ at the grid angles (0 where the file has no value: ``missing_deg``).
    reversal_urad : (n,) [µrad] or None
        ``φ⁺ − φ⁻`` at the grid angles, None when the map is not per direction.
    zero_urad : float or None
        E [µrad] when the file gives it a value.
    missing_deg : tuple of float
        Grid angles θ without a value (entered as 0).
    """

    axis: str
    sense: int
    grid: MapGrid
    mean_urad: np.ndarray
    reversal_urad: np.ndarray | None
    zero_urad: float | None
    missing_deg: tuple[float, ...] = ()

    @property
    def per_direction(self) -> bool:
        return self.reversal_urad is not None

    @property
    def full_turn(self) -> bool:
        return bool(self.grid.full_turn)

    def error_urad(self, theta_deg: np.ndarray, direction: np.ndarray | int = 0, with_zero: bool = True
                   ) -> np.ndarray:
        """``E + φ^d(θ)`` [µrad] at θ (the §10 angle) approached in the θ direction d (+1, −1; 0: the mean); without
        ``with_zero``, ``φ^d(θ)`` (a table whose controller enters E elsewhere)."""
        theta = np.atleast_1d(np.asarray(theta_deg, dtype=float))
        out = self.grid.interpolate(self.mean_urad, theta) + ((self.zero_urad or 0.0) if with_zero else 0.0)
        if self.reversal_urad is not None:
            d = np.broadcast_to(np.sign(np.asarray(direction, dtype=float)), theta.shape)
            out = out + 0.5 * d * self.grid.interpolate(self.reversal_urad, theta)
        return np.asarray(out)

    def commanded_error_deg(self, theta_cmd_deg: np.ndarray, direction_cmd: np.ndarray | int = 0,
                            with_zero: bool = True) -> np.ndarray:
        """e [deg]: the axis stands at θ_cmd + e when θ_cmd is commanded, moving in the commanded direction
        ``direction_cmd`` (+1: θ_cmd increasing; module docstring); without ``with_zero``, e less σE (the part of the
        error a table holds when the controller enters E elsewhere)."""
        s = float(self.sense)
        d = s * np.sign(np.asarray(direction_cmd, dtype=float))
        theta = s * np.asarray(theta_cmd_deg, dtype=float)
        return np.asarray(s * self.error_urad(theta, d, with_zero) * URAD_TO_DEG)

    def nodes_cmd(self, travel_cmd_deg: tuple[float, float] | None = None) -> np.ndarray:
        """The grid angles in the commanded angle, increasing [deg]: over ``travel_cmd_deg`` (lo, hi) for a
        full-turn axis (from the node at or below lo to the node at or above hi), else the grid itself."""
        g = self.sense * np.asarray(self.grid.angles_deg, dtype=float)
        if not self.full_turn:
            return np.sort(g)
        if travel_cmd_deg is None:
            raise InputError(f"{self.axis}: a full-turn axis' table needs the travel it covers")
        lo, hi = travel_cmd_deg
        turns = np.arange(math.floor((lo - g.max()) / 360.0) - 1, math.ceil((hi - g.min()) / 360.0) + 2)
        every = np.sort((g[None, :] + 360.0 * turns[:, None]).ravel())
        first = int(np.searchsorted(every, lo + 1e-9, side="right")) - 1
        last = int(np.searchsorted(every, hi - 1e-9, side="left"))
        return np.asarray(every[max(first, 0): last + 1])

    def uniform_step_deg(self) -> float | None:
        """The grid's step [deg] when its angles are equidistant (a full turn: also across the wrap), else None."""
        g = np.asarray(self.grid.angles_deg, dtype=float)
        if g.size < 2:
            return None
        steps = np.diff(np.append(g, g[0] + 360.0) if self.full_turn else g)
        return float(steps[0]) if np.allclose(steps, steps[0], rtol=0.0, atol=1e-9) else None

    def notes(self, zero_entered_by: str | None = None) -> list[str]:
        """What the table holds and what it does not, in words (every table prints them); ``zero_entered_by``: the
        controller's entry that carries E instead of the table (SINUMERIK's offset angle)."""
        out = [f"{self.axis}: positioning map of {self.grid.n} grid angles (CONVENTIONS §10), sigma = {self.sense:+d} "
               "(§9)" + (", per direction of motion (forward/reverse)" if self.per_direction else ", "
                         "one value for both directions (the map is not per direction)")]
        if self.zero_urad is None:
            out.append(f"{self.axis}: the zero-position error E{self.axis[0]}0{self.axis} has no value in the file "
                       "(not entered: the table holds the map's shape, its mean left out)")
        elif zero_entered_by is not None:
            out.append(f"{self.axis}: the zero-position error E{self.axis[0]}0{self.axis} = {self.zero_urad:.3f} urad "
                       f"is entered by {zero_entered_by}, not by this table (it holds the map's shape, E left out)")
        else:
            out.append(f"{self.axis}: the zero-position error E{self.axis[0]}0{self.axis} = {self.zero_urad:.3f} urad "
                       "is entered with the map")
        if self.missing_deg:
            out.append(f"{self.axis}: no value at theta = {', '.join(f'{a:g}' for a in self.missing_deg)} deg: entered "
                       "as 0 (nothing corrected there, as the NC rewrite does)")
        return out


def positioning_maps(params: CompensationParameters) -> dict[str, PositioningMap]:
    """The positioning error of every rotary axis whose maps hold φ (module docstring), axis → map."""
    maps = params.error_maps
    if maps is None:
        return {}
    out = {}
    for axis, axis_maps in maps.axes.items():
        by_kind = {m.kind: v for m, v in axis_maps.motion_values()}
        if "positioning" not in by_kind and "reversal" not in by_kind:
            continue
        n = axis_maps.grid.n
        mean = np.asarray(by_kind.get("positioning", np.zeros(n)), dtype=float)
        rev = by_kind.get("reversal")
        missing = ~np.isfinite(mean)
        if rev is not None:
            missing |= ~np.isfinite(np.asarray(rev, dtype=float))
        zero_name = f"E{axis[0]}0{axis}"
        zero = params.values.get(zero_name) if zero_name not in params.set_to_zero else None
        out[axis] = PositioningMap(
            axis, axis_sense(params, axis), axis_maps.grid, np.nan_to_num(mean),
            None if rev is None else np.nan_to_num(np.asarray(rev, dtype=float)),
            None if zero is None or not np.isfinite(zero) else float(zero),
            tuple(float(a) for a in np.asarray(axis_maps.grid.angles_deg)[missing]))
    return out


def positioning_names(params: CompensationParameters) -> list[str]:
    """``<axis>:<name>`` of the map values a positioning table carries (φ, φ± and the reversal)."""
    maps = params.error_maps
    if maps is None:
        return []
    out = []
    for axis, axis_maps in maps.axes.items():
        phi = next(m.name for m in axis_motions(axis) if m.kind == "positioning")
        out += [f"{axis}:{n}" for n in axis_maps.values if n in (phi, phi + "+", phi + "-", phi + ":reversal")]
    return out


def entered_map_values(params: CompensationParameters, pm: PositioningMap,
                       printed: Callable[[np.ndarray, int], np.ndarray], zero_elsewhere: bool = False,
                       ) -> dict[str, float]:
    """The map values a positioning table enters, as printed, in the weighing's names (``C:ECC+@30``) [µrad].

    ``printed(theta_cmd_deg, direction_cmd)`` gives the table's value e [deg] at commanded angles for a commanded
    direction of motion (+1, −1; 0 for a table that holds one value for both), as the table prints it (rounded to
    its unit).  From ``e = σ·(E + φ^{σd}(σ·θ_cmd))`` (module docstring) the entered ``φ^d(θ) = σ·e − E``, E the
    zero-position error the table carries with the map (0 when the file has none).  A map per direction in a table
    that holds one value for both directions enters that value as φ⁺ and φ⁻ alike (their mean).  With
    ``zero_elsewhere`` the controller's other entries enter E (SINUMERIK's offset angle) and the table holds φ alone
    (``commanded_error_deg(..., with_zero=False)``): its whole value is counted as φ (``φ = σ·e``) and E is not named
    here, so that the two entries together count E once.
    """
    maps = params.error_maps
    if maps is None or pm.axis not in maps.axes:
        return {}
    axis = pm.axis
    s = pm.sense
    phi = next(m.name for m in axis_motions(axis) if m.kind == "positioning")
    theta = np.asarray(pm.grid.angles_deg, dtype=float)
    zero = 0.0 if zero_elsewhere else (pm.zero_urad or 0.0)

    def entered(direction_theta: int) -> np.ndarray:
        e = printed(s * theta, s * direction_theta)
        return np.asarray(s * np.asarray(e, dtype=float) / URAD_TO_DEG - zero)

    names = maps.axes[axis].values
    out: dict[str, float] = {}
    if phi + "+" in names and phi + "-" in names:
        plus, minus = entered(+1), entered(-1)
        for name, vals in ((phi + "+", plus), (phi + "-", minus)):
            out |= {f"{axis}:{name}@{g:g}": float(v) for g, v in zip(theta, vals, strict=True)}
    elif phi in names:
        out |= {f"{axis}:{phi}@{g:g}": float(v) for g, v in zip(theta, entered(0), strict=True)}
    if pm.zero_urad is not None and not zero_elsewhere:
        out[f"E{axis[0]}0{axis}"] = float(pm.zero_urad)
    return out
