"""The loop on real LinuxCNC 2.9 (issue 31, item 4): pige writes the probing program, LinuxCNC runs it on its
shipped trt simulation whose table has known PIGEs, pige imports LinuxCNC's own probe log and identifies them.

How it runs (``make test-linuxcnc``; skipped with the reason when LinuxCNC, halcompile or namespaces are
missing, or when the simulation cannot start):

- **The controller** is Debian's ``linuxcnc-uspace`` 2.9.0~pre1 (commit f1270d6ed7), started by its own
  ``linuxcnc`` script from the shipped ``sim/axis/vismach/5axis/table-rotary-tilting/xyz[ab]c-trt.ini``,
  copied and changed as :func:`lcnc_harness.ini_changes` lists (a headless DISPLAY program, no GUI parts,
  one more HAL file, a longer motion command timeout, faster rapids).  Its kinematics (the stock
  ``xyz[ab]c-trt-kins`` with the shipped pins, switchable: M429 identity, M428 TCP) and tool table are the
  shipped ones.  Each run lives in its own IPC/PID/mount namespaces with a private ``/tmp``, so runs go in
  parallel and cannot disturb other LinuxCNC instances on the machine (:mod:`lcnc_harness` says why each
  piece is needed: root and ``RTAPI_UID``, ``RTAPI_FIFO_PATH``, the lock file, the module folder).
- **The operator** is :mod:`lcnc_driver` (the INI's DISPLAY): estop reset, machine on, home, MDI (``M428``
  for a TCP run, ``T9 M6`` or ``T2 M6`` to load the stylus), the program in AUTO, the error channel, exit.
- **The true machine** is the realtime HAL component ``true_table.comp`` (compiled by ``halcompile`` for each
  run), last in the 1 ms servo thread: from ``joint.N.pos-fb`` it computes the stylus-tip centre in table
  coordinates with the kinematics pige emits (``render_model_c``: the nominal stock lines, σ = −1 as the stock
  kinematics turn the table, the PIGEs chosen in :mod:`loop_setup`, tilts included) and drives
  ``motion.probe-input``; an exact rigid-body twin written in the test (CONVENTIONS §2–3) runs beside it and
  the largest distance between the two over the run is checked.  Motion latches the feedback position of the
  period in which the input rose, so every contact lies inside the trip sphere by less than one servo period
  of probing feed (0.83 µm at F50): checked on every logged contact with the NumPy twin (in TCP mode through
  the stock inverse kinematics transcribed in :mod:`stock_trt`).
- **The runs:** both machines, in identity kinematics (the program switches with M429 and back with M428)
  and in the stock TCP kinematics (``--kinematics tcp``), four simulations at once (:func:`conftest.table_runs`:
  made once per session, the check-up and the corrections start from the identity runs).
"""

from __future__ import annotations

import numpy as np
import pytest
from loop_setup import PROBE_FEED_MM_MIN, ProbeRun
from stock_trt import stock_pins, trt_inverse

from conftest import RUNS, TWIN_TOL_MM

pytestmark = pytest.mark.linuxcnc
SERVO_PERIOD_S = 1e-3  # [EMCMOT]SERVO_PERIOD of the shipped sims
STEP_MM = PROBE_FEED_MM_MIN / 60.0 * SERVO_PERIOD_S


def test_headless_sim_runs_mdi_and_the_true_table_matches_its_twin(smoke) -> None:
    table, run = smoke
    assert run.result["ok"], run.summary()
    step = run.result["steps"][0]
    joints = np.array([[10, -5, 40, 0, 0], [10, -5, 40, 20, 30], [-7, 12, 33, -35.5, -123.25]], dtype=float)
    got = np.array([[r["ptt.tip-x"], r["ptt.tip-y"], r["ptt.tip-z"]] for r in step["readings"]])
    # identity kinematics: the joints are the commanded axes; pige's model in C and the NumPy twin agree
    assert np.abs(got - table.tip_in_table(joints)).max() < TWIN_TOL_MM
    assert np.allclose(run.result["final"]["joint"], joints[-1], atol=1e-9)
    assert not any(r["ptt.probe"] for r in step["readings"])
    final = run.result["steps"][1]["readings"][0]
    assert final["ptt.model-failures"] == 0 and 0 <= final["ptt.twin-diff"] < TWIN_TOL_MM
    assert step["sim_s"] > 0


def contact_joints(pr: ProbeRun, log: np.ndarray) -> np.ndarray:
    """The joints at each logged contact (n, 5): identity kinematics log the joints less the tool length; TCP
    kinematics log work coordinates, turned into joints by the stock inverse (:mod:`stock_trt`)."""
    angles = log[:, [3 + "ABC".index(pr.machine.outer), 5]]
    length = pr.machine.stylus[1]
    if pr.kinematics == "identity":
        return np.column_stack([log[:, :3] + [0.0, 0.0, length], angles])
    pins = stock_pins(pr.machine.kind) | {"tool-offset": length}
    world = log[:, :3] + [0.0, 0.0, length]
    return np.column_stack([trt_inverse(pr.machine.kind, world, angles, pins), angles])


@pytest.mark.parametrize("key", RUNS, ids=[f"{k}-{mode}" for k, mode in RUNS])
def test_linuxcnc_runs_the_probing_program_and_logs_exact_contacts(probe_runs, key) -> None:
    pr = probe_runs[key]
    assert pr.run.result["ok"], pr.run.summary()
    log = np.loadtxt(pr.log, ndmin=2)
    program = pr.program.read_text().splitlines()
    confirming = [ln for ln in program if ln.startswith("G38.3") and ln.endswith(f"F{PROBE_FEED_MM_MIN:g}")]
    assert len(log) == sum(ln.startswith("G38.2") for ln in program)
    assert pr.readings["ptt.trips"] == len(log) + len(confirming)  # nothing else touched the sphere
    assert pr.readings["ptt.model-failures"] == 0 and pr.readings["ptt.twin-diff"] < TWIN_TOL_MM
    tip = pr.table.tip_in_table(contact_joints(pr, log))
    gap = np.linalg.norm(tip - pr.table.sphere_mm, axis=1) - pr.table.trip_radius_mm
    assert gap.max() <= 1e-6 and gap.min() >= -STEP_MM - 1e-6, (gap.min(), gap.max())
    sim_s = pr.step("program")["sim_s"]
    print(f"{key}: {len(log)} contacts, {sim_s:.1f} s simulated, {pr.step('program')['wall_s']:.1f} s wall, "
          f"gap {gap.min() * 1e3:.3f}..{gap.max() * 1e3:.3f} um, twin {pr.readings['ptt.twin-diff']:.1e} mm, "
          f"attempts {pr.run.attempts}")
    assert sim_s < 180.0, f"a 13-pose probing run took {sim_s:.1f} s of simulated machine time"


@pytest.mark.parametrize("key", RUNS, ids=[f"{k}-{mode}" for k, mode in RUNS])
def test_pige_identifies_the_true_pige_from_linuxcnc_s_log(probe_runs, key) -> None:
    pr = probe_runs[key]
    assert pr.run.result["ok"], pr.run.summary()
    ident = pr.identification
    truth = pr.machine.pige
    assert set(ident["pige"]) == set(truth)
    z = {k: (ident["pige"][k] - truth[k]) / ident["std"][k] for k in truth}
    print(f"{key}: errors in std " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    assert all(abs(v) < 4.0 for v in z.values()), z
