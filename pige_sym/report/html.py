"""The HTML page of the report: :func:`render_html` is pure (``ReportData`` with its figures in,
HTML text out; every piece of text goes through :func:`html.escape`); :func:`write_report`
draws the figures into ``DIR/<label>/*.png`` and writes ``DIR/report.html`` with every PNG
embedded as a base64 ``data:`` URI and the CSS inline: the page loads nothing from anywhere.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pige_sym.constants import VERSION as __version__
from pige_sym.files import atomic_write_text, staged_folder
from pige_sym.plotting import collector_paused
from pige_sym.report.checkup_section import checkup_html
from pige_sym.report.data import MeasurementReport, ReportData
from pige_sym.report.estimate_used import estimate_used_html
from pige_sym.report.figures import draw_figures, draw_report_figures
from pige_sym.report.gather import findings_text, gather_report
from pige_sym.report.html_blocks import CSS, esc, figs, img, num, path_html, table
from pige_sym.report.html_sections import (
    compensation_html,
    diagnosis_html,
    identification_html,
    projection_html,
    sobol_html,
    summary_html,
)
from pige_sym.report.html_verdict import answer_html, check_html, compare_html, history_html
from pige_sym.report.joint_section import answer_joint_html, joint_html
from pige_sym.report.lead import improvement
from pige_sym.report.words import count


def write_report(data: ReportData, out_dir: str | os.PathLike[str], *, force: bool = False,
                 inputs: Sequence[str | os.PathLike[str]] = (), figures: bool = True) -> Path:
    """Draw the figures, write the compensated programs and ``out_dir/report.html``; returns the HTML path.

    The folder is written all at once (:func:`pige_sym.files.staged_folder`): an interrupt leaves nothing
    partial, and what an earlier report wrote there is replaced only with ``force``.  The page embeds every
    figure; ``figures=False`` (``pige report --no-figures``) keeps them only there: they are drawn into a
    temporary folder, not written beside the page.
    """
    import tempfile

    out = Path(out_dir)
    with staged_folder(out, force=force, inputs=inputs) as stage, \
            tempfile.TemporaryDirectory(prefix="pige-figures-") as scratch:
        _write_into(data, stage, stage if figures else Path(scratch), out)
        if not figures:  # the PNGs are gone with the scratch folder: none is listed
            for rep in data.measurements:
                rep.figures = []
            data.figures = []
    _relocate(data, stage, out)
    return out / "report.html"


def _write_into(data: ReportData, out: Path, drawn: Path, final: Path) -> None:
    """``write_report`` into the staged folder ``out``, the figures drawn under ``drawn`` (``out`` or scratch);
    ``final`` is where the folder will be: the page names the compensated programs there, never in the stage."""
    for rep in data.measurements:
        sub = out / rep.label
        with collector_paused():
            rep.figures = draw_figures(rep, drawn / rep.label)
        text = rep.compensated_program_text
        if text is not None and data.program is not None:
            sub.mkdir(parents=True, exist_ok=True)
            target = sub / f"{data.program.stem}_compensated{data.program.suffix or '.mpf'}"
            atomic_write_text(target, text, newline="")
            rep.compensated_program = final / target.relative_to(out)
    with collector_paused():
        data.figures = draw_report_figures(data, drawn / "_report")
    if data.plan is not None:
        from pige_sym.report.plan_section import plan_section

        data.plan_html, _ = plan_section(data.plan, drawn / "_report")
    atomic_write_text(out / "report.html", render_html(data, base=out))


def _relocate(data: ReportData, stage: Path, out: Path) -> None:
    """The paths recorded while writing into the staged folder, moved to where the folder now is."""
    def moved(p: Path) -> Path:
        return out / p.relative_to(stage) if p.is_relative_to(stage) else p

    for rep in data.measurements:
        for f in rep.figures:
            f.path = moved(f.path)
        if rep.compensated_program is not None:
            rep.compensated_program = moved(rep.compensated_program)
    for f in data.figures:
        f.path = moved(f.path)
    data.html_path = out / "report.html"


def build_report(measurement_paths: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str],
                 **options: Any) -> Path:
    """Build the report of measurement files into ``out_dir``; returns the path of ``report.html``.

    ``options`` are those of :func:`gather_report`; PNGs are kept in ``out_dir/<label>/``.
    """
    return write_report(gather_report(measurement_paths, **options), out_dir)


def _measurement_html(i: int, rep: MeasurementReport, base: Path | None) -> str:
    sid = f"m{i + 1}"
    parts = [f'<section class="measurement" id="{sid}" data-file="{esc(rep.path)}">',
             f"<h2>{i + 1}. {esc(rep.path.name)} — <code>{esc(rep.machine)}</code></h2>"]
    for note in rep.notes:
        parts.append(f'<p class="note">{esc(note)}</p>')
    if rep.check is not None:
        parts += [f'<section data-section="conformance" id="{sid}-conformance"><h3>Conformance</h3>',
                  check_html(rep), "</section>"]
    parts += [f'<section data-section="summary" id="{sid}-summary"><h3>Machine and test</h3>',
              summary_html(rep), "</section>",
              f'<section data-section="deviations" id="{sid}-deviations"><h3>Measured deviations</h3>',
              figs(rep, "deviation", base), figs(rep, "polar", base), "</section>",
              f'<section data-section="identification" id="{sid}-identification"><h3>Identified PIGEs</h3>',
              estimate_used_html(rep), figs(rep, "identification", base), identification_html(rep), "</section>",
              f'<section data-section="diagnosis" id="{sid}-diagnosis"><h3>Diagnosis</h3>',
              diagnosis_html(rep, base), "</section>",
              f'<section data-section="compensation" id="{sid}-compensation"><h3>Compensation before/after</h3>',
              compensation_html(rep, base), "</section>"]
    if rep.projection is not None:
        parts += [f'<section data-section="projection-study" id="{sid}-projection"><h3>Projection study</h3>',
                  projection_html(rep), "</section>"]
    if rep.sobol is not None:
        parts += [f'<section data-section="sobol" id="{sid}-sobol"><h3>Sobol indices</h3>',
                  sobol_html(rep, base), "</section>"]
    parts.append("</section>")
    return "\n".join(parts)


def _overview_html(data: ReportData) -> str:
    head = ["#", "file", "machine", "rows", "rank", "residual RMS [µm]", "diagnosis", "RMSE before → after [µm]",
            "basis"]
    rows = []
    for i, rep in enumerate(data.measurements):
        gn = rep.identification["gauss-newton"]
        findings = findings_text(rep)
        imp = improvement(rep, data)
        arrow = "→ ≈" if imp.basis == "model" else "→"
        rank = esc(f"{gn.rank}/{len(gn.parameters)}")
        if gn.rank < len(gn.parameters):
            rank = f'<span class="unid">{rank}</span>'
        rows.append([f'<a href="#m{i + 1}">{i + 1}</a>', f'<code class="path">{path_html(rep.path.name)}</code>',
                     f"<code>{esc(rep.machine)}</code>", esc(rep.measurement.n_rows), rank, num(gn.rms_um, ".3g"),
                     esc(findings), f"{num(imp.before_um)} {arrow} {num(imp.after_um, '.3g')}", esc(imp.label)])
    return table(head, rows, num_cols=[3, 5])


def _maps_answer(data: ReportData) -> str:
    """The error maps' answer, first when the report fits maps (:func:`~pige_sym.report.map_section.map_answer_html`):
    the files' own answers follow it."""
    if data.maps is None:
        return ""
    from pige_sym.report.map_section import map_answer_html

    return map_answer_html(data.maps) + '<h2 class="per-file">Each file on its own</h2>'


def _instruments(data: ReportData) -> str:
    """The instruments of the page's files, for its title."""
    names = [str(r.measurement.metadata.get("instrument") or "R-test") for r in data.measurements]
    names += ["ballbar" for j in data.joints for fd in j.diagnosis.files if fd.instrument == "ballbar"]
    if not names and data.history is not None:  # the history's own runs: their set-ups, else their methods
        names = [str((r.setup or {}).get("instrument") or ("ballbar" if r.method.startswith("joint") else "run"))
                 for r in data.history.runs]
        names = [n for n in names if n != "run"] or ["machine history"]
    if not names and data.comparison is not None:
        names = ["R-test"]
    shown = {"rtest": "R-test", "sphere-probe": "touch probe"}
    return ", ".join(dict.fromkeys(shown.get(n, n) for n in names)) or "R-test"


def render_html(data: ReportData, *, base: Path | None = None) -> str:
    """The report page: one self-contained HTML document (inline CSS, PNGs as data URIs, no script).

    Parameters
    ----------
    data : ReportData
        With figures drawn (:func:`draw_figures`).
    base : Path, optional
        Figure paths are shown relative to it.
    """
    nav = " ".join([f'<a href="#joint-{i + 1}">joint: {count(len(j.paths), "file")}</a>'
                    for i, j in enumerate(data.joints)]
                   + [f'<a href="#m{i + 1}">{esc(r.path.name)}</a>' for i, r in enumerate(data.measurements)]
                   + (['<a href="#compare">measured before/after</a>'] if data.comparison is not None else [])
                   + (['<a href="#history">history</a>'] if data.history is not None else [])
                   + (['<a href="#plan">test plan</a>'] if data.plan_html or data.plan is not None else [])
                   + (['<a href="#maps">error maps</a>'] if data.maps is not None else []))
    settings = "; ".join(f"{k}: {v}" for k, v in data.settings.items())
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>pige_sym calibration report</title>",
        f"<style>{CSS}</style></head><body>",
        f"<header><h1>Five-axis calibration report ({esc(_instruments(data))})</h1>",
        f'<p class="meta">pige_sym {esc(__version__)} — {esc(data.created)}</p></header><main>',
        '<section data-section="answer" id="answer">', _maps_answer(data),
        *(answer_joint_html(i, j) for i, j in enumerate(data.joints)), answer_html(data), "</section>",
        (f'<p class="meta">{esc(settings)}'
         + (f" — NC program <code>{esc(data.program)}</code>" if data.program is not None else "") + "</p>"
         if data.measurements or data.joints else ""),
        f"<nav>{nav}</nav>",
    ]
    if data.measurements:
        parts += ['<section data-section="overview" id="overview"><h2>Overview</h2>', _overview_html(data),
                  "</section>"]
    if data.comparison is not None:
        parts += ['<section data-section="measured-compare" id="compare"><h2>Measured before/after</h2>',
                  compare_html(data, base), "</section>"]
    if data.history is not None:
        parts += ['<section data-section="history" id="history"><h2>Machine history</h2>',
                  history_html(data, base), "</section>", checkup_html(data, base)]
    parts += [joint_html(i, j, "".join(img(f, base) for f in data.figures if f.key == f"joint-{i + 1}"))
              for i, j in enumerate(data.joints)]
    if data.maps is not None:
        from pige_sym.report.map_section import maps_html

        parts.append(maps_html(data.maps, "".join(img(f, base) for f in data.figures if f.key == "maps")))
    parts += [_measurement_html(i, rep, base) for i, rep in enumerate(data.measurements)]
    if data.plan_html:
        parts.append(data.plan_html)
    parts += [
        "</main><footer><p>PIGEs: position-independent geometric errors of the rotary axes (ISO 230-7), position "
        "errors in µm, orientation errors in µrad, as defined in pige_sym's docs/conventions.md (frames, senses, "
        "what each instrument measures). Standard errors from the weighted least squares of each fit, σ² = "
        "RSS/(N − rank) (probe files: generalised least squares with the reference pose's correlation; several "
        "files: each file's rows divided by its own σ); 95 % intervals from Student's t. A parameter with weight "
        "in a near-null direction of the scaled design is not identifiable and gets no value.</p></footer>",
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"
