"""Benchmark of ``pige checkup`` (issue 42: an answer in under 1 s with 1,000 runs in the history).

A history of one machine is built in a temporary SQLite file: a full probing calibration of the virtual machine
(``pige history add``), then 999 check-ups stored as ``pige checkup`` stores them (the JSON a real check-up wrote,
with values drawn around the machine's, one a day), so the history holds 1,000 runs and the chart has 999 points
with the check-up program's signature.  Then ``pige checkup`` judges new check-up files (the virtual machine's logs of
the program ``pige program --checkup`` wrote, imported): each as a fresh process (``python -m pige_sym checkup``,
wall and CPU time, median of the repeats, interpreter start included, with Python's bytecode cache as an installed
pige has it), and in this process (the work alone).  The bare ``python -c "import numpy"`` and ``import numpy,
sqlalchemy`` (what reading the history through SQLAlchemy would add: ``pige checkup`` reads an SQLite history with
``sqlite3``) are timed in the same run.

``main()`` prints a markdown section (``--runs`` sets the history's size, ``--repeats`` the timed check-ups).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pige_sym.cli.main import main as pige  # noqa: E402

MACHINE = "wC'A'bXYZ(C1)t"
TRUTH = "EY0A=3,EZ0A=-2,EB0A=15,EC0A=-12,EX0C=2.5,EY0C=-1.5,EA0C=8,EB0C=-6"
SPHERE = ["--sphere", "100,20,60", "--sphere-radius", "12.7", "--stylus-radius", "1.5"]
KINS = ["--rtcp-off", "M429", "--rtcp-on", "M428", "--stylus-tool", "99", "--stylus-length", "120"]
T0 = datetime(2024, 1, 1, 7, 0, tzinfo=timezone.utc)
TOL = ROOT / "examples" / "tolerances.json"


def _quiet(*args: object) -> None:
    """``pige ARGS`` in this process, its output dropped; fails loudly."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        code = pige([str(a) for a in args])
    if code != 0:
        raise RuntimeError(f"pige {' '.join(map(str, args))} exited {code}")


def _checkup_file(program: Path, seed: int, out: Path) -> Path:
    _quiet("simulate", "--instrument", "sphere-probe", "--program", program, "--pige", TRUTH, "--seed", seed,
           "--noise", 0.3, "--out", out.with_suffix(".txt"), "--force")
    _quiet("import-probe", out.with_suffix(".txt"), "--format", "linuxcnc", "--program", program, "--out", out,
           "--force")
    return out


def build_history(folder: Path, runs: int) -> tuple[Path, Path]:
    """(database, check-up program): a full calibration, one real check-up, then check-ups stored directly."""
    db = folder / "h.db"
    _quiet("program", "--instrument", "sphere-probe", "--dialect", "linuxcnc", "--machine", MACHINE, *SPHERE, *KINS,
           "--out", folder / "full.ngc")
    _quiet("simulate", "--instrument", "sphere-probe", "--program", folder / "full.ngc", "--pige", TRUTH, "--seed", 1,
           "--noise", 0.3, "--out", folder / "full.txt")
    _quiet("import-probe", folder / "full.txt", "--format", "linuxcnc", "--program", folder / "full.ngc", "--out",
           folder / "full.csv")
    _quiet("history", "add", folder / "full.csv", "--machine-id", "BENCH", "--db", db, "--date",
           (T0 - timedelta(days=1)).isoformat(), "--method", "gauss-newton", "--tolerances", TOL)
    program = folder / "checkup.ngc"
    _quiet("program", "--checkup", "--machine-id", "BENCH", "--db", db, "--dialect", "linuxcnc", "--out", program)
    _quiet("checkup", _checkup_file(program, 2, folder / "first.csv"), "--machine-id", "BENCH", "--db", db,
           "--date", T0.isoformat())
    _store_many(db, runs - 2)
    return db, program


def _store_many(db: Path, n: int) -> None:
    """``n`` more check-ups like the stored one (values drawn with its covariance), one a day, in one transaction."""
    import sqlalchemy as sa

    from pige_sym.verdict.history import connect
    from pige_sym.verdict.history import tables as T

    engine = connect(str(db))
    with engine.connect() as conn:
        row = conn.execute(sa.select(T.runs).where(T.runs.c.kind == "checkup")).one()._asdict()
    rng = np.random.default_rng(0)
    values = np.array(json.loads(row["values_json"]))
    cov = np.array(json.loads(row["covariance_json"]))
    rows = []
    for i in range(n):
        x = rng.multivariate_normal(values, cov).tolist()
        rows.append({**{k: v for k, v in row.items() if k != "id"}, "file_sha256": f"{i:064x}",
                     "file_name": f"/bench/checkup{i}.csv", "values_json": json.dumps(x),
                     "measured_at": (T0 + timedelta(days=i + 1)).isoformat(timespec="seconds")})
    with engine.begin() as conn:
        conn.execute(sa.insert(T.runs), rows)


#: The children run as an installed pige runs: with Python's bytecode cache (a session that sets
#: PYTHONDONTWRITEBYTECODE would compile every module of pige_sym from source at each start).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def _timed(cmd: list[str]) -> tuple[float, float]:
    """(wall, CPU of the child) [s] of one command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, env=ENV)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(cmd)} exited {proc.returncode}: {proc.stderr}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> str:
    """Run the benchmark and print (and return) a markdown section."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=1000, help="runs in the history (default %(default)s)")
    ap.add_argument("--repeats", type=int, default=5, help="check-ups timed as commands (default %(default)s)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        db, program = build_history(folder, args.runs)
        built = time.perf_counter() - t0
        files = [_checkup_file(program, 100 + k, folder / f"c{k}.csv") for k in range(2 * args.repeats)]
        day = args.runs + 10
        _timed([sys.executable, "-m", "pige_sym", "--version"])  # the bytecode cache written once
        walls, cpus = [], []
        for k in range(args.repeats):
            cmd = [sys.executable, "-m", "pige_sym", "checkup", str(files[k]), "--machine-id", "BENCH", "--db",
                   str(db), "--date", (T0 + timedelta(days=day + k)).isoformat()]
            wall, cpu = _timed(cmd)
            walls.append(wall)
            cpus.append(cpu)
        inproc = _in_process(db, files[args.repeats:], day + args.repeats)
        bare = [_timed([sys.executable, "-c", "import numpy"]) for _ in range(args.repeats)]
        imports = [_timed([sys.executable, "-c", "import numpy, sqlalchemy"]) for _ in range(args.repeats)]
    load = os.getloadavg()[0]
    lines = ["## Check-up: `pige checkup` with a long history (issue 42: under 1 s with 1,000 runs)", "",
             f"History of {args.runs} runs (1 full calibration, {args.runs - 1} check-ups of the same program) built "
             f"in {built:.1f} s; load average {load:.1f} at the end; medians of {args.repeats}.", "",
             "| what | wall [s] | CPU [s] |", "|---|---|---|",
             f"| `pige checkup FILE` (fresh process) | {statistics.median(walls):.3f} | "
             f"{statistics.median(cpus):.3f} |",
             f"| the same in process (no interpreter start, imports done) | {statistics.median(inproc):.3f} | — |",
             f"| `python -c \"import numpy\"` | {statistics.median(w for w, _ in bare):.3f} | "
             f"{statistics.median(c for _, c in bare):.3f} |",
             f"| `python -c \"import numpy, sqlalchemy\"` (SQLAlchemy, not imported by `pige checkup` on SQLite) | "
             f"{statistics.median(w for w, _ in imports):.3f} | {statistics.median(c for _, c in imports):.3f} |"]
    text = "\n".join(lines)
    print(text)
    return text


def _in_process(db: Path, files: list[Path], day: int) -> list[float]:
    """Each check-up as ``pige checkup`` runs it (the history opened and checked, the run stored), in this process."""
    from pige_sym.verdict.checkup.routine import CheckupOptions, run_checkup
    from pige_sym.verdict.history.sqlite_fast import open_history

    out = []
    for k, path in enumerate(files):
        t0 = time.perf_counter()
        run_checkup(open_history(str(db)), path, "BENCH",
                    CheckupOptions(date=(T0 + timedelta(days=day + k)).isoformat()))
        out.append(time.perf_counter() - t0)
    return out


if __name__ == "__main__":
    main()
