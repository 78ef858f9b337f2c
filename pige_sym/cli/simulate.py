"""``pige simulate``: write a synthetic R-test file, probe log or ballbar file, and its truth sidecar.

With ``--instrument sphere-probe`` it writes the probe log a probing program produces on the virtual
probing machine (:mod:`pige_sym.simulation.probe_machine`): the program given with ``--program``, or the
one ``pige program --instrument sphere-probe`` would write for the same options.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from pige_sym.cli._ballbar import add_ballbar_arguments
from pige_sym.cli._probe import INSTRUMENT_CHOICES, add_probe_program_arguments
from pige_sym.cli._setup import (
    add_setup_arguments,
    axis_sense_option,
    finite_option,
    pige_values,
    setup_geometry,
    trajectory_options,
)
from pige_sym.constants import PROBE_DIALECTS
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text, check_output, to_json


def _error_maps(args: argparse.Namespace, kern: Any) -> Any:
    """``--error-maps FILE``: the ``error_motions`` of a JSON file (``pige identify --map --json`` writes them;
    validated by :func:`~pige_sym.measurements.error_motions_file.read_error_motions`), or None."""
    from pige_sym.errors import FileFormatError
    from pige_sym.measurements.error_motions_file import read_error_motions
    from pige_sym.measurements.schema import load_json
    from pige_sym.model.error_motions import error_maps_from

    if not args.error_maps:
        return None
    data = load_json(args.error_maps, "--error-maps file")
    if not isinstance(data, dict) or not isinstance(data.get("error_motions"), dict) or not data["error_motions"]:
        raise FileFormatError(args.error_maps, None, 'expected a JSON object with an "error_motions" object (axis: '
                              '{"angle_deg": [...], "EXC": {"value": [...]}, ...}), as identify --map --json writes')
    _same_machine(args.error_maps, data.get("machine"), kern.MACHINE_CODE)
    return error_maps_from(read_error_motions(data["error_motions"], args.error_maps, kern))


def _same_machine(path: str, named: Any, machine: str) -> None:
    """The machine a maps file names (``machine``, optional) must be the simulated one (CONVENTIONS §10: maps are of
    one machine's axes, in its frames)."""
    from pige_sym.codegen.machine_code import parse_machine_code
    from pige_sym.errors import FileFormatError, PigeError

    if named is None:
        return
    try:
        code = parse_machine_code(named).canonical if isinstance(named, str) else None
    except PigeError:
        code = None
    if code is None:
        raise FileFormatError(path, None, f"machine: {named!r:.60} is not a machine code (CONVENTIONS §1)")
    if code != machine:
        raise FileFormatError(path, None, f"machine: the maps are of {code}, the simulated machine is {machine}: give "
                              "the maps of this machine (or --machine of theirs)")


def _run_probe(args: argparse.Namespace) -> int:
    from pige_sym.cli._probe import probe_setup
    from pige_sym.cli._setup import parse_vec3
    from pige_sym.kernels import load_kernels
    from pige_sym.model.effects import parse_effect
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.nc.probe_program import plan_probing
    from pige_sym.nc.probe_readback import verify_probe_program, verify_rendered_program
    from pige_sym.nc.probe_render import render_probe_program
    from pige_sym.nc.program_file import read_program
    from pige_sym.simulation.probe_machine import ProbeMachine, run_probe_program

    for name in ("noise", "pretravel", "lobing", "vertical_pretravel"):
        finite_option(getattr(args, name), "--" + name.replace("_", "-"), minimum=0.0 if name == "noise" else None)
    if args.program:
        text = read_program(args.program)
        setup = _program_setup(args, text)
        kern = load_kernels(setup.machine)
    else:
        kern = load_kernels(args.machine)
        setup = probe_setup(args, kern.MACHINE_CODE, dialect=args.dialect, controller_required=False)
        traj = make_trajectory(kern.MACHINE_CODE, args.trajectory, **trajectory_options(args))
        text = render_probe_program(plan_probing(setup, traj.angles_deg, traj.description), args.dialect)
    if args.program:
        verify_probe_program(text, args.dialect, setup, tuple(kern.ROTARY_AXES), path=args.program)
    else:
        verify_rendered_program(text, args.dialect, setup, tuple(kern.ROTARY_AXES))
    offset = parse_vec3(args.setup_offset, "--setup-offset")
    bent = parse_vec3(args.stylus_error, "--stylus-error")
    if any(bent) and setup.tool_mm is None:
        raise InputError("--stylus-error: a stylus off its tool vector matters on a head machine (give --tool)")
    machine = ProbeMachine(setup, pige_values(args.pige, kern.MACHINE_CODE, args.seed),
                           [parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []],
                           (offset[0], offset[1], offset[2]), args.noise, args.pretravel, args.lobing,
                           args.vertical_pretravel, args.seed, (bent[0], bent[1], bent[2]), _error_maps(args, kern))
    inputs = [x for x in (args.trajectory, args.pige, args.program, args.error_maps) if x and os.path.isfile(x)]
    out = check_output(args.out, force=args.force, inputs=inputs, what="--out")
    truth_path = check_output(out.with_name(out.stem + ".truth.json"), force=args.force, inputs=inputs,
                              what="truth sidecar")
    log = run_probe_program(text, args.dialect, machine, path=args.program or "<program>")
    atomic_write_text(out, log)
    truth = {"machine": kern.MACHINE_CODE, "instrument": "sphere-probe", "dialect": args.dialect,
             "pige": machine.pige, "effects": args.effect or [], "sphere_mm": list(setup.sphere_mm),
             "setup_offset_um": list(machine.setup_offset_um), "pivot_mm": list(setup.pivot_mm),
             "contact_noise_um": args.noise, "pretravel_um": args.pretravel, "lobing_um": args.lobing,
             "vertical_pretravel_um": args.vertical_pretravel, "seed": args.seed,
             **({} if setup.tool_mm is None else {"tool_mm": [float(v) for v in setup.tool_mm],
                                                  "stylus_error_um": list(machine.tool_error_um)}),
             **({} if machine.error_maps is None else {"error_motions": machine.error_maps.to_dict()})}
    atomic_write_text(truth_path, to_json(truth) + "\n")
    print(f"wrote {out} ({log.count(chr(10))} contacts, {args.dialect} log) and {truth_path}")
    return 0


def _program_setup(args: argparse.Namespace, text: str) -> Any:
    """The set-up of ``--program``: what its header states, with the options given in place of its items (the
    read-back then refuses any that disagrees, naming the option).  With ``--sphere`` every set-up option is read
    as for a new program (:func:`~pige_sym.cli._probe.probe_setup`); without it (the short form) the header gives
    the sphere, radii, pivots, axis sense, controller state and, on a head, the tool."""
    from pige_sym.cli._probe import probe_setup
    from pige_sym.nc.probe_header import header_setup

    h = header_setup(text, args.program)
    if h.dialect != args.dialect:
        raise InputError(f"--dialect {args.dialect}: the program {args.program} is a {h.dialect} program")
    if not args.sphere:
        return _stated(_header_probe_setup(args, h), args, h)
    dialect = args.dialect if _controller_given(args) else None  # None: the header's controller state, unchecked here
    radii = {k: getattr(args, k) if getattr(args, k) is not None else stated  # the header's radii where none is given
             for k, stated in (("sphere_radius", h.sphere_radius_mm), ("stylus_radius", h.stylus_radius_mm))}
    filled = argparse.Namespace(**{**vars(args), **radii})
    return _stated(probe_setup(filled, args.machine, dialect=dialect, controller_required=False), args, h)


def _controller_given(args: argparse.Namespace) -> bool:
    return any(getattr(args, k) is not None for k in ("kinematics", "rtcp_off", "rtcp_on", "stylus_tool",
                                                       "stylus_length"))


def _header_probe_setup(args: argparse.Namespace, h: Any) -> Any:
    """The short form's set-up: the header's, with the sphere-probe options that were given (not their defaults)."""
    import numpy as np

    from pige_sym.cli._probe import probe_controller, probe_tool
    from pige_sym.cli._setup import axis_sense_option, finite_option
    from pige_sym.nc.probe_program import ProbeSetup

    radius, stylus = (finite_option(v, flag, positive=True) if v is not None else stated for v, flag, stated in
                      ((args.sphere_radius, "--sphere-radius", h.sphere_radius_mm),
                       (args.stylus_radius, "--stylus-radius", h.stylus_radius_mm)))
    tool = probe_tool(args.tool)
    sense = axis_sense_option(args, tuple(h.pivots_mm))
    return ProbeSetup(h.machine, h.sphere_mm, np.zeros(3), radius, stylus, clearance_mm=args.clearance,
                      overtravel_mm=args.overtravel, contacts=args.contacts, pivots_mm=h.pivots_mm,
                      axis_sense=h.axis_sense if sense is None else sense,
                      controller=probe_controller(args, args.dialect, required=False) if _controller_given(args)
                      else h.controller, tool_mm=None if tool is None else np.array(tool))


def _stated(setup: Any, args: argparse.Namespace, h: Any) -> Any:
    """The set-up with what the program's header states where no option says it (the read-back then checks
    that every option given agrees)."""
    import dataclasses

    tool = setup.tool_mm if setup.tool_mm is not None else h.tool_mm
    single = tool is not None and not args.pivot  # a head is probed about one pivot (the axis lines meet)
    return dataclasses.replace(setup, controller=setup.controller if _controller_given(args) else h.controller,
                               axis_sense=setup.axis_sense if args.axis_sense is not None else h.axis_sense,
                               pivots_mm=None if single else setup.pivots_mm if args.pivot else h.pivots_mm,
                               pivot_mm=next(iter(h.pivots_mm.values())) if single else setup.pivot_mm,
                               tool_mm=tool)


#: Decimals of the simulated length changes written [µm].
BALLBAR_DECIMALS = 4


def _run_ballbar(args: argparse.Namespace) -> int:
    from dataclasses import replace

    import numpy as np

    from pige_sym.cli._ballbar import ballbar_setup_of
    from pige_sym.kernels import load_kernels
    from pige_sym.measurements.ballbar import write_ballbar
    from pige_sym.model.effects import parse_effect
    from pige_sym.simulation.ballbar import simulate_ballbar_with_outliers

    kern = load_kernels(args.machine)
    effects = [parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []]
    finite_option(args.noise, "--noise", minimum=0.0)
    setup = ballbar_setup_of(args, kern.MACHINE_CODE)
    pige = pige_values(args.pige, kern.MACHINE_CODE, args.seed)
    inputs = [x for x in (args.pige,) if os.path.isfile(x)]
    out = check_output(args.out, force=args.force, inputs=inputs, what="--out")
    truth_path = check_output(out.with_name(out.stem + ".truth.json"), force=args.force, inputs=inputs,
                              what="truth sidecar")
    maps = _error_maps(args, kern)
    run, outlier_rows = simulate_ballbar_with_outliers(kern.MACHINE_CODE, setup, pige=pige, noise_um=args.noise,
                                                       seed=args.seed, zero=args.zero, effects=effects,
                                                       error_maps=maps)
    run.axis_sense = axis_sense_option(args, tuple(kern.ROTARY_AXES)) or {}
    # a ballbar reads to 0.1 um at best: written to 0.1 nm, the file shows no 17-digit noise of the simulation
    run = replace(run, dl_um=np.round(run.dl_um, BALLBAR_DECIMALS) + 0.0)
    write_ballbar(run, out)
    truth = {"machine": kern.MACHINE_CODE, "instrument": "ballbar", "setup": setup.label, "pige": pige,
             "effects": [e.to_dict() for e in effects], "outlier_rows": outlier_rows,
             "noise_um": args.noise, "seed": args.seed, "zero": args.zero,
             "written_resolution_um": 10.0**-BALLBAR_DECIMALS,
             "model": "exact |T - P| - L0; effects and error maps first order at the tool ball, projected on the bar",
             **({} if maps is None else {"error_motions": maps.to_dict()}),
             **({"axis_sense": run.axis_sense} if run.axis_sense else {})}
    atomic_write_text(truth_path, to_json(truth) + "\n")
    print(f"wrote {out} ({run.n_rows} rows, {setup.label} setup, bar {run.length_mm:g} mm, zero {args.zero}) "
          f"and {truth_path}")
    return 0


def _run(args: argparse.Namespace) -> int:
    from pige_sym.kernels import load_kernels

    if args.instrument == "sphere-probe":
        return _run_probe(args)
    if args.instrument == "ballbar":
        return _run_ballbar(args)
    from pige_sym.measurements.rtest_writer import write_measurement
    from pige_sym.model.effects import parse_effect
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.simulation.simulator import simulate

    finite_option(args.noise, "--noise", minimum=0.0)
    kern = load_kernels(args.machine)
    traj = make_trajectory(kern.MACHINE_CODE, args.trajectory, **trajectory_options(args))
    ball, pivots, tool = setup_geometry(args)
    for axis in pivots:
        if axis not in kern.ROTARY_AXES:
            axes = ", ".join(kern.ROTARY_AXES)
            raise InputError(f"--pivot {axis}: not a rotary axis of {kern.MACHINE_CODE} ({axes})")
    pige = pige_values(args.pige, kern.MACHINE_CODE, args.seed)
    effects = [parse_effect(e, tuple(kern.ROTARY_AXES)) for e in args.effect or []]
    maps = _error_maps(args, kern)
    inputs = [x for x in (args.trajectory, args.pige, args.error_maps) if x and os.path.isfile(x)]
    out = check_output(args.out, force=args.force, inputs=inputs, what="--out")
    truth_path = check_output(out.with_name(out.stem + ".truth.json"), force=args.force, inputs=inputs,
                              what="truth sidecar")
    result = simulate(
        kern.MACHINE_CODE, traj, pige=pige, ball_mm=ball, pivots_mm=pivots, tool_mm=tool, effects=effects,
        noise_um=args.noise, seed=args.seed, frame=args.frame,
        axis_sense=axis_sense_option(args, tuple(kern.ROTARY_AXES)), error_maps=maps,
    )
    csv = write_measurement(result.measurement, out)
    truth = atomic_write_text(truth_path, to_json(result.truth) + "\n")
    if args.json:
        print(to_json({"csv": str(csv), "truth_file": str(truth), "rows": result.measurement.n_rows,
                          "truth": result.truth}))
    else:
        print(f"wrote {csv} ({result.measurement.n_rows} rows) and {truth}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate an R-test file, a probe log or a ballbar setup on a machine with known errors",
        description=("Simulate a test on a machine with known errors (PIGEs, effects, sensor noise) and write its\n"
                     "truth sidecar: an R-test measurement file, the log a probing program writes on a virtual\n"
                     "probing machine (--instrument sphere-probe), or one ballbar setup (--instrument ballbar)."),
        epilog=(
            "examples:\n"
            "  pige simulate --machine \"wC'A'bXYZ(C1)t\" --trajectory cone-frustum --pige random \\\n"
            "      --seed 1 --out run.csv\n"
            "  pige simulate --machine \"wC'B'bXYZ(C1)t\" --trajectory figure-eight --pige EX0B=5,EA0C=-8 \\\n"
            "      --effect angular_error_C:harmonic=2,cos_urad=15 --noise 0.2 --out bc.csv\n"
            "  pige simulate --instrument sphere-probe --dialect linuxcnc --program probe.ngc --sphere 100,20,60 \\\n"
            "      --sphere-radius 12.7 --stylus-radius 1.5 --pivot 0,0,0 --pige random --out pige_probe.txt\n"
            "  pige simulate --instrument ballbar --setup tangential --axis C --tilt -45 --pige random --seed 4 \\\n"
            "      --out tangential_C45.csv"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_setup_arguments(p)
    p.add_argument("--pige", default="random", help="'random', NAME=VALUE,... [um|urad], or a JSON file")
    p.add_argument("--effect", action="append", metavar="NAME[:k=v,...]",
                   help="add an unmodelled effect (ballbar: first order at the tool ball, projected on the bar)")
    p.add_argument("--noise", type=float, default=0.25, help="sensor noise sigma [um] (default %(default)s)")
    p.add_argument("--error-maps", metavar="FILE", help="error maps of the rotary axes (CONVENTIONS §10): a JSON file "
                   "with an \"error_motions\" object, as pige identify --map --json writes it (every instrument)")
    p.add_argument("--seed", type=int, default=None, help="random seed")
    p.add_argument("--frame", choices=["machine", "table"], default="machine", help="frame of the deviations")
    p.add_argument("--out", required=True, help="output CSV (a .truth.json sidecar is written beside it)")
    p.add_argument("--force", action="store_true", help="replace an existing output CSV and its sidecar")
    p.add_argument("--json", action="store_true", help="print the files written and the truth as one JSON object")
    p.add_argument("--instrument", choices=INSTRUMENT_CHOICES, default="rtest",
                   help="rtest (a measurement file) or sphere-probe (the probe log of a probing program)")
    add_probe_program_arguments(p)
    add_ballbar_arguments(p)
    p.add_argument("--dialect", choices=PROBE_DIALECTS, default="linuxcnc", help="probing program and log dialect")
    p.add_argument("--program", help="probing program to run (default: the one pige program would write)")
    p.add_argument("--setup-offset", default="0,0,0", help="true minus nominal sphere centre [um] (default 0,0,0)")
    p.add_argument("--pretravel", type=float, default=0.0, help="constant probe pre-travel [um]")
    p.add_argument("--lobing", type=float, default=0.0, help="three-lobed pre-travel amplitude [um]")
    p.add_argument("--vertical-pretravel", type=float, default=0.0,
                   help="extra pre-travel of Z probing moves (along the stylus axis on a head) [um]")
    p.add_argument("--stylus-error", default="0,0,0", metavar="dx,dy,dz",
                   help="head machines: the true stylus centre minus --tool [um] (a bent stylus, a wrong tool length)")
    p.set_defaults(handler=_run)
