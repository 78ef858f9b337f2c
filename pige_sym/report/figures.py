"""Figures of the HTML report (matplotlib, Agg backend), one PNG per figure.

*Deviation plots (ISO 10791-6 / R-test style).*  Per measurement: the deviation components dx,
dy, dz [µm] in the machine frame against the point index, above the commanded rotary angles
[deg] against the same index; and, when one rotary axis turns through at least 180° (cone
frustum, stepped sweeps), a polar plot of each component against that axis' angle, drawn about
a nominal circle (radius offset, radial scale in µm).  The PIGE model of the primary estimate
is overlaid when every parameter was determined.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.compensation.study import CompensationStudyRow
from pige_sym.diagnosis.residual_plots import residual_plots
from pige_sym.errors import InputError
from pige_sym.identification.result import IdentificationResult
from pige_sym.identification.studies import SobolStudy
from pige_sym.measurements.measurement import Measurement
from pige_sym.plotting import fixed_layout, outside_legend_room, pyplot, save_png
from pige_sym.report.data import UNIT_TEXT, HistoryData, MeasurementReport, ReportData, ReportFigure, Truth
from pige_sym.report.words import small_um, vocabulary


def deviation_figure(m: Measurement, model_um: np.ndarray | None) -> Any:
    """Deviation components against the point index above the commanded angles.

    Parameters
    ----------
    m : Measurement
    model_um : ndarray, shape=(n, 3) [µm] or None
        PIGE-model deviation (machine frame) to overlay.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    words = vocabulary(m)
    dev = m.deviation_machine_um()
    idx = np.arange(m.n_rows)
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(10, 5.6), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    colors = ("tab:blue", "tab:orange", "tab:green")
    for k, c in enumerate("xyz"):
        ax0.plot(idx, dev[:, k], "o-", ms=3.5, lw=1, color=colors[k], label=f"d{c} measured")
        if model_um is not None:
            ax0.plot(idx, model_um[:, k], "--", lw=1, color=colors[k], alpha=0.8, label=f"d{c} PIGE model")
    ax0.axhline(0, color="k", lw=0.6)
    ax0.set_ylabel(words.deviation_axis)
    ax0.set_title(f"{words.measurand}, machine frame" + (" (converted from the table frame)" if m.frame == "table"
                                                         else ""), fontsize=10, y=1.0)
    legends = [_legend_outside(ax0)]
    ax0.grid(alpha=0.3)
    commanded = m.commanded_deg  # as the program and the controller hold them (axis_sense)
    for k, a in enumerate(m.rotary_axes):
        ax1.plot(idx, commanded[:, k], ".-", lw=1, label=f"{a}" + (" (sense -1)" if m.axis_sense.get(a, 1) == -1
                                                                     else ""))
    ax1.set_xlabel(f"{words.row} (0 = reference pose)")
    ax1.set_ylabel("commanded angle [deg]")
    legends.append(_legend_outside(ax1))
    ax1.grid(alpha=0.3)
    fixed_layout(fig, right=outside_legend_room(fig, *legends), top=0.3, hspace=0.15)
    return fig


def _legend_outside(ax: Any, **kwargs: Any) -> Any:
    """The legend right of the axes, never over a curve (:func:`~pige_sym.plotting.outside_legend_room` makes
    room for it); returns it."""
    return ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kwargs)


def polar_axis(m: Measurement) -> int | None:
    """Index of the rotary axis that turns through at least 180° (the largest span), or None."""
    spans = np.ptp(m.angles_deg, axis=0)
    k = int(np.argmax(spans))
    return k if spans[k] >= 180.0 else None


def polar_figure(m: Measurement, model_um: np.ndarray | None, axis_index: int) -> Any:
    """Deviation components magnified about a nominal circle against one rotary angle.

    The radius is ``R0 + d`` [µm] with ``R0`` a round offset larger than the largest
    deviation; the dashed circle is zero deviation and the radial ticks read in µm of
    deviation.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    dev = m.deviation_machine_um()
    theta = np.radians(m.angles_deg[:, axis_index])
    peak = float(np.abs(dev).max())
    if model_um is not None:
        peak = max(peak, float(np.abs(model_um).max()))
    step = _nice_step(peak if peak > 0 else 1.0)
    r0 = 2 * step * math.ceil(peak / step if peak > 0 else 1.0)
    fig, axs = plt.subplots(1, 3, figsize=(11, 4), subplot_kw={"projection": "polar"})
    circle = np.linspace(0, 2 * np.pi, 361)
    ticks = np.arange(-r0 / 2, r0 / 2 + step / 2, step)
    ticks = ticks[(ticks >= -r0 + 1e-12)]
    colors = ("tab:blue", "tab:orange", "tab:green")
    for k, (ax, c) in enumerate(zip(axs, "xyz", strict=True)):
        ax.plot(circle, np.full_like(circle, r0), "k--", lw=0.8)
        ax.plot(theta, r0 + dev[:, k], "o-", ms=3, lw=1, color=colors[k], label="measured")
        if model_um is not None:
            ax.plot(theta, r0 + model_um[:, k], "-", lw=0.8, color="0.3", alpha=0.8, label="PIGE model")
        ax.set_rlim(0, r0 + r0 / 2 + step / 2)
        ax.set_rticks(r0 + ticks)
        shown = ticks[::2] if ticks.size > 4 else ticks  # every other ring labelled: room for each label
        ax.set_yticklabels([f"{t:+g}" if t in shown else "" for t in ticks], fontsize=8)
        ax.set_rlabel_position(_emptiest_direction(theta))
        for label in ax.get_yticklabels():
            label.set_bbox({"facecolor": "white", "edgecolor": "none", "alpha": 0.85, "pad": 1.0})
        ax.set_title(f"d{c} [µm] vs {m.rotary_axes[axis_index]} [deg]", fontsize=10, y=1.1)  # above the 90° label
        ax.tick_params(axis="x", labelsize=7)
    handles, labels = axs[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=2, frameon=False)
    fig.suptitle(f"deviation about the nominal circle (dashed = 0 µm, ring step {step:g} µm)", fontsize=10)
    fixed_layout(fig, left=0.45, right=0.45, bottom=0.5, top=0.85, wspace=0.9)
    return fig


def _emptiest_direction(theta: np.ndarray) -> float:
    """The direction [deg] farthest from every measured angle: where the radial labels cover no point."""
    grid = np.radians(np.arange(0.0, 360.0, 7.5))
    gap = np.abs((grid[:, None] - np.asarray(theta)[None, :] + np.pi) % (2 * np.pi) - np.pi).min(axis=1) \
        if np.size(theta) else np.zeros(grid.size)
    return float(np.degrees(grid[int(np.argmax(gap))]))


def _nice_step(x: float) -> float:
    """A 1-2-5 step near x/2."""
    target = x / 2
    exp = math.floor(math.log10(target))
    for mult in (1, 2, 5, 10):
        if mult * 10**exp >= target:
            return float(mult * 10**exp)
    return float(10 ** (exp + 1))  # pragma: no cover


def identification_figure(results: dict[str, IdentificationResult], truth: Truth | None) -> Any:
    """Estimates with 95 % intervals per parameter and method; truth as crosses; no bar where undetermined.

    Two panels: position errors [µm], orientation and zero-position errors [µrad].

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    from matplotlib.transforms import blended_transform_factory

    first = next(iter(results.values()))
    groups = [("position errors", "um"), ("orientation / zero-position errors", "urad")]
    fig, axs = plt.subplots(1, 2, figsize=(11, 3.8))
    markers = {"gauss-newton": ("o", "tab:blue"), "double-differential": ("s", "tab:purple"),
               "used for compensation (diagnosis)": ("D", "tab:green")}
    for ax, (title, unit) in zip(axs, groups, strict=True):
        names = [n for n in first.parameters if first.units.get(n) == unit and "." not in n]
        x = np.arange(len(names))
        for i, (meth, res) in enumerate(results.items()):
            ci = res.ci95()
            mk, col = markers.get(meth, ("^", "tab:gray"))
            off = (i - (len(results) - 1) / 2) * 0.22
            q = np.array([res.parameters.index(name) for name in names], dtype=int)
            v = res.values[q]
            ok = np.isfinite(v)
            if ok.any():  # one errorbar call per method: the same markers, bars and caps, not one artist set each
                ax.errorbar(x[ok] + off, v[ok], yerr=[v[ok] - ci[q[ok], 0], ci[q[ok], 1] - v[ok]], fmt=mk,
                            color=col, ms=5, capsize=3, label=meth if ok[0] else None)
            for j in np.flatnonzero(~ok):  # no value: a label at mid-height (axes coordinates), never a number
                ax.text(x[j] + off, 0.5, "not identifiable", transform=blended_transform_factory(
                    ax.transData, ax.transAxes), fontsize=6.5, color="crimson", ha="center", va="center",
                    rotation=90)
        if truth is not None:
            ax.plot(x, [truth.values.get(n, 0.0) for n in names], "x", color="crimson", ms=8, mew=2, label="truth")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x)
        ax.set_xticklabels(names)
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.set_ylabel(f"value [{UNIT_TEXT.get(unit, unit)}]")
        ax.set_title(f"{title} (95 % intervals)", fontsize=10, y=1.0)
        ax.grid(alpha=0.3)
    handles, labels = axs[0].get_legend_handles_labels()
    if handles:  # one legend for both panels, below them: it covers no interval
        fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=len(handles), frameon=False)
    fixed_layout(fig, bottom=0.65 if handles else 0.45, top=0.3, wspace=0.8)
    return fig


def sobol_figure(study: SobolStudy) -> Any:
    """Total Sobol indices per parameter, one bar group per projection.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.6))
    n_proj = len(study.projections)
    x = np.arange(len(study.parameters))
    width = 0.8 / max(n_proj, 1)
    for i, proj in enumerate(study.projections):
        ax.bar(x + (i - (n_proj - 1) / 2) * width, study.total_order[i], width, label=f"{proj} (total)")
    ax.set_xticks(x)
    ax.set_xticklabels(study.parameters)
    ax.set_ylabel("total Sobol index [-]")
    ax.set_title("sensitivity of the mean-square projected deviation to each PIGE", fontsize=10, y=1.0)
    legend = _legend_outside(ax)
    ax.grid(alpha=0.3, axis="y")
    fixed_layout(fig, right=outside_legend_room(fig, legend), top=0.3, bottom=0.45)
    return fig


def draw_figures(rep: MeasurementReport, out_dir: Path) -> list[ReportFigure]:
    """Write every PNG of one measurement into ``out_dir`` (created); returns them in page order."""
    out_dir.mkdir(parents=True, exist_ok=True)
    m = rep.measurement
    figs: list[ReportFigure] = []
    overlay = "; dashed: PIGE model of the " + rep.primary_method + " estimate" if rep.model_um is not None else (
        "; no model overlay: a parameter is undetermined")
    words = vocabulary(m)
    figs.append(ReportFigure("deviation", save_png(deviation_figure(m, rep.model_um), out_dir / "deviation.png"),
                             f"{words.measurand[0].upper() + words.measurand[1:]} per {words.row} [µm], machine "
                             f"frame, with the commanded rotary angles [deg]{overlay}."))
    k = polar_axis(m)
    if k is not None:
        figs.append(ReportFigure("polar", save_png(polar_figure(m, rep.model_um, k), out_dir / "deviation_polar.png"),
                                 f"Deviation components against the {m.rotary_axes[k]} angle, magnified about a "
                                 f"nominal circle (dashed line = zero deviation; radial labels in µm)."))
    shown = dict(rep.identification)
    if rep.primary is not rep.identification.get(rep.primary_method):  # the diagnosis' fit, with its effects
        shown = {"used for compensation (diagnosis)": rep.primary, **shown}
    figs.append(ReportFigure("identification", save_png(identification_figure(shown, rep.truth),
                                                     out_dir / "identification.png"),
                             "Identified PIGEs with 95 % confidence intervals: "
                             + ("the estimate used for compensation (green: the diagnosis' final fit) and the "
                                "PIGE-only fits of both methods" if len(shown) > 2 else
                                f"both methods; the estimate used for compensation is the {rep.primary_method} fit")
                             + ("; red crosses: truth from the sidecar." if rep.truth is not None else ".")))
    paths: list[str] = []
    if rep.diagnosis is not None:
        try:
            paths = residual_plots(m, rep.diagnosis, out_dir)
        except InputError:
            paths = []
    against = "the pose's order" if words.time_unit == "poses" else "time"
    captions = {"residual_time": f"Residual of the PIGE fit against {against} [µm] (a drift shows as a trend).",
                "residual_rows": "Residual norm per row (red: outliers) and its autocorrelation in time.",
                "residual_approach": "Tangential residual by direction of approach (backlash shows as a split)."}
    for path in paths:
        stem = Path(path).stem
        cap = captions.get(stem, f"Residual of the PIGE fit in the radial / tangential / axial frame of axis "
                                 f"{stem.removeprefix('residual_')} [µm] against its angle (harmonics show at their "
                                 "order).")
        figs.append(ReportFigure("residual", Path(path), cap))
    basis = ("simulated on the known truth of the sidecar" if rep.compensation_basis == "truth" else
             "model-predicted: the machine is assumed to carry exactly the identified errors, so 'after' is only "
             "what the compensation algorithm itself leaves, not a prediction for the real machine")
    for i, row in enumerate(rep.compensation):
        fig = before_after_figure(row, BASIS_LABEL[rep.compensation_basis])
        figs.append(ReportFigure("compensation", save_png(fig, out_dir / f"compensation_{i}.png"),
                                 f"Tool-point error before (top) and after compensation (bottom, its own scale) [µm], "
                                 f"{row.trajectory} ({basis})."))
    if rep.sobol is not None and rep.sobol_same_as is None:
        figs.append(ReportFigure("sobol", save_png(sobol_figure(rep.sobol), out_dir / "sobol.png"),
                                 "Total Sobol indices of the mean-square projected deviation, per projection."))
    return figs


BASIS_LABEL = {"truth": "simulated on a known truth", "model": "model-predicted", "measured": "measured"}


def before_after_figure(row: CompensationStudyRow, label: str) -> Any:
    """Error components and norm per point, before (top) and after (bottom), each panel on its own scale.

    Parameters
    ----------
    row : CompensationStudyRow
        ``before_um``, ``after_um`` shape=(n, 3) [µm].
    label : str
        Basis of the numbers (measured, simulated on a known truth, model-predicted), in the titles.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    fig, axs = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True)
    legends = []
    idx = np.arange(row.before_um.shape[0])
    colors = ("tab:blue", "tab:orange", "tab:green")
    for ax, err, when, rms in ((axs[0], row.before_um, "before", row.rmse_before_um),
                               (axs[1], row.after_um, "after", row.rmse_after_um)):
        for k, c in enumerate("xyz"):
            ax.plot(idx, err[:, k], "-", lw=0.9, color=colors[k], label=f"{c}")
        ax.plot(idx, np.linalg.norm(err, axis=1), "k.-", lw=1, ms=3, label="|error|")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel("tool-point error [µm]")
        ax.set_title(f"{when} compensation ({label}): RMSE {small_um(rms)} µm", fontsize=9, y=1.0)
        ax.grid(alpha=0.3)
        legends.append(_legend_outside(ax))
    axs[1].set_xlabel("pose of the test")
    fixed_layout(fig, right=outside_legend_room(fig, *legends), top=0.3, hspace=0.35)
    return fig


def compare_figure(result: Any) -> Any:
    """Measured |d| per pose before (top) and after (bottom, its own scale) with the parts of what is left.

    Parameters
    ----------
    result : CompareResult

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    fig, axs = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True)
    legends = []
    idx = np.arange(result.before_um.shape[0])
    panels = ((axs[0], result.before_um, result.before_parts, "before", result.rms_before_um),
              (axs[1], result.after_um, result.after_parts, "after", result.rms_after_um))
    for ax, norms, dec, when, rms in panels:
        ax.plot(idx, norms, "ko-", ms=3, lw=1.2, label="|d| measured")
        for part in (dec.parts if dec is not None else []):
            if part.values_um is not None:
                ax.plot(idx, np.linalg.norm(part.values_um, axis=1), "--", lw=0.9, label=f"|{part.name} part|")
        ax.set_ylabel("|d| [µm]")
        ax.set_title(f"{when} (measured): RMS {small_um(rms)} µm", fontsize=9, y=1.0)
        ax.grid(alpha=0.3)
        legends.append(_legend_outside(ax))
    axs[1].set_xlabel("pose")
    fixed_layout(fig, right=outside_legend_room(fig, *legends), top=0.3, hspace=0.35)
    return fig


def trend_figure(history: HistoryData) -> Any:
    """Value ± 2 std of each location PIGE per run, tolerance band shaded, significant changes circled.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from pige_sym.kernels import load_kernels

    plt = pyplot()
    runs = history.runs
    kern = load_kernels(runs[-1].machine_code)
    names = list(kern.LOCATION_PARAMETERS)
    cols = 4
    rows = math.ceil(len(names) / cols)
    fig, axs = plt.subplots(rows, cols, figsize=(11, 2.4 * rows), sharex=True, squeeze=False)
    x = np.arange(len(runs))
    flagged = {(comp.to_run, ch.parameter) for comp in history.comparisons for ch in comp.changes
               if ch.significant}
    for ax, name in zip(axs.ravel(), names, strict=False):
        vals = np.array([r.values[r.parameters.index(name)] if name in r.parameters else np.nan for r in runs])
        std = np.array([r.std[r.parameters.index(name)] if name in r.parameters else np.nan for r in runs])
        limit = history.limits.get(name)
        if limit is not None:
            ax.axhspan(-limit, limit, color="tab:green", alpha=0.12, lw=0)
            ax.axhline(limit, color="tab:green", lw=0.8)
            ax.axhline(-limit, color="tab:green", lw=0.8)
        ax.errorbar(x, vals, yerr=2 * np.nan_to_num(std), fmt="o-", ms=4, capsize=3, lw=1, color="tab:blue")
        ringed = [i for i, r in enumerate(runs) if (r.id, name) in flagged]
        if ringed:
            ax.plot(x[ringed], vals[ringed], "o", ms=11, mfc="none", mec="crimson", mew=1.8, ls="none")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_title(f"{name} [{UNIT_TEXT.get(kern.UNITS[name], kern.UNITS[name])}]", fontsize=9, y=1.0)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in axs.ravel()[len(names):]:
        ax.set_visible(False)
    step = max(1, -(-len(runs) // 16))  # at most 16 dates: a label per run of a long history is unreadable and slow
    for ax in axs[-1]:
        ax.set_xticks(x[::step])
        ax.set_xticklabels([r.measured_at[:10] for r in runs[::step]], rotation=45, ha="right", fontsize=7)
    fig.suptitle(f"{history.machine_id}: value ± 2 std per run; green band = tolerance; red ring = significant "
                 "change from the previous run", fontsize=9)
    fixed_layout(fig, left=0.6, right=0.15, bottom=0.85, top=0.5, wspace=0.55, hspace=0.4)
    return fig


def ballbar_figure(curves: list[tuple[str, np.ndarray, np.ndarray]]) -> Any:
    """Each ballbar setup's measured length change and its joint PIGE-only fit against the pose.

    Parameters
    ----------
    curves : list of (label, measured (n,), fitted (n,)) [µm]

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = pyplot()
    cols = min(3, len(curves))
    rows = math.ceil(len(curves) / cols)
    fig, axs = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.4 * rows), squeeze=False)
    for ax, (label, measured, fitted) in zip(axs.flat, curves, strict=False):
        idx = np.arange(measured.size)
        ax.plot(idx, measured, "k.", ms=3, label="ΔL measured")
        ax.plot(idx, fitted, "-", lw=1.2, label="joint fit")
        rms = float(np.sqrt(np.mean((measured - fitted) ** 2)))
        ax.set_title(f"{label[-30:]}: rest {small_um(rms, '.2g')} µm", fontsize=8, y=1.0)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.set_xlabel("pose", fontsize=7)
        ax.set_ylabel("ΔL [µm]", fontsize=7)
    for ax in list(axs.flat)[len(curves):]:
        ax.axis("off")
    handles, labels = axs.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=2, frameon=False)
    fixed_layout(fig, left=0.6, right=0.15, bottom=0.75, top=0.3, wspace=0.6, hspace=0.75)
    return fig


def draw_report_figures(data: ReportData, out_dir: Path) -> list[ReportFigure]:
    """The figures of the whole report (measured before/after, history trends) into ``out_dir``."""
    figs: list[ReportFigure] = []
    if data.comparison is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        figs.append(ReportFigure("measured-compare", save_png(compare_figure(data.comparison),
                                                           out_dir / "measured_before_after.png"),
                                 "Measured |d| per pose [µm] before (top) and after (bottom, its own scale), with "
                                 "the model parts of each (PIGEs, accepted effects, unexplained rest)."))
    if data.history is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        figs.append(ReportFigure("trend", save_png(trend_figure(data.history), out_dir / "history_trend.png"),
                                 f"History of machine {data.history.machine_id}: each PIGE per run with ± 2 std, "
                                 "the tolerance band and the significant changes."))
        from pige_sym.report.checkup_section import checkup_figures

        figs += checkup_figures(data, out_dir)
    if data.maps is not None:
        from pige_sym.identification.map_output import map_figure

        out_dir.mkdir(parents=True, exist_ok=True)
        for axis in data.maps.result.maps:
            figs.append(ReportFigure("maps", save_png(map_figure(data.maps.result, axis), out_dir / f"map_{axis}.png"),
                                     f"The error motions of {axis} (conventions §10) with ±2σ bands: translations "
                                     "[µm] above, rotations [µrad] below."))
    for i, jr in enumerate(data.joints):
        if jr.curves:
            out_dir.mkdir(parents=True, exist_ok=True)
            png = save_png(ballbar_figure(jr.curves), out_dir / f"joint_{i + 1}.png")
            figs.append(ReportFigure(f"joint-{i + 1}", png,
                                     "Each ballbar setup's measured length change ΔL per pose [µm] and the joint "
                                     "fit of it (the PIGEs, the effects seen jointly and the file's constant): the "
                                     "rest is noise, or a setup that disagrees."))
    return figs
