"""The probing program's own checks, on real LinuxCNC 2.9 (issue 31, item 2): a controller left in a state the
program was not written for stops it, with pige's message on LinuxCNC's error channel, before anything is
logged.

Three short runs of the AC machine's identity-kinematics program (:mod:`safety_cases`, three simulations at
once): the stylus not loaded (T1 in the spindle), a G54 offset
left over from earlier work (``G10 L2 P1 X5``), and a sphere 0.6 mm from where the program expects it (the
confirming first contacts accept 0.3 mm).
"""

from __future__ import annotations

import pytest
from loop_setup import run_all
from safety_cases import CASES, safety_run

from conftest import need_started

pytestmark = pytest.mark.linuxcnc


@pytest.fixture(scope="module")
def refused(lcnc: None, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Each case's run, three simulations at once."""
    runs = run_all({case: (lambda case=case: safety_run(case, tmp_path_factory.mktemp("lcnc_safety")))
                    for case in CASES})
    for _, run in runs.values():
        need_started(run)
    return runs


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_program_stops_with_pige_s_message_before_logging(refused, case: str) -> None:
    sim, run = refused[case]
    errors = [text for kind, text in run.result.get("messages", []) if kind == "error"]
    print(f"{case}: {errors}")
    assert run.result.get("start_s") is not None, run.summary()  # LinuxCNC ran: the program stopped itself
    assert not run.result["ok"] and errors, run.summary()
    assert any("PIGE" in e and CASES[case][2] in e for e in errors), errors
    log = sim.cfg / "pige_probe.txt"
    assert not log.exists() or not log.read_text().strip()  # nothing logged
