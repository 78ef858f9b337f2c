"""The loop on real LinuxCNC 2.9 (issue 31, item 4): pige writes the probing program, LinuxCNC runs it on a
simulated trt machine whose table has known PIGEs, pige imports LinuxCNC's own probe log and identifies them.

How it runs (``make test-linuxcnc``; skipped with the reason when LinuxCNC, halcompile or namespaces are
missing, or when the simulation cannot start):

- **The controller** is Debian's ``linuxcnc-uspace`` 2.9.0~pre1 (commit f1270d6ed7), started by its own
  ``linuxcnc`` script from the shipped ``sim/axis/vismach/5axis/table-rotary-tilting/xyz[ab]c-trt.ini``,
  copied and changed as :func:`lcnc_harness.ini_changes` lists (a headless DISPLAY program, no GUI parts,
  one more HAL file).  Each run lives in its own IPC/PID/mount namespaces with a private ``/tmp``, so runs
  go in parallel and cannot disturb other LinuxCNC instances on the machine (:mod:`lcnc_harness` says why
  each piece is needed: root and ``RTAPI_UID``, ``RTAPI_FIFO_PATH``, the lock file, the module folder).
- **The operator** is :mod:`lcnc_driver` (the INI's DISPLAY): estop reset, machine on, home, run the
  program in AUTO, report the error channel, exit.
- **The true machine** is the realtime HAL component ``true_table.comp`` (compiled by ``halcompile`` for each
  run), last in the 1 ms servo thread: from ``joint.N.pos-fb`` it computes the stylus-tip centre in table
  coordinates with the exact rigid-body motion of CONVENTIONS §2–3 and the PIGEs chosen in
  :mod:`loop_setup`, and drives ``motion.probe-input``.  Motion latches the feedback position of the period
  in which the input rose, so every contact lies inside the trip sphere by less than one servo period of
  probing feed (1.67 µm at F100): checked on every logged contact with the NumPy twin of the component.
- **Today's probing program** works in identity kinematics (the shipped sims start in identity:
  ``sparm=identityfirst``) with the tool length cancelled (``G49``), so the true table here turns in
  CONVENTIONS' sense (σ = +1).  The stock trt kinematics turn the other way (σ = −1, CONVENTIONS §9); the
  stock-sense runs follow once ``pige program`` can write for them (issue 31 items 1–2).
"""

from __future__ import annotations

import numpy as np
import pytest
from lcnc_harness import compile_component, make_sim, run_sim, unavailable
from loop_setup import MACHINES, PROBE_FEED_MM_MIN, ProbeRun, import_and_identify, probing_run, run_all
from true_table import COMPONENT, COMPONENT_NAME

pytestmark = pytest.mark.linuxcnc
SERVO_PERIOD_S = 1e-3  # [EMCMOT]SERVO_PERIOD of the shipped sims
STEP_MM = PROBE_FEED_MM_MIN / 60.0 * SERVO_PERIOD_S


@pytest.fixture(scope="module")
def lcnc() -> None:
    reason = unavailable()
    if reason:
        pytest.skip(reason)


@pytest.fixture(scope="module")
def smoke(lcnc: None, tmp_path_factory: pytest.TempPathFactory):
    """A short run: start, home, MDI moves with the true table's outputs read after each; skip if no start."""
    m = MACHINES["AC"]
    table = m.true_table()
    sim = make_sim(tmp_path_factory.mktemp("lcnc_smoke"), m.kind, table.hal_lines())
    compile_component(sim, COMPONENT, COMPONENT_NAME)
    pins = ["ptt.tip-x", "ptt.tip-y", "ptt.tip-z", "ptt.probe"]
    lines = ["G0 X10 Y-5 Z40", "G0 A20 C30", "G0 A-35.5 C-123.25 X-7 Y12 Z33"]
    run = run_sim(sim, [{"op": "mdi", "lines": lines, "read": pins, "clock": "ptt.clock"}], timeout_s=600)
    if "start_s" not in run.result:
        pytest.skip(f"the LinuxCNC simulation does not start here:\n{run.summary()}")
    return table, run


def test_headless_sim_runs_mdi_and_the_true_table_matches_its_twin(smoke) -> None:
    table, run = smoke
    assert run.result["ok"], run.summary()
    step = run.result["steps"][0]
    joints = np.array([[10, -5, 40, 0, 0], [10, -5, 40, 20, 30], [-7, 12, 33, -35.5, -123.25]], dtype=float)
    got = np.array([[r["ptt.tip-x"], r["ptt.tip-y"], r["ptt.tip-z"]] for r in step["readings"]])
    # identity kinematics: the joints are the commanded axes; the C component and the NumPy twin agree
    assert np.abs(got - table.tip_in_table(joints)).max() < 1e-9
    assert np.allclose(run.result["final"]["joint"], joints[-1], atol=1e-9)
    assert not any(r["ptt.probe"] for r in step["readings"])
    assert step["sim_s"] > 0


@pytest.fixture(scope="module")
def probe_runs(smoke, tmp_path_factory: pytest.TempPathFactory) -> dict[str, ProbeRun]:
    """Both machines probed at once (identity kinematics, σ = +1)."""
    jobs = {k: (lambda m=m, k=k: probing_run(m, tmp_path_factory.mktemp(f"lcnc_{k}"), m.true_table()))
            for k, m in MACHINES.items()}
    return run_all(jobs)


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_linuxcnc_runs_the_probing_program_and_logs_exact_contacts(probe_runs, machine: str) -> None:
    pr = probe_runs[machine]
    assert pr.run.result["ok"], pr.run.summary()
    log = np.loadtxt(pr.log, ndmin=2)
    program = (pr.sim.cfg / "probe.ngc").read_text()
    assert len(log) == program.count("G38.2") == pr.run.result["steps"][1]["readings"][0]["ptt.trips"]
    outer = "ABC".index(pr.machine.outer)
    joints = log[:, [0, 1, 2, 3 + outer, 5]]  # identity kinematics, no offsets: the log holds the joints
    tip = pr.table.tip_in_table(joints)
    gap = np.linalg.norm(tip - pr.table.sphere_mm, axis=1) - pr.table.trip_radius_mm
    assert gap.max() <= 1e-6 and gap.min() >= -STEP_MM - 1e-6, (gap.min(), gap.max())
    sim_s = pr.program_step["sim_s"]
    print(f"{machine}: {len(log)} contacts, {sim_s:.1f} s simulated, {pr.program_step['wall_s']:.1f} s wall, "
          f"gap {gap.min() * 1e3:.3f}..{gap.max() * 1e3:.3f} um")
    assert sim_s < 180.0, f"a 13-pose probing run took {sim_s:.1f} s of simulated machine time"


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_pige_identifies_the_true_pige_from_linuxcnc_s_log(probe_runs, machine: str, tmp_path) -> None:
    pr = probe_runs[machine]
    assert pr.run.result["ok"], pr.run.summary()
    ident = import_and_identify(pr.machine, pr.log, pr.sim.root / "probe.csv")
    truth = pr.machine.pige
    assert set(ident["pige"]) == set(truth)
    z = {k: (ident["pige"][k] - truth[k]) / ident["std"][k] for k in truth}
    print(f"{machine}: errors in std " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    assert all(abs(v) < 4.0 for v in z.values()), z
