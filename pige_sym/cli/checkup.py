"""``pige checkup``: a short check run compared with the machine's history: ok, drifted or out, and what to enter.

``pige checkup FILE --machine-id ID`` fits the check-up's PIGEs (the others held at the last full calibration's
values), judges each against control limits learned from the machine's own check-ups and against its tolerance,
fits its trend and forecasts when it leaves the tolerance, prints the verdict and the changes to enter, and stores
the run as a check-up.  Exit status 0 ok, 1 drifted or out (action needed), 2 bad input.  The method and its
measured false-alarm and detection rates: docs/checkup.md.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from pige_sym.cli.history import DB_HELP


def _check_controller_options(args: argparse.Namespace) -> None:
    """The controller's options each read by ``--controller`` (as ``pige compensate`` checks them: each controller
    module's ``OPTIONS``), none without it."""
    from pige_sym.cli.compensate import given_controller_options
    from pige_sym.compensation.controllers import check_options
    from pige_sym.errors import InputError

    given = given_controller_options(args)
    if args.controller:
        check_options(args.controller, given)
    elif given:
        raise InputError(f"{given[0]} goes with --controller (the changes printed as that controller's entries): "
                         "leave it out, or give --controller")


def _options(args: argparse.Namespace) -> Any:
    from pige_sym.cli.compensate import _max_change
    from pige_sym.verdict.checkup.routine import CheckupOptions

    _check_controller_options(args)
    current = None
    if args.current:
        from pige_sym.compensation.controllers.hal_config import read_current

        current = read_current(args.current)
    return CheckupOptions(args.tolerances, args.rule, args.k, args.alpha, args.pige, args.corrected, args.date,
                          args.controller, current, 1 if args.carrier is None else args.carrier, args.heidenhain_trans,
                          _max_change(args.max_change), args.db)


def _run(args: argparse.Namespace) -> int:
    from pige_sym.errors import InputError
    from pige_sym.files import to_json
    from pige_sym.verdict.checkup.routine import run_checkup
    from pige_sym.verdict.history.sqlite_fast import open_history

    if not args.machine_id.strip():
        raise InputError("--machine-id must not be empty")
    options = _options(args)  # checked before the history is opened
    result = run_checkup(open_history(args.db), args.file, args.machine_id, options)
    print(to_json(result.to_dict()) if args.json else format_checkup(result))
    return result.exit_status


def _num(x: float | None, fmt: str = "+.3f") -> str:
    return "—" if x is None or not math.isfinite(x) else format(x, fmt)


def _rate(item: Any) -> str:
    """The drift per day and its 90 % interval (one unit for the column, whatever the check-ups' spacing)."""
    t = item.trend
    if t is None:
        return "— (too few check-ups)"
    sig = "" if t.significant else " n.s."
    over = f" ({t.points} flagged)" if t.episode else ""
    return f"{t.rate * 24:+.3g} [{t.rate_low * 24:+.3g}, {t.rate_high * 24:+.3g}]{sig}{over}"


def _at(iso: str | None) -> str:
    """An ISO time to the minute; ``not bounded`` for None; words (past the year 9999) as they are."""
    if iso is None:
        return "not bounded"
    return iso[:16].replace("T", " ") if iso[:1].isdigit() else iso


def _leaves(item: Any, origin: str) -> str:
    """When the PIGE leaves its tolerance: only where its drift is shown (:mod:`~pige_sym.verdict.checkup.trend`)."""
    from pige_sym.verdict.checkup.routine import when_text as when

    t = item.trend
    if t is None or item.tolerance is None:
        return "—"
    if not t.shown:
        return "— (no drift shown)"
    if t.leaves_at is None:
        return "— (drifts away from its limit)" if t.rate != 0 else "—"
    high = _at(when(origin, t.leaves_high))
    if t.reached:
        return f"may be outside now (by {high})"
    return f"{_at(when(origin, t.leaves_at))} ({_at(when(origin, t.leaves_low))} .. {high})"


def _columns(rows: list[list[str]], right: set[int]) -> list[str]:
    """Rows of cells as text, each column as wide as its widest cell (nothing runs into the next)."""
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    return ["  ".join(c.rjust(w) if k in right else c.ljust(w) for k, (c, w) in enumerate(zip(r, widths,
                                                                                             strict=True))).rstrip()
            for r in rows]


def format_checkup(r: Any) -> str:
    """The check-up as text: verdict, one line per PIGE, where the limits came from, the changes, the next step."""
    unit = ", ".join(sorted({i.unit for i in r.items}))
    rows = [["PIGE", "value ± std", "centre", "limit ±", "z", "error left", "tol", "status",
             f"drift [{unit}/day, 90 %]", "leaves its tolerance (interval), UTC"]]
    for it in r.items:
        lim = it.limit
        rows.append([it.name, f"{_num(it.value)} ± {_num(it.std, '.3f')}", _num(lim and lim.centre),
                     _num(lim and lim.half_width, ".3f"), _num(None if lim is None else lim.z, "+.2f"),
                     _num(it.left), _num(it.tolerance, "g"), it.status + ("*" if lim and lim.outside else ""),
                     _rate(it), _leaves(it, r.origin)])
    lines = [f"check-up of {r.machine_id} ({r.machine}), its run {r.run_number}, measured "
             f"{r.measured_at[:16].replace('T', ' ')} UTC: verdict {r.verdict.upper()}", f"file {r.file}",
             *_columns(rows, {1, 2, 3, 4, 5, 6})]
    out = [f"{i.name} by {i.limit.by.replace('+', ' and ')}" for i in r.items if i.limit and i.limit.outside]
    lines.append(f"* outside its control limits: {'; '.join(out)}" if out else
                 "no PIGE outside its control limits")
    lines.append("(z: distance from the centre in limit widths, |z| > 1 outside; error left: what the values in force "
                 "leave, judged against the tolerance; drift of that error over the segment's check-ups, or over the "
                 "flagged check-ups of a drift; forecast only where the drift is shown)")
    lines += _limits_lines(r)
    from pige_sym.kernels import load_kernels

    units = load_kernels(r.machine).UNITS
    shown = r.changes.held if r.changes is not None else r.held
    held = ", ".join(f"{n} {v:+.3g}" + (f" ± {r.changes.std(n):.2g}" if r.changes is not None else "") +
                     f" {units.get(n, '')}" for n, v in shown.items())
    less = ", less the correction entered" if r.corrected else ""
    lines.append(f"held at the values in force (the last full calibration's{less}): {held}")
    if r.verdict != "ok" and r.changes is not None:
        lines += ["", "changes to enter, since the values in force (weighed by their uncertainty, within "
                      "--max-change; the held PIGEs stay as they are):"]
        lines += [f"  {n:<6}{_num(v, '+.3f') if v is not None else 'not entered':>12}  {r.changes.why[n]}"
                  for n, v in r.changes.entered.items()]
        if r.changes.controller_text:
            lines += ["", f"as pige compensate --controller {r.changes.controller} prints them:",
                      r.changes.controller_text]
    lines += [f"note: {n}" for n in r.notes]
    what, command = r.next_step()
    lines += [f"next step: {what}", *([f"  {command}"] if command else [])]
    return "\n".join(lines)


def _limits_lines(r: Any) -> list[str]:
    """Where the limits came from, and each PIGE's run-to-run scatter as learned."""
    lims = [(i, i.limit) for i in r.items if i.limit is not None]
    head = f"limits: {r.limits_source()}; alpha {r.alpha:g} per check-up over {len(r.items)} PIGEs"
    learned = [f"{i.name} {lim.scatter:.2g} ({lim.scatter_low:.2g}..{lim.scatter_high:.2g})" for i, lim in lims
               if not lim.provisional and lim.scatter is not None]
    if not learned:
        return [head]
    return [head, f"run-to-run scatter [{', '.join(sorted({i.unit for i in r.items}))}] (90 % interval): "
                  f"{', '.join(learned)}"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "checkup",
        help="a short R-test or probe check run against the machine's history: ok / drifted / out, trend, what to "
             "enter",
        description=__doc__,
        epilog=(
            "examples:\n"
            "  pige checkup checkup.csv --machine-id DMU50-2 --tolerances tolerances.json\n"
            "  pige checkup checkup.csv --machine-id DMU50-2 --controller linuxcnc --current xyzac-trt.ini\n"
            "  pige checkup next.csv --machine-id DMU50-2 --corrected     # after entering the changes\n"
            "  pige checkup checkup.csv --machine-id DMU50-2 --json --db postgresql://pige@dbhost/calibration"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", metavar="FILE", help="the check-up's measurement (pige import-probe or pige acquire "
                                                 "output of the program pige program --checkup wrote)")
    p.add_argument("--machine-id", required=True, metavar="ID", help="the shop's name of the machine")
    p.add_argument("--db", metavar="URL", help=DB_HELP)
    p.add_argument("--tolerances", metavar="TOL.json", help="tolerance file (default: the one stored with the "
                                                             "machine's last check-up or check)")
    p.add_argument("--rule", choices=("guard", "simple"), default="guard",
                   help="decision rule against the tolerance (default %(default)s: out unless shown within it)")
    p.add_argument("--k", type=float, default=2.0, help="coverage factor of the guard band (default %(default)s)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="false-alarm rate per check-up of a machine that did not drift (default %(default)s)")
    p.add_argument("--pige", metavar="LIST", help="the PIGEs re-measured (default: the program header's, else the "
                                                  "last check-up's, else the axis lines' positions)")
    p.add_argument("--corrected", action="store_true",
                   help="the changes printed for the previous run were entered into the controller before this run")
    p.add_argument("--date", metavar="ISO", help="when it was measured (default: the file's date, else its mtime)")
    from pige_sym.compensation.controllers import controller_names

    p.add_argument("--controller", choices=list(controller_names()), help="print the changes as this controller's "
                                                                           "entries (as pige compensate --controller)")
    p.add_argument("--current", help="LinuxCNC: today's trt pins (PIN=VALUE,... or the INI/HAL file)")
    p.add_argument("--carrier", type=int, help="Siemens swivel data record (default 1)")
    p.add_argument("--heidenhain-trans", choices=["position", "shift"], help="Heidenhain: what a Trans row holds")
    p.add_argument("--max-change", default="0.2,0.1", metavar="MM[,DEG]",
                   help="largest change entered (default %(default)s, as pige compensate)")
    p.add_argument("--json", action="store_true", help="print the check-up as one JSON object")
    p.set_defaults(handler=_run)
