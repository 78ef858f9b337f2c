"""``pige demo``: the whole story on the default AC tilting table, end to end.

Stages (each prints what it did; every file lands in ``--out``):

1. kernels of the machine (generated on demand when absent);
2. the R-test program: a BK3-style cone frustum (``--trajectory``: or figure-eight, steps)
   as a Siemens 840D program in machine coordinates (``rtest_<trajectory>.mpf``, one 7 s
   G4 dwell per pose: about 1 s to settle, then
   the 5 s averaging window);
3. a virtual R-test device (``pige rtest-sim``, a separate process) with random
   PIGEs and one *hidden* effect runs that program and streams the device protocol
   on a pseudo-terminal (accelerated device time);
4. acquisition over that serial port (``rtest.csv``, raw byte log, summary);
5. identification by Gauss–Newton and by the double-differential scheme;
6. diagnosis: the residual analysis must name the hidden effect;
7. compensation of the test program (``rtest_<trajectory>_comp.mpf``) with the PIGEs of the
   diagnosis' final fit, and the corrected kinematic chain;
8. the HTML report (``report/report.html``).

The device's truth (PIGEs, effect, faults) is copied beside the measurement as
``rtest.truth.json`` so that the report compares identified and true values, and
the demo prints whether the diagnosis found the hidden effect.  Exit status 1 when
it did not (the demo is also a check).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from pige_sym.cli._setup import show_progress
from pige_sym.constants import DEFAULT_BALL_MM, DEFAULT_MACHINE
from pige_sym.files import atomic_write_text, make_folder, to_json

BALL = DEFAULT_BALL_MM

DEFAULT_EFFECT = "angular_error_C:harmonic=2,cos_urad=12,sin_urad=-8"
#: The acceptance limits the demo judges against: ``examples/tolerances.json`` of the checkout, byte for byte
#: (``tests/test_demo.py`` checks it), written into ``--out`` so that an installed package needs no checkout.
DEMO_TOLERANCES = """{
 "format": "pige-tolerances 1",
 "machine": "wC'A'bXYZ(C1)t",
 "description": "example acceptance limits of an AC tilting table: 10 um / 20 urad per PIGE, tighter on the C axis \
offsets, and the 2nd-order angular error of C",
 "defaults": {"um": 10, "urad": 20},
 "limits": {"EX0C": 8, "EY0C": 8, "angular_error_C.cos_urad": 25, "angular_error_C.sin_urad": 25}
}
"""


def _stage(n: int, text: str) -> None:
    print(f"\n[{n}] {text}", flush=True)


def _truth_sidecar(device_truth: dict[str, Any], machine: str, pige: dict[str, float], effect: str,
                   ball: list[float]) -> dict[str, Any]:
    """The device truth in the simulator's sidecar layout (what ``pige report`` reads), device fields kept."""
    from pige_sym.kernels import load_kernels

    kern = load_kernels(machine)
    return {
        **device_truth,
        "machine": kern.MACHINE_CODE,
        "pige": {p: float(pige.get(p, 0.0)) for p in kern.PARAMETERS},
        "units": dict(kern.UNITS),
        "ball_mm": ball,
        "hidden_effect": effect,
    }


def _prepare(args: argparse.Namespace) -> Path:
    """The output folder: refused when an earlier demo is in it, unless ``--force``."""
    from pige_sym.errors import InputError

    out = Path(args.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())) and not args.force:
        raise InputError(f"--out {out} exists and is not an empty folder: pass --force to replace the demo's "
                         "files in it, or choose another --out")
    make_folder(out, what="--out")
    return out


def _write_program(args: argparse.Namespace, kern: Any, out: Path) -> tuple[Any, Path]:
    """Stage 2: the R-test program as an 840D file, read back as the test schedule."""
    from pige_sym.nc.program import make_rtest_program
    from pige_sym.nc.rtest_program import load_test_program

    code = kern.MACHINE_CODE
    incl = "X" if kern.ROTARY_AXES[0] == "A" else "Y"
    options: dict[str, Any] = {"incl_axis": incl} if args.trajectory == "cone-frustum" else {}
    program = load_test_program(code, args.trajectory, ball_mm=BALL, **options)
    nc_path = out / f"rtest_{args.trajectory.split('-')[0]}.mpf"
    nc_path.write_text(make_rtest_program(program.angles_deg, program.linear_mm(), tuple(kern.ROTARY_AXES),
                                          dwell_s=7.0, title=f"R-test {program.description}, {code}"), encoding="utf-8")
    program = load_test_program(code, str(nc_path), ball_mm=BALL)
    print(f"wrote {nc_path}: {program.n_poses} poses, {program.duration_s / 60:.1f} min of machine time")
    return program, nc_path


def _measure(args: argparse.Namespace, code: str, program: Any, nc_path: Path, out: Path,
             pige: dict[str, float]) -> Path | None:
    """Stages 3-4: the virtual device on a pseudo-terminal and the acquisition; the CSV, or None if incomplete."""
    from pige_sym.acquisition.engine import acquire
    from pige_sym.acquisition.virtual_run import start_virtual_device

    progress = show_progress(args.quiet)
    device_truth = out / "device.truth.json"
    print(f"hidden in the machine: random PIGEs (seed {args.seed}) and an effect the demo does not tell the "
          f"diagnosis about; device time runs {args.time_scale:g}x faster than real time")
    device_log = (out / "device.log").open("w", encoding="utf-8")
    with device_log, start_virtual_device(code, str(nc_path), ball_mm=BALL, pige=pige, effects=[args.effect],
                                          seed=args.seed, truth=device_truth, time_scale=args.time_scale,
                                          stderr=device_log, extra_args=["--force"] if args.force else []) as device:
        print(f"device streaming on {device.url} (its messages: {out / 'device.log'})")
        _stage(4, f"acquisition over the serial port {device.url}")
        csv = out / "rtest.csv"
        summary = acquire(device.url, program, csv, progress=progress, force=args.force)
        print(summary.format())
        device.wait(60)
    if not summary.completed:
        print("the acquisition did not complete: stopping the demo")
        return None
    truth = _truth_sidecar(json.loads(device_truth.read_text()), code, pige, args.effect, list(BALL))
    atomic_write_text(out / "rtest.truth.json", to_json(truth) + "\n")
    return csv


def _analyse(args: argparse.Namespace, kern: Any, csv: Path, out: Path, pige: dict[str, float]) -> tuple[Path, bool]:
    """Stages 5-6: both identifications and the diagnosis; the diagnosis JSON and whether it named the effect."""
    from pige_sym.diagnosis.diagnose import diagnose
    from pige_sym.identification.least_squares import identify
    from pige_sym.identification.result import format_result
    from pige_sym.measurements.rtest import read_measurement

    m = read_measurement(csv)
    _stage(5, "identification")
    results = {}
    for method in ("gauss-newton", "double-differential"):
        results[method] = res = identify(m, method=method)
        atomic_write_text(out / f"identify_{method}.json", to_json(res.to_dict()) + "\n")
        print(format_result(res) + "\n")
    _stage(6, "diagnosis: what does the PIGE model miss?")
    diag = diagnose(m, progress=show_progress(args.quiet))
    diag_json = atomic_write_text(out / "diagnosis.json", to_json(diag.to_dict()) + "\n")
    print(diag.verdict())
    effect_id = args.effect.partition(":")[0]
    found = [f.effect for f in diag.findings]
    hit = bool(found) and found[0] == effect_id
    print(f"hidden effect: {effect_id}; diagnosis found: {', '.join(found) or 'nothing'} "
          f"-> {'FOUND' if hit else 'NOT FOUND'}")
    gn = results["gauss-newton"]
    print("\nPIGEs: true, Gauss-Newton (PIGEs only), diagnosis (PIGEs + accepted effects)")
    print(f"{'parameter':10s} {'true':>9s} {'GN':>9s} {'±std':>7s} {'diagnosis':>10s} {'±std':>7s}  unit")
    for name in kern.LOCATION_PARAMETERS:
        i, j = gn.parameters.index(name), diag.final.parameters.index(name)
        print(f"{name:10s} {pige[name]:9.3f} {_num(gn.values[i]):>9s} {_num(gn.std[i]):>7s} "
              f"{_num(diag.final.values[j]):>10s} {_num(diag.final.std[j]):>7s}  {kern.UNITS[name]}")
    return diag_json, hit


def _compensate_and_report(args: argparse.Namespace, code: str, csv: Path, nc_path: Path, diag_json: Path,
                           out: Path) -> None:
    """Stages 7-8: the compensated test program, the controller corrections and the report."""
    from pige_sym.compensation.parameters import load_parameters
    from pige_sym.compensation.stage import ProgramRequest, compensate
    from pige_sym.report import gather_report, write_report

    _stage(7, "compensation of the test program")
    params = load_parameters(diag_json, code)
    comp_path = nc_path.with_name(f"{nc_path.stem}_comp.mpf")
    result = compensate(params, program=ProgramRequest(nc_path.read_text(encoding="utf-8"), str(nc_path)),
                        controller="table")
    assert result.program is not None and result.controller is not None
    atomic_write_text(comp_path, result.program.text, newline="")
    print(f"wrote {comp_path} (parameters from {params.source})")
    print(result.controller.text)
    _stage(8, "report: in tolerance?")
    tolerances = out / "tolerances.json"
    generic = to_json({"format": "pige-tolerances 1", "description": "10 um / 20 urad per PIGE",
                       "defaults": {"um": 10, "urad": 20}}) + "\n"
    atomic_write_text(tolerances, DEMO_TOLERANCES if code == "wC'A'bXYZ(C1)t" else generic)
    data = gather_report([csv], program=nc_path, method="diagnosis", progress=show_progress(args.quiet),
                         tolerances=tolerances)
    check = data.measurements[0].check
    if check is not None:
        print(f"in tolerance? {check.verdict} (limits of {tolerances.name}, ISO 14253-1 guard band)")
    row = data.measurements[0].compensation[-1]  # the NC program, run on the true machine (PIGEs + hidden effect)
    print(f"test program run on the true machine, tool-point error RMSE: {row.rmse_before_um:.3f} um as programmed, "
          f"{row.rmse_after_um:.3f} um compensated ({row.reduction:.1%} less)")
    report = write_report(data, out / "report", force=args.force)
    print(f"\nreport: {report.resolve()}")


def _run(args: argparse.Namespace) -> int:
    from pige_sym.kernels import load_kernels
    from pige_sym.simulation.simulator import random_pige

    started = time.perf_counter()
    out = _prepare(args)
    kern = load_kernels(args.machine)
    if args.instrument == "sphere-probe":
        from pige_sym.cli._demo_probe import run_probe_demo

        status = run_probe_demo(args, kern, out)
        print(f"demo finished in {time.perf_counter() - started:.1f} s; everything is in {out.resolve()}")
        return status
    _stage(1, "kernels")
    code = kern.MACHINE_CODE
    print(f"machine {code}: rotary axes {', '.join(kern.ROTARY_AXES)}; "
          f"parameters {', '.join(f'{p} [{kern.UNITS[p]}]' for p in kern.LOCATION_PARAMETERS)}")
    _stage(2, "R-test program")
    program, nc_path = _write_program(args, kern, out)
    _stage(3, "virtual R-test device (separate process, pseudo-terminal)")
    pige = random_pige(code, args.seed)
    csv = _measure(args, code, program, nc_path, out, pige)
    if csv is None:
        return 1
    diag_json, hit = _analyse(args, kern, csv, out, pige)
    _compensate_and_report(args, code, csv, nc_path, diag_json, out)
    print(f"demo finished in {time.perf_counter() - started:.1f} s; everything is in {out.resolve()}")
    return 0 if hit else 1


def _num(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.3f}"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="the whole story on a virtual machine, with an R-test or a touch probe (--instrument sphere-probe)",
        description=("Virtual R-test device with a hidden effect -> acquisition over a pseudo-terminal -> "
                     "identification -> diagnosis -> compensated program -> HTML report."),
        epilog=("examples:\n  pige demo\n  pige demo --out /tmp/demo --effect thermal_drift --seed 3\n"
                "  pige demo --trajectory steps --effect backlash_C:b_urad=30\n"
                "  pige demo --instrument sphere-probe --out /tmp/probe-demo"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--machine", default=DEFAULT_MACHINE, help="machine structure code (default %(default)s)")
    p.add_argument("--out", default="demo-out", help="output directory (default %(default)s)")
    p.add_argument("--effect", default=DEFAULT_EFFECT,
                   help="the effect hidden in the virtual machine, NAME[:k=v,...] (default %(default)s)")
    p.add_argument("--trajectory", choices=["cone-frustum", "figure-eight", "steps"], default="cone-frustum",
                   help="test trajectory (default %(default)s; steps reveals backlash)")
    p.add_argument("--seed", type=int, default=7, help="seed of the PIGEs, noise and device (default %(default)s)")
    p.add_argument("--time-scale", type=float, default=100.0,
                   help="device seconds per wall second (default %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--force", action="store_true", help="replace the files of an earlier demo in --out")
    p.add_argument("--instrument", choices=["rtest", "sphere-probe"], default="rtest",
                   help="the instrument of the story (sphere-probe: touch probe and calibration sphere)")
    p.set_defaults(handler=_run)
