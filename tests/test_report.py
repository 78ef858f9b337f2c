"""pige report: a self-contained HTML page with every section, escaped text, honest flags; renders in Chromium."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.compensation import compensation_study
from pige_sym.kernels import load_kernels
from pige_sym.nc.program import make_rtest_program
from pige_sym.report.build import ReportData, build_report, gather_report, write_report
from pige_sym.simulator import random_pige, simulate
from pige_sym.trajectories import cone_frustum, figure_eight

AC = "wC'A'bXYZ(C1)t"
WEIRD = 'odd <b>&"name'
HOSTILE = "<img src=x onerror=alert(1)> & <script>alert(2)</script>"
PNG = b"\x89PNG\r\n\x1a\n"


def _simulate(path: Path, seed: int, *, truth: bool = True, source: str | None = None) -> Path:
    sim = simulate(AC, cone_frustum(AC, points=30), pige=random_pige(AC, seed), noise_um=0.25, seed=seed)
    if source is not None:
        sim.measurement.metadata["source"] = source
    csv, truth_path = sim.write(path)
    if not truth:
        truth_path.unlink()
    return csv


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[ReportData, Path, str]:
    """One report of two files (one with a truth sidecar, one without, with a hostile name and metadata),
    with both studies and an NC program."""
    root = tmp_path_factory.mktemp("report")
    first = _simulate(root / "ac_cone.csv", 5)
    second = _simulate(root / f"{WEIRD}.csv", 6, truth=False, source=HOSTILE)
    kern = load_kernels(AC)
    tr = figure_eight(AC)
    program = root / "fig8.mpf"
    program.write_text(make_rtest_program(tr.angles_deg, kern.linear_commands(tr.angles_deg, [120.0, 0.0, 80.0]),
                                          kern.ROTARY_AXES, title="figure eight"))
    data = gather_report([first, second], studies=("projection", "sobol"), program=program, presets=6,
                         sobol_samples=256)
    path = write_report(data, root / "out")
    return data, path, path.read_text(encoding="utf-8")


def test_report_is_self_contained(built: tuple[ReportData, Path, str]) -> None:
    data, path, text = built
    assert path.name == "report.html" and path.is_file()
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:|//|file:)""", text, re.IGNORECASE)
    assert "<script" not in text.lower() and "<link" not in text.lower() and "@import" not in text
    srcs = re.findall(r'<img src="([^"]*)"', text)
    pngs = sorted(path.parent.rglob("*.png"))
    assert len(srcs) == len(pngs) == sum(len(m.figures) for m in data.measurements) > 10
    for src in srcs:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1], validate=True).startswith(PNG)


def test_every_section_is_there(built: tuple[ReportData, Path, str]) -> None:
    _, _, text = built
    sections = re.findall(r'data-section="([^"]+)"', text)
    assert sections[0] == "overview"
    expected = ["summary", "deviations", "identification", "diagnosis", "compensation", "projection-study", "sobol"]
    assert sections[1:] == expected * 2
    figures = re.findall(r'data-figure="([^"]+)"', text)
    for key in ("deviation", "polar", "identification", "residual", "compensation", "sobol"):
        assert key in figures
    for words in ("Stages of the double-differential scheme", "Unidentifiable combinations", "Rejected candidates",
                  "observability indices", "condition number", "Verdict", "held-out RMS"):
        assert words in text


def test_text_is_escaped(built: tuple[ReportData, Path, str]) -> None:
    data, path, text = built
    assert "<img src=x" not in text and "<script>alert" not in text and "<b>&" not in text
    assert "&lt;img src=x onerror=alert(1)&gt; &amp; &lt;script&gt;alert(2)&lt;/script&gt;" in text
    assert "odd &lt;b&gt;&amp;&quot;name.csv" in text
    label = data.measurements[1].label
    assert re.fullmatch(r"[A-Za-z0-9._-]+", label) and (path.parent / label / "deviation.png").is_file()


def test_truth_and_model_predicted_before_after(built: tuple[ReportData, Path, str]) -> None:
    data, _, text = built
    with_truth, without = data.measurements
    assert with_truth.compensation_basis == "truth" and without.compensation_basis == "model"
    assert "model-predicted" in text and "|error| / std" in text
    gn = with_truth.identification["gauss-newton"]
    assert gn.rank == 8
    err = np.array([gn.value(p) - with_truth.truth.values[p] for p in gn.parameters])  # type: ignore[union-attr]
    assert (np.abs(err) < 5 * gn.std).all()
    for rep in data.measurements:
        row = rep.compensation[0]
        assert row.rmse_after_um < 0.2 * row.rmse_before_um


def test_program_before_after_matches_the_compensation_study(built: tuple[ReportData, Path, str]) -> None:
    data, _, _ = built
    rep = data.measurements[0]
    assert rep.compensated_program is not None and rep.compensated_program.is_file()
    assert "compensated by pige_sym" in rep.compensated_program.read_text()
    values, missing, cov = rep.estimate()
    assert not missing
    assert rep.truth is not None
    ref = compensation_study(AC, [figure_eight(AC)], truth=rep.truth.values, identified=values, covariance=cov)[0]
    row = rep.compensation[1]
    assert row.before_um.shape == ref.before_um.shape
    # the program holds positions rounded to 0.1 µm
    assert np.allclose(row.before_um, ref.before_um, atol=1e-3)
    assert np.allclose(row.after_um, ref.after_um, atol=1e-3)
    assert row.predicted_after_um == pytest.approx(ref.predicted_after_um, rel=1e-4)


def test_unidentifiable_parameters_are_flagged(tmp_path: Path) -> None:
    csv = _simulate(tmp_path / "run.csv", 7)
    out = build_report([csv], tmp_path / "out", projection="x")
    text = out.read_text(encoding="utf-8")
    assert "NOT IDENTIFIABLE" in text and "Not compensated (no value)" in text
    flagged = 0
    for attrs, row in re.findall(r"<tr([^>]*)>(.*?)</tr>", text, re.DOTALL):
        cells = re.findall(r"<td[^>]*>(.*?)</td>", row, re.DOTALL)
        if len(cells) > 6 and cells[0].startswith("<b>E"):  # the identification table
            if "NOT IDENTIFIABLE" in cells[6]:
                flagged += 1
                assert 'class="unid"' in attrs
                assert cells[2] == "not identifiable" and cells[3] == "—" and cells[4] == "—"
            else:
                assert re.fullmatch(r"-?\d+\.\d+", cells[2]), cells[2]
    assert flagged >= 2


def test_cli_json_and_exit_status(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _simulate(tmp_path / "run.csv", 8, truth=False)
    assert main(["report", str(csv), "--out", str(tmp_path / "out"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert Path(out["report"]).is_file()
    (m,) = out["measurements"]
    assert m["compensation"]["basis"] == "model" and m["identification"]["gauss-newton"]["rank"] == 8


@pytest.mark.parametrize("problem", ["format", "missing", "truth", "study", "program"])
def test_bad_input_gives_status_2_and_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                               problem: str) -> None:
    good = _simulate(tmp_path / "good.csv", 9)
    args = ["report", str(good)]
    if problem == "format":
        bad = tmp_path / "bad.csv"
        bad.write_text(good.read_text().replace("# pige-rtest 1", "# something else"))
        args.append(str(bad))
        name = str(bad)
    elif problem == "missing":
        name = str(tmp_path / "nowhere.csv")
        args.append(name)
    elif problem == "truth":
        sidecar = tmp_path / "good.truth.json"
        sidecar.write_text('{"pige": {"EX0Q": 1.0}}')
        name = str(sidecar)
    elif problem == "study":
        args += ["--study", "projection,fourier"]
        name = "fourier"
    else:
        prog = tmp_path / "p.mpf"
        prog.write_text("G90\nTRAFOOF\nG1 X1 Y2 Z3 A0 C0\nL100\n")
        args += ["--program", str(prog)]
        name = f"{prog}:4"
    assert main([*args, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pige report: ") and name in err, err
    assert not (tmp_path / "out" / "report.html").exists()


def test_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["report", "--help"])
    assert exc.value.code == 0
    assert "examples:" in capsys.readouterr().out


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHECK = """<script>
window.addEventListener('load', function () {
  var imgs = Array.from(document.images);
  var broken = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0 && i.naturalHeight > 0); });
  var secs = Array.from(document.querySelectorAll('[data-section]')).map(function (s) {
    return s.getAttribute('data-section') + ':' + (s.getBoundingClientRect().height > 0 ? 1 : 0); });
  var d = document.createElement('pre');
  d.id = 'pige-check';
  d.textContent = 'images=' + imgs.length + ' broken=' + broken.length + ' sections=' + secs.join(',');
  document.body.appendChild(d);
});
</script>"""


def _chromium(tmp: Path, *args: str) -> subprocess.CompletedProcess[str]:
    assert CHROMIUM is not None
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
           f"--user-data-dir={tmp / 'profile'}", "--virtual-time-budget=10000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")
def test_renders_in_headless_chromium(built: tuple[ReportData, Path, str], tmp_path: Path) -> None:
    data, path, text = built
    probe = tmp_path / "probe.html"
    probe.write_text(text.replace("</body>", CHECK + "</body>"), encoding="utf-8")
    run = _chromium(tmp_path, "--dump-dom", probe.as_uri())
    found = re.search(r'<pre id="pige-check">([^<]*)</pre>', run.stdout)
    assert found, run.stderr[-2000:]
    check = dict(kv.split("=", 1) for kv in found.group(1).split())
    assert int(check["images"]) == sum(len(m.figures) for m in data.measurements)
    assert check["broken"] == "0"
    sections = check["sections"].split(",")
    assert "overview:1" in sections and sections.count("identification:1") == 2 and sections.count("sobol:1") == 2

    shot = tmp_path / "shot.png"
    _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1280,2400", path.as_uri())
    assert shot.is_file() and shot.stat().st_size > 50_000
    import matplotlib.image

    img = matplotlib.image.imread(shot)
    assert img.shape[:2] == (2400, 1280)
    ink = (img[:, :, :3].mean(axis=2) < 0.8).mean()
    assert ink > 0.02, ink  # text, tables and plots, not a blank page


def test_a_failing_diagnosis_is_reported_not_fatal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pige_sym.identification import IdentificationError
    from pige_sym.report import build as report

    def boom(*args: object, **kwargs: object) -> None:
        raise IdentificationError("Gauss–Newton did not converge")

    monkeypatch.setattr(report, "diagnose", boom)
    csv = _simulate(tmp_path / "run.csv", 10)
    data = gather_report([csv], method="diagnosis")
    (rep,) = data.measurements
    assert rep.diagnosis is None and rep.primary_method == "gauss-newton"
    text = write_report(data, tmp_path / "out").read_text(encoding="utf-8")
    assert "The diagnosis failed on these data: Gauss–Newton did not converge" in text
    assert 'data-section="compensation"' in text and 'data-figure="residual"' not in text
