"""The check-up (issue 42): history schema, plan, programs, the fit with PIGEs held, the command, trend, limits, timing.

Oracles written here: the held PIGEs' effect by finite differences, scipy.stats' Theil–Sen slope, the trapezoidal move
time by hand, Student's t false-alarm rate of the limits by simulation, the forecast's coverage on simulated drifts.
"""

from __future__ import annotations

import json
import math
import re
import shlex
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from checkup_sim import FREE, MACHINE, T0, TRUTH, checkup_file, checkup_program, full_calibration, pige

from pige_sym.cli.main import main
from testdata import figures_not_drawn, refused_in_one_line

TOL = Path(__file__).resolve().parents[1] / "examples" / "tolerances.json"


@pytest.fixture(scope="module")
def machine(tmp_path_factory: pytest.TempPathFactory) -> dict:
    folder = tmp_path_factory.mktemp("checkup")
    db = folder / "h.db"
    full = full_calibration(folder, db, "DMU-1", TRUTH, tolerances=TOL)
    return {"folder": folder, "db": db, "full": full, "program": checkup_program(folder, db, "DMU-1")}


def _run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    capsys.readouterr()  # what came before (files made for the test)
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_history_of_schema_1_is_migrated_and_its_runs_read_as_full_calibrations(tmp_path: Path) -> None:
    from pige_sym.verdict.history import connect, list_runs
    from pige_sym.verdict.history.migrations import MIGRATIONS

    path = tmp_path / "old.db"
    engine = sa.create_engine(f"sqlite:///{path}")
    with engine.begin() as conn:
        MIGRATIONS[0].apply(conn)
        conn.execute(sa.text("CREATE TABLE schema_version (version INTEGER PRIMARY KEY, description TEXT NOT NULL, "
                             "applied_at VARCHAR(40) NOT NULL)"))
        conn.execute(sa.text("INSERT INTO schema_version VALUES (1, 'v1', 'then')"))
        conn.execute(sa.text("INSERT INTO machines VALUES ('OLD', :c, 'then')"), {"c": MACHINE})
        conn.execute(sa.text(
            "INSERT INTO runs (machine_id, file_sha256, file_name, measured_at, time_source, added_at, machine_code, "
            "method, parameters, units, values_json, std_json, covariance_json, dof, effects_json) VALUES ('OLD', "
            "'ab', '/gone.csv', '2025-01-01T00:00:00+00:00', 'x', 'x', :c, 'gauss-newton', '[\"EX0C\"]', "
            "'{\"EX0C\": \"um\"}', '[1.5]', '[0.1]', '[[0.01]]', 30, '[]')"), {"c": MACHINE})
    runs = list_runs(connect(str(path)), "OLD")
    assert [(r.kind, r.setup, r.values[0]) for r in runs] == [("full", None, 1.5)]
    with pytest.raises(Exception, match="no stored set-up and its file is not there"):
        from pige_sym.verdict.checkup.reference import run_setup

        run_setup(runs[0])


def _to_schema_1(db: Path) -> None:
    """Make a history of this version one of schema version 1 (its check-ups gone, the check-up columns dropped)."""
    import sqlite3

    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM runs WHERE kind = 'checkup'")
        for column in ("kind", "setup_json", "checkup_json", "chart_json", "after_correction"):
            conn.execute(f"ALTER TABLE runs DROP COLUMN {column}")
        conn.execute("DELETE FROM schema_version WHERE version >= 2")
    conn.close()


def _schema(db: Path) -> tuple[list[int], list[str]]:
    import sqlite3

    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
        versions = sorted(r[0] for r in conn.execute("SELECT version FROM schema_version"))
        columns = [r[1] for r in conn.execute("PRAGMA table_info(runs)")]
    conn.close()
    return versions, columns


def test_reading_a_schema_1_history_changes_nothing_and_a_check_up_migrates_it(machine: dict, tmp_path: Path,
                                                                                capsys, monkeypatch) -> None:
    """Reading never migrates or changes the file (issue 43); writing migrates (issue 42's schema 2): history show,
    fleet, plan --checkup and the check-up's own reading take a version-1 file as it is (its runs full calibrations,
    their set-up read from their files); the check-up migrates it when it stores its run, and only then.  (The
    report reads the file without drawing its figures: the trend plot's test below draws them.)"""
    import shutil

    figures_not_drawn(monkeypatch)
    db = tmp_path / "v1.db"
    shutil.copy(machine["db"], db)
    _to_schema_1(db)
    assert _schema(db)[0] == [1] and "kind" not in _schema(db)[1]
    before = db.read_bytes()
    for argv in (("history", "show", "DMU-1", "--db", db), ("history", "fleet", "--db", db),
                 ("plan", "--checkup", "--machine-id", "DMU-1", "--db", db, "--json"),
                 ("report", machine["full"], "--history", "DMU-1", "--db", db, "--out", tmp_path / "r",
                  "--no-figures")):
        code, _, err = _run(capsys, *argv)
        assert code == 0, (argv, err)
        assert db.read_bytes() == before, argv
    path = checkup_file(machine["program"], TRUTH, 96, tmp_path / "c.csv")
    code, _, err = _run(capsys, "checkup", tmp_path / "missing.csv", "--machine-id", "DMU-1", "--db", db)
    assert code == 2 and db.read_bytes() == before  # refused before storing: nothing migrated
    code, out, err = _run(capsys, "checkup", path, "--machine-id", "DMU-1", "--db", db, "--date",
                          (T0 + timedelta(days=1)).isoformat(), "--json")
    assert code in (0, 1), err
    versions, columns = _schema(db)
    assert versions == [1, 2, 3] and {"kind", "setup_json", "checkup_json", "chart_json",
                                      "after_correction"} <= set(columns)
    from pige_sym.verdict.history import connect, list_runs

    runs = list_runs(connect(str(db), create=False), "DMU-1")
    assert [r.kind for r in runs] == ["full", "checkup"] and runs[-1].id == json.loads(out)["run"]


@pytest.mark.parametrize("path", ["sqlite3", "sqlalchemy"])
def test_a_check_up_is_checked_before_it_is_stored(machine: dict, tmp_path: Path, capsys, monkeypatch,
                                                    path: str) -> None:
    """What the history would refuse to read back is never stored, a check-up too (issue 43's rule on issue 42's
    writes), on both paths: an absurd fit is refused in one line before it is judged, and a check-up row with an
    absurd estimate or a chart that is not one is refused by the store itself; the file is left as it was."""
    import shutil
    from types import SimpleNamespace

    import pige_sym.identification.subset as subset
    from pige_sym.errors import HistoryError
    from pige_sym.verdict.checkup.routine import CheckupOptions, run_checkup
    from pige_sym.verdict.history.sqlite_fast import SqliteHistory
    from pige_sym.verdict.history.store import EngineHistory, connect

    db = tmp_path / "h.db"
    shutil.copy(machine["db"], db)
    checkup = checkup_file(machine["program"], TRUTH, 97, tmp_path / "c.csv")
    real = subset.identify_subset

    def absurd(*args: object, **kwargs: object) -> object:
        fit = real(*args, **kwargs)  # type: ignore[arg-type]
        fit.values[0] = 1e308  # what a faulty fit could hand on
        return fit

    before = db.read_bytes()
    when = (T0 + timedelta(days=600)).isoformat()
    with monkeypatch.context() as patched:
        patched.setattr(subset, "identify_subset", absurd)
        if path == "sqlite3":
            code, _, err = _run(capsys, "checkup", checkup, "--machine-id", "DMU-1", "--db", db, "--date", when)
            refused_in_one_line(code, err, "c.csv: not added to the history", "EY0A = 1e+308 um is beyond ±10000")
        else:
            with pytest.raises(HistoryError, match="not added to the history.*EY0A = 1e\\+308 um is beyond"):
                run_checkup(EngineHistory(connect(str(db), create=False)), checkup, "DMU-1", CheckupOptions(date=when))
    assert db.read_bytes() == before
    history = SqliteHistory(db) if path == "sqlite3" else EngineHistory(connect(str(db), create=False))
    fit = SimpleNamespace(parameters=FREE, units={n: "um" for n in FREE}, values=np.array([1e308, 0, 0, 0]),
                          std=np.ones(4), covariance=np.eye(4), dof=3, rms_um=0.3)
    chart = {"signature": "s", "after_correction": False, "in_control": {}, "outside": {}, "flagged": {},
             "to_enter": None, "tolerance": {}}
    store = (checkup, "DMU-1", MACHINE, (when, "--date"))
    with pytest.raises(HistoryError, match="c.csv: not added to the history.*EY0A = 1e\\+308 um"):
        history.add_checkup(*store, fit, {}, "ok", {}, chart)
    fit.values[0] = 1.0
    with pytest.raises(HistoryError, match="chart_json: in_control: expected flags, got a list"):
        history.add_checkup(*store, fit, {}, "ok", {}, chart | {"in_control": [True]})
    assert db.read_bytes() == before


def test_a_damaged_check_up_is_refused_where_it_is_read(machine: dict, tmp_path: Path, capsys) -> None:
    """A check-up's chart (what later check-ups read) is checked with every run whenever the history is opened, by
    pige checkup as by history show; its findings (long, what show, the report and the fleet print) where they are
    read.  Both refused in one line naming the run and the column; the file is left as it was."""
    import shutil
    import sqlite3

    good = tmp_path / "good.db"
    shutil.copy(machine["db"], good)
    first = checkup_file(machine["program"], TRUTH, 98, tmp_path / "c1.csv")
    code, out, err = _run(capsys, "checkup", first, "--machine-id", "DMU-1", "--db", good, "--date",
                          (T0 + timedelta(days=700)).isoformat(), "--json")
    assert code in (0, 1), err
    run = json.loads(out)["run"]
    second = checkup_file(machine["program"], TRUTH, 99, tmp_path / "c2.csv")
    show = ("history", "show", "DMU-1")
    cases = {"chart_json": ('{"signature": 1}', "chart_json: no item 'after_correction'",
                            [("checkup", second, "--machine-id", "DMU-1"), show, ("history", "fleet"),
                             ("plan", "--checkup", "--machine-id", "DMU-1")]),
             "checkup_json": ('{"items": [', "checkup_json: not valid JSON",
                              [show, ("history", "fleet"), ("report", machine["full"], "--history", "DMU-1", "--out",
                                                            tmp_path / "r", "--no-figures")])}
    for column, (text, said, commands) in cases.items():
        db = tmp_path / f"{column}.db"
        shutil.copy(good, db)
        with sqlite3.connect(db) as conn:
            conn.execute(f"UPDATE runs SET {column} = ? WHERE id = ?", (text, run))
        conn.close()
        before = db.read_bytes()
        for argv in commands:
            code, _, err = _run(capsys, *argv, "--db", db)
            refused_in_one_line(code, err, f"history database {db} is damaged (run {run}, {said}",
                                "restore the file from a backup")
            assert db.read_bytes() == before, argv
    assert not (tmp_path / "r").exists()


def test_a_check_up_on_postgresql_reads_read_only_and_stores_its_run(tmp_path: Path, capsys, request) -> None:
    """On PostgreSQL a check-up reads through a read-only connection (issue 43) and stores its run through one that
    writes (the SQLAlchemy path: no sqlite3 file to read)."""
    from pige_sym.verdict.history import connect, list_runs

    url = request.getfixturevalue("postgres_url")  # skips when no server can start
    full_calibration(tmp_path, url, "PG-1", TRUTH, tolerances=TOL)  # type: ignore[arg-type]
    program = checkup_program(tmp_path, url, "PG-1")  # type: ignore[arg-type]
    path = checkup_file(program, TRUTH, 5, tmp_path / "c.csv")
    code, out, err = _run(capsys, "checkup", path, "--machine-id", "PG-1", "--db", url, "--date",
                          (T0 + timedelta(days=1)).isoformat(), "--json")
    assert code in (0, 1), err
    runs = list_runs(connect(url, create=False), "PG-1")
    assert [r.kind for r in runs] == ["full", "checkup"] and runs[-1].id == json.loads(out)["run"]


def test_the_plan_takes_the_fewest_poses_inside_the_calibrated_range(machine: dict, capsys) -> None:
    code, out, _ = _run(capsys, "plan", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--json")
    plan = json.loads(out)
    assert code == 0 and plan["free"] == FREE and plan["seconds"] <= 120
    angles = np.array(plan["angles_deg"])
    assert angles.shape[0] == 3 and not angles[0].any()  # 4 offsets, 3 per pose: the reference and two more
    from pige_sym.measurements.rtest import read_measurement

    full = read_measurement(machine["full"])
    assert (angles.min(axis=0) >= full.angles_deg.min(axis=0) - 1e-9).all()
    assert (angles.max(axis=0) <= full.angles_deg.max(axis=0) + 1e-9).all()
    code, out, _ = _run(capsys, "plan", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--pige",
                        "EX0C,EY0C", "--json")
    assert code == 0 and len(json.loads(out)["angles_deg"]) == 2  # the C line's offsets: one pose turned in C
    code, _, err = _run(capsys, "plan", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--budget", "20")
    refused_in_one_line(code, err, "take", "--budget 20")


def test_the_predicted_standard_errors_are_those_of_the_check_up_fits(machine: dict, tmp_path: Path, capsys) -> None:
    from pige_sym.identification.subset import identify_subset
    from pige_sym.measurements.rtest import read_measurement

    _, out, _ = _run(capsys, "plan", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--json")
    predicted = np.array([json.loads(out)["std"][n] for n in FREE])
    held = {n: v for n, v in TRUTH.items() if n not in FREE}
    fits = [identify_subset(read_measurement(checkup_file(machine["program"], TRUTH, 40 + i, tmp_path / f"{i}.csv")),
                            FREE, held) for i in range(10)]
    stated = np.mean([f.std for f in fits], axis=0)
    assert np.all(np.abs(stated / predicted - 1) < 0.35), (stated, predicted)  # contact scatter 0.3 vs the full's


def test_plan_and_program_plan_the_same_check_up_and_refuse_a_noise_that_is_no_positive_number(
        machine: dict, tmp_path: Path, capsys) -> None:
    """Both plan the same poses with the same predicted standard errors (program's --noise default is --map's alone);
    a --noise that is not a positive number is refused, also where the history's noise is used."""
    from pige_sym.nc.program_header import read_header

    _, out, _ = _run(capsys, "plan", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--json")
    code, text, err = _run(capsys, "program", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--out",
                        tmp_path / "c.ngc")
    assert code == 0, err
    header = read_header((tmp_path / "c.ngc").read_text())
    plan = json.loads(out)
    assert header["checkup"] == ",".join(plan["free"]) and f": {len(plan['angles_deg'])} poses" in text, text
    stated = dict(re.findall(r"(\w+) ([0-9.]+)", text.split("predicted: ")[1].split("std ")[1].splitlines()[0]))
    assert stated == {n: f"{plan['std'][n]:.3g}" for n in plan["free"]}, (stated, plan["std"])
    for command, value in (("plan", "nan"), ("program", "-1")):
        code, _, err = _run(capsys, command, "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--noise",
                            value, "--out", tmp_path / f"bad.{command}")
        refused_in_one_line(code, err, "--noise")
        assert not (tmp_path / f"bad.{command}").exists()


@pytest.mark.parametrize("dialect", ["linuxcnc", "fanuc", "siemens", "heidenhain"])
def test_check_up_programs_in_every_dialect_are_read_back_and_state_the_check_up(machine: dict, dialect: str,
                                                                                 tmp_path: Path, capsys) -> None:
    out = tmp_path / f"c.{dialect}"
    code, text, _ = _run(capsys, "program", "--checkup", "--machine-id", "DMU-1", "--db", machine["db"], "--dialect",
                         dialect, "--out", out)
    assert code == 0 and "read back:" in text
    from pige_sym.nc.program_header import read_header

    header = read_header(out.read_text())
    assert header["checkup"] == ",".join(FREE) and header["machine_id"] == "DMU-1"
    sphere = np.array([float(v) for v in header["sphere_mm"].split(",")])
    assert np.abs(sphere - [100, 20, 60]).max() < 1e-3  # where the calibration found it (fitted c(0), to 0.1 um)
    if dialect != "heidenhain":  # the program's safety statements are today's (tool, length, work offset)
        assert "99" in out.read_text() and "120" in out.read_text()


def test_the_fit_with_held_pige_against_finite_differences(machine: dict, tmp_path: Path) -> None:
    from pige_sym.identification.subset import identify_subset
    from pige_sym.measurements.rtest import read_measurement

    m = read_measurement(checkup_file(machine["program"], TRUTH, 3, tmp_path / "c.csv", noise=0.0))
    held = {n: v for n, v in TRUTH.items() if n not in FREE}
    fit = identify_subset(m, FREE, held)
    assert np.abs(fit.values - [TRUTH[n] for n in FREE]).max() < 0.02  # the log's six decimals
    assert fit.sensitivity is not None
    for j, name in enumerate(held):
        moved = identify_subset(m, FREE, held | {name: held[name] + 10.0})
        assert np.allclose((moved.values - fit.values) / 10.0, -fit.sensitivity[:, j], atol=1e-6)


def test_pige_checkup_says_ok_drifted_or_out_and_stores_the_run(machine: dict, tmp_path: Path, capsys) -> None:
    db, prog = machine["db"], machine["program"]
    days = iter(range(1, 50))
    status = {}
    for case, shift in (("ok", 0.0), ("drifted", 2.0), ("out", 10.0)):
        path = checkup_file(prog, TRUTH | {"EX0C": TRUTH["EX0C"] + shift}, 60 + next(days), tmp_path / f"{case}.csv")
        code, out, _ = _run(capsys, "checkup", path, "--machine-id", "DMU-1", "--db", db, "--date",
                            (T0 + timedelta(days=next(days))).isoformat(), "--json")
        res = json.loads(out)
        status[case] = (code, res["verdict"], res["run"])
    assert status["ok"][:2] == (0, "ok") and status["drifted"][:2] == (1, "drifted") and status["out"][:2] == (1, "out")
    code, out, _ = _run(capsys, "history", "show", "DMU-1", "--db", db, "--json")
    runs = json.loads(out)["runs"]
    assert [r["kind"] for r in runs] == ["full", "checkup", "checkup", "checkup"]
    # the change since the values in force (the full calibration's EX0C), never its value again (issue 49)
    assert runs[-1]["checkup"]["to_enter"]["EX0C"] == pytest.approx(10.0, abs=0.5)
    code, out, _ = _run(capsys, "history", "fleet", "--db", db, "--json")
    row = json.loads(out)["machines"][0]
    assert code == 0 and row["verdict"] == "out" and "said out" in row["why"]


def test_bad_input_is_refused_with_status_2(machine: dict, tmp_path: Path, capsys) -> None:
    db = machine["db"]
    path = checkup_file(machine["program"], TRUTH, 90, tmp_path / "c.csv")
    code, _, err = _run(capsys, "checkup", path, "--machine-id", "OTHER", "--db", db)
    refused_in_one_line(code, err, "DMU-1", "OTHER")
    code, _, err = _run(capsys, "checkup", machine["full"], "--machine-id", "DMU-1", "--db", db)
    refused_in_one_line(code, err, "already in the history")
    code, _, err = _run(capsys, "checkup", path, "--machine-id", "DMU-1", "--db", db, "--date", "2020-01-01")
    refused_in_one_line(code, err, "not after the machine's last run")
    code, _, err = _run(capsys, "checkup", path, "--machine-id", "DMU-1", "--db", tmp_path / "none.db")
    refused_in_one_line(code, err, "no history database")


def test_a_first_check_up_needs_tolerances_and_a_full_calibration(tmp_path: Path, capsys) -> None:
    db = tmp_path / "h.db"
    full = full_calibration(tmp_path, db, "NEW", TRUTH, seed=4)
    path = checkup_file(checkup_program(tmp_path, db, "NEW"), TRUTH, 91, tmp_path / "c.csv")
    code, _, err = _run(capsys, "checkup", path, "--machine-id", "NEW", "--db", db, "--date", "2027-01-01")
    refused_in_one_line(code, err, "--tolerances")
    assert full.exists()


def test_theil_sen_slope_against_scipy() -> None:
    from scipy.stats import theilslopes

    from pige_sym.verdict.checkup.trend import theil_sen

    rng = np.random.default_rng(1)
    for n in (2, 3, 7, 20):
        t = np.sort(rng.uniform(0, 100, n))
        x = 0.3 * t + rng.standard_normal(n) + np.where(rng.uniform(size=n) < 0.1, 20.0, 0.0)
        assert theil_sen(t, x)[0] == pytest.approx(theilslopes(x, t)[0], rel=1e-12)


def test_a_shown_drift_s_forecast_interval_covers_the_true_crossing() -> None:
    """Linear drifts of 0.5 to 2 scatter units per run over 6 check-ups, scatter known on 20 dof: a forecast is made
    only where the drift is shown (at the chart's level, here 0.25 %), and its 90 % interval of the time the line
    reaches the limit holds the true time in about nine of ten of those cases (an earliest time at the check-up:
    the band has reached the limit, the PIGE may be outside already)."""
    from pige_sym.verdict.checkup.trend import trend

    rng = np.random.default_rng(2)
    hits, shown, cases = 0, 0, 400
    for _ in range(cases):
        rate = rng.uniform(0.5, 2.0)
        t = np.arange(6.0)
        x = rate * t + rng.standard_normal(6)
        s = math.sqrt(rng.chisquare(20) / 20)
        tr = trend(t, x, 5.0, 20.0, scale=s, dof=20, shown_alpha=0.0025)
        assert tr is not None and (tr.leaves_at is not None) == tr.shown
        if not tr.shown:
            continue
        shown += 1
        truth = 20.0 / rate
        low = -math.inf if tr.reached else tr.leaves_low
        hits += low <= truth <= (tr.leaves_high if tr.leaves_high is not None else math.inf)
    assert shown > 300 and 0.84 <= hits / shown <= 0.96, (hits, shown)
    flat = [trend(np.arange(6.0), rng.standard_normal(6), 5.0, 20.0, scale=1.0, dof=20, shown_alpha=0.0025)
            for _ in range(2000)]
    assert sum(tr is not None and tr.leaves_at is not None for tr in flat) <= 12  # 0.25 %: 5 expected


def test_the_scatter_s_likelihood_against_the_normal_density() -> None:
    """The restricted likelihood of τ² (each segment's level integrated out under a flat prior) against scipy's
    multivariate normal: ``log N(x; μ̂1, V) − ½ log(1ᵀV⁻¹1)`` per segment, up to a constant in τ²."""
    from scipy.stats import multivariate_normal

    from pige_sym.verdict.checkup.scatter import Series, log_likelihood

    rng = np.random.default_rng(4)
    seg = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    x = rng.normal(size=seg.size) + seg * 3.0
    u2 = rng.uniform(0.1, 2.0, seg.size)
    tau2 = np.array([0.01, 0.3, 1.0, 4.0])
    mine = log_likelihood(Series("M", "EX0C", x, u2, seg), tau2)
    oracle = []
    for t in tau2:
        total = 0.0
        for s in np.unique(seg):
            v = t + u2[seg == s]
            w = 1 / v
            mu = (w @ x[seg == s]) / w.sum()
            total += multivariate_normal(np.full(v.size, mu), np.diag(v)).logpdf(x[seg == s]) - 0.5 * np.log(w.sum())
        oracle.append(total)
    assert np.allclose(mine - mine[0], np.array(oracle) - oracle[0], atol=1e-9)


def test_the_predictive_limits_hold_their_false_alarm_rate() -> None:
    """The limits for a machine that holds still, by simulation: segments of 10 runs (run-to-run scatter 1, own
    standard errors 0.5) judged with the posterior of their own and three like series (the hierarchical prior);
    each test's rate near its share of alpha (here alpha 0.2 over one PIGE, so that rates are counted)."""
    from pige_sym.verdict.checkup.limits import SHEWHART_SHARE, control_limit
    from pige_sym.verdict.checkup.scatter import Series, posteriors

    rng = np.random.default_rng(3)
    flags, n = np.zeros(2), 1500
    for _ in range(n):
        units = [Series("M", f"P{k}", rng.normal(size=10) * math.sqrt(1.25), np.full(10, 0.25), np.zeros(10, int))
                 for k in range(4)]
        post = posteriors(units[:1], units)["P0"]
        lim = control_limit(units[0].values, units[0].variances, post, value=rng.normal() * math.sqrt(1.25),
                            variance=0.25, run_dof=17, m=1, alpha=0.2)
        assert lim is not None and not lim.provisional
        flags += [abs(lim.z or 0) > 1, (lim.p_ewma or 1) < lim.alpha_test]
    rates = flags / n  # measured 4.5 % and 16.6 % against 4 % and 16 %
    assert 0.02 <= rates[0] <= 0.2 * SHEWHART_SHARE * 1.4, rates
    assert 0.09 <= rates[1] <= 0.2 * (1 - SHEWHART_SHARE) * 1.25, rates
    lim = control_limit(np.zeros(3), np.full(3, 1.0), None, value=100.0, variance=1.0, run_dof=17, m=4)
    assert lim is not None and lim.provisional and lim.outside  # nothing known of the scatter: provisional


def test_machine_time_of_a_move_by_hand() -> None:
    from pige_sym.nc.probe_timing import move_seconds

    assert move_seconds(100.0, 100.0, 1000.0) == pytest.approx(1.1)  # 100 mm at 100 mm/s: 1 s + 0.1 s to accelerate
    assert move_seconds(1.0, 100.0, 1000.0) == pytest.approx(2 * math.sqrt(1e-3))  # never reaches 100 mm/s
    assert move_seconds(0.0, 100.0, 1000.0) == 0.0


def test_the_check_up_program_time_against_its_moves(machine: dict) -> None:
    """The timed program: 27 probing moves of the clearance (3 mm) at F100 are 48.6 s alone; the rest is rapids."""
    from pige_sym.nc.probe_header import header_setup
    from pige_sym.nc.probe_program import ProbeSetup
    from pige_sym.nc.probe_timing import program_seconds

    text = Path(machine["program"]).read_text()
    h = header_setup(text, "p")
    setup = ProbeSetup(h.machine, h.sphere_mm, h.pivots_mm["A"], h.sphere_radius_mm, h.stylus_radius_mm,
                       controller=h.controller)
    t = program_seconds(text, "linuxcnc", setup, ("A", "C"))
    probes = text.count("G38.2")
    assert probes == 27
    assert t.probing_s == pytest.approx(probes * (3.0 / (100 / 60)) + 3 * 1.0, rel=0.2)  # + the 3 confirmations
    assert 60 < t.seconds < 120


def test_the_report_of_a_machine_with_check_ups_has_their_trend_plot(machine: dict, tmp_path: Path, capsys,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    path = checkup_file(machine["program"], TRUTH, 77, tmp_path / "c.csv")
    code, _, _ = _run(capsys, "checkup", path, "--machine-id", "DMU-1", "--db", machine["db"], "--date",
                      (T0 + timedelta(days=300)).isoformat())
    assert code in (0, 1)
    code, out, _ = _run(capsys, "report", "--history", "DMU-1", "--db", machine["db"], "--out", tmp_path / "rep")
    page = (tmp_path / "rep" / "report.html").read_text()
    assert code == 0 and 'data-section="checkup"' in page and 'data-figure="checkup-trend"' in page
    assert (tmp_path / "rep" / "_report" / "checkup_trend.png").stat().st_size > 10_000
    figures_not_drawn(monkeypatch)  # the same page with --json: its status is read, its figures were drawn above
    code, out, _ = _run(capsys, "report", "--history", "DMU-1", "--db", machine["db"], "--out", tmp_path / "r2",
                        "--json")
    assert code == 0


def test_t_quantile_and_chi_square_tail_against_scipy() -> None:
    from scipy.special import chdtrc, stdtrit

    from pige_sym.identification.distributions import chi2_sf, t_quantile

    for dof in (1, 1.5, 2, 3, 4, 7, 10, 19, 60, 1e3, 1e6, 1e8):
        for p in (0.5, 0.6, 0.95, 0.99875, 0.999375, 1 - 1e-7, 0.01, 1e-6):
            assert t_quantile(dof, p) == pytest.approx(stdtrit(dof, p), rel=1e-7, abs=1e-9), (dof, p)
    for k in (1, 2, 3, 17, 60, 1000):
        for x in (0.01, 1.0, 5.0, 30.0, 300.0, 3000.0):
            assert chi2_sf(k, x) == pytest.approx(chdtrc(k, x), rel=1e-10, abs=1e-300), (k, x)


def test_the_sqlite_path_reads_and_writes_what_sqlalchemy_does(machine: dict, tmp_path: Path) -> None:
    """``pige checkup`` reads an SQLite history with sqlite3 (SQLAlchemy's import is most of its second): the same
    records, the same stored row (the check-up judged once through each path, on two copies of the history)."""
    import shutil

    from pige_sym.verdict.checkup.routine import CheckupOptions, run_checkup
    from pige_sym.verdict.history.migrations import MIGRATIONS
    from pige_sym.verdict.history.sqlite_fast import SCHEMA_VERSION, SqliteHistory, open_history
    from pige_sym.verdict.history.store import EngineHistory, connect

    assert SCHEMA_VERSION == max(m.version for m in MIGRATIONS)
    path = checkup_file(machine["program"], TRUTH, 95, tmp_path / "c.csv")
    rows = {}
    for how in ("sqlite3", "sqlalchemy"):
        db = tmp_path / f"{how}.db"
        shutil.copy(machine["db"], db)
        history = open_history(str(db)) if how == "sqlite3" else EngineHistory(connect(str(db)))
        assert isinstance(history, SqliteHistory) == (how == "sqlite3")
        res = run_checkup(history, path, "DMU-1", CheckupOptions(date=(T0 + timedelta(days=400)).isoformat()))
        with sa.create_engine(f"sqlite:///{db}").connect() as conn:
            row = conn.execute(sa.text("SELECT * FROM runs WHERE id = :i"), {"i": res.run_id}).one()._asdict()
        rows[how] = {k: v for k, v in row.items() if k not in ("added_at", "checkup_json")}
        light = {h: list_runs_of(h, db) for h in ("fast", "engine")}
        assert [r.id for r in light["fast"]] == [r.id for r in light["engine"]]
        for a, b in zip(light["fast"], light["engine"], strict=True):
            assert np.array_equal(a.values, b.values, equal_nan=True) and a.checkup == b.checkup and a.kind == b.kind
    assert rows["sqlite3"] == rows["sqlalchemy"]


def list_runs_of(how: str, db: Path) -> list:
    from pige_sym.verdict.history.sqlite_fast import SqliteHistory
    from pige_sym.verdict.history.store import EngineHistory, connect

    history = SqliteHistory(db) if how == "fast" else EngineHistory(connect(str(db)))
    return history.list_runs("DMU-1", light=True)


def test_an_r_test_check_up_from_a_simulated_nest(tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch) -> None:
    """The R-test way: a full calibration, the check-up's poses as an angle file and its program, the nest's file of
    those poses; the noise is the calibration's (three poses leave two degrees of freedom of their own).  The
    drifted check-up's next step writes the next check-up's program as printed (Siemens: the R-test file does not
    state the dialect, and the words say so)."""
    db = tmp_path / "h.db"
    truth = ",".join(f"{k}={v}" for k, v in TRUTH.items())
    assert pige("simulate", "--machine", MACHINE, "--pige", truth, "--seed", 1, "--out", tmp_path / "full.csv") == 0
    assert pige("history", "add", tmp_path / "full.csv", "--machine-id", "RT", "--db", db, "--date", "2026-01-01",
                "--tolerances", TOL, "--method", "gauss-newton") == 0
    code, out, _ = _run(capsys, "plan", "--checkup", "--machine-id", "RT", "--db", db, "--out", tmp_path / "a.csv",
                        "--json")
    assert code == 0 and json.loads(out)["seconds"] <= 120 and len(json.loads(out)["angles_deg"]) == 3
    code, _, _ = _run(capsys, "program", "--checkup", "--machine-id", "RT", "--db", db, "--dialect", "fanuc", "--out",
                      tmp_path / "c.nc")
    assert code == 0 and "G04 X7." in (tmp_path / "c.nc").read_text()
    verdicts = []
    for day, shift in ((2, 0.0), (3, 3.0)):
        moved = truth.replace(f"EX0C={TRUTH['EX0C']}", f"EX0C={TRUTH['EX0C'] + shift}")
        assert pige("simulate", "--machine", MACHINE, "--pige", moved, "--seed", day, "--trajectory",
                    tmp_path / "a.csv", "--out", tmp_path / f"c{day}.csv") == 0
        code, out, _ = _run(capsys, "checkup", tmp_path / f"c{day}.csv", "--machine-id", "RT", "--db", db, "--date",
                            f"2026-01-0{day}", "--json")
        verdicts.append((code, json.loads(out)["verdict"], json.loads(out)["items"][2]["std"]))
    assert verdicts[0][:2] == (0, "ok") and verdicts[1][:2] == (1, "drifted")
    assert verdicts[0][2] < 0.3  # the calibration's noise, not two residual degrees of freedom
    what, command = json.loads(out)["next_step"]
    assert command == f"pige program --checkup --machine-id RT --db {db} --out checkup_RT_run4.mpf", command
    assert "add --dialect fanuc or linuxcnc" in what and "--corrected" in what
    monkeypatch.chdir(tmp_path)
    code, _, _ = _run(capsys, *shlex.split(command)[1:])
    assert code == 0 and "TRAFOOF" in (tmp_path / "checkup_RT_run4.mpf").read_text()


@pytest.mark.parametrize(("argv", "said"), [
    (["plan", "--checkup", "--map", "C,A", "--machine-id", "M"], "--checkup and --map plan different tests"),
    (["plan", "--machine-id", "M"], "--machine-id and --pige plan a check-up: give --checkup"),
    (["program", "--checkup", "--map", "C,A", "--machine-id", "M", "--out", "x.ngc"],
     "--checkup and --map write different programs"),
    (["program", "--pige", "EX0C", "--out", "x.ngc"], "--machine-id and --pige write a check-up program"),
])
def test_the_check_up_options_come_together(capsys: pytest.CaptureFixture[str], tmp_path: Path, argv: list[str],
                                             said: str) -> None:
    out = tmp_path / "x.ngc"
    code, _, err = _run(capsys, *[str(out) if a == "x.ngc" else a for a in argv])
    assert code == 2 and said in err, err
    assert not out.exists()
