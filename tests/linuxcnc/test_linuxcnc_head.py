"""Heads on real LinuxCNC 2.9 (issue 35, item 1): pige's probing programs for a table C + head B
(``wC'bXYZB(C1)t``, on the shipped ``xyzbc-trt`` simulation) and a fork head C + A (``wbXYZCA(C1)t``, on
``xyzac-trt``) run on LinuxCNC, and pige identifies each machine from LinuxCNC's log (:mod:`head_setup`).

- **The controller** is the shipped simulation, changed as for the table runs (:mod:`lcnc_harness`).  The
  program probes in identity kinematics (it switches with M429, back with M428), where the joints are the
  axes, so the shipped trt kinematics never turn anything here: joints 3 and 4 are driven as the head's axes.
- **The true machine** is ``true_head.comp``, written in the test from CONVENTIONS (:mod:`true_head`): the
  axis lines with PIGEs, tilts included, one axis commanded in the reverse sense (σ = −1), the probe tripping
  when the stylus-tip centre, turned by the head and taken into the table's coordinates, reaches the sphere.
- **The checks:** LinuxCNC ran the whole program (every ``G38.2`` logged, nothing else touched the sphere);
  every logged contact lies inside the trip sphere by less than one servo period of probing feed (so the
  program's inclined moves went where pige meant them to, on a head that turns the stylus); ``pige
  import-probe --program`` and ``pige identify`` recover every PIGE within 4 standard errors.  With the head's
  sense reversed in the true machine the mixed machine's run stopped at a ``G38.2`` without contact: the
  checks can fail.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from head_setup import HEADS, POSES, PROBE_FEED_MM_MIN, SPHERE_MM, STEP_MM, HeadRun, head_probing_run
from loop_setup import pige, run_all

from conftest import need_started

pytestmark = pytest.mark.linuxcnc


@pytest.fixture(scope="module")
def head_runs(lcnc: None, tmp_path_factory: pytest.TempPathFactory) -> dict[str, HeadRun]:
    """Both head machines' probing runs, two simulations at once."""
    runs = run_all({k: (lambda k=k: head_probing_run(HEADS[k], tmp_path_factory.mktemp(f"lcnc_head_{k}")))
                    for k in HEADS})
    for run in runs.values():
        need_started(run.run)
    return runs

@pytest.mark.parametrize("key", sorted(HEADS))
def test_linuxcnc_runs_the_head_program_and_every_contact_is_where_pige_meant_it(head_runs, key) -> None:
    hr: HeadRun = head_runs[key]
    machine, sim, program, run = hr.machine, hr.sim, hr.program, hr.run
    assert run.result["ok"], run.summary()
    log = np.loadtxt(sim.cfg / "pige_probe.txt", ndmin=2)
    lines = program.read_text().splitlines()
    confirming = [ln for ln in lines if ln.startswith("G38.3") and ln.endswith(f"F{PROBE_FEED_MM_MIN:g}")]
    assert len(log) == sum(ln.startswith("G38.2") for ln in lines) == 5 * (POSES + 1)
    readings = next(s for s in run.result["steps"] if s["op"] == "read")["readings"][0]
    assert readings["pth.trips"] == len(log) + len(confirming)  # nothing else touched the sphere
    columns = [3 + "ABC".index(axis) for axis in hr.head.roles]  # identity: the joints are X Y Z and the axes
    joints = np.column_stack([log[:, :3] + [0.0, 0.0, hr.head.stylus[1]], log[:, columns]])
    assert np.ptp(joints[:, 3]) > 20.0  # the head did turn the stylus
    gap = np.linalg.norm(machine.tip_in_table(joints) - SPHERE_MM, axis=1) - machine.trip_radius_mm
    assert gap.max() <= 1e-6 and gap.min() >= -STEP_MM - 1e-6, (gap.min(), gap.max())
    sim_s = next(s for s in run.result["steps"] if s["op"] == "program")["sim_s"]
    print(f"{key} head: {len(log)} contacts, {sim_s:.1f} s simulated, gap {gap.min() * 1e3:.3f}..{gap.max() * 1e3:.3f}"
          f" um, attempts {run.attempts}")


@pytest.mark.parametrize("key", sorted(HEADS))
def test_pige_identifies_the_head_machine_from_linuxcnc_s_log(head_runs, key) -> None:
    hr: HeadRun = head_runs[key]
    assert hr.run.result["ok"], hr.run.summary()
    out = hr.sim.root / "probe.csv"
    pige("import-probe", str(hr.sim.cfg / "pige_probe.txt"), "--format", "linuxcnc", "--program", str(hr.program),
         "--out", str(out), cwd=hr.sim.root)
    ident = json.loads(pige("identify", str(out), "--json", cwd=hr.sim.root))
    truth = hr.head.pige
    assert set(ident["pige"]) == set(truth)
    z = {k: (ident["pige"][k] - truth[k]) / ident["std"][k] for k in truth}
    print(f"{key} head: errors in std " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    assert all(abs(v) < 4.0 for v in z.values()), z
