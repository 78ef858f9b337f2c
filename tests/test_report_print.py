"""The report on screen at 1000 and 1400 px and printed to PDF, in headless Chromium (skipped without it).

Three reports a reader gets: an R-test run with a finding, a probe import and ballbar setups with an effect
seen jointly.  Each is checked:

- on screen, 1000 and 1400 px wide: nothing wider than the window, no table hidden behind a scroll bar
  (its box as wide as the table), file names that wrap only between words, the verdict on the first screen
  and, for the ballbar setups, the joint PIGE values on it;
- printed (the page's own print CSS applied at the printable width of A4, 186 mm): the same, every
  collapsed ``<details>`` open;
- the PDF Chromium prints: a PDF of pages; with ``pdftotext`` (poppler-utils) also every column heading of
  every table present (no lost column), no page that ends with a heading, no ``nan``.

One Chromium serves the module (``tests/chromium_pipe.py``): each page is loaded, read and printed as the command
line's ``--dump-dom`` and ``--print-to-pdf`` do, in a page as wide and high as ``--window-size`` gave.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from chromium_pipe import Browser, window_viewport

from pige_sym.cli.main import main
from pige_sym.simulation.simulator import random_pige
from testdata import CHROMIUM, REPO, simulated_probe_file

PDFTOTEXT = shutil.which("pdftotext")
TOLERANCES = REPO / "examples" / "tolerances.json"
AC = "wC'A'bXYZ(C1)t"
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")

LAYOUT = """<script>
window.addEventListener('load', function () {
  var w = document.documentElement.clientWidth;
  var all = Array.from(document.querySelectorAll('body *'));
  var wide = all.filter(function (e) { return e.getBoundingClientRect().right > w + 1; });
  var hidden = Array.from(document.querySelectorAll('.tw')).filter(function (e) {
    return e.scrollWidth > e.clientWidth + 1; });
  var broken = Array.from(document.querySelectorAll('code.path, span.file')).filter(function (e) {
    var r = document.createRange(); r.selectNodeContents(e);
    var lines = Array.from(r.getClientRects()).map(function (q) { return Math.round(q.top); });
    var words = e.textContent.split(/[_\\-\\/\\s]/).filter(function (x) { return x.length; });
    return new Set(lines).size > words.length; });
  var closed = Array.from(document.querySelectorAll('details')).filter(function (d) {
    var inner = d.querySelector(':scope > :not(summary)');
    return inner && inner.getBoundingClientRect().height === 0; });
  var v = document.querySelector('[data-verdict]');
  var j = document.querySelector('#answer-j1 .used table');
  var d = document.createElement('pre');
  d.id = 'pige-layout';
  d.textContent = 'width=' + w + ' scroll=' + document.documentElement.scrollWidth + ' wide=' + wide.length +
    ' hidden=' + hidden.length + ' broken=' + broken.length + ' closed=' + closed.length +
    ' verdict=' + (v ? Math.round(v.getBoundingClientRect().bottom) : -1) +
    ' joint=' + (j ? Math.round(j.getBoundingClientRect().bottom) : -1) + ' height=' + window.innerHeight +
    ' offenders=' + wide.concat(hidden).slice(0, 3).map(function (e) {
      return e.tagName + '.' + e.className + ':' + (e.textContent || '').slice(0, 30).replace(/\\s+/g, '_');
    }).join('|');
  document.body.appendChild(d);
});
</script>"""


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """report.html of an R-test run with a finding, a probe import and four ballbar setups with an effect."""
    root = tmp_path_factory.mktemp("print")
    out = {}
    run = root / ("rtest_" + "a_long_file_name_" * 3 + "run.csv")
    assert main(["simulate", "--seed", "1", "--effect", "angular_error_C", "--out", str(run)]) == 0
    assert main(["program", "--out", str(root / "rtest.mpf")]) == 0
    assert main(["report", str(run), "--out", str(root / "rtest"), "--program", str(root / "rtest.mpf"),
                 "--tolerances", str(TOLERANCES)]) == 0
    out["rtest"] = root / "rtest" / "report.html"
    probe = simulated_probe_file(root, 2, "table_drift:vx_um=3,vy_um=-2,vz_um=4,tau_s=10")
    assert main(["report", str(probe), "--out", str(root / "probe"), "--tolerances",
                 str(TOLERANCES)]) == 0
    out["probe"] = root / "probe" / "report.html"
    truth = ",".join(f"{k}={v!r}" for k, v in random_pige(AC, 4).items())
    setups = []
    for i, (kind, axis, tilt) in enumerate([("tangential", "C", 0), ("tangential", "C", -45), ("tangential", "A", 0),
                                            ("axial", "C", 0), ("radial", "C", 0)]):
        setups.append(root / f"bb_{kind}_{axis}{tilt}.csv")
        assert main(["simulate", "--instrument", "ballbar", "--setup", kind, "--axis", axis, "--tilt", str(tilt),
                     "--pige", truth, "--seed", str(i), "--noise", "0.1", "--effect",
                     "angular_error_C:harmonic=2,cos_urad=15,sin_urad=-10", "--out", str(setups[-1])]) == 0
    assert main(["report", *map(str, setups), "--out", str(root / "ballbar"), "--tolerances", str(TOLERANCES)]) == 0
    out["ballbar"] = root / "ballbar" / "report.html"
    return out


def _layout(chromium: Browser, html: Path, tmp: Path, width: int, *, printed: bool = False) -> dict[str, str]:
    text = html.read_text(encoding="utf-8")
    if printed:  # the print CSS on screen, at A4's printable width (210 - 2 × 12 mm at 96 px/in)
        text = text.replace("@media print{", "@media all{")
    probe = tmp / f"layout-{width}-{printed}.html"
    probe.write_text(text.replace("</body>", LAYOUT + "</body>"), encoding="utf-8")
    with chromium.load(probe.as_uri(), window_viewport(width, 800)) as page:
        dom = page.dom()
    found = re.search(r'<pre id="pige-layout">([^<]*)</pre>', dom)
    assert found, chromium.stderr()
    return dict(kv.split("=", 1) for kv in found.group(1).split())


@pytest.mark.parametrize("kind", ["rtest", "probe", "ballbar"])
@pytest.mark.parametrize("width", [1000, 1400])
def test_the_page_fits_the_window_and_leads_with_the_answer(chromium, reports, kind, width, tmp_path) -> None:
    got = _layout(chromium, reports[kind], tmp_path, width)
    assert int(got["width"]) == width and int(got["scroll"]) <= width, got
    assert got["wide"] == "0" and got["hidden"] == "0", got  # no overflow, no column behind a scroll bar
    assert got["broken"] == "0", got  # file names break between words only
    assert 0 < int(got["verdict"]) <= int(got["height"]), got
    if kind == "ballbar":
        assert 0 < int(got["joint"]) <= int(got["height"]), got  # the joint PIGEs on the first screen


@pytest.mark.parametrize("kind", ["rtest", "probe", "ballbar"])
def test_the_printed_page_loses_no_column_and_opens_every_detail(chromium, reports, kind, tmp_path) -> None:
    got = _layout(chromium, reports[kind], tmp_path, 703, printed=True)
    assert got["wide"] == "0" and got["hidden"] == "0", got
    assert got["closed"] == "0", got


@pytest.mark.parametrize("kind", ["rtest", "probe", "ballbar"])
def test_the_pdf_has_every_column_and_no_heading_alone_at_a_page_bottom(chromium, reports, kind, tmp_path) -> None:
    pdf = tmp_path / f"{kind}.pdf"
    with chromium.load(reports[kind].as_uri()) as page:
        page.print_pdf(pdf)  # as --print-to-pdf --no-pdf-header-footer
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF") and len(re.findall(rb"/Type\s*/Page\b", data)) >= 2
    if PDFTOTEXT is None:
        pytest.skip("pdftotext (poppler-utils) is not installed: the PDF's text is not checked")
    pages = subprocess.run([PDFTOTEXT, "-layout", str(pdf), "-"], capture_output=True, text=True,
                           check=True).stdout.split("\f")
    flat = re.sub(r"\s+", " ", " ".join(pages))
    html = reports[kind].read_text(encoding="utf-8")
    heads = {re.sub(r"<[^>]+>", "", h).strip() for h in re.findall(r"<th>(.*?)</th>", html)}
    words = {w for h in heads for w in re.findall(r"[A-Za-z]{4,}", h)}
    missing = sorted(w for w in words if w not in flat)
    assert missing == [], missing  # every column heading printed: no lost column
    assert not re.search(r"\bnan\b", flat, re.IGNORECASE)
    headings = {re.sub(r"<[^>]+>", "", h).strip() for h in re.findall(r"<h[234][^>]*>(.*?)</h[234]>", html)}
    for number, page in enumerate(pages[:-1], 1):
        lines = [x.strip() for x in page.splitlines() if x.strip()]
        if lines:
            assert lines[-1] not in headings, f"page {number} ends with the heading {lines[-1]!r}"
