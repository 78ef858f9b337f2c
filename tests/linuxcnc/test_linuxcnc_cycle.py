"""The cycle inside LinuxCNC 2.9 (issue 48, "Done means"): ``pige cycle install``, then ``M451 P0/P1/P2`` and
``M452`` called from MDI (and from a program in AUTO) on the shipped trt simulations with a hidden true machine.

Six simulations at once (:mod:`cycle_setup`), each in its own folder and namespaces:

- **the loop**, on ``xyzac-trt`` and ``xyzbc-trt``, each with the stock kinematics and with pige's component (four
  simulations): install; ``M451 P0`` with the configuration's files and pins read before and after (the first
  ``xyzbc`` stock call from a program in AUTO); ``M451 P1``; the true tool point at every probed pose (the stylus
  centre commanded onto the sphere centre in TCP kinematics); ``M451 P2``; the pins and the tool point again;
  ``M451 P0``; then LinuxCNC started again and the pins read;
- **the check-up** (``xyzac-trt``, stock, tolerances 40 µm / 150 µrad): ``M451 P0`` as the full calibration, the true
  machine warmed up (EX0C and EZ0A moved 5 µm), ``M452``, ``M451 P2``, ``M452``;
- **the guards** (``xyzac-trt``, stock, 6 poses): a sphere 0.05 mm larger than stated (``M451 P1``); the A line's
  offset moved 0.5 mm (``M451 P1`` then ``M451 P2``); pige's analysis process killed (SIGKILL, by its id) while it
  identifies; Esc while probing; the E-stop while probing.  Around each: the configuration's files, the pins, the
  cycle's record (proposal, journal, history) read before and after; after the last three, 3 s to settle, the
  kinematics mode read (identity again, as found), and the operator's next two MDI lines (both must run).
"""

from __future__ import annotations

import json
import re
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import pytest
from cycle_setup import (
    CycleSim,
    cycle_sim,
    cycle_step,
    files_step,
    pins_step,
    probed_angles,
    run_cycle,
    table_commands,
    tcp_error_steps,
    tcp_errors,
    true_pige_table,
)
from lcnc_harness import RunResult, run_sim

pytestmark = pytest.mark.linuxcnc
LOOPS = [("AC", "stock"), ("BC", "stock"), ("AC", "pige"), ("BC", "pige")]
WARM = {"EX0C": 5.0, "EZ0A": 5.0}
#: after an abort, what the operator does first: look (the kinematics mode is read after it)
SETTLE = {"op": "sleep", "seconds": 3, "allow_error": True}
#: the probe's trips until the second logged contact: the three confirming contacts before the log opens, then two
LOGGED = 5


def loop_steps(cs: CycleSim, from_program: bool) -> list[dict[str, Any]]:
    """The loop (module docstring); the first ``M451 P0`` from a program in AUTO when ``from_program``."""
    first = cycle_step("M451 P0")
    if from_program:
        program = cs.sim.cfg / "check.ngc"
        program.write_text("(the operator's program: the cycle's check)\nM451 P0\nM2\n")
        first = {"op": "program", "file": str(program), "timeout": 1800, "clock": "ptt.clock"}
    return [files_step(cs), pins_step(cs), first, files_step(cs), pins_step(cs),
            cycle_step("M451 P1"), *tcp_error_steps(cs), cycle_step("M451 P2"), pins_step(cs), *tcp_error_steps(cs),
            cycle_step("M451 P0"), pins_step(cs)]


def warm_steps(cs: CycleSim) -> list[dict[str, Any]]:
    return [cycle_step("M451 P0"), {"op": "hal", "commands": table_commands(true_pige_table(cs, WARM))},
            cycle_step("M452"), cycle_step("M451 P2"), cycle_step("M452")]


def record_step(cs: CycleSim) -> dict[str, Any]:
    """The cycle's record: proposal, journal, history (its SHA-256 per file)."""
    return {"op": "files", "root": str(cs.sim.cfg / "pige_cycle"), "exclude": ["run/", "runs/"]}


def guard_steps(cs: CycleSim) -> list[dict[str, Any]]:
    """The guards (module docstring), each case labelled; around each, the files, pins and record."""
    runs = str(cs.sim.cfg / "pige_cycle" / "runs" / "*")
    trip = cs.table.trip_radius_mm

    def case(label: str, *inner: dict[str, Any]) -> list[dict[str, Any]]:
        around = [files_step(cs), pins_step(cs), record_step(cs)]
        return [s | {"label": label} for s in [*around, *inner, *around]]

    return [*case("sphere", {"op": "hal", "commands": [f"setp ptt.trip-radius {trip + 0.05!r}"]},
                  cycle_step("M451 P1", allow_error=True),
                  {"op": "hal", "commands": [f"setp ptt.trip-radius {trip!r}"]}),
            {"op": "hal", "commands": table_commands(true_pige_table(cs, {"EY0A": 500.0})), "label": "moved"},
            cycle_step("M451 P1") | {"label": "moved"},
            *case("limit", cycle_step("M451 P2", allow_error=True)),
            {"op": "hal", "commands": table_commands(true_pige_table(cs, {})), "label": "back"},
            *case("kill", {"op": "mdi_start", "line": "M451 P0"},
                  {"op": "wait_for", "glob": runs + "/status.txt", "contains": "identify", "timeout": 1200},
                  {"op": "kill", "pid_glob": runs + "/analyse.pid", "allow_error": True},
                  {"op": "idle", "timeout": 300, "allow_error": True}, SETTLE),
            alive("kill"),
            *case("esc", {"op": "mdi_start", "line": "M451 P0", "watch": ["ptt.trips"]},
                  {"op": "wait_for", "pin": "ptt.trips", "increase": LOGGED, "timeout": 600},
                  {"op": "abort", "allow_error": True}, {"op": "idle", "timeout": 300, "allow_error": True}, SETTLE),
            alive("esc"),
            *case("estop", {"op": "mdi_start", "line": "M451 P0", "watch": ["ptt.trips"]},
                  {"op": "wait_for", "pin": "ptt.trips", "increase": LOGGED, "timeout": 600},
                  {"op": "estop", "allow_error": True}, {"op": "machine_on", "allow_error": True},
                  {"op": "idle", "timeout": 300, "allow_error": True}, SETTLE),
            alive("estop")]


def alive(after: str) -> dict[str, Any]:
    """The operator's next MDI lines after an abort: each must run (LinuxCNC takes commands again, the abort handler
    left nothing half-way that would get in their way), read as the commanded Z after each."""
    return {"op": "mdi", "lines": ["G0 Z61", "G0 Z62"], "read": ["axis.z.pos-cmd"], "label": f"alive-{after}"}


def _loop(key: str, kinematics: str, tmp: Any) -> tuple[CycleSim, RunResult, RunResult]:
    cs = cycle_sim(tmp.mktemp(f"cycle_{key}_{kinematics}"), key, kinematics=kinematics, poses=8)
    run = run_cycle(cs, loop_steps(cs, from_program=(key, kinematics) == ("BC", "stock")))
    restart = run_sim(cs.sim, [pins_step(cs)], attempts=1)
    return cs, run, restart


def _warm(tmp: Any) -> tuple[CycleSim, RunResult]:
    root = tmp.mktemp("cycle_warm")
    (root / "tol.json").write_text(json.dumps({"format": "pige-tolerances 1", "defaults": {"um": 40, "urad": 150}}))
    cs = cycle_sim(root, "AC", poses=8, extra=["--tolerances", str(root / "tol.json")])
    return cs, run_cycle(cs, warm_steps(cs))


def _guards(tmp: Any) -> tuple[CycleSim, RunResult]:
    cs = cycle_sim(tmp.mktemp("cycle_guards"), "AC", poses=6)
    return cs, run_cycle(cs, guard_steps(cs))


def wanted(request: pytest.FixtureRequest) -> set[Any]:
    """The simulations the selected tests of this module read: a loop's ``key`` parameter, ``warm`` for the check-up
    test, ``guards`` for the others (so that ``-k`` starts only those it needs)."""
    out: set[Any] = set()
    for item in request.session.items:
        if getattr(item, "module", None) is not request.module:
            continue
        params = getattr(getattr(item, "callspec", None), "params", {})
        out.add(params["key"] if "key" in params else "warm" if "check_up" in item.name else "guards")
    return out


@pytest.fixture(scope="module")
def cycle_runs(lcnc: None, tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> dict[Any, Any]:
    """The simulations of the module docstring the selected tests need (all of them in a full run), at once."""
    jobs = {k: (lambda k=k: _loop(*k, tmp_path_factory)) for k in LOOPS}
    jobs["warm"] = lambda: _warm(tmp_path_factory)
    jobs["guards"] = lambda: _guards(tmp_path_factory)
    jobs = {k: job for k, job in jobs.items() if k in wanted(request)}
    with ThreadPoolExecutor(max_workers=len(jobs)) as pool:
        futures = {k: pool.submit(f) for k, f in jobs.items()}
        return {k: f.result() for k, f in futures.items()}


def steps(run: RunResult) -> list[dict[str, Any]]:
    assert run.result.get("ok"), run.summary()
    return list(run.result["steps"])[1:]  # the first step loads the stylus


def lines_of(step: dict[str, Any]) -> list[str]:
    return [t for kind, t in step["messages"] if kind == "display"]


@pytest.mark.parametrize("key", LOOPS, ids=[f"{k}-{kin}" for k, kin in LOOPS])
def test_install_then_check_changes_no_pin_and_no_file(cycle_runs, key):
    cs, run, _ = cycle_runs[key]
    s = steps(run)
    files0, pins0, check, files1, pins1 = s[:5]
    assert files0["files"] == files1["files"] and len(files0["files"]) > 30
    assert pins0["readings"] == pins1["readings"] and pins0["readings"][0]["motion.switchkins-type"] == 0
    lines = lines_of(check)
    assert lines[0].startswith("PIGE M451 P0 check: ") and len(lines) >= 3, lines
    runs = cs.runs
    assert runs[0].name.endswith("M451-check") and (runs[0] / "result.json").is_file()
    print(f"{key}: M451 P0 {check['wall_s']:.1f} s wall, {check.get('sim_s', 0):.1f} s simulated; {lines[0]}")


def _held_residuals(cs: CycleSim, result: dict[str, Any]) -> dict[str, float]:
    """The PIGEs the kinematics hold, in standard errors from zero."""
    return {r["name"]: r["value"] / r["std"] for r in result["rows"] if r["held"]}


@pytest.mark.parametrize("key", LOOPS, ids=[f"{k}-{kin}" for k, kin in LOOPS])
def test_optimise_enter_check_brings_the_tool_point_within_the_noise(cycle_runs, key):
    cs, run, _ = cycle_runs[key]
    s = steps(run)
    optimise, before, enter, pins, after, check = s[5], s[7], s[10], s[11], s[13], s[16]
    p1 = cs.run_of(1)
    proposal = p1["result"]["proposal"]
    entered = {e["pin"]: e["new"] for e in proposal["entries"]}
    assert all(abs(pins["readings"][0][pin] - v) < 1e-9 for pin, v in entered.items()), (pins, entered)
    assert lines_of(enter)[0].startswith("PIGE M451 P2: entered from ")
    e_before, e_after = tcp_errors(before), tcp_errors(after)
    assert len(e_after) == len(probed_angles(cs)) == 9
    program = (cs.runs[1] / "program.ngc").read_text()
    for t, c in probed_angles(cs)[1:]:
        assert f"{cs.machine.outer}{t:.4f} C{c:.4f}".replace(".0000", "") in program or \
            f"{cs.machine.outer}{round(t, 4):g} C{round(c, 4):g}" in program
    rms = {k: float(np.sqrt(np.mean(e ** 2))) for k, e in (("before", e_before), ("after", e_after))}
    # the bound set by the noise: P1's predicted RMS after the entry (drawn from the identification's covariance) at 4
    # of its standard deviations, as the PIGEs are judged (its 95 % point is mean + 1.645 std)
    after = p1["result"]["predicted_um"]["probed"]["after"]
    bound = after["expected"] + 4.0 * (after["p95"] - after["expected"]) / 1.645
    residuals = _held_residuals(cs, cs.run_of(3)["result"])
    print(f"{key}: true tool-point error at the {len(e_after)} probed poses: RMS {rms['before']:.3f} -> "
          f"{rms['after']:.3f} um (max {e_before.max():.3f} -> {e_after.max():.3f}); predicted after "
          f"{after['expected']:.3f} (95 % {after['p95']:.3f}), bound (4 std) {bound:.3f} um; remeasured held PIGEs in "
          "std: "
          + ", ".join(f"{k} {v:+.2f}" for k, v in residuals.items())
          + f"; M451 P1 {optimise['wall_s']:.0f} s, P2 {enter['wall_s']:.1f} s, P0 {check['wall_s']:.0f} s wall")
    assert rms["after"] <= bound and rms["after"] < rms["before"] / 5
    assert all(abs(v) < 4.0 for v in residuals.values()), residuals


@pytest.mark.parametrize("key", LOOPS, ids=[f"{k}-{kin}" for k, kin in LOOPS])
def test_the_entered_values_hold_after_linuxcnc_restarts(cycle_runs, key):
    cs, run, restart = cycle_runs[key]
    entered = steps(run)[11]["readings"][0]
    assert restart.result.get("ok"), restart.summary()
    assert restart.result["steps"][0]["readings"][0] == entered | {"motion.switchkins-type": 0.0}
    values = (cs.sim.cfg / "pige_cycle" / "values.hal").read_text()
    previous = (cs.sim.cfg / "pige_cycle" / "values.hal.previous").read_text()
    written = sorted(float(v) for v in re.findall(r"^set[ps] \S+ (\S+)", values, re.M))
    held = sorted(v for pin, v in entered.items() if pin != "motion.switchkins-type")
    assert values != previous and np.allclose(written, held, rtol=0, atol=1e-9), (written, held)


def test_a_check_up_after_a_warm_up_drifts_enters_and_is_ok_again(cycle_runs):
    cs, run = cycle_runs["warm"]
    s = steps(run)
    first, enter, second = s[2], s[3], s[4]
    drifted, ok = lines_of(first), lines_of(second)
    print("warm-up:", *drifted, *lines_of(enter), *ok, sep="\n  ")
    assert drifted[0].startswith("PIGE M452 check-up: DRIFTED"), drifted
    assert any(ln.startswith("proposal: ") for ln in drifted)
    assert lines_of(enter)[0].startswith("PIGE M451 P2: entered from ") and "M452-checkup" in lines_of(enter)[0]
    assert ok[0].startswith("PIGE M452 check-up: OK"), ok
    journal = [json.loads(ln) for ln in (cs.sim.cfg / "pige_cycle" / "journal.jsonl").read_text().splitlines()]
    assert [j["outcome"] for j in journal] == ["measured", "measured", "entered", "measured"]


def _case(s: list[dict[str, Any]], label: str) -> list[dict[str, Any]]:
    return [x for x in s if x.get("label") == label]


def _unchanged(case: list[dict[str, Any]]) -> list[str]:
    """A guard case's files, pins and record (three steps before it, three after) the same; its errors."""
    before, after = case[:3], case[-3:]
    assert before[0]["files"] == after[0]["files"], "the configuration's files changed"
    values = [{k: v for k, v in x["readings"][0].items() if k != "motion.switchkins-type"}
              for x in (before[1], after[1])]
    assert values[0] == values[1], "the pins changed"
    assert before[2]["files"] == after[2]["files"], "the cycle's record (proposal, journal, history) changed"
    return [t for x in case for kind, t in x["messages"] if kind == "error"]


def test_a_sphere_larger_than_stated_is_stopped_with_nothing_changed(cycle_runs):
    _, run = cycle_runs["guards"]
    errors = _unchanged(_case(steps(run), "sphere"))
    print("sphere 0.05 mm larger:", errors)
    assert errors[-1].startswith("PIGE M451 P1 optimise stopped, nothing changed (log pige_cycle/runs/")
    assert re.search(r"sphere radius found 7\.89\d\d mm, \+0\.04\d\d from R \+ r = 7\.85", errors[-1])


def test_an_offset_moved_0_5_mm_is_refused_by_the_change_limit(cycle_runs):
    _, run = cycle_runs["guards"]
    s = steps(run)
    proposal = lines_of(_case(s, "moved")[1])
    errors = _unchanged(_case(s, "limit"))
    print("A line offset moved 0.5 mm:", [ln for ln in proposal if "proposal" in ln or "LIMIT" in ln], errors)
    assert any("BEYOND THE CHANGE LIMIT" in ln for ln in proposal)
    assert errors[-1].startswith("PIGE M451 P2 refused, nothing changed") and "exceeds the change limit" in errors[-1]


def test_killing_pige_during_identification_leaves_linuxcnc_running_and_changes_nothing(cycle_runs):
    cs, run = cycle_runs["guards"]
    s = steps(run)
    case = _case(s, "kill")
    errors = _unchanged(case)
    kill = next(x for x in case if x["op"] == "kill")
    print("killed pid", kill["pid"], kill["pid_file"], errors)
    assert any("pige's analyse step failed (ended by signal 9), nothing changed (log pige_cycle/runs/" in e
               for e in errors)
    assert [x["op"] for x in _case(s, "alive-kill")] == ["mdi"]  # LinuxCNC takes the next command
    status = (cs.sim.cfg / "pige_cycle" / "runs" / kill["pid_file"].split("/")[-2] / "status.txt").read_text()
    assert "identify" in status and "analyse done" not in status


@pytest.mark.parametrize("label", ["esc", "estop"])
def test_esc_or_e_stop_while_probing_changes_nothing(cycle_runs, label):
    _, run = cycle_runs["guards"]
    case = _case(steps(run), label)
    errors = _unchanged(case)
    print(f"{label}:", errors)


@pytest.mark.parametrize("label", ["kill", "esc", "estop"])
def test_after_an_abort_the_kinematics_mode_is_the_one_found(cycle_runs, label):
    """Found in identity kinematics, aborted while in the TCP ones (probing, or identifying after it): identity again
    once the abort is handled (pige_on_abort's M68 on the switch's output), before any other command."""
    _, run = cycle_runs["guards"]
    case = _case(steps(run), label)
    assert case[1]["readings"][0]["motion.switchkins-type"] == 0  # as found
    assert case[-2]["readings"][0]["motion.switchkins-type"] == 0  # identity again


@pytest.mark.parametrize("label", ["kill", "esc", "estop"])
def test_after_an_abort_the_operator_s_next_command_runs(cycle_runs, label):
    _, run = cycle_runs["guards"]
    (step,) = _case(steps(run), f"alive-{label}")
    z61, z62 = (r["axis.z.pos-cmd"] for r in step["readings"])
    assert z62 - z61 == pytest.approx(1.0, abs=1e-6), step["readings"]
