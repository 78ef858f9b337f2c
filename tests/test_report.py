"""pige report: a self-contained HTML page with every section, escaped text, honest flags; renders in Chromium."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest
from chromium_pipe import Browser, window_viewport

from pige_sym.cli.main import main
from pige_sym.compensation.study import compensation_study
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import cone_frustum, figure_eight
from pige_sym.nc.program import make_rtest_program
from pige_sym.report import ReportData, build_report, gather_report, write_report
from pige_sym.simulation.simulator import random_pige, simulate
from testdata import CHROMIUM, REPO, figures_not_drawn, simulated_probe_file

AC = "wC'A'bXYZ(C1)t"
WEIRD = 'odd <b>&"name'
HOSTILE = "<img src=x onerror=alert(1)> & <script>alert(2)</script>"
PNG = b"\x89PNG\r\n\x1a\n"
TOLERANCES = REPO / "examples" / "tolerances.json"


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
    first = _simulate(root / ("ac_cone_" + "a_long_file_name_without_any_space_" * 4 + ".csv"), 5)  # wraps at 1000 px
    second = _simulate(root / f"{WEIRD}.csv", 6, truth=False, source=HOSTILE)
    kern = load_kernels(AC)
    tr = figure_eight(AC)
    program = root / "fig8.mpf"
    program.write_text(make_rtest_program(tr.angles_deg, kern.linear_commands(tr.angles_deg, [120.0, 0.0, 80.0]),
                                          kern.ROTARY_AXES, title="figure eight"))
    db = f"sqlite:///{root / 'history.sqlite'}"
    for seed in (31, 32, 33):
        assert main(["history", "add", str(_simulate(root / f"h{seed}.csv", seed)), "--machine-id", "M-1",
                     "--db", db, "--date", f"2026-0{seed - 30}-01", "--tolerances", str(TOLERANCES)]) == 0
    data = gather_report([first, second], studies=("projection", "sobol"), program=program, presets=6,
                         sobol_samples=256, tolerances=TOLERANCES, compare=(first, second), history="M-1", db=db)
    path = write_report(data, root / "out")
    return data, path, path.read_text(encoding="utf-8")


@pytest.fixture(name="figures_not_drawn")
def _figures_not_drawn(monkeypatch: pytest.MonkeyPatch) -> None:
    """For a test that reads a report's words or JSON only: its figures are not drawn.  The same kind of report,
    R-test with the diagnosis, with and without a truth sidecar, is drawn, embedded and checked in ``built``."""
    figures_not_drawn(monkeypatch)


def test_report_is_self_contained(built: tuple[ReportData, Path, str]) -> None:
    data, path, text = built
    assert path.name == "report.html" and path.is_file()
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:|//|file:)""", text, re.IGNORECASE)
    assert "<script" not in text.lower() and "<link" not in text.lower() and "@import" not in text
    srcs = re.findall(r'<img src="([^"]*)"', text)
    pngs = sorted(path.parent.rglob("*.png"))
    assert len(srcs) == len(pngs) == sum(len(m.figures) for m in data.measurements) + len(data.figures) > 10
    assert len(set(srcs)) == len(srcs)  # no figure twice
    for src in srcs:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1], validate=True).startswith(PNG)


def test_every_section_is_there(built: tuple[ReportData, Path, str]) -> None:
    _, _, text = built
    sections = re.findall(r'data-section="([^"]+)"', text)
    assert sections[:4] == ["answer", "overview", "measured-compare", "history"]
    expected = ["conformance", "summary", "deviations", "identification", "diagnosis", "compensation",
                "projection-study", "sobol"]
    assert sections[4:] == expected * 2
    figures = re.findall(r'data-figure="([^"]+)"', text)
    for key in ("deviation", "polar", "identification", "residual", "compensation", "sobol", "measured-compare",
                "trend"):
        assert key in figures
    for words in ("Stages of the double-differential scheme", "Unidentifiable combinations", "Rejected candidates",
                  "observability indices", "condition number", "What the diagnosis concludes", "held-out RMS"):
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
    _, missing, cov = rep.estimate()
    assert not missing
    assert rep.truth is not None and rep.weighing is not None
    # compensation enters the estimate weighed by its uncertainty (compensation.weighing), judged on the program
    entered = {n: v for n, v in rep.weighing.entered.items() if v is not None}
    ref = compensation_study(AC, [figure_eight(AC)], truth=rep.truth.values, identified=entered, covariance=cov)[0]
    row = rep.compensation[1]
    assert row.before_um.shape == ref.before_um.shape
    # the program holds positions rounded to 0.1 µm
    assert np.allclose(row.before_um, ref.before_um, atol=1e-3)
    assert np.allclose(row.after_um, ref.after_um, atol=1e-3)
    assert row.predicted_after_um == pytest.approx(rep.weighing.predicted["entered"].expected_um, rel=1e-9)
    assert "poses" in rep.weighing.judged_on and "program" in rep.weighing.judged_on


def test_unidentifiable_parameters_are_flagged(tmp_path: Path) -> None:
    csv = _simulate(tmp_path / "run.csv", 7)
    out = build_report([csv], tmp_path / "out", projection="x", method="gauss-newton")
    text = out.read_text(encoding="utf-8")
    assert "NOT IDENTIFIABLE" in text and "Not compensated (no value)" in text
    flagged = 0
    for attrs, row in re.findall(r"<tr([^>]*)>(.*?)</tr>", text, re.DOTALL):
        cells = re.findall(r"<td[^>]*>(.*?)</td>", row, re.DOTALL)
        if len(cells) > 6 and cells[0].startswith("<b>E"):  # the identification tables
            if "NOT IDENTIFIABLE" in cells[6]:
                flagged += 1
                assert 'class="unid"' in attrs
                # Gauss–Newton table: "not identifiable"; double-differential table: "no value"
                assert cells[2] in ("not identifiable", "no value") and cells[3] == "—" and cells[4] == "—"
            else:
                assert re.fullmatch(r"-?\d+\.\d+", cells[2]), cells[2]
    assert flagged >= 2


def test_cli_json_and_exit_status(tmp_path: Path, capsys: pytest.CaptureFixture[str], figures_not_drawn: None) -> None:
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


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")
def test_renders_in_headless_chromium(chromium: Browser, built: tuple[ReportData, Path, str], tmp_path: Path) -> None:
    data, path, text = built
    probe = tmp_path / "probe.html"
    probe.write_text(text.replace("</body>", CHECK + "</body>"), encoding="utf-8")
    with chromium.load(probe.as_uri()) as page:
        dom = page.dom()
    found = re.search(r'<pre id="pige-check">([^<]*)</pre>', dom)
    assert found, chromium.stderr()
    check = dict(kv.split("=", 1) for kv in found.group(1).split())
    assert int(check["images"]) == sum(len(m.figures) for m in data.measurements) + len(data.figures)
    assert check["broken"] == "0"
    sections = check["sections"].split(",")
    assert "answer:1" in sections and sections.count("identification:1") == 2 and sections.count("sobol:1") == 2

    shot = tmp_path / "shot.png"
    with chromium.load(path.as_uri(), (1280, 2400)) as page:
        page.screenshot(shot)
    assert shot.is_file() and shot.stat().st_size > 50_000
    import matplotlib.image

    img = matplotlib.image.imread(shot)
    assert img.shape[:2] == (2400, 1280)
    ink = (img[:, :, :3].mean(axis=2) < 0.8).mean()
    assert ink > 0.02, ink  # text, tables and plots, not a blank page


def test_a_failing_diagnosis_is_reported_not_fatal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pige_sym.identification.least_squares import IdentificationError
    from pige_sym.report import gather as report

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


def _answer(text: str) -> str:
    found = re.search(r'<section data-section="answer" id="answer">(.*?)</section>', text, re.DOTALL)
    assert found
    return found.group(1)


def test_the_answer_leads(built: tuple[ReportData, Path, str]) -> None:
    data, _, text = built
    answer = _answer(text)
    assert text.index('data-section="answer"') < text.index('data-section="overview"')
    blocks = answer.split('<div class="answer"')[1:]
    assert len(blocks) == 2
    for rep, block in zip(data.measurements, blocks, strict=True):
        assert rep.check is not None and f'data-verdict="{rep.check.verdict}"' in block
        for label in ("machine", "measured", "verdict", "main finding", "improvement"):
            assert f"<th>{label}" in block
        # the PIGEs shown are those compensated: the primary (diagnosis final) estimate
        assert rep.primary_method == "diagnosis" and rep.diagnosis is not None
        final = rep.diagnosis.final
        shown = dict(re.findall(r"<td><b>(E\w+)</b></td><td[^>]*>(-?\d+(?:\.\d+)?) ±", block))
        assert len(shown) == 8
        for name, value in shown.items():  # to the decimals of its std (two significant digits)
            decimals = len(value.partition(".")[2])
            assert float(value) == pytest.approx(final.value(name), abs=0.51 * 10.0**-decimals)
    # a measured before/after is labelled measured, with the measured numbers
    comp = data.comparison
    assert comp is not None and 'class="basis measured"' in answer
    assert f"{comp.rms_before_um:.3g} → {comp.rms_after_um:.3g} µm" in answer


def test_model_predicted_never_claims_its_own_leftover(tmp_path: Path, figures_not_drawn: None) -> None:
    from pige_sym.report.lead import improvement, unexplained_rms_um

    csv = _simulate(tmp_path / "run.csv", 12, truth=False)
    data = gather_report([csv])
    text = write_report(data, tmp_path / "out").read_text(encoding="utf-8")
    (rep,) = data.measurements
    row = rep.compensation[0]
    assert row.rmse_after_um < 0.05 * row.rmse_before_um  # the algorithm on its own model: nearly nothing left
    imp = improvement(rep, data)
    assert imp.basis == "model" and 'class="basis model"' in _answer(text)
    expected = float(np.hypot(row.predicted_after_um, unexplained_rms_um(rep)))
    assert imp.after_um == pytest.approx(expected) and imp.after_um > 5 * row.rmse_after_um
    assert "100 %" not in text and f"{row.reduction * 100:.1f} %" not in text
    overview = re.search(r'data-section="overview".*?</section>', text, re.DOTALL)
    assert overview and f"→ ≈ {imp.after_um:.3g}" in overview.group(0) and "model-predicted" in overview.group(0)
    assert 'data-verdict="none"' in _answer(text)  # no tolerances: not judged, never a made-up pass


def test_rejected_candidates_are_one_sentence_each(built: tuple[ReportData, Path, str]) -> None:
    data, _, text = built
    d = data.measurements[0].diagnosis
    assert d is not None and d.rejected
    lists = re.findall(r'<ul class="rejected">(.*?)</ul>', text, re.DOTALL)
    items = re.findall(r"<li>(.*?)</li>", lists[0], re.DOTALL)
    assert len(items) == len(d.rejected)
    for item, r in zip(items, d.rejected, strict=True):
        sentence, _, folded = item.partition("<details>")
        assert sentence.strip().endswith(".") and "ΔBIC" not in sentence
        # why, in words: each test's value once, with the threshold it missed; never a bare "ΔBIC —, p —"
        assert "—" not in folded and folded.count("ΔBIC") <= 1, folded
        if r.reason.startswith("not supported"):
            assert re.search(r"the BIC (rises|falls only) by|the BIC falls by only", folded), folded
            assert "accepted at" in folded and "the F test gives p = " in folded, folded


def test_sobol_parameters_are_scaled(built: tuple[ReportData, Path, str]) -> None:
    data, _, _ = built
    rep = data.measurements[0]
    kern = load_kernels(AC)
    m = rep.measurement
    jac = kern.jacobian(m.angles_deg, None, m.ball_mm, None, None)[1:, :, :8]
    assert rep.sobol is not None and list(rep.sobol_ranges) == list(kern.LOCATION_PARAMETERS)
    for j, name in enumerate(kern.LOCATION_PARAMETERS):
        effect = rep.sobol_ranges[name] * np.sqrt((jac[:, :, j] ** 2).sum(axis=1).mean())
        assert effect == pytest.approx(15.0)
    units = {kern.UNITS[n] for n in kern.LOCATION_PARAMETERS}
    assert units == {"um", "urad"}  # both kinds, on one effect scale


def test_history_only_report(built: tuple[ReportData, Path, str], tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    _, path, _ = built
    db = f"sqlite:///{path.parent.parent / 'history.sqlite'}"
    assert main(["report", "--history", "M-1", "--db", db, "--out", str(tmp_path / "h")]) == 0
    text = (tmp_path / "h" / "report.html").read_text(encoding="utf-8")
    answer = _answer(text)
    assert "M-1" in answer and "what changed" in answer and "data-verdict=" in answer
    assert 'data-figure="trend"' in text and 'data-section="overview"' not in text
    assert "3 runs" in capsys.readouterr().out
    assert main(["report", "--out", str(tmp_path / "none")]) == 2


CHECK_LAYOUT = """<script>
window.addEventListener('load', function () {
  var w = document.documentElement.clientWidth;
  var wide = Array.from(document.querySelectorAll('body *')).filter(function (e) {
    return e.getBoundingClientRect().right > w + 1; }).map(function (e) { return e.tagName; });
  var v = document.querySelector('[data-verdict]');
  var d = document.createElement('pre');
  d.id = 'pige-layout';
  d.textContent = 'width=' + w + ' scroll=' + document.documentElement.scrollWidth + ' wide=' + wide.length +
    ' verdict=' + (v ? Math.round(v.getBoundingClientRect().bottom) : -1) + ' height=' + window.innerHeight;
  document.body.appendChild(d);
});
</script>"""


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")
def test_fits_1000_px_and_the_verdict_is_on_the_first_screen(chromium: Browser, built: tuple[ReportData, Path, str],
                                                              tmp_path: Path) -> None:
    _, _, text = built
    probe = tmp_path / "layout.html"
    probe.write_text(text.replace("</body>", CHECK_LAYOUT + "</body>"), encoding="utf-8")
    with chromium.load(probe.as_uri(), window_viewport(1000, 800)) as page:  # as --window-size=1000,800
        dom = page.dom()
    found = re.search(r'<pre id="pige-layout">([^<]*)</pre>', dom)
    assert found, chromium.stderr()
    check = {k: int(v) for k, v in (kv.split("=", 1) for kv in found.group(1).split())}
    assert check["width"] == 1000 and check["height"] >= 600, check  # a 1000 px wide, laptop-high viewport
    assert check["scroll"] <= 1000 and check["wide"] == 0, check  # no horizontal overflow
    assert 0 < check["verdict"] <= check["height"], check  # the verdict is on the first screen


def test_cli_methods_match_the_report() -> None:
    from pige_sym.cli.report import METHODS
    from pige_sym.report import PRIMARY_METHODS

    assert sorted(METHODS) == sorted(PRIMARY_METHODS)


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """One run and the arguments of its Gauss–Newton report graded on a test plan; that report, with its PNG files
    beside the page, in ``<run folder>/both``."""
    root = tmp_path_factory.mktemp("planned")
    csv = _simulate(root / "run.csv", 12)
    args = ["report", str(csv), "--method", "gauss-newton", "--plan", "figure-eight"]
    assert main([*args, "--out", str(root / "both")]) == 0
    return root, args


def test_report_grades_a_test_plan(planned: tuple[Path, list[str]]) -> None:
    """`pige report --plan` adds the predicted std per PIGE (graded test vs default cone) and the pose figure."""
    root, _ = planned
    text = (root / "both" / "report.html").read_text(encoding="utf-8")
    section = re.search(r'<section data-section="plan".*?</section>', text, re.DOTALL)
    assert section is not None and 'data-figure="plan"' in section.group(0)
    for name in load_kernels(AC).LOCATION_PARAMETERS:
        assert f"<td>{name}</td>" in section.group(0)


def test_no_figures_keeps_them_only_in_the_page(planned: tuple[Path, list[str]], tmp_path: Path) -> None:
    """`--no-figures`: the page embeds every figure and no PNG is written beside it (the PNGs are not kept twice)."""
    root, args = planned
    assert main([*args, "--out", str(tmp_path / "page"), "--no-figures"]) == 0
    pngs = sorted(p.name for p in (root / "both").rglob("*.png"))
    assert pngs and not list((tmp_path / "page").rglob("*.png"))
    page = (tmp_path / "page" / "report.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == len(pngs) and ".png)" not in page


def test_a_probe_report_speaks_of_contacts_and_poses(tmp_path: Path) -> None:
    """Issue 34 item 5: a probe import's report in the probe's words: poses and contacts, no seconds, no nest."""
    probe = simulated_probe_file(tmp_path, 3, "table_drift:vx_um=6,vy_um=-4,vz_um=8,tau_s=10", "--noise", "0.3")
    data = gather_report([probe], tolerances=TOLERANCES)
    (rep,) = data.measurements
    assert rep.diagnosis is not None and [f.effect for f in rep.diagnosis.findings] == ["table_drift"]
    html = write_report(data, tmp_path / "out").read_text(encoding="utf-8")
    text = re.sub(r"data:image/png;base64,[^\"]+", "", html)
    text = re.sub(r"<details>.*?</details>", "", text, flags=re.DOTALL)  # the statistics folded away
    for wrong in ("R-test deviation", "ball − nest", "ball at the reference pose", " s</td>", "t [s]", "tau_s",
                  "the machine shows table_drift", "file(s)", "False"):
        assert wrong not in text, wrong
    assert not re.search(r"(RMSE?|RMS \|d\|) -?[\d.]+e-\d", text)  # no RMSE of numerical noise: 1.52e-11
    assert "31 poses: the reference pose and 30 more poses, 155 contacts" in text
    assert "τ " in text and " poses" in text and "sphere centre at the reference pose" in text
    assert "the test set-up shows table_drift" in _answer(text)
    assert "sphere-probe: the search fits every row at its own precision" in text  # the note `pige diagnose` prints
    assert "Why two residuals" in text  # Overview (GLS, plain residual) and diagnosis baseline (whitened) explained
    sentence = rep.diagnosis.findings[0].sentence()
    assert "poses" in sentence and " s," not in sentence
