"""``pige study``: projection study, Sobol sensitivity, compensation before/after."""

from __future__ import annotations

import argparse

from pige_sym.cli._setup import show_progress
from pige_sym.constants import DEFAULT_MACHINE
from pige_sym.errors import InputError
from pige_sym.files import to_json


def _trajectory(args: argparse.Namespace):  # noqa: ANN202
    from pige_sym.kernels import load_kernels
    from pige_sym.model.trajectories import make_trajectory

    kern = load_kernels(args.machine)
    opts = {"incl_axis": args.incl_axis} if args.trajectory == "cone-frustum" and args.incl_axis else {}
    return kern, make_trajectory(kern.MACHINE_CODE, args.trajectory, **opts)


def _tool(args: argparse.Namespace) -> list[float] | None:
    """``--tool x,y,z`` [mm] (head machines), None when not given."""
    from pige_sym.cli._setup import parse_vec3

    return parse_vec3(args.tool, "--tool") if args.tool else None


def _projection(args: argparse.Namespace) -> int:
    from pige_sym.identification.studies import projection_study

    if args.instrument == "ballbar":
        return _ballbar_projection(args)
    if args.instrument == "sphere-probe":
        return _probe_projection(args)
    kern, traj = _trajectory(args)
    study = projection_study(kern.MACHINE_CODE, traj, projections=args.projections.split(","), sweep=args.sweep,
                             presets=args.presets, noise_um=args.noise, seed=args.seed, tool_mm=_tool(args),
                             progress=show_progress(args.json))
    print(to_json(study.to_dict()) if args.json else study.format())
    return 0


def _ballbar_projection(args: argparse.Namespace) -> int:
    """Each candidate ballbar setup alone: what it determines and what it cannot see."""
    from pige_sym.kernels import load_kernels
    from pige_sym.planning.ballbar import candidate_setups, evaluate, format_setups

    code = load_kernels(args.machine).MACHINE_CODE
    sets = sorted((evaluate(code, [s], args.noise) for s in candidate_setups(code)),
                  key=lambda s: (-s.determined, -s.rank, s.worst_std))
    if args.json:
        print(to_json([{"setups": s.labels, "rank": s.rank, "determined": s.determined, "std": s.std,
                        "undetermined": s.undetermined} for s in sets]))
    else:
        text = format_setups(code, sets, None, target=None, noise_um=args.noise)
        print(text + "\n\nno single setup determines all PIGEs: pige plan --instrument ballbar picks a set")
    return 0


def _probe_projection(args: argparse.Namespace) -> int:
    """What a touch-probe test determines, with the reference pose's coupling and ignoring it."""
    import numpy as np

    from pige_sym.nc.probe_program import ProbeSetup
    from pige_sym.planning.probe import coupling_study, format_tilt_study, predict_probe, tilt_study

    kern, traj = _trajectory(args)
    tool = _tool(args)
    setup = ProbeSetup(kern.MACHINE_CODE, np.array([100.0, 20.0, 60.0]), np.zeros(3), 12.7, 1.5,
                       tool_mm=None if tool is None else np.array(tool))
    pred = predict_probe(setup, traj.angles_deg, contact_sigma_um=args.noise)
    tilts = tilt_study(setup, contact_sigma_um=args.noise)
    if args.json:
        print(to_json({"std": pred.std, "std_ignoring_coupling": pred.std_ignoring_coupling, "poses": pred.poses,
                       "contacts": pred.contacts,
                       "tilt_study": [{"tilt_deg": t, "std": p.std if not isinstance(p, str) else None,
                                       "refused": p if isinstance(p, str) else None} for t, p in tilts]}))
    else:
        on = f", stylus at {', '.join(f'{v:g}' for v in tool)} mm from the head's pivot" if tool else ""
        print(f"sphere probe on {kern.MACHINE_CODE}, {traj.description}, sphere 12.7 mm at 100, 20, 60 mm{on}, "
              f"contact scatter {args.noise:g} um (full 3-D centres)\n" + coupling_study(pred) + "\n\n"
              + format_tilt_study(setup, tilts, args.noise))
    return 0


def _sobol(args: argparse.Namespace) -> int:
    from pige_sym.identification.studies import sobol_study

    if args.samples is not None and (args.samples < 2 or args.samples & (args.samples - 1)):
        raise InputError(f"--samples must be a power of 2, got {args.samples}")
    kern, traj = _trajectory(args)
    study = sobol_study(kern.MACHINE_CODE, traj, projections=args.projections.split(","), n=args.samples,
                        default_range=args.range, seed=args.seed, tool_mm=_tool(args))
    print(to_json(study.to_dict()) if args.json else study.format())
    return 0


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="ISO 10791 machine code (default %(default)s)")
    p.add_argument("--trajectory", default="cone-frustum", help="cone-frustum, figure-eight, steps or an angle CSV")
    p.add_argument("--incl-axis", choices=["X", "Y"], help="cone inclination axis")
    p.add_argument("--projections", default="x,y,z,xyz", help="comma list of projections (default %(default)s)")
    p.add_argument("--tool", help="ball (stylus) centre from the last tool-side pivot x,y,z [mm] (head machines)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def register(subparsers: argparse._SubParsersAction) -> None:
    study = subparsers.add_parser(
        "study", help="projection, sobol and compensation studies (R-test; projection also for probe and ballbar)",
        description="Studies of identifiability, sensitivity and compensation.",
        epilog="examples:\n"
               "  pige study projection --machine \"wC'A'bXYZ(C1)t\" --presets 100\n"
               "  pige study projection --instrument ballbar\n"
               "  pige study sobol --trajectory figure-eight\n"
               "  pige study compensation --seed 3 --plots plots/",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = study.add_subparsers(dest="study", metavar="STUDY", parser_class=type(study))
    sub.required = True
    p = sub.add_parser("projection", help="identifiability per excitation projection (paper Tables 3-6)",
                       epilog="examples:\n  pige study projection --machine \"wC'B'bXYZ(C1)t\" --presets 100\n"
                              "  pige study projection --instrument sphere-probe --sphere 100,20,60 "
                              "--sphere-radius 12.7 --stylus-radius 1.5",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(p)
    p.add_argument("--presets", type=int, default=50, help="random presets (default %(default)s)")
    p.add_argument("--sweep", type=int, default=0, help="also N directions over 180 deg in the XY plane")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise [um]")
    p.add_argument("--instrument", choices=["rtest", "ballbar", "sphere-probe"], default="rtest",
                   help="ballbar: rank the ISO 10791-6 style setups; sphere-probe: what a probe test determines, "
                        "with the reference pose's coupling")
    p.set_defaults(handler=_projection)
    s = sub.add_parser("sobol", help="Sobol sensitivity indices per projection",
                       epilog="examples:\n  pige study sobol --trajectory cone-frustum\n"
                              "  pige study sobol --samples 4096   # Monte-Carlo estimate, to cross-check",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(s)
    s.add_argument("--samples", type=int, default=None,
                   help="estimate with scipy.stats.sobol_indices on this base sample size (a power of 2) "
                        "instead of the exact closed form (default: exact)")
    s.add_argument("--range", type=float, default=15.0, help="half range of every PIGE [um|urad]")
    s.set_defaults(handler=_sobol)
    try:
        from pige_sym.cli.compensate import register_study_compensation
    except ImportError:
        pass
    else:
        register_study_compensation(sub)
