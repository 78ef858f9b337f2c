"""Residual plots of a diagnosis, in the frames of the rotary axes.

:func:`axis_frames` gives per rotary axis its radial, tangential and axial unit vectors at every pose
(machine frame); :func:`residual_plots` draws the residuals of the PIGE fit and of the final model
against each axis angle in those components [µm] (matplotlib, PNG files).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.diagnosis.results import DiagnosisResult
from pige_sym.errors import InputError
from pige_sym.files import make_folder
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.model.effects import EffectContext
from pige_sym.plotting import fixed_layout, outside_legend_room, save_png


def axis_frames(m: Measurement, kern: Any) -> dict[str, np.ndarray]:
    """Per workpiece-side rotary axis and row, unit vectors (radial, tangential, axial) in M, shape=(n, 3, 3).

    Axial is the axis direction at the pose, radial points from the axis line to the
    nest (ball) position, tangential = axial × radial.  (Tool-side axes: not yet.)
    """
    structure = m.structure
    angles = dict(zip(kern.ROTARY_AXES, np.radians(m.angles_deg).T, strict=True))
    nest = kern.linear_commands(m.angles_deg, m.ball_mm, m.pivots_mm or None, m.tool_mm)
    out = {}
    n = m.n_rows

    def rot(axis: str, sign: int) -> np.ndarray:
        d = "ABC".index(axis[0])
        th = sign * angles[axis]
        c, s = np.cos(th), np.sin(th)
        r = np.tile(np.eye(3), (n, 1, 1))
        i, j = [(1, 2), (2, 0), (0, 1)][d]
        r[:, i, i], r[:, i, j], r[:, j, i], r[:, j, j] = c, -s, s, c
        return r

    wp = [a for a in structure.workpiece_axes if a.kind == "rotary"]
    for idx, ax in enumerate(wp):
        carrier = np.tile(np.eye(3), (n, 1, 1))  # nominal rotation of the axis' carrier into M
        for outer in wp[idx + 1:]:
            carrier = rot(outer.name, -1) @ carrier
        u = carrier[:, :, ax.direction]
        p = np.einsum("nij,j->ni", carrier, (m.pivots_mm or {}).get(ax.name, np.zeros(3)))
        rvec = nest - p
        rvec = rvec - (rvec * u).sum(axis=1, keepdims=True) * u
        norm = np.linalg.norm(rvec, axis=1, keepdims=True)
        radial = np.where(norm > 1e-9, rvec / np.where(norm > 1e-9, norm, 1.0), 0.0)
        tang = np.cross(u, radial)
        out[ax.name] = np.stack([radial, tang, u], axis=1)
    return out


def save_figure(fig: Any, path: Path) -> str:
    """Lay out (fixed margins, room for the legends outside the axes), write (PNG, 90 dpi) and close a figure;
    returns the path."""
    legends = [ax.get_legend() for ax in fig.axes]
    fixed_layout(fig, right=outside_legend_room(fig, *legends), top=0.35, bottom=0.55, wspace=0.6)
    save_png(fig, path, dpi=90)
    return str(path)


def _legend_outside(ax: Any) -> None:
    """The legend right of the axes, where it covers no point (none when nothing is labelled)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def residual_plots(m: Measurement, result: DiagnosisResult, out_dir: str | Path) -> list[str]:
    """Write the residual-signature plots (PNG) of the baseline PIGE fit; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kern = load_kernels(m.machine)
    out = Path(out_dir)
    make_folder(out, what="--plots")
    resid = result.baseline.residuals_um
    if resid.size == 0:
        raise InputError("no residuals to plot")
    paths = []
    t = m.t_s
    probe = m.metadata.get("instrument") == "sphere-probe"  # a probe log has no clock: t is the pose's order
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for i, c in enumerate("xyz"):
        ax.plot(t, resid[:, i], ".-", label=f"d{c}")
    ax.set_xlabel("pose (its order in the log)" if probe else "t [s]")
    ax.set_ylabel("residual [µm]")
    ax.set_title("PIGE-fit residual vs pose order" if probe else "PIGE-fit residual vs time", y=1.0)
    _legend_outside(ax)
    paths.append(save_figure(fig, out / "residual_time.png"))
    frames = axis_frames(m, kern)
    for k, axis in enumerate(kern.ROTARY_AXES):
        if axis not in frames:
            continue
        comp = np.einsum("nci,ni->nc", frames[axis], resid)
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for i, name in enumerate(("radial", "tangential", "axial")):
            ax.plot(m.angles_deg[:, k], comp[:, i], "o", ms=3, label=name)
        ax.set_xlabel(f"{axis} [deg]")
        ax.set_ylabel("residual [µm]")
        ax.set_title(f"residual in the frame of axis {axis}", y=1.0)
        _legend_outside(ax)
        paths.append(save_figure(fig, out / f"residual_{axis}.png"))
    appr = EffectContext(kern, m.angles_deg, m.t_s, m.ball_mm).approach
    assert appr is not None
    fig, axs = plt.subplots(1, 2, figsize=(9, 3.5))
    norms = np.linalg.norm(resid, axis=1)
    axs[0].bar(np.arange(len(norms)), norms)
    for r in result.outlier_rows:
        axs[0].bar([r], [norms[r]], color="red")
    axs[0].set_xlabel("row")
    axs[0].set_ylabel("|residual| [µm]")
    axs[0].set_title("per row (red: outliers)", y=1.0)
    r = resid[1:] - resid[1:].mean(axis=0)
    ac = [1.0] + [float((r[:-lag] * r[lag:]).sum() / max((r * r).sum(), 1e-300)) for lag in range(1, min(15, len(r)))]
    axs[1].stem(range(len(ac)), ac)
    axs[1].set_xlabel("lag [rows]")
    axs[1].set_title("autocorrelation in time", y=1.0)
    paths.append(save_figure(fig, out / "residual_rows.png"))
    if (appr != 0).any():
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for k, axis in enumerate(kern.ROTARY_AXES):
            if axis in frames:
                tang = np.einsum("ni,ni->n", frames[axis][:, 1], resid)
                for sgn, mk in ((1, "^"), (-1, "v")):
                    sel = appr[:, k] == sgn
                    ax.plot(m.angles_deg[sel, k], tang[sel], mk, label=f"{axis} approached {'+' if sgn > 0 else '-'}")
        ax.set_xlabel("angle [deg]")
        ax.set_ylabel("tangential residual [µm]")
        ax.set_title("residual by direction of approach", y=1.0)
        _legend_outside(ax)
        paths.append(save_figure(fig, out / "residual_approach.png"))
    result.plots = paths
    return paths
