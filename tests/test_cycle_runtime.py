"""The cycle's steps without LinuxCNC: prepare, analyse and enter on an installed configuration, the probe log written
by pige's virtual probing machine, the running HAL a dictionary (:class:`FakeHal`).  The guards: the sphere radius,
the proposal's refusals (none, too old, the configuration changed, the change limit), the state checks before
anything moves, the check-up's basis; the remap's own logic (its modes and phases, the AXIS preview)."""

from __future__ import annotations

import json
import re
import subprocess
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest
from cycle_configs import install_args, write_stock

from pige_sym.cli.main import main
from pige_sym.cycle.layout import Layout
from pige_sym.cycle.runtime import run_step

TRUTH = "EY0A=15,EZ0A=-10,EB0A=60,EC0A=-45,EX0C=12,EY0C=-8,EA0C=40,EB0C=-30"


class FakeHal:
    """A running HAL as ``halcmd`` shows it: pins and signals by name."""

    def __init__(self, values: dict[str, float]) -> None:
        self.values = dict(values)
        self.commands: list[list[str]] = []

    def __call__(self, argv: list[str]) -> subprocess.CompletedProcess[str]:
        self.commands.append(list(argv))
        args = [a for a in argv[1:] if a != "-s"]
        if args[0] == "show":
            return subprocess.CompletedProcess(argv, 0, "", "")
        if args[0] in ("getp", "gets"):
            return subprocess.CompletedProcess(argv, 0, f"{self.values[args[1]]}\n", "")
        self.values[args[1]] = float(args[2])
        return subprocess.CompletedProcess(argv, 0, "", "")


@pytest.fixture
def hal(monkeypatch: pytest.MonkeyPatch) -> FakeHal:
    from pige_sym.cycle import hal_live

    fake = FakeHal({"xyzac-trt-kins.x-rot-point": 0.0, "xyzac-trt-kins.y-rot-point": 0.0,
                    "xyzac-trt-kins.z-rot-point": 0.0, ":y-offset": 20.0, ":z-offset": 10.0})
    monkeypatch.setattr(hal_live, "_run", fake)
    monkeypatch.setattr(hal_live.shutil, "which", lambda name: "/usr/bin/halcmd")
    return fake


@pytest.fixture
def config(tmp_path: Path) -> Layout:
    ini = write_stock(tmp_path / "cfg")
    assert main(install_args(ini, "--poses", "6", "--force")) == 0
    return Layout(ini.parent.resolve())


def request(layout: Layout, name: str, mode: str, **state: object) -> Path:
    run = layout.runs / name
    run.mkdir(parents=True)
    req = {"format": "pige-cycle-request 1", "code": "M452" if mode == "checkup" else "M451", "mode": mode,
           "started": datetime.now(timezone.utc).isoformat(timespec="seconds"), "tool": 9, "system": 1,
           "offset": [0.0] * 9, "rotation": 0.0, "g92_on": False, "position": [20, 10, 60, 0, 0, 0],
           "switchkins_type": 0} | state
    (run / "request.json").write_text(json.dumps(req))
    return run


def probe(run: Path, truth: str = TRUTH, seed: int = 3, pretravel_um: float = 0.0) -> None:
    """What LinuxCNC would log running the run's program on a machine with ``truth`` (a negative pre-travel: a
    sphere larger than stated)."""
    assert main(["simulate", "--instrument", "sphere-probe", "--program", str(run / "program.ngc"), "--pige", truth,
                 "--seed", str(seed), "--noise", "0.3", "--pretravel", f"{pretravel_um:g}",
                 "--out", str(run / "probe_log.txt")]) == 0


def messages(run: Path, step: str = "analyse") -> dict:
    return json.loads((run / f"{step}.messages.json").read_text())


def measure(layout: Layout, name: str, mode: str, *, live: bool = False, **kw: object) -> Path:
    run = request(layout, name, mode)
    assert run_step("prepare", run, live=live) == 0, messages(run, "prepare")
    probe(run, **kw)  # type: ignore[arg-type]
    run_step("analyse", run, live=live)
    return run


def record(layout: Layout) -> dict[str, bytes]:
    """The cycle's record and the configuration's values (what 'nothing changed' compares)."""
    paths = [layout.values, layout.proposal, layout.journal, layout.default_db, layout.config / "xyzac-trt.ini"]
    return {p.name: p.read_bytes() for p in paths if p.is_file()}


def test_optimise_then_enter_then_check(config, hal):
    run = measure(config, "p1", "optimise", live=True)
    m = messages(run)
    assert m["error"] is None and m["lines"][0].startswith("PIGE M451 P1 optimise: FAIL")
    assert any(line.startswith("proposal: setp xyzac-trt-kins.x-rot-point 0.01") for line in m["lines"])
    proposal = json.loads(config.proposal.read_text())
    assert {e["target"] for e in proposal["entries"]} == {"xyzac-trt-kins.x-rot-point", "xyzac-trt-kins.y-rot-point",
                                                          ":y-offset", ":z-offset"}
    before = config.values.read_text()
    enter = request(config, "p2", "enter", switchkins_type=1)  # from TCP kinematics
    assert run_step("prepare", enter) == 0 and run_step("enter", enter) == 0, messages(enter, "enter")
    assert "M429" in (config.current / "pige_cycle_probe.ngc").read_text()  # entered in identity kinematics
    sets = [c for c in hal.commands if c[1] in ("setp", "sets")]
    assert [c[2] for c in sets] == [e["target"] for e in proposal["entries"]]
    assert hal.values[":y-offset"] == pytest.approx(proposal["entries"][2]["new"])
    assert config.values_previous.read_text() == before and f"sets :y-offset {hal.values[':y-offset']:.7f}".rstrip(
        "0") in config.values.read_text()
    assert not config.proposal.exists() and (enter / "proposal.entered.json").is_file()
    again = request(config, "p2b", "enter")
    assert run_step("prepare", again) == 0 and run_step("enter", again) == 1
    assert "no proposal to enter" in messages(again, "enter")["error"]
    # the next run is written for the moved lines; the virtual machine's PIGEs are relative to the program's
    # lines, so the same physical machine has its offsets less what was entered (trtfuncs.c's lines)
    d = {e["target"].split(".")[-1].lstrip(":"): (e["new"] - e["old"]) * 1e3 for e in proposal["entries"]}
    left = {"EX0C": 12 - d["x-rot-point"], "EY0C": -8 - d["y-rot-point"],
            "EY0A": 15 - d["y-rot-point"] - d["y-offset"], "EZ0A": -10 - d["z-offset"]}
    truth = dict(kv.split("=") for kv in TRUTH.split(",")) | {k: f"{v:.4f}" for k, v in left.items()}
    check = measure(config, "p0", "check", live=True, truth=",".join(f"{k}={v}" for k, v in truth.items()))
    assert "(pige pivot_C_mm: 0.0" in (check / "program.ngc").read_text()
    rows = json.loads((check / "result.json").read_text())["rows"]
    offsets = [r for r in rows if r["unit"] == "um"]
    assert all(abs(r["value"]) < 4 * r["std"] for r in offsets), offsets


def test_a_sphere_larger_than_stated_stops_the_run_before_identifying(config):
    before = record(config)
    run = measure(config, "big", "optimise", pretravel_um=-50.0)
    m = messages(run)
    assert m["error"] == ("PIGE M451 P1 optimise stopped, nothing changed (log pige_cycle/runs/big/log.txt): sphere "
                          "radius found 7.9000 mm, +0.0500 from R + r = 7.85 (limit ±0.02): dirt on the sphere or "
                          "stylus, or a wrong one; clean them or correct the radii in settings.json")
    assert record(config) == before
    assert "identify" not in (run / "status.txt").read_text()


@pytest.mark.parametrize("case", ["old", "edited", "limit", "pins"])
def test_enter_refuses_and_changes_nothing(config, hal, case):
    moved = TRUTH.replace("EY0A=15", "EY0A=500")  # the A line's offset moved by 0.5 mm
    measure(config, "p1", "optimise", live=True, truth=moved if case == "limit" else TRUTH)
    if case == "old":
        p = json.loads(config.proposal.read_text())
        p["created"] = (datetime.now(timezone.utc) - timedelta(hours=9)).isoformat(timespec="seconds")
        config.proposal.write_text(json.dumps(p))
    elif case == "edited":
        ini = config.config / "xyzac-trt.ini"
        ini.write_text(ini.read_text() + "# a comment\n")
    elif case == "pins":
        hal.values[":z-offset"] = 10.5
    before, pins = record(config), dict(hal.values)
    run = request(config, "p2", "enter")
    assert run_step("prepare", run) == 0
    assert run_step("enter", run) == 1
    why = {"old": "h old, older than 8 h", "edited": "the configuration changed since the proposal",
           "limit": r"an entry exceeds the change limit: :y-offset \+0\.5\d* mm \(limit 0\.2 mm\)",
           "pins": r"the configuration changed since the proposal of p1 \(values in force\)"}[case]
    assert re.search(why, messages(run, "enter")["error"]), messages(run, "enter")
    assert record(config) == before
    assert hal.values == pins


def test_a_change_beyond_the_limit_is_named_in_the_proposal(config, hal):
    run = measure(config, "p1", "optimise", live=True, truth="EY0A=500,EX0C=12")
    lines = messages(run)["lines"]
    assert any("BEYOND THE CHANGE LIMIT, M451 P2 will refuse it: :y-offset +0.5" in ln for ln in lines), lines


@pytest.mark.parametrize(("state", "why"), [
    ({"tool": 1}, "the spindle holds T1; the cycle probes with the stylus T9: load it (T9 M6)"),
    ({"g92_on": True}, "G92 offsets are active"),
    ({"rotation": 5.0}, "G54 rotates XY"),
    ({"position": [20, 10, 60, -30, 0, 12]}, "the rotary axes stand at A -30, C 12"),
    ({"switchkins_type": 2}, "the kinematics are switched to type 2"),
])
def test_prepare_refuses_before_anything_moves(config, state, why):
    run = request(config, "x", "check", **state)
    assert run_step("prepare", run, live=False) == 1
    m = messages(run, "prepare")
    assert why in m["error"] and not (run / "program.ngc").exists()
    assert "abort" in (config.current / "pige_cycle_probe.ngc").read_text()  # the placeholder: nothing prepared


def test_a_work_offset_shifts_the_program_and_the_entries_stay_in_machine_coordinates(config):
    run = request(config, "g55", "optimise", system=2, offset=[100.0, -5.0, -20.0, 0, 0, 0, 0, 0, 0])
    assert run_step("prepare", run, live=False) == 0
    text = (run / "program.ngc").read_text()
    assert "(pige sphere_mm: -80, 15, 35)" in text and "(pige pivot_A_mm: -100, 25, 30)" in text
    assert "G55" in text.splitlines()
    # the TCP program ends at the reference pose it must start from (so the cycle runs again as it is)
    assert [ln for ln in text.splitlines() if ln.startswith("G0 A")][-1] == "G0 A0 C0"
    probe(run)
    assert run_step("analyse", run, live=False) == 0
    p = json.loads(config.proposal.read_text())
    assert p["entries"][0]["target"] == "xyzac-trt-kins.x-rot-point" and 0.005 < p["entries"][0]["new"] < 0.02


def test_checkup_needs_a_full_calibration_of_the_configuration_in_force():
    from pige_sym.cycle.journal import JournalEntry, checkup_basis
    from pige_sym.errors import InputError

    def e(outcome: str, kind: str | None = None, fp: str = "a", **kw: object) -> JournalEntry:
        return JournalEntry("t", "r", "M451", "check", outcome, fp, kind, 7 if kind == "full" else 9, **kw)

    with pytest.raises(InputError, match="no full calibration"):
        checkup_basis([], "a")
    assert checkup_basis([e("measured", "full")], "a").corrected is False
    with pytest.raises(InputError, match="changed since the last full calibration"):
        checkup_basis([e("measured", "full")], "b")
    entered = e("entered", entered_kind="checkup", fingerprint_after="b")
    basis = checkup_basis([e("measured", "full"), e("measured", "checkup"), entered], "b")
    assert (basis.full_run, basis.corrected) == (7, True)
    assert checkup_basis([e("measured", "full"), entered, e("measured", "checkup", "b")], "b").corrected is False
    with pytest.raises(InputError, match="from a full calibration"):
        checkup_basis([e("measured", "full"), e("entered", entered_kind="full", fingerprint_after="b")], "b")


class FakeInterp:
    """What the remap reads of LinuxCNC's interpreter."""

    def __init__(self, task: int = 1, remap_level: int = 1) -> None:
        self.task, self.remap_level = task, remap_level
        self.params: dict[object, float] = {"_hal[motion.switchkins-type]": 1.0}


def test_the_remap_s_modes_phases_and_preview():
    from pige_sym.cycle import linuxcnc_remap as r

    assert r.pige_m451_prolog(FakeInterp(task=0), p=7.0) == r.INTERP_OK  # AXIS preview: nothing happens
    assert r.pige_m451_epilog(FakeInterp(task=0), p=1.0) == r.INTERP_OK
    assert "is not a mode of the cycle (P0, P1, P2, P3)" in r.pige_m451_prolog(FakeInterp(), p=4.0)
    assert "is not a mode" in r.pige_m451_prolog(FakeInterp(), p=1.5)
    assert "is not a mode of the cycle (P0)" in r.pige_m452_prolog(FakeInterp(), p=1.0)
    assert "is a step of the cycle itself" in r.pige_m451_prolog(FakeInterp(), p=101.0)
    interp = FakeInterp()
    assert r.pige_m451_prolog(interp) == r.INTERP_OK
    assert interp.params["_pige_kins_before"] == 1 and interp.params["_pige_phase"] == 0
    inner = FakeInterp(remap_level=2)
    assert r.pige_m451_prolog(inner, p=201.0) == r.INTERP_OK and inner.params["_pige_phase"] == 2
    assert r._mode("M451", {"p": 102.0}) == (1, "enter") and r._mode("M452", {"p": 200.0}) == (2, "checkup")


def test_the_analysis_identifies_once_and_the_history_stores_that_estimate(config, monkeypatch):
    """``M451 P0``'s analysis hands its identification to the history (``add_run(identified=...)``) instead of
    identifying the same file a second time (about 1 s of the cycle's wait)."""
    from pige_sym.identification import least_squares
    from pige_sym.verdict.history import connect, list_runs
    from pige_sym.verdict.history.store import machine_ids

    calls: list[int] = []
    real = least_squares.identify

    def counted(*args, **kw):
        calls.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(least_squares, "identify", counted)
    run = measure(config, "p0", "check")
    assert messages(run)["error"] is None
    assert len(calls) == 1
    rows = {r["name"]: r["value"] for r in json.loads((run / "result.json").read_text())["rows"]}
    engine = connect(f"sqlite:///{config.default_db}")
    (stored,) = list_runs(engine, machine_ids(engine)[0])
    assert stored.method == "gauss-newton" and stored.kind == "full"
    assert dict(zip(stored.parameters, stored.values.tolist(), strict=True)) == pytest.approx(rows, abs=1e-9)


def test_after_an_abort_the_mode_found_is_put_back_until_it_shows_and_never_later(monkeypatch):
    """``o<pige_cycle_abort>`` (LinuxCNC's ON_ABORT_COMMAND): the mode the cycle found as a float in ``#<_value>``,
    again at each abort until ``motion.switchkins-type`` shows it (LinuxCNC may run the handler twice for one abort
    and drop what the first queued), then -1; -1 after ``REASSERT_S``, after the normal restore, with no cycle."""
    from pige_sym.cycle import linuxcnc_remap as r

    clock = [100.0]
    monkeypatch.setattr(r.time, "monotonic", lambda: clock[0])
    interp = FakeInterp()  # found in TCP kinematics (switchkins-type 1)
    assert r.pige_cycle_abort(interp) == -1.0  # no cycle since LinuxCNC started
    interp.params["_hal[motion.switchkins-type]"] = 0.0
    assert r.pige_m451_prolog(interp) == r.INTERP_OK and interp.params["_pige_kins_before"] == 0  # found: identity
    interp.params["_hal[motion.switchkins-type]"] = 1.0  # probing in TCP kinematics, then Esc
    first = r.pige_cycle_abort(interp)
    assert first == 0.0 and isinstance(first, float)
    clock[0] += 0.01
    assert r.pige_cycle_abort(interp) == 0.0  # the second handler of the same abort: again
    interp.params["_hal[motion.switchkins-type]"] = 0.0  # the M68 reached motion
    assert r.pige_cycle_abort(interp) == -1.0 and interp.params["_pige_kins_before"] == -1
    interp.params["_hal[motion.switchkins-type]"] = 1.0  # the operator's own M428, then an abort of their program
    assert r.pige_cycle_abort(interp) == -1.0
    assert r.pige_m451_prolog(interp) == r.INTERP_OK and interp.params["_pige_kins_before"] == 1
    interp.params["_hal[motion.switchkins-type]"] = 0.0
    assert r.pige_cycle_abort(interp) == 1.0
    clock[0] += r.REASSERT_S + 1  # the mode never showed: a later abort does not switch
    assert r.pige_cycle_abort(interp) == -1.0 and interp.params["_pige_kins_before"] == -1


def test_the_abort_handler_stops_pige_first_and_sets_the_switch_s_output_without_synchronising(tmp_path):
    """pige_on_abort.ngc: ``o<pige_cycle_abort>`` first (it stops pige's step), then ``M68`` on the output that the
    shipped M429/M428 set (found from the INI's net to motion.switchkins-type); no call of the codes, whose ``M66``
    would suspend the handler at abort time."""
    ini = write_stock(tmp_path)
    assert main(install_args(ini, "--force")) == 0
    settings = json.loads((tmp_path / "pige_cycle" / "settings.json").read_text())
    assert settings["kinematics_switch"]["analog_out"] == 3
    # the INI's handler is the Python procedure's call itself (LinuxCNC may execute the handler's last block twice)
    assert "\nON_ABORT_COMMAND = O <pige_cycle_abort> call\n" in ini.read_text()
    # an earlier install's NGC handler is replaced, not left beside it
    ini.write_text(ini.read_text().replace("O <pige_cycle_abort> call", "O <pige_on_abort> call"))
    assert main(install_args(ini, "--force")) == 0
    assert ini.read_text().count("ON_ABORT_COMMAND = ") == 1 and "O <pige_cycle_abort> call" in ini.read_text()
    lines = [ln for ln in (tmp_path / "pige_cycle" / "ngc" / "pige_on_abort.ngc").read_text().splitlines()
             if ln and not ln.startswith((";", "("))]
    assert lines == ["o<pige_on_abort> sub", "o<pige_cycle_abort> call",
                     "o100 if [[#<_value_returned> EQ 1] AND [#<_value> GE 0]]", "M68 E3 Q#<_value>", "o100 endif",
                     "o<pige_on_abort> endsub", "M2"]


def test_once_the_helper_saw_the_mode_in_force_a_later_abort_puts_nothing_back(monkeypatch, tmp_path):
    """The command-channel helper writes the abort's token into ``IN_FORCE`` once ``motion.switchkins-type`` shows
    the mode: an abort after that, within ``REASSERT_S`` (the operator's own job, switched to TCP kinematics since),
    puts nothing back; without the token (the set dropped, LinuxCNC's second handler of one abort) it does."""
    from pige_sym.cycle import linuxcnc_remap as r

    monkeypatch.setattr(r, "IN_FORCE", str(tmp_path / "abort.in_force"))
    interp = FakeInterp()
    interp.params["_hal[motion.switchkins-type]"] = 0.0
    assert r.pige_m451_prolog(interp) == r.INTERP_OK  # found: identity
    interp.params["_hal[motion.switchkins-type]"] = 1.0  # probing in TCP kinematics, then Esc
    assert r.pige_cycle_abort(interp) == 0.0
    (tmp_path / "abort.in_force").write_text("another abort's token\n")
    assert r.pige_cycle_abort(interp) == 0.0  # not this abort's: again
    (tmp_path / "abort.in_force").write_text(r.ABORTED["token"] + "\n")  # the helper saw identity
    # the operator's M428 (TCP), then an abort of their job, a second later
    assert r.pige_cycle_abort(interp) == -1.0 and interp.params["_pige_kins_before"] == -1
    assert r.pige_cycle_abort(interp) == -1.0
