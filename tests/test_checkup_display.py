"""What a user sees of the check-ups (issue 49, item 4): the CLI, ``history show``/``fleet`` and the history report.

Histories of real files (the virtual machine's logs, imported, ``pige checkup``), in one database with a second
machine stored first (so that the database's run ids are not the machine's run numbers):

- the report of a machine whose last check-up is ``ok``, ``drifted`` and ``out``: its verdict badge visible in
  Chromium (a coloured box, white text of contrast ≥ 4.5 on it), its title names the instrument (touch probe), the
  database's path, run numbers per machine, a "changed" that names the PIGE, the same next step as the CLI, a
  check-up section that opens in words (no formula), one unit for the drift column;
- the CLI: run numbers per machine, one unit for the drift column, the legend naming the PIGE flagged (never
  "(by none)"), every row's cells apart; ``history fleet``: "1 day", "OVERDUE".
"""

from __future__ import annotations

import json
import re
import shutil
from datetime import datetime, timedelta, timezone
from html import unescape
from pathlib import Path

import pytest
from checkup_sim import T0, TRUTH, checkup_file, checkup_program, full_calibration
from chromium_pipe import Browser, window_viewport

from pige_sym.cli.main import main
from testdata import CHROMIUM

TOL = Path(__file__).resolve().parents[1] / "examples" / "tolerances.json"
SHIFT = {"ok": 0.0, "drifted": 2.0, "out": 10.0}


def _run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str]:
    capsys.readouterr()
    code = main([str(a) for a in args])
    return code, capsys.readouterr().out


@pytest.fixture(scope="module")
def histories(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Per verdict a copy of one history (another machine first, then DMU-9's calibration and two check-ups) whose
    last check-up says it; and the CLI's text of that check-up."""
    import contextlib
    import io

    root = tmp_path_factory.mktemp("display")
    db = root / "h.db"
    full_calibration(root / "other", db, "OTHER", TRUTH, seed=3)
    full_calibration(root, db, "DMU-9", TRUTH, tolerances=TOL, when=T0 + timedelta(days=1))
    program = checkup_program(root, db, "DMU-9")
    for day in (2, 3):
        path = checkup_file(program, TRUTH, 700 + day, root / f"c{day}.csv")
        with contextlib.redirect_stdout(io.StringIO()):
            main(["checkup", str(path), "--machine-id", "DMU-9", "--db", str(db), "--date",
                  (T0 + timedelta(days=day)).isoformat()])
    out = {}
    for verdict, shift in SHIFT.items():
        copy = root / f"{verdict}.db"
        shutil.copy(db, copy)
        path = checkup_file(program, TRUTH | {"EX0C": TRUTH["EX0C"] + shift}, 710, root / f"{verdict}.csv")
        text = io.StringIO()
        with contextlib.redirect_stdout(text):
            code = main(["checkup", str(path), "--machine-id", "DMU-9", "--db", str(copy), "--date",
                         (T0 + timedelta(days=4)).isoformat()])
        assert main(["report", "--history", "DMU-9", "--db", str(copy), "--out", str(root / f"rep-{verdict}"),
                     "--no-figures"]) == 0
        out[verdict] = {"db": copy, "code": code, "text": text.getvalue(),
                        "html": (root / f"rep-{verdict}" / "report.html").read_text(encoding="utf-8")}
    return out


def test_the_cli_numbers_runs_per_machine_and_keeps_one_unit_per_column(histories: dict) -> None:
    text = histories["drifted"]["text"]
    assert "its run 4," in text  # the database's id is 5: the other machine's run came first
    assert "drift [um/day, 90 %]" in text and "/h" not in text
    assert "(by none)" not in text and "* outside its control limits: EX0C by" in text
    rows = [ln for ln in text.splitlines() if re.match(r"(PIGE|E[XYZ]0[AC]) ", ln)]
    for row in rows:  # ten cells apart, none running into the next (cells hold single blanks only)
        assert len(re.split(r" {2,}", row.strip())) == 10, row
    assert "no PIGE outside its control limits" in histories["ok"]["text"]


def test_history_show_numbers_runs_per_machine(histories: dict, capsys) -> None:
    code, out = _run(capsys, "history", "show", "DMU-9", "--db", histories["ok"]["db"])
    assert code == 0 and re.search(r"^\s+1\s+2026-03-03", out, re.M) and "run 3 -> 4" in out
    code, out = _run(capsys, "history", "show", "DMU-9", "--db", histories["ok"]["db"], "--json")
    assert [r["number"] for r in json.loads(out)["runs"]] == [1, 2, 3, 4]


def test_fleet_says_days_right_and_overdue(histories: dict, capsys) -> None:
    code, out = _run(capsys, "history", "fleet", "--db", histories["ok"]["db"])
    assert code == 0 and not re.search(r"\b1 days", out) and "(1 day, median of 2 gaps)" in out, out
    assert "OVERDUE since" in out  # 2026 is past: the check-up after the last was due a day after it
    code, out = _run(capsys, "history", "fleet", "--db", histories["drifted"]["db"])
    row = next(ln for ln in out.splitlines() if ln.startswith("DMU-9"))
    assert "OVERDUE since 2026-03-06 07:00 (the last check-up said drifted)" in row


@pytest.mark.parametrize("verdict", list(SHIFT))
def test_the_report_names_what_the_cli_says(histories: dict, verdict: str) -> None:
    h = histories[verdict]
    html = h["html"]
    assert h["code"] == (0 if verdict == "ok" else 1)
    assert "<h1>Five-axis calibration report (touch probe)</h1>" in html
    assert f"in <code>{h['db']}</code>" in html  # the path, not sqlite://
    assert f'data-verdict="{verdict}" class="badge {verdict}"' in html
    said = re.search(r"^next step: (.*)$", h["text"], re.M)
    assert said is not None
    step = re.search(r'data-next-step="1">([^<]*)<', html)
    assert step is not None and unescape(step.group(1)).rstrip(".").lower() == said.group(1).lower(), (step, said)
    section = html[html.index('data-section="checkup"'):]
    opening = section[:section.index("</p>")]
    assert "t_nu" not in html and "alpha/(" not in opening and "The last one's limits: learned from" in opening
    assert "drift per day [90 %]" in section and "per hour" not in section
    assert re.search(r"<td[^>]*>4</td>", section)  # run 4 of the machine (database id 5)
    if verdict != "ok":
        assert re.search(r"run 3 → 4: <b>changed: EX0C", html), re.findall(r"run \d → \d: [^(]*", html)


BADGE_PROBE = """<script>
window.addEventListener('load', function () {
  function lum(c) { var v = c.match(/[\\d.]+/g).slice(0, 3).map(function (x) { x = x / 255;
    return x <= 0.03928 ? x / 12.92 : Math.pow((x + 0.055) / 1.055, 2.4); });
    return 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2]; }
  var b = document.querySelector('.answer [data-verdict]');
  var s = getComputedStyle(b);
  var bg = s.backgroundColor, fg = s.color, alpha = (bg.match(/[\\d.]+/g)[3] || '1');
  var l1 = lum(bg), l2 = lum(fg), ratio = (Math.max(l1, l2) + 0.05) / (Math.min(l1, l2) + 0.05);
  var r = b.getBoundingClientRect();
  var w = document.documentElement.clientWidth;
  var wide = Array.from(document.querySelectorAll('body *')).filter(function (e) {
    return e.getBoundingClientRect().right > w + 1; }).length;
  var d = document.createElement('pre'); d.id = 'pige-badge';
  d.textContent = 'text=' + b.textContent.trim() + ' alpha=' + alpha + ' contrast=' + ratio.toFixed(2) +
    ' width=' + Math.round(r.width) + ' bottom=' + Math.round(r.bottom) + ' wide=' + wide;
  document.body.appendChild(d);
});
</script>"""


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")
@pytest.mark.parametrize("verdict", list(SHIFT))
def test_the_verdict_badge_is_visible_in_chromium(chromium: Browser, histories: dict, verdict: str,
                                                   tmp_path: Path) -> None:
    """The first screen's verdict of the history is a coloured badge with readable text (WCAG contrast ≥ 4.5), and
    the page, its check-up tables too, fits a 1000 px window."""
    page = tmp_path / "page.html"
    page.write_text(histories[verdict]["html"].replace("</body>", BADGE_PROBE + "</body>"), encoding="utf-8")
    with chromium.load(page.as_uri(), window_viewport(1000, 800)) as loaded:  # as --window-size=1000,800
        dom = loaded.dom()
    found = re.search(r'<pre id="pige-badge">([^<]*)</pre>', dom)
    assert found, chromium.stderr()
    got = dict(kv.split("=", 1) for kv in found.group(1).split())
    assert got["text"] == verdict.upper() and float(got["alpha"]) == 1.0, got
    assert float(got["contrast"]) >= 4.5 and int(got["width"]) > 20 and int(got["bottom"]) < 800, got
    assert got["wide"] == "0", got


def test_the_report_s_next_step_for_an_old_check_up_is_computed_as_the_cli_s() -> None:
    """A check-up stored before the next step was: the report computes it with the CLI's function."""
    from types import SimpleNamespace

    from pige_sym.report.next_step import checkup_next
    from pige_sym.verdict.checkup.routine import NextRun, next_step

    run = SimpleNamespace(verdict="drifted", machine_id="M 1", checkup={"to_enter": {"EX0C": 2.0}, "notes": []})
    step = checkup_next(run, "h.db", 3)
    what, command = next_step("drifted", [], {"EX0C": 2.0}, "M 1", NextRun("h.db", None, 3))
    assert step.what.rstrip(".").lower() == what.lower() and step.commands == [command]
    assert command == "pige program --checkup --machine-id 'M 1' --db h.db --out checkup_M_1_run4.mpf"
    assert what.endswith("with --machine-id 'M 1' --db h.db --corrected")


def test_due_dates_are_marked_overdue() -> None:
    from pige_sym.cli.history import _due

    now = datetime(2026, 5, 1, 12, 0, tzinfo=timezone.utc)
    assert _due("2026-04-30T12:00+00:00", now) == "OVERDUE since 2026-04-30 12:00"
    assert _due("2026-05-02T12:00+00:00", now) == "2026-05-02 12:00"
    assert _due("2026-05-01T12:00+00:00", now) == "now"


def test_a_full_calibration_after_a_correction_is_said_so_and_starts_a_segment(histories: dict, tmp_path: Path,
                                                                                 capsys) -> None:
    """``pige history add --corrected``: stored (schema 3), said by add and show, and it starts a segment."""
    from pige_sym.verdict.checkup.reference import segments_of
    from pige_sym.verdict.history import connect, list_runs

    db = tmp_path / "h.db"
    shutil.copy(histories["ok"]["db"], db)
    folder = tmp_path / "again"
    full = full_calibration(folder, tmp_path / "scratch.db", "X", TRUTH, seed=9, when=T0 + timedelta(days=9))
    code, out = _run(capsys, "history", "add", full, "--machine-id", "DMU-9", "--db", db, "--date",
                     (T0 + timedelta(days=9)).isoformat(), "--corrected")
    assert code == 0 and "added run 5 of machine DMU-9" in out and "after a correction" in out, out
    code, out = _run(capsys, "history", "show", "DMU-9", "--db", db)
    assert re.search(r"^\s+5\s.*\(after a correction\)$", out, re.M), out
    runs = list_runs(connect(str(db), create=False), "DMU-9")
    assert runs[-1].after_correction and segments_of(runs) == [0, 0, 0, 0, 1]
