"""Shared by the LinuxCNC tests: skip without LinuxCNC, the smoke run, and the four probing runs of the two table
machines (both kinematics) that several files start from.

``make test-linuxcnc`` runs each test file in its own pytest-xdist worker, all at once (docs/testing.md): a file
makes its own simulations in module-scoped fixtures (several at once with :func:`loop_setup.run_all`), and what
more than one file needs (:func:`table_runs`) is made once per session by :func:`shared_runs.once`, whichever
worker asks first.  A run that LinuxCNC could not start skips its tests with the reason (:func:`need_started`).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from lcnc_harness import RunResult, compile_component, make_sim, run_sim, unavailable
from loop_setup import MACHINES, MODES, READ_PINS, ProbeRun, probing_run, run_all
from shared_runs import once, session_folder, set_folder
from true_table import COMPONENT_NAME, component_source

TWIN_TOL_MM = 1e-5  # the emitted model is first order in the PIGEs: second order here ~ 15 um x 75 urad ~ 1e-6 mm
RUNS = [(k, mode) for k in sorted(MACHINES) for mode in MODES]


@pytest.fixture(scope="session", autouse=True)
def _shared_folder(tmp_path_factory: pytest.TempPathFactory):
    """:func:`shared_runs.once` keeps its locks and results in the folder all workers of this session share."""
    set_folder(session_folder(tmp_path_factory.getbasetemp()) / "lcnc_shared")
    yield
    set_folder(None)


@pytest.fixture(scope="session")
def lcnc() -> None:
    reason = unavailable()
    if reason:
        pytest.skip(reason)


def need_started(run: RunResult) -> None:
    """Skip (with LinuxCNC's output) when the simulation did not start: LinuxCNC cannot run here."""
    if "start_s" not in run.result:
        pytest.skip(f"the LinuxCNC simulation does not start here:\n{run.summary()}")


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
    need_started(run)
    return table, run


def table_run(key: tuple[str, str], tmp_path_factory: pytest.TempPathFactory) -> ProbeRun:
    """The 13-pose probing run of table machine ``key[0]`` in kinematics ``key[1]``, made once per session, with
    LinuxCNC's log imported and identified beside it when the run went through."""
    k, mode = key

    def make() -> ProbeRun:
        run = probing_run(MACHINES[k], tmp_path_factory.mktemp(f"lcnc_{k}_{mode}"), mode)
        if run.run.result.get("ok"):
            run.identification  # noqa: B018 - import-probe and identify now, in the run's folder, once
        return run

    return once(f"table probing run {k} {mode}", make)


@pytest.fixture(scope="session")
def table_runs(lcnc: None, tmp_path_factory: pytest.TempPathFactory) -> Callable[..., dict[tuple[str, str], ProbeRun]]:
    """``table_runs(key, ...)``: those table runs (:func:`table_run`), side by side; skip if LinuxCNC did not start."""

    def get(*keys: tuple[str, str]) -> dict[tuple[str, str], ProbeRun]:
        runs = run_all({key: (lambda key=key: table_run(key, tmp_path_factory)) for key in keys})
        for run in runs.values():
            need_started(run.run)
        return runs

    return get


@pytest.fixture(scope="session")
def probe_runs(table_runs) -> dict[tuple[str, str], ProbeRun]:
    """All four table runs: both machines in both kinematics."""
    return table_runs(*RUNS)
