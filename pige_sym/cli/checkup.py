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


def _options(args: argparse.Namespace) -> Any:
    from pige_sym.cli.compensate import _max_change
    from pige_sym.verdict.checkup.routine import CheckupOptions

    current = None
    if args.current:
        from pige_sym.compensation.controllers.hal_config import read_current

        current = read_current(args.current)
    return CheckupOptions(args.tolerances, args.rule, args.k, args.alpha, args.pige, args.corrected, args.date,
                          args.controller, current, args.carrier, args.heidenhain_trans, _max_change(args.max_change))


def _run(args: argparse.Namespace) -> int:
    from pige_sym.errors import InputError
    from pige_sym.files import to_json
    from pige_sym.verdict.checkup.routine import run_checkup
    from pige_sym.verdict.history.sqlite_fast import open_history

    if not args.machine_id.strip():
        raise InputError("--machine-id must not be empty")
    result = run_checkup(open_history(args.db), args.file, args.machine_id, _options(args))
    print(to_json(result.to_dict()) if args.json else format_checkup(result))
    return result.exit_status


def _num(x: float | None, fmt: str = "+.3f") -> str:
    return "—" if x is None or not math.isfinite(x) else format(x, fmt)


def _rate(item: Any, per_day: bool) -> str:
    t = item.trend
    if t is None:
        return "— (too few check-ups)"
    f = 24.0 if per_day else 1.0
    sig = "" if t.significant else " n.s."
    over = f" ({t.points} flagged)" if t.episode else ""
    return f"{t.rate * f:+.3g} [{t.rate_low * f:+.3g}, {t.rate_high * f:+.3g}]{sig}{over}"


def _leaves(item: Any, origin: str) -> str:
    from pige_sym.verdict.checkup.routine import when_text as when

    t = item.trend
    if t is None or t.leaves_at is None:
        return "—"
    if not t.significant:
        return "— (no drift shown)"
    low, high = when(origin, t.leaves_low), when(origin, t.leaves_high)
    return f"{when(origin, t.leaves_at)} ({low} .. {high or 'not bounded'})"


def format_checkup(r: Any) -> str:
    """The check-up as text: verdict, one line per PIGE, what the limits rest on, the changes to enter."""
    episode = any(p.trend is not None and p.trend.episode for p in r.items)
    per_day = not episode and _span_hours(r) > 48
    unit = "day" if per_day else "h"
    lines = [f"check-up of {r.machine_id} ({r.machine}), run {r.run_id}, measured {r.measured_at}: "
             f"verdict {r.verdict.upper()}", f"file {r.file}",
             f"{'PIGE':<6}{'value ± std':>17}{'centre':>9}{'limit ±':>9}{'z':>7}{'tol':>6}  {'status':<10}"
             f"{'drift /' + unit + ' [90 %]':<34}leaves tolerance (interval)"]
    for it in r.items:
        lim = it.limit
        lines.append(f"{it.name:<6}{_num(it.value):>9} ± {_num(it.std, '.3f'):<5}{_num(lim and lim.centre):>9}"
                     f"{_num(lim and lim.half_width, '.3f'):>9}{_num(lim and lim.z and lim.z * 1.0, '+.2f'):>7}"
                     f"{_num(it.tolerance, 'g'):>6}  {it.status + ('*' if lim and lim.outside else ''):<10}"
                     f"{_rate(it, per_day):<34}{_leaves(it, r.origin)}")
    lines.append(f"(z: distance from the centre in limit widths, |z| > 1 outside; * outside its control limits (by "
                 f"{', '.join(sorted({i.limit.by for i in r.items if i.limit and i.limit.by})) or 'none'}); units "
                 f"{', '.join(sorted({i.unit for i in r.items}))}; drift over the segment, or over the flagged "
                 "check-ups of a drift)")
    lines.append(_limits_line(r))
    held = ", ".join(f"{n} {v:+.3g}" for n, v in r.held.items())
    lines.append(f"held at the last full calibration{' less the correction entered' if r.corrected else ''}: {held}")
    if r.verdict != "ok" and r.changes is not None:
        lines += ["", "changes to enter (weighed by their uncertainty, within --max-change):"]
        lines += [f"  {n:<6}{_num(v, '+.3f') if v is not None else 'not entered':>12}  {r.changes.why[n]}"
                  for n, v in r.changes.entered.items()]
        if r.changes.controller_text:
            lines += ["", f"as pige compensate --controller {r.changes.controller} prints them:",
                      r.changes.controller_text]
        lines.append("after entering them, run the next check-up with --corrected")
    lines += [f"note: {n}" for n in r.notes]
    return "\n".join(lines)


def _span_hours(r: Any) -> float:
    from pige_sym.verdict.checkup.reference import hours

    return hours(r.measured_at, r.origin)


def _limits_line(r: Any) -> str:
    lims = [i.limit for i in r.items if i.limit is not None]
    if not lims:
        return "limits: none yet (the first check-up of this segment)"
    lim = lims[0]
    if lim.provisional:
        return (f"limits: provisional, from the runs' own standard errors (scatter pooled on {lim.dof} degrees of "
                f"freedom so far); alpha {r.alpha:g} per check-up over {len(r.items)} PIGEs")
    return (f"limits: learned, run-to-run scatter pooled on {lim.dof} degrees of freedom, centre of {lim.n_centre} "
            f"check-up{'s' if lim.n_centre != 1 else ''}; alpha {r.alpha:g} per check-up over {len(r.items)} PIGEs "
            "(Student t, Bonferroni)")


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
    p.add_argument("--carrier", type=int, default=1, help="Siemens swivel data record (default %(default)s)")
    p.add_argument("--heidenhain-trans", choices=["position", "shift"], help="Heidenhain: what a Trans row holds")
    p.add_argument("--max-change", default="0.2,0.1", metavar="MM[,DEG]",
                   help="largest change entered (default %(default)s, as pige compensate)")
    p.add_argument("--json", action="store_true", help="print the check-up as one JSON object")
    p.set_defaults(handler=_run)
