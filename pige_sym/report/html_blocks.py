"""Building blocks of the report page: the inline CSS, escaping, numbers with units, tables, figures.

Every piece of text goes through :func:`html.escape` (:func:`esc`); figures are embedded as base64
``data:`` URIs so that the page loads nothing from anywhere.
"""

from __future__ import annotations

import base64
import html
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

from pige_sym.identification.result import IdentificationResult
from pige_sym.report.data import UNIT_TEXT, MeasurementReport, ReportFigure

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:0;color:#1d232a;
background:#f6f7f9;line-height:1.4}
header,main,footer{max-width:1150px;margin:0 auto;padding:0 18px;box-sizing:border-box}
table{max-width:100%}
.tw{max-width:100%;overflow-x:auto}
td,th{overflow-wrap:break-word}
code{overflow-wrap:break-word}
.kv td,.kv td code,nav a,h1,h2,h3,h4,figcaption{overflow-wrap:anywhere}
code.path,span.file{overflow-wrap:break-word;word-break:normal}
.meta{margin:.2em 0;color:#4a5563;font-size:.85em}
.answer{display:flex;flex-wrap:wrap;gap:6px 18px;background:#fff;border:2px solid #2b6cb0;border-radius:6px;
padding:8px 14px;margin:8px 0}
.answer .facts{flex:1 1 420px;min-width:0}
.answer .used{flex:1 1 340px;min-width:0}
.answer table{margin:.2em 0;width:100%}
.answer th{width:9em}
.cap{margin:.2em 0;font-size:.85em;color:#2b4a6f;font-weight:600}
.badge{display:inline-block;padding:1px 10px;border-radius:4px;font-weight:700;letter-spacing:.04em;color:#fff}
.badge.pass{background:#1b7f3a}
.badge.fail{background:#b00020}
.badge.undecided{background:#b26a00}
.badge.none{background:#6b7480}
.badge.ok{background:#1b7f3a;color:#fff}
.badge.drifted{background:#a35f00;color:#fff}
.badge.out{background:#b00020;color:#fff}
.st.pass{color:#1b7f3a;font-weight:600}
.st.fail{color:#b00020;font-weight:600}
.st.undecided{color:#b26a00;font-weight:600}
.basis{display:inline-block;padding:0 6px;border-radius:3px;font-size:.8em;font-weight:700;background:#eef2f7}
.basis.measured{background:#d7f0de}
.basis.model{background:#fde7c8}
ul.rejected li{margin:.15em 0}
ul.rejected details{display:inline}
details summary{cursor:pointer;color:#2b6cb0}
header{padding-top:10px}
h1{font-size:1.35em;margin:.1em 0}
h2{font-size:1.3em;border-bottom:2px solid #2b6cb0;padding-bottom:3px;margin-top:1.6em}
h3{font-size:1.08em;margin:1.2em 0 .4em;color:#2b4a6f}
section.measurement{background:#fff;border:1px solid #d9dee5;border-radius:6px;padding:6px 18px 18px;margin:18px 0}
table{border-collapse:collapse;margin:.4em 0 .8em;font-size:.86em}
th,td{border:1px solid #d0d6de;padding:3px 7px;text-align:left;vertical-align:top}
th{background:#eef2f7}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr.unid td{background:#fde8e8}
span.unid,.bad{color:#b00020;font-weight:600}
.ok{color:#1b7f3a;font-weight:600}
.note{background:#fff8e1;border-left:4px solid #f0b400;padding:6px 10px;margin:.6em 0;font-size:.92em}
figure{margin:.8em 0}
.figrow{display:flex;flex-wrap:wrap;gap:0 14px}
.figrow figure{flex:1 1 480px;max-width:100%}
figure img{max-width:100%;height:auto;border:1px solid #e2e6ea}
figcaption{font-size:.85em;color:#4a5563}
nav a{margin-right:12px}
.nw{white-space:nowrap}
code{background:#eef2f7;padding:0 3px;border-radius:3px}
ul.verdict li{margin:.25em 0}
footer{font-size:.8em;color:#5c6670;padding-bottom:30px}
td.stack{white-space:nowrap;font-variant-numeric:tabular-nums}
@media print{
@page{size:A4;margin:12mm}
body{background:#fff;font-size:10pt}
header,main,footer{max-width:none;padding:0}
.tw{overflow:visible}
table{width:auto;max-width:100%;table-layout:auto;font-size:8.5pt}
td,th{white-space:normal !important;overflow-wrap:break-word;word-break:normal}
td.num,td.stack{white-space:nowrap !important}
tr,figure,img,.answer,.note,li{break-inside:avoid;page-break-inside:avoid}
thead{display:table-header-group}
h1,h2,h3,h4,p.cap{break-after:avoid;page-break-after:avoid}
h2,h3,h4{break-inside:avoid}
section.measurement{border:none;padding:0;margin:0}
section.measurement>h2{break-before:page;page-break-before:always}
figure img{max-height:230mm;border:none}
.figrow{display:block}
nav{display:none}
details::details-content{content-visibility:visible;display:block}
details summary{display:none}
a{color:inherit;text-decoration:none}
}
"""


_UNIT_WORD = re.compile(r"(?<![\w./\\-])u(m|rad)(?![\w./\\-])")


def esc(text: object) -> str:
    """HTML-escaped text, with the ASCII units of messages shown as µm / µrad (``cos_urad`` stays a name)."""
    return html.escape(_UNIT_WORD.sub(r"µ\1", str(text)), quote=True)


def path_html(name: object) -> str:
    """A file name, escaped, that may wrap only after ``_ - /`` (``rtest_<wbr>C45.csv``), never inside a word."""
    return re.sub(r"([_\-/\\])", r"\1<wbr>", esc(name))


def units(unit: str) -> str:
    return UNIT_TEXT.get(unit, unit)


def num(x: float | None, fmt: str = ".3f", none: str = "—") -> str:
    if x is None:
        return none
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return none
    if math.isnan(xf):
        return none
    if math.isinf(xf):
        return "∞" if xf > 0 else "−∞"
    return format(xf, fmt)


def table(head: Sequence[str], rows: Iterable[Sequence[str]], *, row_classes: Sequence[str] | None = None,
           num_cols: Iterable[int] = ()) -> str:
    """An HTML table in a box that scrolls sideways when it is wider than the page (the page itself never
    does, at 1000 px either); ``head`` is escaped, cells are already HTML."""
    nums = set(num_cols)
    heads = "".join(f"<th>{esc(h)}</th>" for h in head)
    out = ['<div class="tw"><table>', f"<thead><tr>{heads}</tr></thead>", "<tbody>"]
    for i, row in enumerate(rows):
        cls = row_classes[i] if row_classes and row_classes[i] else ""
        attr = f' class="{esc(cls)}"' if cls else ""
        cells = "".join(f'<td class="num">{c}</td>' if j in nums else f"<td>{c}</td>" for j, c in enumerate(row))
        out.append(f"<tr{attr}>{cells}</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


def kvs(items: Iterable[tuple[str, str]]) -> str:
    """Two-column key/value table; keys escaped, values already HTML."""
    return '<table class="kv">' + "".join(f"<tr><th>{esc(k)}</th><td>{v}</td></tr>" for k, v in items) + "</table>"


def img(fig: ReportFigure, base: Path | None) -> str:
    """The figure embedded; its caption names the PNG beside the page when there is one (under ``base``)."""
    data = base64.b64encode(fig.path.read_bytes()).decode("ascii")
    beside = base is not None and fig.path.is_relative_to(base)
    shown = f' <span class="file">({path_html(fig.path.relative_to(base))})</span>' if beside and base else ""
    return (f'<figure data-figure="{esc(fig.key)}"><img src="data:image/png;base64,{data}" '
            f'alt="{esc(fig.caption)}"><figcaption>{esc(fig.caption)}{shown}</figcaption></figure>')


def figs(rep: MeasurementReport, key: str, base: Path | None) -> str:
    return "\n".join(img(f, base) for f in rep.figures if f.key == key)


def badge(res: IdentificationResult, j: int) -> tuple[str, bool]:
    """(HTML status, flagged) of parameter j."""
    if not bool(res.identifiable[j]):
        return '<span class="unid">NOT IDENTIFIABLE — no value</span>', True
    if not math.isfinite(res.values[j]):
        return '<span class="unid">not fixed by any differential — no value</span>', True
    return '<span class="ok">identified</span>', False
