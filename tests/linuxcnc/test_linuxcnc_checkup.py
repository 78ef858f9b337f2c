"""The check-up on real LinuxCNC 2.9 (issues 42 and 49): pige's check-up program runs on the shipped ``xyzac-trt``
simulation, ``pige checkup`` says ``ok`` for a true machine that did not drift and ``drifted`` for one whose pivots
moved, and the entries it prints for the controller keep what it held.

- **The full calibration** is the 13-pose probing run of the AC table in identity kinematics (:mod:`loop_setup`,
  :func:`conftest.table_runs`: made once per session): its LinuxCNC log imported and stored with ``pige history
  add`` (machine ``LCNC-AC``, tolerances of 40 µm / 150 µrad, so a drift of a few µm is inside them).
- **The correction in force**: the shop enters the full calibration's correction as ``pige compensate --controller
  linuxcnc --current <the shipped pins>`` prints it (the trt pins' ``sets``/``setp`` lines, :mod:`corrections`);
  both simulations run with that configuration.  The check-up probes in identity kinematics, so it measures the
  machine itself: the values in force are that correction.
- **The check-up program** is ``pige program --checkup --machine-id LCNC-AC`` (everything from the history: the
  sphere where the calibration found it, the stock lines' pivots, σ = −1, M429/M428, stylus T9 of 30 mm; the probing
  feed and clearance of the calibration given again, ``--probe-feed 50 --clearance 1``, which the history does not
  keep), read back before it is written.
- **Two simulations at once** run it: the same true table (``still``), and the true table with its pivots moved as a
  warm-up moves them (EX0C +6 µm, EZ0A +5 µm: ``warm``).  Their logs are imported (``--program``) and judged in
  this order by ``pige checkup --controller linuxcnc --current <the simulation's INI>`` (``still`` with
  ``--corrected``: the calibration's correction was entered before it): ``still`` must be ``ok`` (exit 0), ``warm``
  ``drifted`` (exit 1) with EX0C and EZ0A outside their limits and every check-up PIGE within 4 standard errors
  (+0.3 µm) of the true table's.
- **The entries** (issue 49): no printed line changes a PIGE the check-up held (EB0A, EC0A, EA0C, EB0C) by more
  than 3 of its standard errors from its value in force (pige's kinematics component: the held pins are named "leave
  it as it is", never set), and the trt pins it prints (absolute, from the INI's values) move each axis line by the
  change entered since the values in force, not by the value again.
- **Machine time**: the check-up's predicted time (``pige plan --checkup`` with the simulation's speeds: rapids
  100 mm/s, rotary axes 30°/s, 1000 mm/s²) is printed beside LinuxCNC's simulated time.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from corrections import TRT_MODULE, enter_trt_pins, trt_correction
from lcnc_harness import IniChange, RunResult, compile_component, make_sim, run_sim
from loop_setup import CLEARANCE_MM, MACHINES, PROBE_FEED_MM_MIN, READ_PINS, ProbeRun, pige, run_all
from true_table import COMPONENT_NAME, component_source

pytestmark = pytest.mark.linuxcnc
WARM = {"EX0C": 6.0, "EZ0A": 5.0}
MACHINE_ID = "LCNC-AC"
FREE = ("EY0A", "EZ0A", "EX0C", "EY0C")
HELD = ("EB0A", "EC0A", "EA0C", "EB0C")


def _run_checkup(program: Path, root: Path, pige_values: dict[str, float], entered: list[IniChange]) -> RunResult:
    """The check-up program on the xyzac-trt simulation with a true table of these PIGEs and the configuration the
    calibration's correction was ``entered`` into."""
    m = MACHINES["AC"]
    table = m.true_table(pige_values)
    sim = make_sim(root, m.kind, table.hal_lines(), entered)
    compile_component(sim, component_source(m.code), COMPONENT_NAME)
    local = sim.cfg / program.name
    local.write_text(program.read_text())
    steps = [{"op": "mdi", "lines": [f"T{m.stylus[0]} M6"]},
             {"op": "program", "file": str(local), "timeout": 1800, "clock": "ptt.clock"},
             {"op": "read", "pins": READ_PINS}]
    return run_sim(sim, steps)


@pytest.fixture(scope="module")
def checkup(table_runs, tmp_path_factory: pytest.TempPathFactory) -> dict:
    full: ProbeRun = table_runs(("AC", "identity"))[("AC", "identity")]
    assert full.run.result["ok"], full.run.summary()
    folder = tmp_path_factory.mktemp("lcnc_checkup")
    full.identification_file  # noqa: B018 - imports LinuxCNC's log into probe.csv beside it
    tolerances = folder / "tol.json"
    tolerances.write_text(json.dumps({"format": "pige-tolerances 1", "defaults": {"um": 40, "urad": 150}}))
    db = str(folder / "history.db")
    pige("history", "add", str(full.sim.root / "probe.csv"), "--machine-id", MACHINE_ID, "--db", db, "--date",
         "2026-05-04T07:00", "--method", "gauss-newton", "--tolerances", str(tolerances), cwd=folder)
    program = folder / "checkup.ngc"
    opts = ["--probe-feed", f"{PROBE_FEED_MM_MIN:g}", "--clearance", f"{CLEARANCE_MM:g}"]
    pige("program", "--checkup", "--machine-id", MACHINE_ID, "--db", db, "--dialect", "linuxcnc", *opts, "--out",
         str(program), cwd=folder)
    plan = json.loads(pige("plan", "--checkup", "--machine-id", MACHINE_ID, "--db", db, *opts, "--json", cwd=folder))
    m = MACHINES["AC"]
    in_force = trt_correction(m, full.identification_file)[1]  # the calibration's correction, as a shop enters it
    entered = enter_trt_pins(m.kind, in_force)
    truth = m.pige
    warm = {k: v + WARM.get(k, 0.0) for k, v in truth.items()}
    runs = run_all({"still": lambda: _run_checkup(program, folder / "still", truth, entered),
                    "warm": lambda: _run_checkup(program, folder / "warm", warm, entered)})
    out = {"db": db, "program": program, "plan": plan, "runs": runs, "truth": {"still": truth, "warm": warm},
           "in_force": in_force, "full_values": full.identification["pige"]}
    for hour, key in ((8, "still"), (9, "warm")):
        run = runs[key]
        assert run.result["ok"], run.summary()
        csv = folder / f"{key}.csv"
        pige("import-probe", str(folder / key / "cfg" / "pige_probe.txt"), "--format", "linuxcnc", "--program",
             str(program), "--out", str(csv), cwd=folder)
        ini = folder / key / "cfg" / f"{m.kind}-trt.ini"
        out[key] = _judge(csv, db, f"2026-05-05T{hour:02d}:00", folder,
                          ["--controller", "linuxcnc", "--current", str(ini), *(["--corrected"] * (key == "still"))])
    return out


def _judge(csv: Path, db: str, date: str, folder: Path, extra: list[str]) -> tuple[int, dict]:
    """``pige checkup`` as a user runs it: (exit status, its JSON)."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "pige_sym", "checkup", str(csv), "--machine-id", MACHINE_ID, "--db",
                           db, "--date", date, *extra, "--json"], cwd=folder, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode in (0, 1), proc.stderr
    return proc.returncode, json.loads(proc.stdout)


def test_the_check_up_program_runs_on_linuxcnc(checkup: dict) -> None:
    program = checkup["program"].read_text()
    assert "(pige checkup: EY0A,EZ0A,EX0C,EY0C)" in program and "M429" in program and "#5400 NE 9]" in program
    for key, run in checkup["runs"].items():
        step = next(s for s in run.result["steps"] if s["op"] == "program")
        contacts = sum(ln.startswith("G38.2") for ln in program.splitlines())
        print(f"{key}: {contacts} contacts, {step['sim_s']:.1f} s simulated (predicted "
              f"{checkup['plan']['seconds']:.1f} s), {step['wall_s']:.1f} s wall, attempts {run.attempts}")
        assert 0.5 < checkup["plan"]["seconds"] / step["sim_s"] < 1.5


def test_a_machine_that_did_not_drift_is_ok(checkup: dict) -> None:
    code, res = checkup["still"]
    print("still:", {i["name"]: round(i["value"] - checkup["truth"]["still"][i["name"]], 3) for i in res["items"]})
    assert (code, res["verdict"]) == (0, "ok"), res


def test_a_machine_whose_pivots_moved_has_drifted(checkup: dict) -> None:
    code, res = checkup["warm"]
    items = {i["name"]: i for i in res["items"]}
    print("warm:", {n: (round(i["value"], 3), i["limit"]["by"] if i["limit"] else None) for n, i in items.items()})
    assert (code, res["verdict"]) == (1, "drifted"), res
    assert items["EX0C"]["limit"]["outside"] and items["EZ0A"]["limit"]["outside"]
    for name in FREE:
        assert abs(items[name]["value"] - checkup["truth"]["warm"][name]) < 4 * items[name]["std"] + 0.3, items[name]
    assert res["to_enter"]["EX0C"] == pytest.approx(WARM["EX0C"], abs=1.0)  # the change, not the value again


def _printed_pins(text: str, module: str) -> dict[str, float]:
    """The trt pins' values the entries set: ``setp <module>.<pin> V`` and ``sets :<pin> V`` (a netted pin)."""
    found = {p: float(v) for p, v in re.findall(rf"^setp {re.escape(module)}\.(\S+)\s+(\S+)\s*$", text, re.M)}
    found |= {p: float(v) for p, v in re.findall(r"^sets :(\S+)\s+(\S+)\s*$", text, re.M)}
    return found


def test_the_entries_after_a_check_up_keep_what_it_held(checkup: dict) -> None:
    """Issue 49, "held values": the warm check-up's entries for the simulation's own configuration (its INI as
    ``--current``).  pige's kinematics component: no line sets a held PIGE (each is named, left as it is), and no
    line sets any PIGE pin to a value (its pins hold absolute values: the change is named, to add).  The trt pins:
    each axis line moves by the change entered since the values in force (EX0C +6, EZ0A +5 µm, within a nanometre
    of what the check-up says to enter), never by the PIGE's value again; the held tilts have no trt pin."""
    code, res = checkup["warm"]
    changes = res["changes"]
    text = changes["controller_text"]
    assert text and code == 1, res
    component = "pige_xyzac_trt"
    for name in HELD:
        assert not re.search(rf"^setp {component}\.{name.lower()}\s", text, re.M), name
        assert f"{component}.{name.lower()}: held by the check-up" in text and "leave it as it is" in text
        assert changes["held"][name] == pytest.approx(checkup["full_values"][name], abs=3 * changes["held_std"][name])
    assert not re.search(rf"^setp {component}\.e[xyz]0[ac]\s", text, re.M)
    module = TRT_MODULE["xyzac"]
    pins, before = _printed_pins(text, module), checkup["in_force"]
    moved = {p: (pins[p] - before[p]) * 1000.0 for p in pins if p in before}  # µm
    enter = {n: v or 0.0 for n, v in res["to_enter"].items()}
    assert moved["x-rot-point"] == pytest.approx(enter["EX0C"], abs=1e-3)
    assert moved["y-rot-point"] == pytest.approx(enter["EY0C"], abs=1e-3)
    assert moved["y-rot-point"] + moved["y-offset"] == pytest.approx(enter["EY0A"], abs=1e-3)
    assert moved["z-offset"] == pytest.approx(enter["EZ0A"], abs=1e-3)
    assert enter["EX0C"] == pytest.approx(WARM["EX0C"], abs=1.0) and enter["EZ0A"] == pytest.approx(WARM["EZ0A"],
                                                                                                     abs=1.0)
    print("warm entries:", {p: round(v, 4) for p, v in moved.items()}, "um")
