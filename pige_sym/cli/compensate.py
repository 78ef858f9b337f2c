"""``pige compensate``: corrected NC programs and controller corrections; ``pige study compensation``."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

from pige_sym.compensation.controllers import controller_names
from pige_sym.constants import (
    DEFAULT_MACHINE,
    DEFAULT_MAX_CHANGE_DEG,
    DEFAULT_MAX_CHANGE_MM,
    DIALECTS,
)
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text, check_output, to_json


def _max_change(text: str) -> tuple[float, float]:
    from pige_sym.options import parse_vector

    parts = parse_vector(text, "--max-change")
    if len(parts) not in (1, 2) or min(parts) <= 0:
        raise InputError(f"--max-change {text!r}: give MM or MM,DEG (positive numbers), e.g. 0.2,0.1")
    return parts[0], parts[1] if len(parts) == 2 else DEFAULT_MAX_CHANGE_DEG


def _machine(args: argparse.Namespace, text: str | None) -> str | None:
    """``--machine``, checked against the machine the program's header names (either may be silent)."""
    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.nc.program_file import program_machine

    named = program_machine(text) if text is not None else None
    if named is not None:
        try:
            named = parse_machine_code(named).canonical
        except InputError:
            named = None  # a header that is not a machine code says nothing
    if args.machine and named and parse_machine_code(args.machine).canonical != named:
        raise InputError(f"--machine {args.machine} but {args.program} was written for {named}: "
                         "compensate a program with the parameters of its own machine")
    return args.machine or named


def _axis_sense(args: argparse.Namespace, params: Any) -> dict[str, int]:
    """The commanded axis sense: the parameter file's, checked against ``--axis-sense`` (CONVENTIONS §9)."""
    from pige_sym.cli._setup import axis_sense_option
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.axis_sense import reconcile

    axes = tuple(load_kernels(params.machine).ROTARY_AXES)
    return reconcile(params.axis_sense, axis_sense_option(args, axes), str(args.params), axes)


def _current(args: argparse.Namespace) -> Any:
    """``--current`` read (:func:`~pige_sym.compensation.controllers.hal_config.read_current`), for a controller."""
    if args.current is None:
        return None
    if not args.controller:
        raise InputError("--current is today's configuration of a controller: give it with --controller linuxcnc")
    from pige_sym.compensation.controllers.hal_config import read_current

    return read_current(args.current)


def _run(args: argparse.Namespace) -> int:
    from pige_sym.compensation.parameters import load_parameters
    from pige_sym.compensation.stage import ProgramRequest, compensate
    from pige_sym.nc.program_file import read_program

    text = read_program(args.program) if args.program else None
    machine = _machine(args, text)
    params = load_parameters(args.params, machine, allow_missing=args.allow_missing)
    params.axis_sense = _axis_sense(args, params)
    current = _current(args)
    max_mm, max_deg = _max_change(args.max_change)
    options = None
    if args.controller:
        options = _controller_options(args, current, (max_mm, max_deg))
    elif args.comp_dir:
        raise InputError("--comp-dir writes LinuxCNC compensation files: give it with --controller linuxcnc")
    elif args.out_dir:
        raise InputError("--out-dir writes the controller's entries, one file per target: give it with --controller")
    else:
        _no_controller_options(args)
    if not args.program and not args.controller:
        raise InputError("give a PROGRAM to compensate (or --controller to print the corrected kinematics)")
    if args.program and not args.out:
        raise InputError("give --out NEW_PROGRAM")
    out = check_output(args.out, force=args.force, inputs=[args.program, args.params], what="--out") \
        if args.program else None
    request = None
    if text is not None:
        request = ProgramRequest(text, str(args.program), args.dialect, args.pass_through, max_mm, max_deg,
                                 tuple(args.rtcp_on or ()), tuple(args.rtcp_off or ()))
    travel = _travel(args.travel, params.machine) if args.controller else None
    result = compensate(params, program=request, controller=args.controller, options=options, travel=travel,
                        enter=args.enter)
    written = _write_controller_files(args, result) if args.controller else []
    if out is not None and result.program is not None:
        atomic_write_text(out, result.program.text, newline="")
    if args.json:
        print(to_json(_json(args, params, result, out)))
        return 0
    if result.controller is not None and not args.out_dir:
        print(result.controller.text)
    for line in written:
        print(line)
    if result.program is not None:
        _print_report(result, str(out), params.units)
    else:
        _print_after(result)
    return 0


def _json(args: argparse.Namespace, params: Any, result: Any, out: Path | None) -> dict[str, Any]:
    """The JSON of ``pige compensate``: the program's change report or the controller's entries, and the stage's
    result object (``compensation``)."""
    from pige_sym.compensation.controllers.axis_lines import controller_corrections

    doc: dict[str, Any] = {"compensation": result.to_dict()}
    if result.controller is not None:
        c = result.controller
        w = c.weighing
        first = c.choices[0].predicted if c.choices else None  # the controller's own kinematic entries
        doc |= {"machine": params.machine, "parameters_from": params.source,
                "axes": controller_corrections(c.entered_parameters),
                "entered": {n: (v if any(n in ch.values for ch in c.choices if ch.own) else None)
                            for n, v in w.entered.items()},
                "predicted_after_um": first.to_dict() if first else None,
                "predicted_complete_um": c.complete.to_dict() if c.complete else None, "weighing": w.to_dict()}
    if result.program is not None:
        doc |= result.program.report.to_dict() | {
            "out": str(out), "pige": params.values,
            "extensions": [{"effect": e.spec.id, "options": e.spec.options, "params": e.params}
                           for e in params.extensions]}
    return doc


#: The options only some controllers read, and the attribute of ``args`` each is in.
CONTROLLER_OPTIONS = {"--carrier": "carrier", "--heidenhain-trans": "heidenhain_trans",
                      "--machine-axis": "machine_axis", "--isg-unit-deg": "isg_unit_deg", "--current": "current",
                      "--comp-dir": "comp_dir"}


def given_controller_options(args: argparse.Namespace) -> list[str]:
    """The options of :data:`CONTROLLER_OPTIONS` given on the command line (``pige compensate``, ``pige checkup``:
    a command without one of them has none given)."""
    return [option for option, attr in CONTROLLER_OPTIONS.items() if getattr(args, attr, None) is not None]


def _no_controller_options(args: argparse.Namespace) -> None:
    """The NC rewrite reads none of the controllers' options (``--current``, ``--comp-dir``: their own messages), nor
    ``--travel`` (it judges the program's own poses)."""
    extra = ([o for o in given_controller_options(args) if o not in ("--current", "--comp-dir")]
             + (["--travel"] if args.travel else []))
    if extra:
        raise InputError(f"{extra[0]} goes with --controller (the controller's entries), not with the NC rewrite: "
                         "leave it out, or give --controller")


def _controller_options(args: argparse.Namespace, current: Any, max_change: tuple[float, float]) -> Any:
    """The options of ``--controller`` checked (each read by that controller, given once, within its bounds)."""
    from pige_sym.compensation.controllers import ControllerOptions, check_options
    from pige_sym.compensation.controllers.entry_checks import ChangeLimits

    check_options(args.controller, given_controller_options(args))
    return ControllerOptions(carrier=1 if args.carrier is None else args.carrier, current=current,
                             heidenhain_trans=args.heidenhain_trans, machine_axes=_machine_axes(args),
                             isg_unit_deg=args.isg_unit_deg, limits=ChangeLimits(*max_change))


def _machine_axes(args: argparse.Namespace) -> dict[str, str] | None:
    """``--machine-axis C=C1`` (repeatable, each axis once): the controller's name of each rotary axis."""
    if not args.machine_axis:
        return None
    out: dict[str, str] = {}
    for item in args.machine_axis:
        axis, sep, name = (x.strip() for x in item.partition("="))
        if not sep or not axis or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise InputError(f"--machine-axis {item!r}: give AXIS=NAME, e.g. C=C1 (a letter, then letters, digits, "
                             "'_')")
        if axis.upper() in out:
            raise InputError(f"--machine-axis {axis.upper()} is given twice ({out[axis.upper()]} and {name}): give "
                             "each axis once")
        out[axis.upper()] = name
    return out


def _write_controller_files(args: argparse.Namespace, result: Any) -> list[str]:
    """``--comp-dir DIR``: LinuxCNC's ``[JOINT_n]COMP_FILE`` of every positioning map; ``--out-dir DIR``: every
    section of the controller's entries as its own file.  Never over a file without ``--force``, never over an
    input; nothing is written unless every target may be."""
    c = result.controller
    files: dict[Path, str] = {}
    if args.comp_dir:
        if args.controller != "linuxcnc":
            raise InputError(f"--comp-dir writes LinuxCNC compensation files, not {args.controller}'s: give "
                             "--controller linuxcnc")
        comp = {s.file: s.text for s in c.sections if s.kind == "comp"}
        if not comp:
            raise InputError(f"--comp-dir: {args.params} holds no positioning map (ECC, EAA, ...): identify with "
                             "--map")
        files |= {_folder(args.comp_dir, "--comp-dir") / n: t for n, t in comp.items()}
    if args.out_dir:
        from pige_sym.compensation.result import Section

        sections = c.sections or [Section(f"the {c.name} entries", f"pige_{c.name}.txt", "text", c.text)]
        files |= {_folder(args.out_dir, "--out-dir") / s.file: s.text for s in sections}
    inputs = [x for x in (args.params, args.program, args.current if args.current and Path(args.current).exists()
                          else None) if x]
    targets = {p: check_output(p, force=args.force, inputs=inputs, what="--out-dir file" if args.out_dir else
                               "--comp-dir file") for p in files}
    lines = []
    names = {s.file: s.name for s in c.sections}
    for p, text in files.items():
        atomic_write_text(targets[p], text)
        what = names.get(p.name, "")
        lines.append(f"wrote {targets[p]} ({text.count(chr(10))} lines{': ' + what if what else ''})")
    return lines


def _folder(text: str, what: str) -> Path:
    folder = Path(text)
    if not folder.is_dir():
        raise InputError(f"{what} {folder}: not an existing folder")
    return folder


def _travel(items: list[str] | None, machine: str) -> dict[str, tuple[float, float]]:
    """``--travel A=-120:30`` (repeatable, each rotary axis of ``machine`` once) as axis → (min, max) [deg]."""
    from pige_sym.kernels import load_kernels
    from pige_sym.options import parse_axis_ranges

    return parse_axis_ranges(items, "--travel", tuple(load_kernels(machine).ROTARY_AXES), max_span=720.0,
                             example="A=-120:30")


def _print_weighing(result: Any) -> None:
    from pige_sym.compensation.weighing import weighing_rows

    w = result.weighing
    for note in w.notes:
        print(f"note: {note}")
    for row in weighing_rows(w, {}) if w.covariance_from != "none" else []:
        print(f"  {row}")
    p = w.predicted
    if p:
        print(f"predicted tool-point RMS error over {w.judged_on}: uncorrected {p['none'].text()}, after compensation "
              f"{p['entered'].text()}")


#: The comment marker of each controller's lines: what is said after its entries stays a comment when pasted.
COMMENT = {"linuxcnc": "# ", "isg": "# ", "siemens": "; "}


def _print_after(result: Any) -> None:
    """What the stage says beyond the entries: values not corrected, advice (as comments of the controller's
    lines, so that a section pasted whole stays valid)."""
    mark = COMMENT.get(result.controller.name, "") if result.controller is not None else ""
    for u in result.undetermined:
        print(f"{mark}not corrected: {u.name}: {u.why}; {u.remedy}")
    for a in result.advice:
        print(f"{mark}advice: {a}")


def _print_report(result: Any, out: str, units: dict[str, str]) -> None:
    rep = result.program.report
    print(f"wrote {out} ({rep.dialect}): {rep.compensated} of {rep.moves} linear moves changed; "
          f"parameters from {rep.parameters_from}; read back and verified")
    if rep.weighing is not None:
        _print_weighing(result)
    print(f"largest change: {rep.max_change_mm:.4f} mm, {rep.max_change_deg:.4f} deg "
          f"(limits {rep.limits['mm']:g} mm, {rep.limits['deg']:g} deg)")
    for c in rep.changes[:20]:
        words = " ".join(f"{w['old'] or '+'}->{w['new']}" for w in c.words)
        pole = "  [orientation limited: pole]" if c.orientation_limited else ""
        print(f"  line {c.line_in}: {words}; tool point {c.tool_point_error_before_um:.2f} -> "
              f"{c.tool_point_error_after_um:.2f} um{pole}")
    if len(rep.changes) > 20:
        print(f"  ... {len(rep.changes) - 20} more changed blocks (--json lists all)")
    for p in rep.passed_through[:20]:
        print(f"  passed through, line {p['line']}: {p['reason']}")
    if len(rep.passed_through) > 20:
        print(f"  ... {len(rep.passed_through) - 20} more blocks passed through (--json lists all)")
    if rep.orientation_limited_lines:
        print(f"orientation correction limited near the pole at {len(rep.orientation_limited_lines)} "
              f"block{'' if len(rep.orientation_limited_lines) == 1 else 's'}, "
              f"first at line {rep.orientation_limited_lines[0]} (position still corrected)")
    for note in rep.notes:
        print(f"note: {note}")
    if rep.not_compensated_parameters:
        print("not compensated: " + ", ".join(rep.not_compensated_parameters))
    _print_after(result)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "compensate",
        help="write a compensated NC program / print controller corrections",
        description="Rewrite an NC program (Siemens 840D, ISO/Fanuc/Haas or LinuxCNC; output in the same "
                    "dialect) so the tool lands where the nominal program intended.  Only the axis words of "
                    "compensable G0/G1 blocks change; everything else stays byte-identical; the output is "
                    "read back and verified before it is written.",
        epilog=(
            "examples:\n"
            "  pige identify run.csv --json > result.json\n"
            "  pige compensate part.mpf --params result.json --out part_comp.mpf\n"
            "  pige compensate part.nc --params result.json --max-change 0.1,0.05 --json --out part_comp.nc\n"
            "  pige compensate part.ngc --params result.json --rtcp-on M428 --rtcp-off M429 --out comp.ngc\n"
            "  pige compensate --params result.json --controller siemens --carrier 1\n"
            "  pige compensate --params result.json --controller heidenhain --heidenhain-trans position\n"
            "  pige compensate --params result.json --controller linuxcnc --current xyzac-trt.ini"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("program", nargs="?", help="NC program (TRAORI/G43.4/... or machine coordinates)")
    p.add_argument("--params", required=True, help="JSON printed by pige identify --json or pige diagnose --json")
    p.add_argument("--machine", help="machine code (default: from the JSON)")
    p.add_argument("--out", help="compensated program to write (never the input; existing only with --force)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.add_argument("--dialect", choices=list(DIALECTS), help="the program's dialect (default: detected)")
    p.add_argument("--pass-through", action="store_true",
                   help="keep calls, control flow and expressions unchanged instead of refusing the program")
    p.add_argument("--max-change", default=f"{DEFAULT_MAX_CHANGE_MM:g},{DEFAULT_MAX_CHANGE_DEG:g}",
                   metavar="MM[,DEG]", help="refuse corrections larger than this (default %(default)s)")
    p.add_argument("--rtcp-on", action="append", metavar="CODE", help="controller-specific RTCP-on code (M428)")
    p.add_argument("--rtcp-off", action="append", metavar="CODE", help="controller-specific RTCP-off code (M429)")
    from pige_sym.cli._setup import add_axis_sense_argument

    add_axis_sense_argument(p)
    p.add_argument("--enter", choices=["weighed", "all"], default="weighed",
                   help="weighed (default): each estimate weighed by its uncertainty, a weakly determined one entered "
                        "in part or not (docs/algorithms.md); all: every estimate as it is")
    p.add_argument("--travel", action="append", metavar="AXIS=MIN:MAX",
                   help="travel of a rotary axis [deg] over which controller entries are judged (default: C 0:360, "
                        "others -90:90)")
    p.add_argument("--allow-missing", action="store_true",
                   help="set PIGEs without a value (missing, or not identifiable) to 0 and say which")
    p.add_argument("--controller", choices=list(controller_names()), help="print the corrected kinematics "
                   "(see docs/controller-corrections.md)")
    p.add_argument("--carrier", type=int, help="Siemens swivel data record number (default 1)")
    p.add_argument("--current", help="today's LinuxCNC trt pin values: PIN=VALUE,... or the machine's INI or HAL "
                   "file (then absolute setp/sets lines are printed)")
    p.add_argument("--heidenhain-trans", choices=["position", "shift"],
                   help="what a HEIDENHAIN Trans row holds: the next element's position relative to the previous one, "
                        "or the shift of the previous ones (the negative); required with --controller heidenhain")
    p.add_argument("--machine-axis", action="append", metavar="AXIS=NAME",
                   help="the controller's name of a rotary axis where its compensation tables need it (SINUMERIK "
                        "machine axis name, MD10000), e.g. C=C1")
    p.add_argument("--isg-unit-deg", type=float, metavar="U",
                   help="ISG/TwinCAT CNC: the angle [deg] of one unit of a rotary axis' kw.ssfk list (not settled "
                        "by the manual: read it from your axis' list)")
    p.add_argument("--out-dir", metavar="DIR", help="with --controller: write the entries into DIR, one file per "
                   "target (LinuxCNC: the trt pins' HAL lines, the COMP_FILE INI lines and files, pige's "
                   "component's INI and HAL lines), instead of printing them; an existing folder, files replaced "
                   "only with --force")
    p.add_argument("--comp-dir", metavar="DIR", help="with --controller linuxcnc: write each rotary joint's "
                   "positioning map as a LinuxCNC COMP_FILE into DIR (an existing folder; replaced only with --force)")
    p.add_argument("--json", action="store_true", help="print the change report as one JSON object")
    p.set_defaults(handler=_run)


def _study(args: argparse.Namespace) -> int:
    from pige_sym.compensation.study import compensation_study, plot_compensation
    from pige_sym.identification.least_squares import identify
    from pige_sym.kernels import load_kernels
    from pige_sym.model.trajectories import cone_frustum, figure_eight
    from pige_sym.simulation.simulator import random_pige, simulate

    kern = load_kernels(args.machine)
    code = kern.MACHINE_CODE
    incl = "X" if kern.ROTARY_AXES[0] == "A" else "Y"
    trajs = [cone_frustum(code, incl_axis=incl), figure_eight(code)]
    from pige_sym.cli._setup import parse_vec3

    tool = parse_vec3(args.tool, "--tool") if args.tool else None
    truth = random_pige(code, args.seed)
    sim = simulate(code, trajs[0], pige=truth, noise_um=args.noise, seed=args.seed, tool_mm=tool)
    res = identify(sim.measurement)
    ident = {p: v for p, v in zip(res.parameters, res.values, strict=True)}
    rows = compensation_study(code, trajs, truth=truth, identified=ident, covariance=res.covariance, tool_mm=tool)
    paths = plot_compensation(rows, args.plots) if args.plots else []
    if args.json:
        print(to_json({"machine": code, "truth": truth, "identified": ident, "rows": [r.to_dict() for r in rows],
                          "plots": paths}))
        return 0
    print(f"compensation study on {code}: PIGEs identified from a simulated cone test (noise {args.noise} um)")
    for r in rows:
        print(f"  {r.trajectory}: RMSE {r.rmse_before_um:.3f} -> {r.rmse_after_um:.3f} um "
              f"({r.reduction:.1%} reduction; {r.predicted_after_um:.3f} um expected from the std); "
              f"commands moved by {r.command_change_rmse_mm * 1e3:.2f} um RMS")
    for pth in paths:
        print(f"  plot: {Path(pth)}")
    return 0


def register_study_compensation(sub: argparse._SubParsersAction) -> None:
    """Add ``pige study compensation`` to the study subcommands."""
    p = sub.add_parser("compensation", help="before/after compensation on a simulated machine",
                       epilog="example:\n  pige study compensation --seed 3 --plots plots/",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the true errors and the noise (default %(default)s)")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise sigma [um] (default %(default)s)")
    p.add_argument("--tool", help="ball offset from the last tool-side pivot x,y,z [mm] (head machines)")
    p.add_argument("--plots", metavar="DIR", help="write before/after plots (PNG) into DIR")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_study)
