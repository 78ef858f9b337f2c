"""Report section of a test plan (``pige plan``): predicted precision and the trajectory.

:func:`plan_section` returns a self-contained HTML ``<section data-section="plan">`` (the
figure embedded as a base64 PNG, no external resource) and the PNG it wrote:

- a table of the predicted standard error of every PIGE for the planned (or graded) test
  and for the default cone with the same points, noise and ball (undetermined parameters
  show "undetermined", never a number), the worst of each and the gain;
- which catalogue effects the test can reveal, with the reason;
- the figure (:func:`plan_figure`): left, predicted standard errors per PIGE as bars
  (planned vs default cone, log scale); right, the planned poses in the plane of the two
  rotary angles (path in test order, reference pose marked, default cone for comparison,
  the rotary limits as a box when finite).
"""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path
from typing import Any

import numpy as np

from pige_sym.planning import Plan
from pige_sym.planning.plan import default_cone
from pige_sym.plotting import fixed_layout, pyplot, save_png


def plan_figure(plan: Plan) -> Any:
    """Figure of a plan: std per PIGE (planned vs default cone) and the poses in the angle plane."""
    plt = pyplot()
    fig, (ax_s, ax_t) = plt.subplots(1, 2, figsize=(11, 4.2))
    names = plan.prediction.names
    x = np.arange(len(names))
    planned = [np.nan if v is None else v for v in plan.prediction.std_dict().values()]
    ax_s.bar(x - 0.2, planned, 0.4, label=f"planned ({plan.family})", color="tab:blue")
    if plan.baseline is not None:
        base = [np.nan if v is None else v for v in plan.baseline.std_dict().values()]
        ax_s.bar(x + 0.2, base, 0.4, label="default cone", color="tab:gray")
    ax_s.set_xticks(x, [f"{n}\n[{plan.prediction.units.get(n, '')}]" for n in names], fontsize=7)
    ax_s.set_yscale("log")
    ax_s.set_ylabel("predicted standard error [µm or µrad]")
    ax_s.set_title(f"noise {plan.setup.noise_um:g} µm, {plan.points} poses", y=1.0)
    ax_s.legend(fontsize=8)
    _trajectory_axes(ax_t, plan)
    fixed_layout(fig, left=0.8, right=0.2, bottom=0.7, top=0.35, wspace=0.9)
    return fig


def _trajectory_axes(ax: Any, plan: Plan) -> None:
    axes = plan.rotary_axes
    a = plan.angles_deg
    if len(axes) == 1:
        ax.plot(np.arange(a.shape[0]), a[:, 0], "o-", ms=3)
        ax.set_xlabel("pose")
        ax.set_ylabel(f"{axes[0]} [deg]")
        return
    cone = default_cone(plan.setup, plan.points)
    if cone is not None:
        ax.plot(cone[1:, 1], cone[1:, 0], ".", color="tab:gray", ms=4, label="default cone")
    ax.plot(a[:, 1], a[:, 0], "-", color="tab:blue", lw=0.6, alpha=0.6)
    ax.scatter(a[1:, 1], a[1:, 0], c=np.arange(1, a.shape[0]), cmap="viridis", s=14, zorder=3, label="planned")
    ax.plot([0], [0], "k*", ms=10, label="reference pose")
    if plan.limits is not None:
        (lo0, hi0), (lo1, hi1) = plan.limits.rotary[axes[0]], plan.limits.rotary[axes[1]]
        if all(math.isfinite(v) for v in (lo0, hi0)):
            ax.axhspan(lo0, hi0, color="tab:green", alpha=0.06, label=f"{axes[0]} limits")
        if all(math.isfinite(v) for v in (lo1, hi1)):
            ax.axvspan(lo1, hi1, color="tab:orange", alpha=0.06, label=f"{axes[1]} limits")
    ax.set_xlabel(f"{axes[1]} [deg]")
    ax.set_ylabel(f"{axes[0]} [deg]")
    ax.set_title("poses in the angle plane (colour: test order)", y=1.0)
    ax.legend(fontsize=7, loc="best")


def _e(x: object) -> str:
    return html.escape(str(x))


def _num(v: float | None) -> str:
    return "undetermined" if v is None or not math.isfinite(v) else f"{v:.4g}"


def plan_section(plan: Plan, out_dir: str | Path, *, name: str = "plan.png") -> tuple[str, Path]:
    """HTML section and PNG of a plan (module docstring).

    Parameters
    ----------
    plan : Plan
        From :func:`pige_sym.planning.plan_test` or :func:`~pige_sym.planning.grade_test`.
    out_dir : path
        Folder for the PNG (created if needed).
    name : str
        File name of the PNG.

    Returns
    -------
    html : str
    png : Path
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    png = out / name
    save_png(plan_figure(plan), png, dpi=90)
    pred, base = plan.prediction, plan.baseline
    bstd = base.std_dict() if base is not None else {}
    rows = "".join(f"<tr><td>{_e(n)}</td><td>{_num(s)}</td><td>{_num(bstd.get(n))}</td>"
                   f"<td>{_e(pred.units.get(n, ''))}</td></tr>" for n, s in pred.std_dict().items())
    gain = (f"; default cone {base.worst:.4g}, gain {base.worst / pred.worst:.1f}×") if base is not None else ""
    reveal = "".join(f'<tr class="{"ok" if s.revealable else "no"}"><td>{_e(e)}</td>'
                     f"<td>{'yes' if s.revealable else 'no'}{' (forced)' if s.forced else ''}</td>"
                     f"<td>{_e(s.reason)}</td></tr>" for e, s in plan.reveal.items())
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    caption = "Predicted standard error per PIGE (planned vs default cone) and the poses in the angle plane"
    undetermined = (f"<p>Undetermined (no value will be given): {_e(', '.join(pred.undetermined))}</p>"
                    if pred.undetermined else "")
    section = (
        '<section data-section="plan" id="plan"><h3>Test plan</h3>'
        f"<p><code>{_e(plan.machine)}</code>, {plan.points} poses after the reference pose, noise "
        f"{plan.setup.noise_um:g} µm, ball {_e(', '.join(f'{x:g}' for x in plan.setup.ball_mm))} mm, criterion "
        f"{_e(plan.criterion)}. {_e(plan.family)}: {_e(plan.description)}.</p>"
        f"<p>Worst predicted standard error {pred.worst:.4g}{gain}; condition {pred.condition:.3g}; duration "
        f"{plan.duration_s:g} s.</p>{undetermined}"
        "<table><tr><th>parameter</th><th>planned std</th><th>default cone std</th><th>unit</th></tr>"
        f"{rows}</table>"
        "<table><tr><th>effect</th><th>revealable</th><th>why</th></tr>" + reveal + "</table>"
        f'<figure data-figure="plan"><img src="data:image/png;base64,{data}" alt="{_e(caption)}">'
        f"<figcaption>{_e(caption)}</figcaption></figure></section>"
    )
    return section, png
