"""Scale of a long history (issue 47, item 4): the commands that read a machine's whole history, at 100 to 10,000 runs.

A history of one machine is built as benchmarks/bench_checkup.py builds it: a full probing calibration of the virtual
machine (``pige history add``), one real check-up (``pige checkup``), then check-ups stored as ``pige checkup``
stores them, one a day, up to N runs.  Each command runs as a user runs it, in a fresh process
(benchmarks/commands.py: wall time of ``main()``, the process's CPU time, peak resident memory), all in one run:

* ``pige report --history ID --out DIR`` (the trend and check-up plots, the comparisons of consecutive runs);
* ``pige history show ID`` (every run and every consecutive comparison);
* ``pige history fleet``; ``pige plan --checkup --machine-id ID``;
* ``pige checkup FILE --machine-id ID`` (a new check-up file, on a copy of the history: it stores its run).

Each reads every run strictly (a damaged run anywhere is refused), so each is at least linear in the runs; the cost
per run is stated.  With ``--before DIR`` every command is timed also with the pige_sym of another checkout (``git
archive main | tar -x -C DIR``), up to ``--timeout`` seconds.

Target (issue 47): ``pige report --history`` with 1,000 runs within 10 s; the others grow linearly.  ``main()``
prints a markdown section.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from datetime import timedelta
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_checkup import T0, _checkup_file, build_history  # noqa: E402
from commands import cell, run_footer, run_pige  # noqa: E402

SIZES = (100, 1_000, 10_000)


def _commands(db: Path, folder: Path, check: Path, n: int) -> dict[str, tuple[list[str], tuple[int, ...]]]:
    """Each command's argv and the exit statuses it may end with (a check-up may say drifted: 1)."""
    return {
        "report --history": (["report", "--history", "BENCH", "--db", str(db), "--out", str(folder / f"rep{n}"),
                              "--force"], (0,)),
        "history show": (["history", "show", "BENCH", "--db", str(db)], (0,)),
        "history fleet": (["history", "fleet", "--db", str(db)], (0,)),
        "plan --checkup": (["plan", "--checkup", "--machine-id", "BENCH", "--db", str(db)], (0,)),
        "checkup": (["checkup", str(check), "--machine-id", "BENCH", "--db", str(folder / "copy.db"), "--date",
                     (T0 + timedelta(days=n + 5)).isoformat()], (0, 1)),
    }


def measure(sizes: tuple[int, ...], before: Path | None, timeout: float) -> dict[str, dict[int, dict[str, Any]]]:
    """Per command and history size: ``{"now": stats, "before": stats or None}``."""
    out: dict[str, dict[int, dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            folder = Path(tmp) / f"h{n}"
            folder.mkdir()
            db, program = build_history(folder, n)
            check = _checkup_file(program, 700, folder / "new.csv")
            if n == sizes[0]:  # the first command of each code pays the bytecode cache and matplotlib's font cache
                for source in (ROOT, before):
                    if source is not None:
                        run_pige(_commands(db, folder, check, n)["report --history"][0], folder, source=source)
            for name, (argv, codes) in _commands(db, folder, check, n).items():
                got: dict[str, Any] = {}
                for key, source in (("now", ROOT), ("before", before)):
                    if source is None:
                        continue
                    shutil.copy(db, folder / "copy.db")
                    got[key] = run_pige(argv, folder, source=source, codes=codes,
                                        timeout=None if key == "now" else timeout)
                out.setdefault(name, {})[n] = got
            shutil.rmtree(folder)
    return out


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="*", default=list(SIZES), help="runs in the history")
    ap.add_argument("--before", type=Path, help="also time each command with this checkout's pige_sym")
    ap.add_argument("--timeout", type=float, default=600.0, help="for --before's commands [s] (default %(default)s)")
    args = ap.parse_args(argv)
    from run import load_average

    load = os.getloadavg()[0]
    load_start = load_average()
    sizes = tuple(sorted(args.sizes))
    results = measure(sizes, args.before, args.timeout)
    before = args.before is not None
    lines = ["## A long history: the commands that read it all (benchmarks/bench_scale_history.py)", "",
             f"One machine's history (a full calibration, then check-ups, one a day); each command a fresh process: "
             f"wall time of `main()`, CPU time, peak resident memory. Load average {load:.1f} on {os.cpu_count()} "
             "cores when the run started (a shared machine: CPU times follow the work, wall times the load)."
             + (f" Before: the pige_sym of `{args.before}`, up to {args.timeout:g} s." if before else ""), "",
             "| command | runs | wall [s] | CPU [s] | peak [MB] |" + (" before: wall [s] | before: CPU [s] |"
                                                                     if before else ""),
             "|" + "---|" * (5 + (2 if before else 0))]
    for name, by_size in results.items():
        for n in sizes:
            got = by_size[n]
            line = (f"| `pige {name}` | {n:,} | {cell(got['now'], 's')} | {cell(got['now'], 'cpu_s')} | "
                    f"{cell(got['now'], 'rss_mb', '.0f')} |")
            if before:
                line += f" {cell(got['before'], 's', timeout=args.timeout)} | {cell(got['before'], 'cpu_s')} |"
            lines.append(line)
    lines.append("")
    if len(sizes) > 1:
        lo, hi = sizes[0], sizes[-1]
        per_run = {name: (r[hi]["now"]["cpu_s"] - r[lo]["now"]["cpu_s"]) / (hi - lo) * 1e3
                   for name, r in results.items()}
        lines.append("CPU per run (from " + f"{lo:,} to {hi:,} runs): " + ", ".join(
            f"{name} {ms:.2f} ms" for name, ms in per_run.items()) + ".")
    if 1_000 in sizes:
        rep = results["report --history"][1_000]["now"]
        lines.append(f"Target: `pige report --history` with 1,000 runs within 10 s: {rep['s']:.2f} s wall, "
                     f"{rep['cpu_s']:.2f} s CPU ({'PASS' if rep['cpu_s'] <= 10 else 'MISS'} on CPU time; "
                     f"{'PASS' if rep['s'] <= 10 else 'MISS'} on wall time at this load).")
    lines += ["", run_footer(load_start)]
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main()
