"""``pige history``: a machine's calibration runs in a database, and what changed between them.

``pige history add FILE --machine-id ID`` identifies and diagnoses the file and stores the run
(several files of one machine, e.g. ballbar setups, as one joint run);
``pige history show ID`` lists the runs and, between consecutive runs, each parameter's change
with its significance (joint Wald test + Bonferroni follow-up, family-wise false alarm ≤ 1 %);
``pige history fleet`` lists the machines: last full calibration, last check-up, verdict, next due.
"""

from __future__ import annotations

import argparse
from typing import Any

DB_HELP = ("history database: a file path, sqlite:///PATH or postgresql://user@host:port/dbname "
           "(default: $PIGE_HISTORY_DB, else history.sqlite in the user data directory)")


def _add(args: argparse.Namespace) -> int:
    from pige_sym.files import to_json
    from pige_sym.verdict.history import add_run, connect, list_runs

    engine = connect(args.db)
    run = add_run(engine, args.files[0] if len(args.files) == 1 else args.files, args.machine_id,
                  method=args.method, tolerances=args.tolerances, rule=args.rule, k=args.k, date=args.date,
                  corrected=args.corrected)
    if args.json:
        print(to_json(run.to_dict()))
        return 0
    verdict = f", verdict {run.verdict}" if run.verdict is not None else ""
    effects = ", ".join(str(f.get("effect")) for f in run.effects) or "none"
    number = run_numbers(list_runs(engine, run.machine_id, light=True))[run.id]
    print(f"added run {number} of machine {run.machine_id} ({run.machine_code}): {run.file_name}, measured "
          f"{run.measured_at} ({run.time_source}), {run.method} estimate, effects: {effects}{verdict}"
          f"{', after a correction (a new segment of the check-ups)' if run.after_correction else ''}")
    return 0


def run_numbers(runs: list[Any]) -> dict[int, int]:
    """Per run id its number among its machine's runs (1, 2, … in measurement order): what the CLI and the report
    call a run (the database's ids count every machine's runs)."""
    return {r.id: k for k, r in enumerate(runs, start=1)}


def history_comparisons(runs: list[Any], alpha: float) -> list[Any]:
    """Comparisons of consecutive runs."""
    from pige_sym.verdict.history.changes import compare_consecutive

    return compare_consecutive(runs, alpha=alpha)


def _num(x: float | None, fmt: str = ".3f") -> str:
    import math

    return "—" if x is None or not math.isfinite(x) else format(x, fmt)


def _show_text(runs: list[Any], comparisons: list[Any]) -> None:
    print(f"machine {runs[0].machine_id} ({runs[0].machine_code}): {len(runs)} run{'' if len(runs) == 1 else 's'} "
          "(numbered in measurement order)")
    number = run_numbers(runs)
    print(f"{'run':>4s}  {'measured (UTC)':25s} {'method':10s} {'verdict':10s} {'RMS um':>7s}  file")
    for r in runs:
        print(f"{number[r.id]:4d}  {r.measured_at:25s} {r.method:10s} {r.verdict or '—':10s} {_num(r.rms_um):>7s}  "
              f"{r.file_name}{'  (after a correction)' if r.after_correction else ''}")
    for c in comparisons:
        head = "DIFFERENT" if c.significant else "no significant change"
        print(f"\nrun {number[c.from_run]} -> {number[c.to_run]}: {head} (joint p = {_num(c.p_value, '.3g')}, T² = "
              f"{_num(c.statistic, '.1f')}, rank {c.rank}, α = {c.alpha:g})")
        for note in c.notes:
            print(f"  note: {note}")
        for ch in c.changes:
            mark = "SIGNIFICANT" if ch.significant else ("not tested" if ch.significant is None else "")
            print(f"  {ch.parameter:28s} {_num(ch.change, '+.3f'):>9s} ± {_num(ch.std):>6s} {ch.unit:5s} "
                  f"z {_num(ch.z, '+.2f'):>7s}  {mark} {'' if ch.significant else ch.reason}".rstrip())
    if comparisons:
        print(f"\ntest: {comparisons[0].test}")


def _show(args: argparse.Namespace) -> int:
    from pige_sym.files import to_json
    from pige_sym.verdict.history import connect, list_runs

    if not 0 < args.alpha < 1:
        from pige_sym.errors import InputError

        raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
    runs = list_runs(connect(args.db, create=False), args.machine_id)
    comparisons = history_comparisons(runs, args.alpha)
    if args.json:
        number = run_numbers(runs)
        print(to_json({"machine_id": args.machine_id,
                       "runs": [r.to_dict() | {"number": number[r.id]} for r in runs],
                       "comparisons": [{k: v for k, v in c.to_dict().items() if k != "changes"} for c in comparisons],
                       "changes": [ch for c in comparisons for ch in c.to_dict()["changes"]]}))
    else:
        _show_text(runs, comparisons)
    return 0


def _fleet(args: argparse.Namespace) -> int:
    from datetime import datetime, timezone

    from pige_sym.files import to_json
    from pige_sym.verdict.checkup.fleet import fleet
    from pige_sym.verdict.history import connect

    now = datetime.now(timezone.utc)
    rows = fleet(connect(args.db, create=False), now)
    if args.json:
        print(to_json({"machines": [r.to_dict() for r in rows]}))
        return 0
    print(f"{'machine id':<16}{'structure':<16}{'runs':>5}  {'last full calibration':<27}{'last check-up':<27}"
          f"{'verdict':<9}next due")
    for r in rows:
        full = f"{(r.last_full or '—')[:16]} {r.last_full_verdict or ''}".strip()
        print(f"{r.machine_id:<16}{r.machine:<16}{r.runs:>5}  {full:<27}{(r.last_checkup or '—')[:16]:<27}"
              f"{r.verdict or '—':<9}{_due(r.next_due, now)} ({r.why})")
    if not rows:
        print("no machine in the history yet (pige history add FILE --machine-id ID)")
    return 0


def _due(iso: str, now: Any) -> str:
    """The next due time (UTC, to the minute), ``OVERDUE since …`` when it has passed, ``now`` when it is now."""
    from datetime import datetime

    due = datetime.fromisoformat(iso)
    shown = due.astimezone(now.tzinfo).isoformat(timespec="minutes")[:16].replace("T", " ")
    if abs((due - now).total_seconds()) < 60:
        return "now"
    return f"OVERDUE since {shown}" if due < now else shown


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "history",
        help="store R-test, probe or ballbar runs per machine and show what changed (with significance)",
        description=__doc__,
        epilog=(
            "examples:\n"
            "  pige history add run.csv --machine-id DMU50-2\n"
            "  pige history add run.csv --machine-id DMU50-2 --tolerances tolerances.json --date 2026-11-23T14:05\n"
            "  pige history show DMU50-2\n"
            "  pige history show DMU50-2 --json --db postgresql://pige@dbhost/calibration\n"
            "  pige history fleet --db history.db"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="history_command", metavar="ACTION", parser_class=type(p))
    sub.required = True
    add = sub.add_parser(
        "add", help="diagnose a measurement file (or several of one machine, jointly) and store the run",
        description="Diagnose the file(s) and store the estimate used for compensation with its covariance, the\n"
                    "accepted effects, the files' SHA-256 (the same set is stored once), the date and the verdict.",
        epilog="examples:\n"
               "  pige history add run.csv --machine-id DMU50-2 --db history.db\n"
               "  pige history add run.csv --machine-id DMU50-2 --tolerances tolerances.json --date 2026-11-23T14:05\n"
               "  pige history add radial_C.csv tangential_C.csv axial_A.csv --machine-id DMU50-2   # ballbar set",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    add.add_argument("files", nargs="+", metavar="FILE",
                     help="pige-rtest 1 measurement file; several files of one machine (R-test, probe, "
                          "pige-ballbar 1 setups) are stored as one joint run")
    add.add_argument("--machine-id", required=True, metavar="ID", help="the shop's name of the machine")
    add.add_argument("--db", metavar="URL", help=DB_HELP)
    add.add_argument("--method", choices=("diagnosis", "gauss-newton", "double-differential"), default="diagnosis",
                     help="estimate stored (default %(default)s: PIGEs fitted with the accepted effects)")
    add.add_argument("--tolerances", metavar="TOL.json", help="also store the pige check verdict")
    add.add_argument("--rule", choices=("guard", "simple"), default="guard", help="decision rule of the verdict")
    add.add_argument("--k", type=float, default=2.0, help="coverage factor of the verdict (default %(default)s)")
    add.add_argument("--date", metavar="ISO", help="when it was measured (default: the file's date metadata, "
                                                   "else its modification time)")
    add.add_argument("--corrected", action="store_true",
                     help="a correction was entered into the controller since the machine's last run (it starts a "
                          "new segment of the check-ups' limits: docs/checkup.md)")
    add.add_argument("--json", action="store_true", help="print the stored run as JSON")
    add.set_defaults(handler=_add)
    show = sub.add_parser(
        "show", help="list a machine's runs and the changes between consecutive runs",
        description="The runs of a machine and, between consecutive runs, each parameter's change with its\n"
                    "standard error and whether it is significant (a joint Wald test, then Bonferroni t tests).",
        epilog="examples:\n"
               "  pige history show DMU50-2 --db history.db\n"
               "  pige history show DMU50-2 --json --db postgresql://pige@dbhost/calibration",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    show.add_argument("machine_id", metavar="ID", help="machine id")
    show.add_argument("--db", metavar="URL", help=DB_HELP)
    show.add_argument("--alpha", type=float, default=0.01,
                      help="family-wise false-alarm rate per comparison of two runs (default %(default)s)")
    show.add_argument("--json", action="store_true",
                      help='print {"runs": [...], "comparisons": [...], "changes": [...]}')
    show.set_defaults(handler=_show)
    fl = sub.add_parser(
        "fleet", help="every machine: last full calibration, last check-up, its verdict, when the next is due",
        description="One line per machine of the history: its structure, its runs, the last full calibration (and\n"
                    "its check), the last check-up and its verdict, and when the next check-up is due: now after a\n"
                    "drifted or out check-up, else the last run plus the machine's usual interval (the median gap\n"
                    "between its check-ups, 7 days before it has two), earlier when the last check-up's forecast\n"
                    "says a PIGE may leave its tolerance sooner.",
        epilog="examples:\n"
               "  pige history fleet --db history.db\n"
               "  pige history fleet --json --db postgresql://pige@dbhost/calibration",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    fl.add_argument("--db", metavar="URL", help=DB_HELP)
    fl.add_argument("--json", action="store_true", help='print {"machines": [...]}')
    fl.set_defaults(handler=_fleet)
