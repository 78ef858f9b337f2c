"""What ``pige plan --checkup`` and ``pige program --checkup`` share: the history read, the check-up planned."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

from pige_sym.errors import InputError


def checkup_requested(args: argparse.Namespace, tests: str, checkup: str) -> bool:
    """Whether ``--checkup`` was given, its options consistent: refuses it beside ``--map`` ("--checkup and --map
    ``tests``") and ``--machine-id``/``--pige`` without it ("... ``checkup``: give --checkup").

    Raises
    ------
    InputError
    """
    if args.checkup and args.map is not None:
        raise InputError(f"--checkup and --map {tests}: give one of them")
    if not args.checkup and (args.machine_id is not None or args.pige is not None):
        raise InputError(f"--machine-id and --pige {checkup}: give --checkup")
    return bool(args.checkup)


def add_checkup_arguments(p: argparse.ArgumentParser) -> None:
    """``--checkup --machine-id ID [--db URL] [--pige LIST] [--rapid] [--rotary-speed]``."""
    from pige_sym.cli.history import DB_HELP

    g = p.add_argument_group("check-up (planned from the machine's last full calibration in the history)")
    g.add_argument("--checkup", action="store_true",
                   help="the short check run: the fewest poses that determine the PIGEs that change between runs")
    g.add_argument("--machine-id", metavar="ID", help="with --checkup: the machine in the history")
    g.add_argument("--db", metavar="URL", help="with --checkup: " + DB_HELP)
    g.add_argument("--pige", metavar="LIST", help="with --checkup: the PIGEs re-measured (default: the last "
                                                  "check-up's, else the axis lines' positions, the location errors "
                                                  "in um)")
    g.add_argument("--rapid", type=float, default=100.0, metavar="MM_S",
                   help="with --checkup: rapid speed of the linear axes the machine time is predicted with "
                        "[mm/s] (default %(default)s, acceleration 1000 mm/s2)")
    g.add_argument("--rotary-speed", type=float, default=30.0, metavar="DEG_S",
                   help="with --checkup: rotary axes' speed [deg/s] (default %(default)s)")


@dataclass
class PlannedCheckup:
    """A check-up planned for a machine: the plan, the full calibration's set-up, its probing set-up (probe)."""

    machine_id: str
    plan: Any
    setup: Any
    probe: Any
    full_id: int


def plan_from_history(args: argparse.Namespace, *, budget_s: float | None, controller: Any = None,
                      dialect: str = "linuxcnc") -> PlannedCheckup:
    """Read the machine's last full calibration and plan its check-up (:mod:`pige_sym.planning.checkup`)."""
    from pige_sym.cli._setup import finite_option
    from pige_sym.nc.probe_timing import MachineSpeeds
    from pige_sym.planning.checkup import DEFAULT_BUDGET_S, CheckupRequest, parse_free, plan_checkup, probe_setup_of
    from pige_sym.verdict.checkup.reference import last_full, run_setup
    from pige_sym.verdict.history import connect, list_runs

    if not args.machine_id or not args.machine_id.strip():
        raise InputError("--checkup needs --machine-id ID (the machine whose last full calibration it repeats)")
    runs = list_runs(connect(args.db, create=False), args.machine_id, light=True)
    full = last_full(runs)
    setup = run_setup(full)
    last = [r for r in runs if r.kind == "checkup"]
    free = parse_free(args.pige, setup.machine) if args.pige is not None or not last else list(last[-1].parameters)
    speeds = MachineSpeeds(rapid_mm_s=finite_option(args.rapid, "--rapid", positive=True),
                           rotary_deg_s=finite_option(args.rotary_speed, "--rotary-speed", positive=True))
    probe = None
    if setup.instrument == "sphere-probe":
        probe = probe_setup_of(setup, controller, **_probe_options(args))
    given = getattr(args, "noise", None)
    if given is not None:
        finite_option(given, "--noise", positive=True)
    noise = setup.noise_um if setup.noise_um is not None else (full.rms_um or given or 0.25)
    req = CheckupRequest(setup, free, DEFAULT_BUDGET_S if budget_s is None else budget_s, float(noise), probe, speeds,
                         move_s=getattr(args, "move", 5.0), dwell_s=getattr(args, "dwell", 7.0), dialect=dialect)
    return PlannedCheckup(args.machine_id, plan_checkup(req), setup, probe, full.id)


def _probe_options(args: argparse.Namespace) -> dict[str, Any]:
    """The probing options a check-up program takes from the command line (the rest is the full calibration's)."""
    from pige_sym.cli._setup import finite_option, parse_vec3
    from pige_sym.nc.probe_reach import Stem

    out: dict[str, Any] = {}
    for name in ("clearance", "overtravel", "probe_feed"):
        if getattr(args, name, None) is not None:
            out[name + ("_mm_min" if name == "probe_feed" else "_mm")] = finite_option(
                getattr(args, name), "--" + name.replace("_", "-"), positive=True)
    if getattr(args, "safe_z", None) is not None:
        out["safe_z_mm"] = float(args.safe_z)
    if getattr(args, "stem", None):
        v = parse_vec3(args.stem, "--stem")
        out["stem"] = Stem((v[0], v[1], v[2]), args.stem_radius, args.stem_length, args.shank)
    return out


def checkup_controller(args: argparse.Namespace, dialect: str) -> Any:
    """The controller state of a check-up program: the options when any is given, else None (the stored one)."""
    given = any(getattr(args, k, None) is not None for k in ("stylus_tool", "stylus_length", "rtcp_off", "rtcp_on",
                                                              "kinematics"))
    if not given:
        return None
    from pige_sym.cli._probe import probe_controller

    return probe_controller(args, dialect)


def format_plan(pc: PlannedCheckup) -> str:
    """The check-up plan as text: poses, contacts, machine time, predicted standard errors."""
    p = pc.plan
    axes = p.rotary_axes
    lines = [f"check-up of {pc.machine_id} ({p.machine}), from its full calibration run {pc.full_id} "
             f"({p.instrument}): {p.poses} poses with the reference"
             + (f", {p.contacts} contacts each" if p.contacts else "")
             + f", {p.seconds:.0f} s of machine time (budget {p.budget_s:g} s)"]
    for i, row in enumerate(p.angles_deg):
        lines.append(f"  pose {i}: " + ", ".join(f"{a} {v:g} deg" for a, v in zip(axes, row, strict=True))
                     + ("  (reference)" if i == 0 else ""))
    from pige_sym.kernels import load_kernels

    units = load_kernels(p.machine).UNITS
    lines += ["", f"{'PIGE':<8}{'predicted std':>15}  unit",
              *(f"{n:<8}{s:>15.3f}  {units[n]}" for n, s in p.std.items())]
    lines += ["", f"held at the last full calibration: {', '.join(p.held)}",
              f"noise: {p.noise_um:.3g} um ({'contact scatter' if p.contacts else 'per component'} of the full "
              f"calibration); {p.candidates} candidate poses inside its range"]
    lines += [f"note: {n}" for n in p.notes]
    return "\n".join(lines)
