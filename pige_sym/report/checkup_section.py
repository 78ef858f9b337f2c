"""The check-ups of a machine in the report (``pige report --history ID``): a trend plot and the last verdict.

The plot has one panel per PIGE the check-ups re-measure: each check-up's value ± 2 standard errors coloured by what
was found for that PIGE (ok, outside its control limits, not within its tolerance), the full calibrations' values,
the control limits each check-up was judged by (centre ± half-width), the tolerance, the corrections entered
(dashed lines) and, in the panel titles, the last check-up's drift rate and when the PIGE leaves its tolerance with
the forecast's interval.  The runs are spaced in their order (days of check-ups and a warm-up checked every ten
minutes both stay readable).  The table lists the check-ups and the last one's figures per PIGE.  A history without
check-ups shows nothing here.
"""

from __future__ import annotations

import math
from datetime import datetime
from pathlib import Path
from typing import Any

from pige_sym.plotting import fixed_layout, pyplot, save_png
from pige_sym.report.data import ReportData, ReportFigure
from pige_sym.report.html_blocks import esc, img, num, table

COLOURS = {"ok": "tab:blue", "drifted": "tab:orange", "out": "crimson"}
KEY = "checkup-trend"


def checkups(data: ReportData) -> list[Any]:
    """The history's check-ups (empty without a history)."""
    return [] if data.history is None else [r for r in data.history.runs if r.kind == "checkup"]


def _at(iso: str) -> datetime:
    return datetime.fromisoformat(iso)


def _item(run: Any, name: str) -> dict[str, Any] | None:
    return next((x for x in (run.checkup or {}).get("items", []) if x["name"] == name), None)


def _colour(item: dict[str, Any] | None) -> str:
    """Red: not shown within its tolerance; orange: outside its control limits; blue: neither."""
    if item is None:
        return COLOURS["ok"]
    if item.get("status") in ("fail", "undecided"):
        return COLOURS["out"]
    return COLOURS["drifted"] if (item.get("limit") or {}).get("outside") else COLOURS["ok"]


def _panel(ax: Any, name: str, runs: list[Any]) -> None:
    """One PIGE against the run order (check-ups and the full calibrations between them): a fixed number of artists
    whatever the number of runs (the segments of each kind in one line broken by NaN, the check-ups of each colour in
    one errorbar), so a history of 10,000 runs draws as fast as its points."""
    full: list[tuple[int, float]] = []
    points: dict[str, list[tuple[int, float, float]]] = {}
    limits: list[tuple[float, float, float]] = []
    tolerance: list[tuple[float, float, float]] = []
    corrections: list[float] = []
    for x, r in enumerate(runs):
        if name not in r.parameters:
            continue
        i = r.parameters.index(name)
        value, std = float(r.values[i]), float(r.std[i])
        if r.kind == "full":
            full.append((x, value))
            continue
        item = _item(r, name)
        lim = (item or {}).get("limit")
        if lim:
            limits += [(x - 0.35, x + 0.35, lim["centre"] + sign * lim["half_width"]) for sign in (1, -1)]
        if (r.checkup or {}).get("after_correction"):
            corrections.append(x - 0.5)
        points.setdefault(_colour(item), []).append((x, value, 2 * std if math.isfinite(std) else 0))
        if item and item.get("tolerance"):
            tolerance += [(x - 0.5, x + 0.5, sign * item["tolerance"]) for sign in (1, -1)]
    if full:
        ax.plot(*zip(*full, strict=True), "kD", ms=5)
    if limits:
        ax.plot(*_segments(limits), color="0.55", lw=0.9)
    if corrections:
        ax.vlines(corrections, 0, 1, transform=ax.get_xaxis_transform(), colors="k", linestyles="--", lw=0.8)
    for colour, pts in points.items():
        xs, values, errs = zip(*pts, strict=True)
        ax.errorbar(xs, values, yerr=errs, fmt="o", ms=4, capsize=2, color=colour)
    if tolerance:
        ax.plot(*_segments(tolerance), color="tab:green", lw=1.2)


def _segments(segments: list[tuple[float, float, float]]) -> tuple[list[float], list[float]]:
    """Horizontal segments ``(x0, x1, y)`` as the x and y of one line, broken by NaN between them."""
    xs: list[float] = []
    ys: list[float] = []
    for x0, x1, y in segments:
        xs += [x0, x1, math.nan]
        ys += [y, y, math.nan]
    return xs, ys


def _forecast_text(last: Any, name: str) -> str:
    """The last check-up's drift and when it leaves the tolerance, for the panel's title."""
    tr = (_item(last, name) or {}).get("trend")
    if not tr:
        return ""
    from pige_sym.verdict.checkup.routine import BEYOND_CALENDAR

    rate = f"drift {tr['rate_per_h'] * 24:+.3g}/day"
    shown = tr.get("shown", tr.get("significant"))
    if shown and not tr.get("leaves_at") and tr.get("leaves_at_h") is not None:
        return f"; {rate}, leaves {BEYOND_CALENDAR}"
    if not shown or not tr.get("leaves_at"):
        return f"; {rate} (not shown)" if not shown else f"; {rate}"
    high = tr.get("leaves_high")
    return (f"; {rate}, leaves {tr['leaves_at'][5:16].replace('T', ' ')} ({tr['leaves_low'][5:16].replace('T', ' ')}"
            f" .. {high[5:16].replace('T', ' ') if high else 'not bounded'})")


def checkup_figure(data: ReportData) -> Any:
    """The check-ups' trend plot (module docstring); matplotlib Figure."""
    plt = pyplot()
    assert data.history is not None
    runs = [r for r in data.history.runs if r.kind == "checkup" or r.kind == "full"]
    last = checkups(data)[-1]
    names = list(last.parameters)
    cols = 2 if len(names) > 1 else 1
    rows = math.ceil(len(names) / cols)
    fig, axs = plt.subplots(rows, cols, figsize=(11, 2.9 * rows), squeeze=False, sharex=True)
    for ax, name in zip(axs.ravel(), names, strict=False):
        _panel(ax, name, runs)
        unit = last.units.get(name, "").replace("um", "µm").replace("urad", "µrad")
        ax.set_title(f"{name} [{unit}]{_forecast_text(last, name)}", fontsize=8, y=1.0)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in axs.ravel()[len(names):]:
        ax.set_visible(False)
    step = max(1, len(runs) // 16)
    for ax in axs[-1]:
        ax.set_xticks(range(0, len(runs), step))
        ax.set_xticklabels([r.measured_at[5:16].replace("T", " ") for r in runs[::step]], rotation=45, ha="right",
                           fontsize=7)
    fig.suptitle(f"{data.history.machine_id}: each check-up ± 2 std in run order (blue ok, orange outside its control "
                 "limits, red not within its tolerance),\nfull calibrations (black), the limits each was judged by "
                 "(grey), tolerance (green), corrections entered (dashed)", fontsize=8)
    fixed_layout(fig, left=0.6, right=0.15, bottom=0.95, top=0.6, wspace=0.55, hspace=0.45)
    return fig


def checkup_figures(data: ReportData, out_dir: Path) -> list[ReportFigure]:
    """The check-ups' figure written into ``out_dir`` (none without check-ups)."""
    if not checkups(data):
        return []
    out_dir.mkdir(parents=True, exist_ok=True)
    path = save_png(checkup_figure(data), out_dir / "checkup_trend.png", dpi=110)
    assert data.history is not None
    return [ReportFigure(KEY, path, f"Check-ups of machine {data.history.machine_id}: each re-measured PIGE against "
                                    "time with its control limits, tolerance and forecast.")]


def checkup_html(data: ReportData, base: Path | None) -> str:
    """The section: the plot, the check-ups, the last one's figures (empty without check-ups)."""
    from pige_sym.report.html_verdict import run_numbers

    runs = checkups(data)
    if not runs:
        return ""
    assert data.history is not None
    number = run_numbers(data.history.runs)
    rows = []
    for r in runs:
        info = r.checkup or {}
        flagged = [f"{i['name']} ({i['limit']['by'].replace('+', ' and ')})" for i in info.get("items", [])
                   if i.get("limit") and i["limit"].get("by")]
        rows.append([esc(number[r.id]), esc(r.measured_at[:16].replace("T", " ")), _badge(r.verdict),
                     esc(", ".join(flagged) or "—"), "yes" if info.get("after_correction") else "",
                     "provisional" if info.get("provisional") else "learned"])
    last = runs[-1].checkup or {}
    per = [[esc(i["name"]), num(i["value"], "+.3f"), num(i["std"]), num((i.get("limit") or {}).get("centre"), "+.3f"),
            num((i.get("limit") or {}).get("half_width")), esc(_scatter(i.get("limit"))), num(i.get("left"), "+.3f"),
            num(i.get("tolerance"), "g"), esc(i["status"]), esc(_rate(i.get("trend"))), esc(_leaves(i.get("trend")))]
           for i in last.get("items", [])]
    source = last.get("limits_source") or ("provisional" if last.get("provisional") else "learned")
    return "\n".join([
        '<section data-section="checkup" id="checkup"><h2>Check-ups</h2>',
        f"<p>{len(runs)} check-up{'s' if len(runs) != 1 else ''}; the last, run {esc(number[runs[-1].id])}: "
        f"{_badge(runs[-1].verdict)}. Each check-up is judged against control limits from the run-to-run scatter of "
        "the machine's runs (its full calibrations and check-ups, between the corrections entered), with the "
        "machines of its structure in this history as a prior, at a false-alarm rate of "
        f"{esc(format(last.get('alpha', 0.01), 'g'))} per check-up (docs/checkup.md). The last one's limits: "
        f"{esc(source)}.</p>",
        "".join(img(f, base) for f in data.figures if f.key == KEY),
        table(["run", "measured (UTC)", "verdict", "outside its limits (test)", "after a correction", "limits"], rows,
              num_cols=[0]),
        "<h4>The last check-up</h4>",
        table(["PIGE", "value", "std", "centre", "limit ±", "run-to-run scatter (90 %)", "error left (values in force)",
               "tolerance", "status", "drift per day [90 %]", "leaves its tolerance (UTC)"], per,
              num_cols=[1, 2, 3, 4, 6, 7]),
        "</section>"])


def _badge(verdict: str | None) -> str:
    from pige_sym.report.html_verdict import _BADGE

    v = verdict or "none"
    return f'<span data-verdict="{esc(v)}" class="badge {esc(v)}">{esc(_BADGE.get(v, v))}</span>'


def _scatter(lim: dict[str, Any] | None) -> str:
    if not lim or lim.get("scatter") is None:
        return "not known yet" if lim else "—"
    low, high = lim.get("scatter_low"), lim.get("scatter_high")
    return f"{lim['scatter']:.2g}" + (f" ({low:.2g}..{high:.2g})" if low is not None and high is not None else "")


def _rate(tr: dict[str, Any] | None) -> str:
    if not tr:
        return "—"
    return f"{tr['rate_per_h'] * 24:+.3g} [{tr['rate_low'] * 24:+.3g}, {tr['rate_high'] * 24:+.3g}]"


def _leaves(tr: dict[str, Any] | None) -> str:
    from pige_sym.verdict.checkup.routine import BEYOND_CALENDAR

    shown = bool(tr) and tr.get("shown", tr.get("significant"))  # type: ignore[union-attr]
    if tr and shown and not tr.get("leaves_at") and tr.get("leaves_at_h") is not None:
        return BEYOND_CALENDAR
    if not tr or not shown or not tr.get("leaves_at"):
        return "—"
    high = (tr.get("leaves_high") or "not bounded")[:16].replace("T", " ")
    if tr.get("reached"):
        return f"may be outside now (by {high})"
    return (f"{tr['leaves_at'][:16].replace('T', ' ')} ({(tr.get('leaves_low') or '?')[:16].replace('T', ' ')} .. "
            f"{high})")
