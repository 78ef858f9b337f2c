"""The error maps of ``pige identify --map`` for a reader: a table per axis, and plots with ±2σ bands."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pige_sym.identification.maps import MapResult


def format_maps(result: MapResult) -> str:
    """The text output of ``pige identify --map``: per axis a table (angles down, motions across), then what
    is not determined and why."""
    lines: list[str] = []
    for ax, m in result.maps.items():
        names = [mo.name for mo in m.motions]
        units = {mo.name: mo.unit for mo in m.motions}
        head = f"{'angle [deg]':>12}" + "".join(f"{n + ' [' + units[n] + ']':>22}" for n in names)
        lines += ["", f"error motions of {ax} (CONVENTIONS §10: value ± std; '—' not determined; "
                      f"{'full turn' if m.grid.full_turn else 'ends held outside the grid'})", head]
        for g, angle in enumerate(m.grid.angles_deg):
            cells = []
            for n in names:
                v, s = m.value[n][g], m.std[n][g]
                cells.append(f"{v:>+12.3f} ± {s:<7.3f}" if math.isfinite(v) else f"{'—':>22}")
            lines.append(f"{angle:>12g}" + "".join(f"{c:>22}" for c in cells))
    if result.undetermined:
        lines += ["", "not determined by these data (no value is given, and none is corrected: a map value without a "
                      "number corrects nothing at its angle):"]
        lines += [f"  {group.text()}" for group in group_undetermined(result)]
    if result.notes:
        lines += [""] + [f"note: {n}" for n in result.notes]
    return "\n".join(lines)


@dataclass
class UndeterminedGroup:
    """Map values not determined for the same reason, with the same remedy: one line for many."""

    axis: str
    motions: list[str]
    angles_deg: list[float]
    grid_deg: list[float]
    why: str
    remedy: str

    def where(self) -> str:
        """``at every grid angle (0–330°, 12 angles)`` or ``at 15, 45°``."""
        if not self.angles_deg:
            return ""
        if len(self.angles_deg) == len(self.grid_deg) and len(self.grid_deg) > 2:
            return (f" at every grid angle ({self.grid_deg[0]:g}–{self.grid_deg[-1]:g}°, {len(self.grid_deg)} "
                    "angles)")
        return " at " + ", ".join(f"{a:g}" for a in self.angles_deg) + "°"

    def text(self) -> str:
        what = ", ".join(self.motions)
        return f"{what}{self.where()}: {self.why}; to determine {'it' if self.count == 1 else 'them'}: {self.remedy}"

    @property
    def count(self) -> int:
        return len(self.motions) * max(len(self.angles_deg), 1)


def _angle_free(text: str, axis: str) -> str:
    return re.sub(rf"\b{re.escape(axis)} -?\d+(\.\d+)?°", f"{axis} θ°", text)


def group_undetermined(result: MapResult) -> list[UndeterminedGroup]:
    """The undetermined map values grouped by axis, reason and remedy (the angle taken out of both; the combination a
    grid angle does not see kept from its first angle, as an example): one line for what the same setups miss."""
    axis_of = {mo.name: ax for ax, m in result.maps.items() for mo in m.motions}
    axis_of |= {name: ax for ax, m in result.maps.items() for name in m.value}
    groups: dict[tuple[str, str, str], UndeterminedGroup] = {}
    for u in result.undetermined:
        axis = u.motion.split()[0] if u.motion.endswith(" maps") else axis_of.get(u.motion, "")
        base, _, seen = u.why.partition("; not seen: ")
        key = (axis, _angle_free(base, axis), _angle_free(u.remedy, axis))
        grid = [float(a) for a in result.maps[axis].grid.angles_deg] if axis in result.maps else []
        if key not in groups:
            example = f" (not seen at {axis} {u.angle_deg:g}°: {seen})" if seen and u.angle_deg is not None else ""
            why = key[1].replace(f"{axis} θ°", "each angle") + example
            groups[key] = UndeterminedGroup(axis, [], [], grid, why, key[2].replace(f"{axis} θ°", "those angles"))
        g = groups[key]
        if u.motion not in g.motions:
            g.motions.append(u.motion)
        if u.angle_deg is not None and u.angle_deg not in g.angles_deg:
            g.angles_deg.append(float(u.angle_deg))
    return list(groups.values())


def plot_paths(axes: Sequence[str], folder: str) -> list[Path]:
    """The files :func:`plot_maps` writes: ``map_<axis>.png`` per axis."""
    return [Path(folder) / f"map_{ax}.png" for ax in axes]


def map_figure(result: MapResult, axis: str) -> Any:
    """One axis' maps with their ±2σ bands: translations [µm] above, rotations [µrad] below (a figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = result.maps[axis]
    fig, axes = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    for panel, unit in zip(axes, ("um", "urad"), strict=True):
        for mo in (x for x in m.motions if x.unit == unit):
            v, s = m.value[mo.name], m.std[mo.name]
            line = panel.plot(m.grid.angles_deg, v, marker="o", ms=3, label=mo.name)[0]
            panel.fill_between(m.grid.angles_deg, v - 2 * s, v + 2 * s, color=line.get_color(), alpha=0.2)
        panel.set_ylabel(f"[{unit}]")
        panel.grid(alpha=0.3)
        if panel.get_legend_handles_labels()[0]:
            panel.legend(fontsize=8, ncol=3)
    axes[0].set_title(f"error motions of the {axis} axis (±2σ bands)", y=1.0)
    axes[1].set_xlabel(f"{axis} [deg]")
    return fig


def plot_maps(result: MapResult, folder: str) -> list[str]:
    """:func:`map_figure` of each axis as PNG in ``folder`` (checked by the caller with
    :func:`pige_sym.files.check_output`)."""
    import matplotlib.pyplot as plt

    Path(folder).mkdir(parents=True, exist_ok=True)
    written = []
    for ax in result.maps:
        fig = map_figure(result, ax)
        path = Path(folder) / f"map_{ax}.png"
        fig.savefig(path, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(str(path))
    return written
