"""pige history: runs in SQLite and a real PostgreSQL, changes with an honest significance, false alarms <= 1 %."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from scipy import stats

from pige_sym.cli.main import main
from pige_sym.errors import InputError
from pige_sym.identification.least_squares import identify
from pige_sym.model.trajectories import cone_frustum
from pige_sym.simulation.simulator import random_pige, simulate
from pige_sym.verdict.history import compare_runs, connect, list_runs
from pige_sym.verdict.history import tables as T
from pige_sym.verdict.history.migrations import MIGRATIONS

AC = "wC'A'bXYZ(C1)t"
TRAJ = cone_frustum(AC, points=30)
PIGE = random_pige(AC, 1)


def _write_run(path: Path, seed: int, shift_um: float = 0.0, date: str | None = None) -> Path:
    pige = dict(PIGE)
    pige["EX0C"] += shift_um
    sim = simulate(AC, TRAJ, pige=pige, noise_um=0.25, seed=seed)
    if date is not None:
        sim.measurement.metadata["date"] = date
    csv, _ = sim.write(path)
    return csv


# --------------------------------------------------------------------------------------------- PostgreSQL


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'history.sqlite'}"
    url = request.getfixturevalue("postgres_url")
    engine = connect(url)  # a clean schema per test
    with engine.begin() as conn:
        for table in ("runs", "machines", "schema_version"):
            conn.execute(sa.text(f"DROP TABLE IF EXISTS {table} CASCADE"))
    engine.dispose()
    return url


# --------------------------------------------------------------------------------------------- tests


def test_three_runs_one_real_change(db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    files = [_write_run(tmp_path / "a.csv", 11, date="2026-01-05T08:00"),
             _write_run(tmp_path / "b.csv", 12, date="2026-03-05T08:00"),
             _write_run(tmp_path / "c.csv", 13, shift_um=8.0, date="2026-06-05T08:00")]
    for f in reversed(files):  # added out of order: listed by measurement time
        assert main(["history", "add", str(f), "--machine-id", "DMU-1", "--db", db_url]) == 0
    capsys.readouterr()
    assert main(["history", "show", "DMU-1", "--db", db_url, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [Path(r["file"]).name for r in out["runs"]] == ["a.csv", "b.csv", "c.csv"]
    first, second = out["runs"][0]["id"], out["runs"][1]["id"]
    cov = np.array(out["runs"][0]["covariance"]["matrix"])
    assert cov.shape == (8, 8) and np.allclose(cov, cov.T)
    changes = out["changes"]
    assert len(changes) == 16 and {"parameter", "from_run", "to_run", "change", "std", "significant"} <= set(changes[0])
    noise_only = [c for c in changes if c["from_run"] == first]
    assert not any(c["significant"] for c in noise_only)
    moved = [c for c in changes if c["from_run"] == second]
    assert [c["parameter"] for c in moved if c["significant"]] == ["EX0C"]
    ex0c = next(c for c in moved if c["parameter"] == "EX0C")
    assert abs(ex0c["change"] - 8.0) < 4 * ex0c["std"]
    assert [c["significant"] for c in out["comparisons"]] == [False, True]
    assert "Bonferroni" in out["comparisons"][0]["test"]
    assert main(["history", "show", "DMU-1", "--db", db_url]) == 0
    text = capsys.readouterr().out
    assert "SIGNIFICANT" in text and text.count("SIGNIFICANT") == 1


def test_the_same_file_is_refused(db_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = _write_run(tmp_path / "run.csv", 21)
    assert main(["history", "add", str(csv), "--machine-id", "M", "--db", db_url]) == 0
    copy = tmp_path / "renamed.csv"
    shutil.copy(csv, copy)
    for again in (csv, copy):
        capsys.readouterr()
        assert main(["history", "add", str(again), "--machine-id", "M2", "--db", db_url]) == 2
        err = capsys.readouterr().err
        assert "already in the history" in err and err.count("\n") == 1
    assert len(list_runs(connect(db_url), "M")) == 1


def test_verdict_is_stored_and_machine_structure_checked(db_url: str, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    from testdata import REPO

    csv = _write_run(tmp_path / "run.csv", 22)
    assert main(["history", "add", str(csv), "--machine-id", "M", "--db", db_url, "--json",
                 "--tolerances", str(REPO / "examples" / "tolerances.json")]) == 0
    run = json.loads(capsys.readouterr().out)
    assert run["verdict"] in ("pass", "fail", "undecided") and run["check"]["verdict"] == run["verdict"]
    other = simulate("wC'B'bXYZ(C1)t", cone_frustum("wC'B'bXYZ(C1)t", points=20), seed=3)
    b_csv, _ = other.write(tmp_path / "b.csv")
    assert main(["history", "add", str(b_csv), "--machine-id", "M", "--db", db_url]) == 2
    assert "use the right --machine-id" in capsys.readouterr().err


def test_unknown_machine_lists_the_known(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    assert main(["history", "add", str(_write_run(tmp_path / "r.csv", 23)), "--machine-id", "M", "--db", url]) == 0
    assert main(["history", "show", "nope", "--db", url]) == 2
    assert "known: M" in capsys.readouterr().err


def test_migrations_build_the_tables_and_refuse_a_newer_schema(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    engine = connect(url)
    connect(url)  # idempotent
    insp = sa.inspect(engine)
    for table in T.metadata.sorted_tables:
        assert {c["name"] for c in insp.get_columns(table.name)} == {c.name for c in table.columns}
    with engine.begin() as conn:
        versions = list(conn.execute(sa.select(T.schema_version.c.version)).scalars())
        assert versions == [m.version for m in MIGRATIONS]
        conn.execute(sa.insert(T.schema_version).values(version=999, description="future", applied_at="x"))
    with pytest.raises(InputError, match="newer"):
        connect(url)


def test_default_database_follows_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pige_sym.verdict.history import default_url

    monkeypatch.setenv("PIGE_HISTORY_DB", str(tmp_path / "env.sqlite"))
    assert default_url() == str(tmp_path / "env.sqlite")
    monkeypatch.delenv("PIGE_HISTORY_DB")
    assert default_url().startswith("sqlite:///") and default_url().endswith("history.sqlite")


def test_joint_statistic_matches_an_independent_computation() -> None:
    a = identify(simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=31).measurement)
    b = identify(simulate(AC, TRAJ, pige={**PIGE, "EY0A": PIGE["EY0A"] + 0.6}, noise_um=0.25, seed=32).measurement)
    comp = compare_runs(a, b)
    d = b.values - a.values
    cov = a.covariance + b.covariance
    t2 = float(d @ np.linalg.solve(cov, d))
    assert comp.statistic == pytest.approx(t2, rel=1e-6) and comp.rank == 8
    assert comp.p_value == pytest.approx(stats.f.sf(t2 / 8, 8, min(a.dof, b.dof)), rel=1e-6)
    ey = next(c for c in comp.changes if c.parameter == "EY0A")
    assert ey.std == pytest.approx(np.sqrt(cov[0, 0])) and ey.z == pytest.approx(d[0] / np.sqrt(cov[0, 0]))
    va, vb = a.covariance[0, 0], b.covariance[0, 0]
    welch = (va + vb) ** 2 / (va**2 / a.dof + vb**2 / b.dof)
    assert ey.p_value == pytest.approx(2 * stats.t.sf(abs(ey.z), welch), rel=1e-9)


def test_undetermined_parameters_are_not_tested() -> None:
    m1 = simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=41).measurement
    m2 = simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=42).measurement
    a, b = identify(m1, projection="x"), identify(m2)
    comp = compare_runs(a, b)
    missing = {p for p, v in zip(a.parameters, a.values, strict=True) if not np.isfinite(v)}
    assert missing
    for c in comp.changes:
        assert (c.significant is None) == (c.parameter in missing)
    assert comp.n_tested == 8 - len(missing)


def test_false_alarm_rate_of_pure_noise_pairs_is_at_most_one_percent() -> None:
    n = 400
    alarms = joint = 0
    for i in range(n):
        a = identify(simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=1000 + 2 * i).measurement)
        b = identify(simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=1001 + 2 * i).measurement)
        comp = compare_runs(a, b)
        joint += comp.significant
        alarms += any(c.significant for c in comp.changes)
    # binomial(400, 0.01): mean 4, P(X >= 9) < 2 %; a level of 5 % would give ~20
    assert joint <= 8 and alarms <= joint, (joint, alarms)
    # and the test has power: 1 µm on EX0C (σ of the change ≈ 0.07 µm) is always found
    for i in range(20):
        a = identify(simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=5000 + 2 * i).measurement)
        b = identify(simulate(AC, TRAJ, pige={**PIGE, "EX0C": PIGE["EX0C"] + 1.0}, noise_um=0.25,
                              seed=5001 + 2 * i).measurement)
        assert [c.parameter for c in compare_runs(a, b).changes if c.significant] == ["EX0C"]


def test_runs_fitted_with_different_effects_are_noted() -> None:
    from types import SimpleNamespace

    a = identify(simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=51).measurement)
    b = identify(simulate(AC, TRAJ, pige=PIGE, noise_um=0.25, seed=52).measurement)

    def run(res: object, effects: list[dict[str, object]]) -> SimpleNamespace:
        return SimpleNamespace(**{k: getattr(res, k) for k in ("parameters", "values", "covariance", "dof", "units")},
                               effects=effects)

    same = compare_runs(run(a, [{"effect": "angular_error_C"}]), run(b, [{"effect": "angular_error_C"}]))
    other = compare_runs(run(a, []), run(b, [{"effect": "angular_error_C"}, {"effect": "outliers"}]))
    assert same.notes == [] and compare_runs(a, b).notes == []
    assert len(other.notes) == 1 and "none vs angular_error_C" in other.notes[0]


# Racers for the concurrency tests: one fresh interpreter (single-threaded: OpenBLAS kept to one thread)
# imports the code once, forks one process per call, and releases them all at once by closing a pipe they
# block on (a starting gun: every racer returns from its read at the same instant, after every import).
# Each racer is a separate process with its own database connection, as twelve `pige` commands would be;
# forking a pre-imported interpreter instead of starting twelve saves their imports (~1.4 s CPU each) and
# makes the start tighter than a wall-clock instant agreed in advance.
RACE = """
import importlib, json, os, sys, traceback
module, name = sys.argv[1].split(":")
func = getattr(importlib.import_module(module), name)
spec = json.loads(sys.argv[2])
for extra in spec["preload"]:
    importlib.import_module(extra)


def racer(args, gun_r, log):
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    status = 1
    try:
        os.read(gun_r, 1)  # returns when the parent closes the pipe
        result = func(*args)
        status = result if isinstance(result, int) else 0
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)


out = []
for r, calls in enumerate(spec["rounds"]):
    gun_r, gun_w = os.pipe()
    children = []
    for i, args in enumerate(calls):
        log = os.path.join(spec["folder"], f"racer{r}-{i}.log")
        pid = os.fork()
        if pid == 0:
            os.close(gun_w)
            racer(args, gun_r, log)
        children.append((pid, log))
    os.close(gun_r)
    os.close(gun_w)  # the starting gun
    results = []
    for pid, log in children:
        _, status = os.waitpid(pid, 0)
        with open(log, encoding="utf-8", errors="replace") as f:
            results.append([os.waitstatus_to_exitcode(status), f.read()])
    out.append(results)
print(json.dumps(out))
"""


def _race(func: str, rounds: list[list[list[object]]], folder: Path, preload: tuple[str, ...] = ()) -> list[list]:
    """Per round, ``func(*args)`` for every ``args`` of the round in separate processes started at once (RACE);
    the rounds one after the other.  Returns per round ``[exit status, output]`` per call."""
    import sys

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    spec = json.dumps({"rounds": rounds, "folder": str(folder), "preload": list(preload)})
    done = subprocess.run([sys.executable, "-c", RACE, func, spec], capture_output=True, text=True, timeout=300,
                          env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


#: What ``pige history add`` imports, loaded once before the racers fork (``pige_sym.verdict.history`` alone is a
#: lazy package: without its store each racer imported SQLAlchemy and the CLI's modules itself: one add 0.9 s of CPU
#: after the fork, 0.26 s with them loaded; measured: the test 8.4-9.4 -> 2.6-3.5 s CPU).
ADD_PRELOAD = ("pige_sym.cli.history", "pige_sym.verdict.history.store", "pige_sym.verdict.history.migrations",
               "sqlalchemy.dialects.sqlite", "pige_sym.cli.registry", "pige_sym.diagnosis.diagnose",
               "pige_sym.identification.least_squares", "pige_sym.measurements.rtest")


def test_twelve_adds_started_at_once_on_a_new_database_all_succeed(tmp_path) -> None:
    """The first migration must be safe under concurrency: no 'table schema_version already exists'.

    Twelve ``pige history add`` (``main`` as ``python -m pige_sym`` runs it) in twelve processes released at
    one instant on a new SQLite database: every one succeeds and the database holds all twelve runs."""
    files = []
    for i in range(12):
        sim = simulate(AC, cone_frustum(AC, points=12), pige=random_pige(AC, i), noise_um=0.3, seed=i)
        files.append(sim.write(tmp_path / f"run{i}.csv")[0])
    db = tmp_path / "new.db"
    calls = [[["history", "add", str(f), "--machine-id", "M-7", "--db", str(db), "--method", "gauss-newton",
               "--date", f"2026-01-{i + 1:02d}"]] for i, f in enumerate(files)]
    [results] = _race("pige_sym.cli.main:main", [calls], tmp_path,
                      preload=ADD_PRELOAD)
    failed = [(status, out) for status, out in results if status != 0]
    assert not failed, failed
    assert all("added run" in out for _, out in results)
    assert len(list_runs(connect(f"sqlite:///{db}"), "M-7")) == 12


def test_the_first_migration_is_safe_when_twelve_processes_connect_at_the_same_instant(tmp_path) -> None:
    """Twelve processes (not forks of this test run: a fork of a threaded run can deadlock; forks of a fresh
    single-threaded interpreter, RACE) connect to a new database at one instant, three times."""
    urls = [f"sqlite:///{tmp_path / f'race{trial}.db'}" for trial in range(3)]
    rounds = _race("pige_sym.verdict.history.store:connect", [[[url]] * 12 for url in urls], tmp_path)
    for url, results in zip(urls, rounds, strict=True):
        failed = [out.strip().splitlines()[-1] for status, out in results if status != 0]
        assert not failed, failed[:2]
        with connect(url).connect() as conn:
            assert conn.execute(sa.select(sa.func.count()).select_from(T.schema_version)).scalar() == len(MIGRATIONS)
