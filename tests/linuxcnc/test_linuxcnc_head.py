"""A head on real LinuxCNC 2.9 (issue 35, item 1): pige's probing program for a mixed machine (a swivel head B
over a rotary table C, ``wC'bXYZB(C1)t``) runs on LinuxCNC, and pige identifies the machine from its log.

- **The controller** is the shipped ``xyzbc-trt`` simulation, changed as for the table runs
  (:mod:`lcnc_harness`).  The program probes in identity kinematics (it switches with M429, back with M428),
  where the joints are the axes X Y Z B C, so the shipped trt kinematics never turn anything here: joint 3 is
  driven as the head's B axis.  The stylus is the shipped tool table's T2 (10 mm).
- **The true machine** is ``true_mixed.comp``, written in the test from CONVENTIONS (:mod:`true_mixed`): both
  axis lines with PIGEs, tilts included, the table commanded in the reverse sense (σ_C = −1), the probe tipping
  when the stylus-tip centre, turned by the head and taken into the table's coordinates, reaches the sphere.
- **The checks:** LinuxCNC ran the whole program (every ``G38.2`` logged, nothing else touched the sphere);
  every logged contact lies inside the trip sphere by less than one servo period of probing feed (so the
  program's inclined moves went where pige meant them to, on a head that turns the stylus); ``pige
  import-probe --program`` and ``pige identify`` recover every PIGE within 4 standard errors.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from head_setup import PIGE, POSES, PROBE_FEED_MM_MIN, SPHERE_MM, STEP_MM, STYLUS, HeadRun
from loop_setup import pige

pytestmark = pytest.mark.linuxcnc
def test_linuxcnc_runs_the_head_program_and_every_contact_is_where_pige_meant_it(head_run: HeadRun) -> None:
    machine, sim, program, run = head_run.machine, head_run.sim, head_run.program, head_run.run
    assert run.result["ok"], run.summary()
    log = np.loadtxt(sim.cfg / "pige_probe.txt", ndmin=2)
    lines = program.read_text().splitlines()
    confirming = [ln for ln in lines if ln.startswith("G38.3") and ln.endswith(f"F{PROBE_FEED_MM_MIN:g}")]
    assert len(log) == sum(ln.startswith("G38.2") for ln in lines) == 5 * (POSES + 1)
    readings = next(s for s in run.result["steps"] if s["op"] == "read")["readings"][0]
    assert readings["ptm.trips"] == len(log) + len(confirming)  # nothing else touched the sphere
    joints = np.column_stack([log[:, :3] + [0.0, 0.0, STYLUS[1]], log[:, [4, 5]]])  # identity: X Y Z B C
    assert np.ptp(log[:, 4]) > 20.0  # the head did turn the stylus
    gap = np.linalg.norm(machine.tip_in_table(joints) - SPHERE_MM, axis=1) - machine.trip_radius_mm
    assert gap.max() <= 1e-6 and gap.min() >= -STEP_MM - 1e-6, (gap.min(), gap.max())
    sim_s = next(s for s in run.result["steps"] if s["op"] == "program")["sim_s"]
    print(f"head: {len(log)} contacts, {sim_s:.1f} s simulated, gap {gap.min() * 1e3:.3f}..{gap.max() * 1e3:.3f} um, "
          f"attempts {run.attempts}")


def test_pige_identifies_the_head_machine_from_linuxcnc_s_log(head_run: HeadRun) -> None:
    sim, program, run = head_run.sim, head_run.program, head_run.run
    assert run.result["ok"], run.summary()
    out = sim.root / "probe.csv"
    pige("import-probe", str(sim.cfg / "pige_probe.txt"), "--format", "linuxcnc", "--program", str(program),
         "--out", str(out), cwd=sim.root)
    ident = json.loads(pige("identify", str(out), "--json", cwd=sim.root))
    assert set(ident["pige"]) == set(PIGE)
    z = {k: (ident["pige"][k] - PIGE[k]) / ident["std"][k] for k in PIGE}
    print("head: errors in std " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    assert all(abs(v) < 4.0 for v in z.values()), z
