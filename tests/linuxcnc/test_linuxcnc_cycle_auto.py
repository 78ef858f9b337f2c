"""Aborts of the cycle called from a program running in AUTO mode (issue 48: "an abort mid-cycle leaves every value
and file as it was", and the kinematics mode as found), on one simulation.

One copy of the shipped ``xyzac-trt`` (stock kinematics, the hidden true machine, the cycle installed as
:mod:`cycle_setup` does, 6 poses).  The operator's program (:data:`PROGRAM`: a CAM-style header, the stylus loaded
and its length taken, a move clear above the sphere, ``M451 P0``, a retract, ``M2``) is run in AUTO and cut short:

- **esc**: the GUI's Esc (task abort through the command channel) while probing, after the second logged contact;
- **estop**: the E-stop while probing, then E-stop reset and machine on;
- **miss**: a probing move that does not trip (the true machine's probe switched off while probing: LinuxCNC's
  "G38.2 move finished without making contact");
- **kill**: pige's analysis process killed (SIGKILL, by its id) while it identifies.

Around each case the configuration's files, the pins (the stock kinematics' values and ``motion.switchkins-type``)
and the cycle's record (proposal, journal, history) are read before and after (3 s after the abort is handled, task
still in AUTO, before any other command); then the operator's next two MDI lines must run, and a program of theirs
run in AUTO.  The run folder's ``abort.log`` (the command-channel helper of ``o<pige_cycle_abort>``) says which path
put the mode back.  Right after the Esc case the operator's own job (``M428``, a dwell) is started and aborted about
4 s after the cycle's abort: its TCP kinematics must stay (the handler puts back the cycle's mode only).
"""

from __future__ import annotations

import re
from typing import Any

import pytest
from cycle_setup import CycleSim, cycle_sim, files_step, pins_step, run_cycle
from lcnc_harness import RunResult

pytestmark = pytest.mark.linuxcnc
#: the probe's trips until the second logged contact (test_linuxcnc_cycle.LOGGED)
LOGGED = 5
SETTLE = {"op": "sleep", "seconds": 3, "allow_error": True}
CASES = ["esc", "estop", "miss", "kill"]
#: the operator's program around the cycle (``{tool}``: the stylus)
PROGRAM = """%
(PROGRAM: SPHERE CHECK BEFORE THE SHIFT)
(POST: HAND-WRITTEN, LINUXCNC 5-AXIS)
G17 G21 G40 G49 G54 G80 G90 G94
T{tool} M6 (THE STYLUS)
G43 H{tool}
G0 Z60
(KINEMATICS CHECK, CHANGES NOTHING)
M451 P0
G0 Z60
G49
M2
%
"""
AFTER = "(the operator's next program)\nG0 Z63\nG0 Z64\nM2\n"
#: the operator's own job in TCP kinematics, started within seconds of the cycle's abort and aborted itself
TCP_JOB = "(the operator's 5-axis job, TCP kinematics)\nM428\nG4 P30\nM429\nM2\n"


def record_step(cs: CycleSim) -> dict[str, Any]:
    """The cycle's record: proposal, journal, history (its SHA-256 per file)."""
    return {"op": "files", "root": str(cs.sim.cfg / "pige_cycle"), "exclude": ["run/", "runs/"]}


def interruption(cs: CycleSim, label: str) -> list[dict[str, Any]]:
    """What cuts the program short in case ``label`` (module docstring), up to the abort handled; the kinematics
    mode is read just before the cut (``cut``: TCP, the probing's)."""
    runs = str(cs.sim.cfg / "pige_cycle" / "runs" / "*")
    trip = cs.table.trip_radius_mm
    probing = {"op": "wait_for", "pin": "ptt.trips", "increase": LOGGED, "timeout": 600}
    if label == "kill":
        probing = {"op": "wait_for", "glob": runs + "/status.txt", "contains": "identify", "timeout": 1200}
    cut = {"op": "read", "pins": ["motion.switchkins-type"], "label": f"cut-{label}"}
    rest = [{"op": "idle", "timeout": 300, "allow_error": True}, SETTLE, {"op": "status"}]
    how = {"esc": [{"op": "abort", "allow_error": True}],
           "estop": [{"op": "estop", "allow_error": True}, {"op": "machine_on", "allow_error": True}],
           "miss": [{"op": "hal", "commands": ["setp ptt.trip-radius -1"], "allow_error": True}],
           "kill": [{"op": "kill", "pid_glob": runs + "/analyse.pid", "allow_error": True}]}[label]
    back = [{"op": "hal", "commands": [f"setp ptt.trip-radius {trip!r}"]}] if label == "miss" else []
    return [probing, cut, *how, *rest, *back]


def auto_steps(cs: CycleSim) -> list[dict[str, Any]]:
    """Each case (module docstring), labelled: around it the files, pins and record; after it the next MDI lines
    and the next program in AUTO, the commanded Z read after each."""
    program, after = cs.sim.cfg / "sphere_check.ngc", cs.sim.cfg / "next.ngc"
    program.write_text(PROGRAM.format(tool=cs.machine.stylus[0]))
    after.write_text(AFTER)
    out: list[dict[str, Any]] = []
    for label in CASES:
        around = [files_step(cs), pins_step(cs), record_step(cs)]
        start = {"op": "program_start", "file": str(program), "watch": ["ptt.trips"]}
        out += [{"label": label} | s for s in [*around, start, *interruption(cs, label), *around]]
        if label == "esc":
            out += later_steps(cs)
        out += [{"op": "mdi", "lines": ["G0 Z61", "G0 Z62"], "read": ["axis.z.pos-cmd"], "label": f"mdi-{label}"},
                {"op": "program", "file": str(after), "timeout": 120, "label": f"auto-{label}"},
                {"op": "read", "pins": ["axis.z.pos-cmd", "motion.switchkins-type"], "label": f"auto-{label}"},
                {"op": "mdi", "lines": ["G0 Z60"], "label": f"auto-{label}"}]
    return out


def later_steps(cs: CycleSim) -> list[dict[str, Any]]:
    """Right after the Esc case (about 5 s after its abort, within the handler's window for aborts that follow):
    the operator's own job switches to TCP kinematics and is aborted; the mode read after it must stay theirs,
    then ``M429`` in MDI."""
    job = cs.sim.cfg / "tcp_job.ngc"
    job.write_text(TCP_JOB)
    kins = {"op": "read", "pins": ["motion.switchkins-type"]}
    steps = [{"op": "program_start", "file": str(job)}, {"op": "sleep", "seconds": 1}, kins,
             {"op": "abort", "allow_error": True}, {"op": "idle", "timeout": 60, "allow_error": True}, SETTLE, kins,
             {"op": "mdi", "lines": ["M429"]}, kins]
    return [s | {"label": "later"} for s in steps]


@pytest.fixture(scope="module")
def auto_run(lcnc: None, tmp_path_factory: pytest.TempPathFactory) -> tuple[CycleSim, RunResult]:
    cs = cycle_sim(tmp_path_factory.mktemp("cycle_auto"), "AC", poses=6)
    run = run_cycle(cs, auto_steps(cs))
    print(f"\nthe AUTO abort simulation: {run.wall_s:.0f} s wall")
    return cs, run


def steps(run: RunResult) -> list[dict[str, Any]]:
    assert run.result.get("ok"), run.summary()
    return list(run.result["steps"])[1:]  # the first step loads the stylus


def case_of(run: RunResult, label: str) -> list[dict[str, Any]]:
    return [x for x in steps(run) if x.get("label") == label]


def abort_logs(cs: CycleSim) -> dict[str, str]:
    """Every run folder's ``abort.log`` (the command-channel helper's notes), by run folder name."""
    return {r.name: (r / "abort.log").read_text() for r in cs.runs if (r / "abort.log").is_file()}


@pytest.mark.parametrize("label", CASES)
def test_an_abort_in_auto_changes_no_file_no_pin_and_no_record(auto_run, label):
    cs, run = auto_run
    case = case_of(run, label)
    before, after = case[:3], case[-3:]
    errors = [t for x in case for kind, t in x["messages"] if kind == "error"]
    (status,) = [x["status"] for x in case if x["op"] == "status"]
    print(f"{label} in AUTO: errors {errors}; status after {status}; abort.log of the run "
          f"{abort_logs(cs).get(cs.runs[CASES.index(label)].name, '(none)')!r}")
    assert before[0]["files"] == after[0]["files"], "the configuration's files changed"
    values = [{k: v for k, v in x["readings"][0].items() if k != "motion.switchkins-type"}
              for x in (before[1], after[1])]
    assert values[0] == values[1], "the pins changed"
    assert before[2]["files"] == after[2]["files"], "the cycle's record (proposal, journal, history) changed"
    assert status["task_mode"] == 2  # linuxcnc.MODE_AUTO: read before any other command
    if label == "kill":
        assert any("pige's analyse step failed (ended by signal 9), nothing changed" in e for e in errors), errors
    if label == "miss":
        assert any("move finished without making contact" in e for e in errors), errors


@pytest.mark.parametrize("label", CASES)
def test_after_an_abort_in_auto_the_kinematics_mode_is_the_one_found(auto_run, label):
    """Found in identity, cut short in TCP (probing, or identifying after it): identity again 3 s after the abort
    is handled, with task still in AUTO (no command since that could have put it back)."""
    _, run = auto_run
    case = case_of(run, label)
    (cut,) = case_of(run, f"cut-{label}")
    assert case[1]["readings"][0]["motion.switchkins-type"] == 0  # as found
    assert cut["readings"][0]["motion.switchkins-type"] == 1  # cut short in TCP kinematics
    assert case[-2]["readings"][0]["motion.switchkins-type"] == 0, "left in TCP kinematics after the abort"


@pytest.mark.parametrize("label", CASES)
def test_after_an_abort_in_auto_mdi_and_the_next_program_run(auto_run, label):
    _, run = auto_run
    (mdi,) = case_of(run, f"mdi-{label}")
    z61, z62 = (r["axis.z.pos-cmd"] for r in mdi["readings"])
    assert z62 - z61 == pytest.approx(1.0, abs=1e-6), mdi["readings"]
    program, read, _ = case_of(run, f"auto-{label}")
    # the program's Z64 two above the MDI line's Z62 (the same offsets: the tool length taken before the abort)
    assert read["readings"][0]["axis.z.pos-cmd"] - z62 == pytest.approx(2.0, abs=1e-6), read["readings"]
    assert read["readings"][0]["motion.switchkins-type"] == 0


@pytest.mark.parametrize("label", CASES)
def test_after_an_abort_in_auto_the_handler_s_own_set_put_the_mode_back(auto_run, label):
    """Task takes no command-channel command in AUTO: the run's ``abort.log`` (one line per abort the handler put the
    mode back for) must show the mode in force with nothing sent, i.e. set by ``o<pige_cycle_abort>``'s own
    ``SET_AUX_OUTPUT_VALUE``, and within the 3 s the test waits."""
    cs, _ = auto_run
    log = abort_logs(cs).get(cs.runs[CASES.index(label)].name, "")
    lines = log.splitlines()
    note = re.compile(r"analog-out-03 0: in force after (\d+\.\d+) s in AUTO mode \(.*\), sent 0$")
    found = [note.search(ln) for ln in lines]
    assert lines and all(found), log
    assert max(float(m.group(1)) for m in found if m) < 3.0, log


def test_a_later_abort_of_the_operator_s_own_job_keeps_the_mode_they_chose(auto_run):
    """The cycle's abort handler puts the mode found back for the aborts of the cycle only: the operator's own job,
    in TCP kinematics (``M428``), aborted seconds after the cycle's abort, stays in TCP kinematics (LinuxCNC's own
    behaviour without the cycle)."""
    _, run = auto_run
    before, after, identity = (x["readings"][0]["motion.switchkins-type"]
                               for x in case_of(run, "later") if x["op"] == "read")
    assert before == 1, "the job's M428 did not take"
    assert after == 1, "the operator's TCP kinematics switched back to identity by the cycle's abort handler"
    assert identity == 0
