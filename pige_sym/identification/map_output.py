"""The error maps of ``pige identify --map`` for a reader: a table per axis, and plots with ±2σ bands."""

from __future__ import annotations

import math
from collections.abc import Sequence
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
        lines += ["", "not determined by these data (no value is given):"]
        for u in result.undetermined:
            where = f" at {u.angle_deg:g} deg" if u.angle_deg is not None else ""
            lines.append(f"  {u.motion}{where}: {u.why}; to determine it: {u.remedy}")
    return "\n".join(lines)


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
    axes[0].set_title(f"error motions of {axis} (CONVENTIONS §10, ±2σ bands)")
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
