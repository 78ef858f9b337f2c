"""Shared by the LinuxCNC tests: skip without LinuxCNC, the smoke run, and round one: the probing runs of both
table machines in both kinematics, the two head machines' runs and the program's refusals (nine simulations at once,
once per session)."""

from __future__ import annotations

import pytest
from head_setup import HEADS, HeadRun, head_probing_run
from lcnc_harness import compile_component, make_sim, run_sim, unavailable
from loop_setup import MACHINES, MODES, READ_PINS, ProbeRun, probing_run, run_all
from safety_cases import CASES, safety_run
from true_table import COMPONENT_NAME, component_source

TWIN_TOL_MM = 1e-5  # the emitted model is first order in the PIGEs: second order here ~ 15 um x 75 urad ~ 1e-6 mm
RUNS = [(k, mode) for k in sorted(MACHINES) for mode in MODES]


@pytest.fixture(scope="session")
def lcnc() -> None:
    reason = unavailable()
    if reason:
        pytest.skip(reason)


@pytest.fixture(scope="session")
def smoke(lcnc: None, tmp_path_factory: pytest.TempPathFactory):
    """A short run: start, home, MDI moves with the true table's outputs read after each; skip if no start."""
    m = MACHINES["AC"]
    table = m.true_table()
    sim = make_sim(tmp_path_factory.mktemp("lcnc_smoke"), m.kind, table.hal_lines())
    compile_component(sim, component_source(m.code), COMPONENT_NAME)
    pins = ["ptt.tip-x", "ptt.tip-y", "ptt.tip-z", "ptt.probe"]
    lines = ["G0 X10 Y-5 Z40", "G0 A20 C30", "G0 A-35.5 C-123.25 X-7 Y12 Z33"]
    run = run_sim(sim, [{"op": "mdi", "lines": lines, "read": pins, "clock": "ptt.clock"},
                        {"op": "read", "pins": READ_PINS}], timeout_s=600)
    if "start_s" not in run.result:
        pytest.skip(f"the LinuxCNC simulation does not start here:\n{run.summary()}")
    return table, run


@pytest.fixture(scope="session")
def round_one(smoke, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Both table machines probed in both kinematics, the two head machines probed (:mod:`head_setup`), and the
    program's refusals (:mod:`safety_cases`): nine simulations at once."""
    jobs = {(k, mode): (lambda k=k, mode=mode: probing_run(MACHINES[k], tmp_path_factory.mktemp(f"lcnc_{k}_{mode}"),
                                                           mode))
            for k, mode in RUNS}
    jobs |= {("safety", case): (lambda case=case: safety_run(case, tmp_path_factory.mktemp("lcnc_safety")))
             for case in CASES}
    jobs |= {("head", k): (lambda k=k: head_probing_run(HEADS[k], tmp_path_factory.mktemp(f"lcnc_head_{k}")))
             for k in HEADS}
    return run_all(jobs)


@pytest.fixture(scope="session")
def probe_runs(round_one: dict) -> dict[tuple[str, str], ProbeRun]:
    return {key: round_one[key] for key in RUNS}


@pytest.fixture(scope="session")
def refused(round_one: dict) -> dict:
    return {case: round_one[("safety", case)] for case in CASES}


@pytest.fixture(scope="session")
def head_runs(round_one: dict) -> dict[str, HeadRun]:
    return {k: round_one[("head", k)] for k in HEADS}
