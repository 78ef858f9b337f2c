"""``pige plan``: plan the R-test before running it, or grade an existing test program.

With ``--map AXES`` it plans a test of the rotary axes' error maps (CONVENTIONS §10) for the sphere
probe, the R-test or the ballbar: the setups and poses that determine every map value, each value's
predicted standard error, the machine time, and what fewer setups cannot determine
(:mod:`pige_sym.planning.map_plan`).

Planning searches trajectory families and (with ``--ball-region``) the ball position for
the test that determines the PIGEs best within the axis limits, writes it as an angle file
(first row the reference pose) that ``pige program``, ``pige rtest-sim`` and ``pige
acquire`` take, and prints the predicted standard error of every PIGE next to the default
cone's with the same points, noise and ball, plus which catalogue effects the test can
reveal.  ``--grade`` reports the same figures for a given trajectory or NC program.
See :mod:`pige_sym.planning`.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from pige_sym.cli._checkup import add_checkup_arguments, checkup_requested
from pige_sym.cli._maps import add_map_arguments
from pige_sym.cli._probe import add_probe_program_arguments
from pige_sym.constants import DEFAULT_DWELL_S, DEFAULT_MACHINE, DEFAULT_MOVE_S
from pige_sym.errors import InputError


def _points(args: argparse.Namespace, move_s: float, dwell_s: float) -> int:
    """Points from ``--points`` and/or the time budget ``--time`` (schedule: move + dwell per pose)."""
    per = move_s + dwell_s
    if args.time is not None:
        if not (math.isfinite(args.time) and args.time > 0):
            raise InputError("--time must be a positive number of seconds")
        fit = int((args.time - dwell_s) // per)
        if args.points is None:
            if fit < 3:
                raise InputError(f"--time {args.time:g} s holds {max(fit, 0)} poses ({per:g} s each): give at least "
                                 f"{3 * per + dwell_s:g} s")
            return fit
        if args.points > fit:
            raise InputError(f"--points {args.points} takes {args.points * per + dwell_s:g} s with {move_s:g} s move "
                             f"and {dwell_s:g} s dwell per pose, more than --time {args.time:g} s (at most {fit})")
    return 30 if args.points is None else int(args.points)


def _setup(args: argparse.Namespace) -> Any:
    import numpy as np

    from pige_sym.cli._setup import parse_pivots, parse_vec3
    from pige_sym.model.projection import parse_projection
    from pige_sym.planning import Setup

    tool = parse_vec3(args.tool, "--tool") if args.tool else None
    pivots = {a: np.asarray(v, dtype=float) for a, v in parse_pivots(args.pivot).items()}
    return Setup(args.machine, np.asarray(parse_vec3(args.ball, "--ball"), dtype=float),
                 None if tool is None else np.asarray(tool, dtype=float), pivots or None, noise_um=args.noise,
                 projection=parse_projection(args.projection), with_zero=args.with_zero)


def _grade(args: argparse.Namespace, setup: Any, limits: Any) -> Any:
    from pige_sym.model.trajectories import NAMES
    from pige_sym.nc.rtest_program import load_test_program
    from pige_sym.planning import grade_test

    options = {"points": args.points} if args.points is not None and args.grade in NAMES else {}
    prog = load_test_program(setup.machine, args.grade, ball_mm=setup.ball_mm, pivots_mm=setup.pivots_mm,
                             tool_mm=setup.tool_mm, move_s=args.move, dwell_s=args.dwell, **options)
    return grade_test(setup, prog.angles_deg, prog.arrive_s, description=prog.description, criterion=args.criterion,
                      limits=limits, duration_s=prog.duration_s)


def _plan(args: argparse.Namespace, setup: Any, limits: Any) -> Any:
    from pige_sym.files import atomic_write_text, check_output
    from pige_sym.measurements.rtest import read_angle_file
    from pige_sym.planning import PlanRequest, parse_reveal, plan_test, search_ball_region

    if not args.out:
        raise InputError("give --out PLAN.csv for the planned test (or --grade FILE to grade an existing one)")
    out = check_output(args.out, force=args.force, what="--out")
    region = search_ball_region(args.ball_region)
    for i, (lo, hi) in region.items():
        setup.ball_mm[i] = min(max(setup.ball_mm[i], lo), hi)
    req = PlanRequest(setup, _points(args, args.move, args.dwell), limits, region, args.criterion,
                      parse_reveal(args.reveal, tuple(setup.kernels.ROTARY_AXES)), args.move, args.dwell, args.seed)
    plan = plan_test(req)
    text = plan.angle_file_text()
    atomic_write_text(out, text)
    axes, angles, _ = read_angle_file(out)  # read the output back: it must be the planned poses
    if axes != plan.rotary_axes or angles.shape != plan.angles_deg.shape or abs(angles - plan.angles_deg).max() > 0:
        raise InputError(f"{out}: the file read back differs from the plan (please report this)")
    return plan


def _format(plan: Any, out: str | None) -> str:
    pred, base = plan.prediction, plan.baseline
    units = pred.units
    lines = [f"machine {plan.machine}   {plan.points} poses + reference   noise {plan.setup.noise_um:g} um   "
             f"criterion {plan.criterion}   ball {', '.join(f'{x:g}' for x in plan.setup.ball_mm)} mm",
             f"{plan.family}: {plan.description}", "",
             f"{'parameter':<12}{'predicted std':>15}{'default cone':>15}   unit"]
    bstd = base.std_dict() if base is not None else {}
    for name, s in pred.std_dict().items():
        b = bstd.get(name)
        lines.append(f"{name:<12}{'undetermined' if s is None else f'{s:.4f}':>15}"
                     f"{'—' if b is None else f'{b:.4f}':>15}   {units.get(name, '')}")
    gain = f"   (default cone {base.worst:.4g}: {base.worst / pred.worst:.1f}x larger)" if base else ""
    lines += ["", f"worst predicted std {pred.worst:.4g}{gain}", f"condition {pred.condition:.3g}   duration "
              f"{plan.duration_s:g} s" + (f"   planned in {plan.planning_s:.2f} s" if plan.planning_s else "")]
    if pred.undetermined:
        lines.append(f"undetermined (no value will be given): {', '.join(pred.undetermined)}")
    if plan.limits is not None and plan.limits.assumed:
        lines.append("assumed limits (give --limits): " + ", ".join(
            f"{a} {plan.limits.rotary[a][0]:g}:{plan.limits.rotary[a][1]:g}" for a in plan.limits.assumed))
    if plan.baseline_within_limits is False:
        lines.append("note: the default cone itself leaves these limits")
    lines += ["", "effects this test can reveal:"]
    for eff, st in plan.reveal.items():
        lines.append(f"  {'yes' if st.revealable else 'no ':<4}{eff:<20}{'(forced) ' if st.forced else ''}{st.reason}")
    if out:
        ball = ",".join(f"{x:g}" for x in plan.setup.ball_mm)
        tool = f" --tool {','.join(f'{x:g}' for x in plan.setup.tool_mm)}" if plan.setup.tool_mm is not None else ""
        lines += ["", f"wrote {out}; next: pige program --machine \"{plan.machine}\" --trajectory {out} "
                  f"--ball {ball}{tool} --out plan.mpf"]
    return "\n".join(lines)


def _run_ballbar(args: argparse.Namespace) -> int:
    """The smallest set of ballbar setups that determines every PIGE within --target (--out: as JSON)."""
    from pige_sym.cli._setup import finite_option
    from pige_sym.files import atomic_write_text, check_output, to_json
    from pige_sym.kernels import load_kernels
    from pige_sym.planning.ballbar import format_setups, plan_setups

    code = load_kernels(args.machine).MACHINE_CODE
    out = check_output(args.out, force=args.force, what="--out") if args.out else None
    target = 2.0 if args.target is None else finite_option(args.target, "--target", positive=True)
    chosen, sizes = plan_setups(code, target=target, noise_um=args.noise)
    result = {"machine": code, "noise_um": args.noise, "target": target,
              "chosen": None if chosen is None else chosen.labels,
              "programs": [] if chosen is None else chosen.program_commands(code),
              "by_size": [{"setups": s.labels, "determined": s.determined, "worst_std": s.worst_std}
                          for s in sizes]}
    if out is not None:
        atomic_write_text(out, to_json(result) + "\n")
    if args.json:
        print(to_json({**result, "out": None if out is None else str(out)}))
        return 0 if chosen is not None else 1
    print(format_setups(code, sizes, chosen, target=target, noise_um=args.noise))
    if chosen is not None:
        print("\nnext, one program per setup:\n" + "\n".join("  " + c for c in result["programs"]))
    if out is not None:
        print(f"\nwrote {out} (the plan as JSON)")
    return 0 if chosen is not None else 1


def _run_probe(args: argparse.Namespace) -> int:
    """Poses and contacts of a touch-probe test within a probing-time budget."""
    from pige_sym.cli._probe import probe_setup
    from pige_sym.files import atomic_write_text, check_output, to_json
    from pige_sym.kernels import load_kernels
    from pige_sym.planning.probe import angle_file_text, coupling_study, plan_probe

    kern = load_kernels(args.machine)
    setup = probe_setup(args, kern.MACHINE_CODE)
    out = check_output(args.out, force=args.force, what="--out") if args.out else None
    best, tried = plan_probe(setup, budget_s=args.budget, contact_sigma_um=args.noise, pose_s=args.pose_time,
                             contact_s=args.contact_time)
    if out is not None:
        note = (f"pige plan --instrument sphere-probe: {best.poses} poses, {best.contacts} contacts, "
                f"{best.seconds:.0f} s, worst predicted std {best.worst:.3g}")
        atomic_write_text(out, angle_file_text(best, tuple(kern.ROTARY_AXES), note))
    if args.json:
        print(to_json({"poses": best.poses, "contacts": best.contacts, "seconds": best.seconds, "std": best.std,
                       "std_ignoring_coupling": best.std_ignoring_coupling, "candidates": len(tried),
                       "out": None if out is None else str(out)}))
        return 0
    print(f"best of {len(tried)} probe tests within {args.budget:g} s (contact scatter {args.noise:g} um):")
    print(coupling_study(best))
    if out is not None:
        print(f"\nwrote {out}; next: pige program --instrument sphere-probe --contacts {best.contacts} "
              f"--trajectory {out} --sphere {args.sphere} --sphere-radius {args.sphere_radius:g} "
              f"--stylus-radius {args.stylus_radius:g}{f' --tool {args.tool}' if args.tool else ''} --out probe.ngc "
              "--dialect linuxcnc")
    return 0


def _run_checkup(args: argparse.Namespace) -> int:
    """The check-up of a machine in the history (:mod:`pige_sym.planning.checkup`), optionally its poses as a file."""
    from pige_sym.cli._checkup import format_plan, plan_from_history
    from pige_sym.files import atomic_write_text, check_output, to_json

    out = check_output(args.out, force=args.force, what="--out") if args.out else None
    pc = plan_from_history(args, budget_s=args.budget)
    if out is not None:
        atomic_write_text(out, pc.plan.angle_file_text(f"pige plan --checkup --machine-id {pc.machine_id}: "
                                                       f"{pc.plan.poses} poses, {pc.plan.seconds:.0f} s"))
    if args.json:
        print(to_json(pc.plan.to_dict() | {"machine_id": pc.machine_id, "full_run": pc.full_id,
                                           "out": None if out is None else str(out)}))
        return 0
    print(format_plan(pc))
    print(f"\nnext: pige program --checkup --machine-id {pc.machine_id} --dialect DIALECT --out checkup.ngc"
          + (f"   (wrote the poses to {out})" if out is not None else ""))
    return 0


def _map_request(args: argparse.Namespace) -> Any:
    """The map test of the options, for each instrument (docs/maps.md "Planning a map test")."""
    import numpy as np

    from pige_sym.cli._maps import map_request
    from pige_sym.cli._probe import probe_setup
    from pige_sym.cli._setup import parse_pivots, parse_vec3
    from pige_sym.kernels import load_kernels
    from pige_sym.simulation.ballbar import DEFAULT_TABLE_BALL_MM

    kern = load_kernels(args.machine)
    tool = parse_vec3(args.tool, "--tool") if args.tool else None
    if args.instrument == "sphere-probe":
        setup = probe_setup(args, kern.MACHINE_CODE)
        return map_request(args, kern, "sphere-probe", point=setup.sphere_mm, tool=setup.tool_mm, probe=setup,
                           noise_um=args.noise, pose_s=args.pose_time, contact_s=args.contact_time)
    if args.instrument == "ballbar":
        first = args.map_point[0] if args.map_point else ",".join(f"{x:g}" for x in DEFAULT_TABLE_BALL_MM)
        args.map_point = None  # the table ball of every candidate setup (planning/map_plan.py)
        return map_request(args, kern, "ballbar", point=np.array(parse_vec3(first, "--map-point")),
                           noise_um=args.noise, pose_s=args.move + args.dwell)
    return map_request(args, kern, "rtest", point=parse_vec3(args.ball, "--ball"), tool=tool,
                       pivots=parse_pivots(args.pivot), noise_um=args.noise, pose_s=args.move + args.dwell)


def _run_map(args: argparse.Namespace) -> int:
    """``--map AXES``: the setups and poses that determine every map value, their predicted standard errors, the
    machine time and what fewer setups leave undetermined (--out: the plan as JSON and, but for the ballbar, the
    poses as an angle file beside it)."""
    from pige_sym.files import atomic_write_text, check_output, to_json
    from pige_sym.planning.map_ballbar import plan_ballbar_maps
    from pige_sym.planning.map_plan import format_map_plan, plan_map_test

    if args.grade or args.reveal or args.ball_region:
        raise InputError("--map plans a map test: leave out --grade, --reveal and --ball-region")
    request = _map_request(args)
    out = check_output(args.out, force=args.force, what="--out") if args.out else None
    poses = None if out is None or request.instrument == "ballbar" else check_output(
        out.with_name(out.stem + "_poses.csv"), force=args.force, what="poses file")
    plan = plan_ballbar_maps(request) if request.instrument == "ballbar" else plan_map_test(request)
    result = plan.to_dict() | {"poses_file": None if poses is None else str(poses)}
    if out is not None:
        atomic_write_text(out, to_json(result) + "\n")
    if poses is not None:
        _write_poses(poses, plan)
    if args.json:
        print(to_json(result | {"out": None if out is None else str(out)}))
        return 0 if plan.prediction.complete else 1
    print(format_map_plan(plan))
    print(_next_commands(args, plan, poses))
    if out is not None:
        print(f"\nwrote {out} (the plan as JSON)" + (f" and {poses} (its poses)" if poses is not None else ""))
    return 0 if plan.prediction.complete else 1


def _write_poses(path: Any, plan: Any) -> None:
    """The poses every setup visits as an angle file (``t_s,<axis>_deg``), read back."""
    from pige_sym.files import atomic_write_text
    from pige_sym.measurements.rtest import read_angle_file

    setup = plan.setups[0]
    axes = tuple(setup.item.rotary_axes)
    lines = [f"# pige plan --map: the poses of every setup of the map test of {plan.request.machine}",
             ",".join(["t_s", *(f"{a}_deg" for a in axes)])]
    per = setup.seconds / setup.angles_deg.shape[0]
    lines += [",".join([f"{i * per:.10g}", *(f"{v:.10g}" for v in row)]) for i, row in enumerate(setup.angles_deg)]
    atomic_write_text(path, "\n".join(lines) + "\n")
    read_axes, angles, _ = read_angle_file(path)
    if read_axes != axes or angles.shape != setup.angles_deg.shape or abs(angles - setup.angles_deg).max() > 0:
        raise InputError(f"{path}: the file read back differs from the plan (please report this)")


def _next_commands(args: argparse.Namespace, plan: Any, poses: Any) -> str:
    """What to run next: one program per setup (sphere probe), or each setup's R-test program."""
    from pige_sym.cli._maps import map_options_text

    r = plan.request
    if r.instrument == "sphere-probe":
        return _probe_program_command(args, r.machine, map_options_text(args, len(plan.setups)), len(plan.setups))
    if r.instrument == "rtest":
        traj = poses if poses is not None else "POSES.csv (give --out plan.json: it writes plan_poses.csv)"
        lines = [f"  pige program --machine \"{r.machine}\" --trajectory {traj} --ball "
                 f"{','.join(f'{x:.10g}' for x in s.point_mm)}"
                 + ("" if s.tool_mm is None else f" --tool {','.join(f'{x:.10g}' for x in s.tool_mm)}")
                 + f" --out map_{i}.mpf" for i, s in enumerate(plan.setups, start=1)]
        return "\nnext, each setup's R-test program:\n" + "\n".join(lines)
    return "\nnext, each setup: pige program --instrument ballbar --setup KIND --axis AXIS [--tilt DEG] " \
        "--table-ball x,y,z (the setups above)"


def _word(value: Any) -> str:
    """An option's value as the user would type it (``120``, not ``120.0``)."""
    return f"{value:g}" if isinstance(value, float) else str(value)


def _probe_program_command(args: argparse.Namespace, machine: str, map_options: str, setups: int) -> str:
    """``pige program`` writing one probing program per setup, with every option given here that it takes (it runs
    as printed); without the probe's tool number and length (which a program states) and the dialect, what to add."""
    ext = {"siemens": ".mpf", "fanuc": ".nc", "heidenhain": ".h"}.get(args.dialect or "", ".ngc")
    parts = [f"--instrument sphere-probe --machine \"{machine}\" {map_options}", f"--sphere {args.sphere}",
             f"--sphere-radius {args.sphere_radius:g}", f"--stylus-radius {args.stylus_radius:g}"]
    parts += [f"--{name.replace('_', '-')} {_word(getattr(args, name))}" for name in (
        "tool", "dialect", "kinematics", "rtcp_off", "rtcp_on", "stylus_tool", "stylus_length")
        if getattr(args, name, None) is not None]
    if args.work_offset != "G54":
        parts.append(f"--work-offset {args.work_offset}")
    missing = [o for o, v in (("--stylus-tool", args.stylus_tool), ("--stylus-length", args.stylus_length),
                              ("--dialect", args.dialect)) if v is None]
    if missing:
        return (f"\nnext: one program per setup; give {', '.join(missing)} here too (a program states its probe and is "
                "written for one controller) and this plan prints the command that writes them")
    return (f"\nnext, one program per setup (map_1{ext} … map_{setups}{ext}):\n  pige program " + " ".join(parts)
            + f" --out map{ext}")


def _run(args: argparse.Namespace) -> int:
    from pige_sym.files import to_json
    from pige_sym.planning import parse_limits

    if args.target is not None and (args.checkup or (args.map is None and args.instrument != "ballbar")):
        raise InputError("--target is the largest predicted std a ballbar plan or a map plan (--map) accepts: leave it "
                         "out here")
    if checkup_requested(args, "plan different tests", "plan a check-up"):
        return _run_checkup(args)
    if args.budget is None:
        args.budget = 1800.0
    if args.map is not None:
        return _run_map(args)
    if args.instrument == "ballbar":
        return _run_ballbar(args)
    if args.instrument == "sphere-probe":
        return _run_probe(args)

    setup = _setup(args)
    limits = parse_limits(args.limits, setup.kernels)
    if args.grade:
        if args.out or args.reveal or args.ball_region:
            raise InputError("--grade reports on an existing test and writes nothing: leave out --out, --reveal "
                             "and --ball-region (they are for planning)")
        plan = _grade(args, setup, limits)
    else:
        plan = _plan(args, setup, limits)
    if args.json:
        print(to_json({**plan.to_dict(), "out": args.out}))
    else:
        print(_format(plan, args.out))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "plan", help="plan a test: R-test trajectory, probe poses and contacts, or ballbar setups; or grade one",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        epilog=(
            "examples:\n"
            "  pige plan --machine \"wC'A'bXYZ(C1)t\" --points 30 --limits A=-110:30 --out plan.csv\n"
            "  pige plan --machine \"wbXYZCA(C1)t\" --tool 0,0,-250 --points 24 --reveal backlash_C,thermal_drift "
            "--out plan.csv --json\n"
            "  pige plan --ball-region x=80:150,z=50:120 --criterion D --out plan.csv\n"
            "  pige plan --grade rtest.mpf --noise 0.3\n"
            "  pige plan --instrument sphere-probe --map C,A --sphere 100,20,60 --sphere-radius 12.7 "
            "--stylus-radius 1.5\n"
            "  pige plan --checkup --machine-id DMU50-2 --db history.db"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--points", type=int, help="poses after the reference pose (default 30, or what --time holds)")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise per component [um] (default %(default)s)")
    p.add_argument("--limits", action="append", metavar="AXIS=lo:hi",
                   help="axis range: rotary [deg] or X/Y/Z [mm] (repeatable; tilt axis default -90:90)")
    p.add_argument("--ball", default="120,0,80", help="ball centre x,y,z [mm] (start of --ball-region search)")
    p.add_argument("--ball-region", metavar="x=lo:hi,...", help="search the ball position in this box [mm]")
    p.add_argument("--tool", help="ball offset from the last tool-side pivot x,y,z [mm] (head machines)")
    p.add_argument("--pivot", action="append", metavar="AXIS=x,y,z", help="nominal pivot of a rotary axis [mm]")
    p.add_argument("--time", type=float, metavar="S", help="time budget of the test [s] (move + dwell per pose)")
    p.add_argument("--reveal", metavar="EFFECT,...", help="effects the test must be able to reveal (catalogue ids)")
    p.add_argument("--criterion", choices=["worst", "A", "D"], default="worst",
                   help="worst: largest std; A: total variance; D: determinant (default %(default)s)")
    p.add_argument("--projection", default="xyz", help="excitation projection used to identify (default xyz)")
    p.add_argument("--with-zero", action="store_true", help="also plan for the zero-position errors")
    p.add_argument("--move", type=float, default=DEFAULT_MOVE_S, help="move time per pose [s]")
    p.add_argument("--dwell", type=float, default=DEFAULT_DWELL_S, help="dwell per pose [s]")
    p.add_argument("--seed", type=int, default=0, help="seed of the search (default %(default)s: reproducible)")
    p.add_argument("--grade", metavar="TRAJECTORY",
                   help="grade this test instead: cone-frustum, figure-eight, steps, an angle CSV or an NC program")
    p.add_argument("--out", help="angle file of the planned test (ballbar: the chosen setups as JSON)")
    p.add_argument("--instrument", choices=["rtest", "ballbar", "sphere-probe"], default="rtest",
                   help="ballbar: the smallest set of setups; sphere-probe: poses and contacts for a time budget")
    add_probe_program_arguments(p)
    add_checkup_arguments(p)
    add_map_arguments(p)
    p.add_argument("--dialect", choices=["siemens", "fanuc", "linuxcnc", "heidenhain"],
                   help="sphere-probe map test: the controller the programs are for (the next command writes them)")
    p.add_argument("--budget", type=float, help="sphere-probe: probing time budget [s] (default 1800; with --checkup: "
                                                "machine time, default 120)")
    p.add_argument("--pose-time", type=float, default=20.0, help="sphere-probe: time per pose (retract, rotate) [s]")
    p.add_argument("--contact-time", type=float, default=8.0, help="sphere-probe: time per contact [s]")
    p.add_argument("--target", type=float,
                   help="ballbar: largest acceptable predicted std [um or urad] (default 2; with --map: none, the "
                   "fewest setups that determine every value)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    p.set_defaults(handler=_run)
