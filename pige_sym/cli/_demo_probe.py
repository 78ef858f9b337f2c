"""``pige demo --instrument sphere-probe``: the story with a touch probe and a calibration sphere.

Stages (every file lands in ``--out``):

1. the probing program for LinuxCNC (``probe.ngc``), read back and replayed against the sphere;
2. the virtual probing machine (random PIGEs, a 40 µm set-up offset of the sphere, 0.5 µm contact
   noise; on a head or mixed machine the stylus centre 150 mm below the head's pivot, :data:`HEAD_TOOL`) runs
   it and writes the log LinuxCNC would write (``pige_probe.txt``, truth beside it);
3. ``import-probe``: sphere centres, deviations, covariances (``probe.csv``);
4. identification with the reference-pose coupling, compared with the truth (error / std);
5. verdict against ±15 µm / ±30 µrad;
6. compensation of a small 5-axis part program (``part.ngc`` → ``part_comp.ngc``);
7. the HTML report of ``probe.csv`` against the same tolerances (``report/report.html``).

Exit status 1 when a true PIGE lies more than 4 standard errors from its estimate (the demo is also a check).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from pige_sym.cli._setup import show_progress
from pige_sym.files import atomic_write_text, to_json
from pige_sym.nc.probe_safety import ProbeController

SPHERE = (100.0, 20.0, 60.0)
RADII = (12.7, 1.5)
#: The demo's LinuxCNC: the shipped trt sims' kinematics switch (M429 identity, M428 TCP), stylus tool 99.
CONTROLLER = ProbeController(rtcp_off="M429", rtcp_on="M428", stylus_tool=99, stylus_length_mm=120.0)
#: On a head or mixed machine the virtual head carries the stylus centre 150 mm below its pivot (``--tool``).
HEAD_TOOL = (0.0, 0.0, -150.0)
PART = """(a small 5-axis finishing pass in machine coordinates, RTCP off)
G21 G90 G17 G40 G49 G80 G94
G0 Z150
G0 {a}0 {c}0
G0 X90 Y10 Z80
G1 X110 Y10 Z80 F800
G1 {a}-15 {c}30 X105 Y25 Z82
G1 {a}-30 {c}60 X95 Y35 Z85
G0 Z150
M2
"""


def _tool(kern: Any) -> tuple[float, float, float] | None:
    return HEAD_TOOL if kern.TOOL_ROTARY else None


def _stage(n: int, text: str) -> None:
    print(f"\n[{n}] {text}", flush=True)


def _program_and_log(args: argparse.Namespace, code: str, out: Path) -> tuple[Path, dict[str, float]]:
    import numpy as np

    from pige_sym.kernels import load_kernels
    from pige_sym.model.trajectories import make_trajectory
    from pige_sym.nc.probe_program import ProbeSetup, plan_probing
    from pige_sym.nc.probe_readback import verify_rendered_program
    from pige_sym.nc.probe_render import render_probe_program
    from pige_sym.simulation.probe_machine import ProbeMachine, run_probe_program
    from pige_sym.simulation.simulator import random_pige

    tool = _tool(load_kernels(code))
    setup = ProbeSetup(code, np.array(SPHERE), np.zeros(3), *RADII, controller=CONTROLLER,
                       tool_mm=None if tool is None else np.array(tool))
    traj = make_trajectory(code, args.trajectory)
    _stage(1, "probing program (LinuxCNC), read back against the sphere")
    plan = plan_probing(setup, traj.angles_deg, traj.description)
    text = render_probe_program(plan, "linuxcnc")
    check = verify_rendered_program(text, "linuxcnc", setup, plan.rotary_axes, out=str(out / "probe.ngc"))
    atomic_write_text(out / "probe.ngc", text)
    print(f"wrote {out / 'probe.ngc'}: {check.poses} poses, {sum(check.contacts)} contacts; rapid moves >= "
          f"{check.min_rapid_clearance_mm:.2f} mm from the sphere, rotary moves {check.min_rotary_clearance_mm:.1f} mm "
          "above it")
    _stage(2, "virtual probing machine (random PIGEs, sphere set 40 um off, 0.5 um contact noise)")
    pige = random_pige(code, args.seed)
    machine = ProbeMachine(setup, pige, setup_offset_um=(40.0, -25.0, 10.0), noise_um=0.5, seed=args.seed)
    log = out / "pige_probe.txt"
    atomic_write_text(log, run_probe_program(text, "linuxcnc", machine))
    atomic_write_text(out / "pige_probe.truth.json", to_json({"machine": code, "pige": pige}) + "\n")
    print(f"wrote {log} (nine numbers per contact, as LinuxCNC's PROBEOPEN writes them)")
    return log, pige


def run_probe_demo(args: argparse.Namespace, kern: Any, out: Path) -> int:
    """The probe story (module docstring); 0 when every true PIGE is within 4 standard errors."""
    from pige_sym import api
    from pige_sym.measurements.probe_import import ProbeImport, import_probe_log

    code = kern.MACHINE_CODE
    log, pige = _program_and_log(args, code, out)
    _stage(3, "import-probe: sphere centres and deviations")
    m = import_probe_log(log, "linuxcnc", ProbeImport(code, (0.0, 0.0, 0.0), *RADII, tool_mm=_tool(kern)))
    csv = api.write(m, out / "probe.csv", force=True)
    sigma = float(m.metadata["contact_sigma_um"])
    r_eff, _, how = m.metadata["r_eff_mm"].partition(" ")
    atomic_write_text(out / "probe.truth.json", to_json({"machine": code, "pige": pige}) + "\n")  # for the report
    print(f"wrote {csv}: R_eff {float(r_eff):.4f} mm {how}, contact sigma {sigma:.3f} um")
    _stage(4, "identification with the reference-pose coupling, against the truth")
    result = api.identify(csv)
    worst = 0.0
    print(f"{'parameter':10s} {'estimate':>10s} {'std':>7s} {'truth':>9s} {'error/std':>9s}")
    for i, name in enumerate(result.parameters):
        z = (result.values[i] - pige[name]) / result.std[i]
        worst = max(worst, abs(z)) if math.isfinite(z) else math.inf
        print(f"{name:10s} {result.values[i]:10.3f} {result.std[i]:7.3f} {pige[name]:9.3f} {z:9.2f}  "
              f"{kern.UNITS[name]}")
    _stage(5, "verdict")
    tolerances = {"format": "pige-tolerances 1", "description": "the probe demo's limits",
                  "defaults": {"um": 15, "urad": 30}}
    tol = atomic_write_text(out / "tolerances.json", to_json(tolerances) + "\n")  # the check names the file
    print(api.check(result, tol).format())
    _stage(6, "compensation of a part program")
    part = out / "part.ngc"
    atomic_write_text(part, PART.format(a=kern.ROTARY_AXES[0], c=kern.ROTARY_AXES[1]))
    comp = api.compensate(part, result, machine=code)
    atomic_write_text(out / "part_comp.ngc", comp.text, newline="")
    print(f"wrote {out / 'part_comp.ngc'}: {comp.report.compensated} of {comp.report.moves} moves changed, "
          f"largest change {comp.report.max_change_mm:.4f} mm; read back and verified")
    _stage(7, "report")
    from pige_sym.report import gather_report, write_report

    data = gather_report([csv], method="gauss-newton", tolerances=tol, progress=show_progress(args.quiet))
    print(f"report: {write_report(data, out / 'report', force=args.force)}")
    ok = worst <= 4.0
    print(f"\nevery true PIGE within {worst:.2f} standard errors of its estimate: {'yes' if ok else 'NO'}")
    return 0 if ok else 1
