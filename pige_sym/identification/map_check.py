"""The per-angle test of the map fit (:mod:`~pige_sym.identification.maps`): which motions the rows near each
grid angle see, and what is refused where they do not.

Before the joint fit, every grid angle's motions are tested alone (the other values held): the combinations
the rows near that angle do not see (a null direction of their scaled columns, as the PIGEs' rule) take the
values they touch out of the map.  Those values are ``null``, with the combinations (their canonical basis,
:mod:`~pige_sym.identification.canonical`) and what would determine them (CONVENTIONS §10: one measured point
per angle gives three numbers, the motions have six).  The planner (``pige plan --map``) runs the same test on
planned poses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.identification.spectrum import solve_scaled
from pige_sym.model.error_motions import MapGrid, Motion


@dataclass
class Undetermined:
    """A map value (or a whole motion) the data do not determine, why, and what would determine it."""

    motion: str
    angle_deg: float | None
    why: str
    remedy: str

    def to_dict(self) -> dict[str, Any]:
        return {"motion": self.motion, "angle_deg": self.angle_deg, "why": self.why, "remedy": self.remedy}


@dataclass
class MapLayout:
    """The map's unknowns before the projection: per axis its grid and motions, per column (motion, node), and
    the mapped axes on the tool side (their measured point is fixed in the stylus or the R-test ball)."""

    grids: dict[str, MapGrid]
    motions: dict[str, list[Motion]]
    columns: list[tuple[Motion, int]]
    tool_side: tuple[str, ...] = ()
    measured_deg: dict[str, np.ndarray] = field(default_factory=dict)

    def names(self) -> list[str]:
        return [f"{m.name}@{self.grids[m.axis].angles_deg[g]:g}" for m, g in self.columns]


def local_check(blocks: list[Any], sigmas: list[float], p: int,
                layout: MapLayout) -> tuple[list[Undetermined], np.ndarray]:
    """Per grid angle, the motions its rows see alone (module docstring); returns the refusals and a mask
    (M,) of the map columns that stay reported."""
    a = np.vstack([b.design[:, p:] / s for b, s in zip(blocks, sigmas, strict=True)])
    kept = np.ones(len(layout.columns), dtype=bool)
    out: list[Undetermined] = []
    at_angle: dict[tuple[str, int], list[int]] = {}  # each grid angle's columns, found in one pass
    for j, (m, g) in enumerate(layout.columns):
        at_angle.setdefault((m.axis, g), []).append(j)
    for ax, grid in layout.grids.items():
        coarse: list[float | None] = []  # the files' own step, found once per axis (at its first unseen angle)
        for g in range(grid.n):
            idx = at_angle.get((ax, g), [])
            cols = a[:, idx]
            if not np.any(cols):
                kept[idx] = False
                if not coarse:
                    coarse.append(measured_step(layout.measured_deg[ax], _step(grid), grid.full_turn)
                                  if ax in layout.measured_deg else None)
                out.append(Undetermined(f"{ax} maps", float(grid.angles_deg[g]), *_no_pose(ax, grid, g, coarse[0])))
                continue
            sol = solve_scaled(cols.T @ cols, np.zeros(len(idx)), 0.0)
            seen = len(idx) - sol.null_space.dimension  # near-null directions are not seen (the PIGEs' rule)
            if seen == len(idx):
                continue
            motions = [layout.columns[j][0] for j in idx]
            unseen = sol.null_space.involved()
            said = "; ".join(c.text() for c in sol.null_space.combinations([m.name for m in motions]))
            directions = all(m.kind in ("positioning", "reversal") for m, off in zip(motions, unseen, strict=True)
                             if off)
            remedy = (f"approach {ax} {grid.angles_deg[g]:g}° from both sides, with the angle increasing and "
                      "decreasing (at an end of the travel that means going beyond it; or map it for both directions "
                      "at once, without --map-per-direction)" if directions else
                      _remedy(ax, seen, len(idx), ax in layout.tool_side))
            for j, m, off in zip(idx, motions, unseen, strict=True):
                if off:
                    kept[j] = False
                    out.append(Undetermined(m.name, float(grid.angles_deg[g]), f"the poses near {ax} "
                                            f"{grid.angles_deg[g]:g}° see {seen} of its {len(idx)} motions; "
                                            f"not seen: {said}", remedy))
    return out, kept


def direction_notes(items: Sequence[tuple[str, Any]], layout: MapLayout, spec: Any,
                    axes: tuple[str, ...]) -> list[str]:
    """A note per mapped axis not mapped per direction whose grid angles the files approach from both directions
    (at least half of them): its positioning map is then the mean of the two, said so."""
    from pige_sym.model.trajectories import approach_directions

    out = []
    for ax, grid in layout.grids.items():
        if ax in spec.per_direction:
            continue
        k = axes.index(ax)
        seen: dict[int, set[int]] = {}
        for _, x in items:
            a = np.asarray(x.angles_deg, dtype=float)
            appr = approach_directions(a)[:, k]
            at = np.argmax(grid.weights(a[:, k]), axis=1)
            exact = np.isclose(grid.weights(a[:, k]).max(axis=1), 1.0)
            for node, d, ok in zip(at, appr, exact, strict=True):
                if ok and d != 0:
                    seen.setdefault(int(node), set()).add(int(d))
        both = sum(len(d) == 2 for d in seen.values())
        if grid.n and both >= max(2, grid.n // 2):
            out.append(f"the files approach {both} of {ax}'s {grid.n} grid angles from both directions: its "
                       f"positioning map is the mean of the two here; --map-per-direction {ax} maps each direction and "
                       "the reversal")
    return out


def range_notes(layout: MapLayout) -> list[str]:
    """A note per mapped axis that does not turn fully: over its range, a motion's constant and first harmonic are
    the PIGEs' (and the set-up's), and what the true maps hold of them is in the PIGEs, not in the maps."""
    return [f"{ax} is mapped over {grid.angles_deg[0]:g}..{grid.angles_deg[-1]:g}° only: over that range, the part of "
            f"each of its motions that is a constant or a first harmonic is not separable from the PIGEs (CONVENTIONS "
            f"§10), so the PIGEs hold it (of {ax}, and of the axis {ax} carries) and differ from a fit without maps by "
            "it; over a full turn, harmonics 2 and up are separable (docs/maps.md, 'What the PIGEs hold')"
            for ax, grid in layout.grids.items() if not grid.full_turn and grid.n > 1]


def measured_step(angles_deg: np.ndarray, step_deg: float, full_turn: bool) -> float | None:
    """The coarsest multiple of ``step_deg`` that every measured angle is a multiple of [deg] (the grid the files were
    measured on), when it is coarser than ``step_deg``; else None."""
    a = np.asarray(angles_deg, dtype=float)
    if full_turn:
        a = np.mod(a, 360.0)
    best = None
    for k in range(2, int(360.0 / step_deg) + 1):
        s = k * step_deg
        if full_turn and abs(360.0 / s - round(360.0 / s)) > 1e-9:
            continue
        r = np.mod(a + 1e-7, s)
        if np.all(r < 2e-7):
            best = s
    return best


def _no_pose(ax: str, grid: MapGrid, g: int, coarse: float | None) -> tuple[str, str]:
    """Why and remedy of a grid angle no measured pose comes near: the files' own step ``coarse``
    (:func:`measured_step`), when they were measured on a coarser grid (identify on it), else poses at that angle."""
    angle = float(grid.angles_deg[g])
    why = f"no measured pose within {_step(grid):g}° of {ax} {angle:g}°"
    if coarse is not None:
        return (f"{why}: the files measure {ax} every {coarse:g}°, the grid is every {_step(grid):g}°",
                f"identify on the files' grid: --map-step {coarse:g} (or measure poses at {ax} {angle:g}° too)")
    return why, f"measure poses at {ax} {angle:g}° too (the map test's plan puts poses at every grid angle)"


def _combination(vec: np.ndarray, motions: list[Motion]) -> str:
    order = np.argsort(-np.abs(vec))
    lead = vec[order[0]]
    terms = [f"{'-' if vec[j] / lead < 0 else '+'} {abs(vec[j] / lead):.3g}·{motions[j].name}" for j in order
             if abs(vec[j]) > 1e-3]
    text = " ".join(terms)
    return text[2:] if text.startswith("+ ") else text


def _remedy(axis: str, rank: int, full: int, tool_side: bool = False) -> str:
    """What would determine the motions the rows near one grid angle do not see (module docstring): more measured
    points per angle, three not on one line."""
    where = ("for a tool-side axis: the stylus or ball at three positions in the spindle, two tool lengths and an "
             "offset one" if tool_side else "for a workpiece-side axis: the sphere or ball at three positions on the "
             "table")
    if rank <= 3:
        return (f"one measured point sees 3 of the motions at each {axis} angle: measure at three points per angle, "
                f"not on one line ({where}; the map test's plan proposes them)")
    if rank < full:
        return (f"two measured points leave the rotation about the line through them unseen at each {axis} angle: "
                f"add a third point off that line, three points per angle not on one line ({where}; the map test's "
                "plan proposes them)")
    return f"measure at three points per angle, not on one line ({where}; the map test's plan proposes them)"


def _step(grid: MapGrid) -> float:
    return float(np.diff(grid.angles_deg).min()) if grid.n > 1 else 360.0
