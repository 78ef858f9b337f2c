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

from dataclasses import dataclass
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
        for g in range(grid.n):
            idx = at_angle.get((ax, g), [])
            cols = a[:, idx]
            if not np.any(cols):
                kept[idx] = False
                out.append(Undetermined(f"{ax} maps", float(grid.angles_deg[g]),
                                        f"no measured pose within {_step(grid):g}° of {ax} {grid.angles_deg[g]:g}°",
                                        f"measure poses at {ax} {grid.angles_deg[g]:g}° (pige plan --map {ax})"))
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
                      "decreasing (at an end of the travel that means going beyond it)" if directions else
                      _remedy(ax, seen, len(idx), ax in layout.tool_side))
            for j, m, off in zip(idx, motions, unseen, strict=True):
                if off:
                    kept[j] = False
                    out.append(Undetermined(m.name, float(grid.angles_deg[g]), f"the poses near {ax} "
                                            f"{grid.angles_deg[g]:g}° see {seen} of its {len(idx)} motions; "
                                            f"not seen: {said}", remedy))
    return out, kept


def _remedy(axis: str, rank: int, full: int, tool_side: bool = False) -> str:
    points = "one measured point" if rank <= 3 else "two measured points" if rank < full else "the points"
    where = ("a tool-side axis: the stylus or ball at three positions in the spindle, two tool lengths and an "
             "offset one" if tool_side else "a workpiece-side axis: the sphere or ball at three positions on the "
             "table")
    return (f"{points} per angle: measure at three points per angle, not on one line (for {where}; pige plan "
            f"--map {axis})")


def _step(grid: MapGrid) -> float:
    return float(np.diff(grid.angles_deg).min()) if grid.n > 1 else 360.0
