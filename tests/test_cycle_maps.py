"""The cycle's map test without LinuxCNC (``M451 P3 Q<k>``, then ``M451 P2``): pige's kinematics component installed
with ``--map C,A --map-step 45``, each setup's probe log written by pige's virtual probing machine with hidden error
maps (``pige simulate --error-maps``), the running HAL a dictionary (:class:`test_cycle_runtime.FakeHal`).

What is checked: the settings and the map pins (values file, read back, fingerprint); the refusals (stock
kinematics, no map test, a setup number outside 1..N, Q missing in the remap); the message after each setup (where
the next sphere goes); the joint identification after the last one and its proposal (8 PIGE pins and the map pins,
the grid, the values within the truth's reach); ``M451 P2``'s safe order (node counts to 0 first, last to the grid
size) and its values file in the same order; a setup measured again replaces the earlier one; an entry starts the
map test afresh."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cycle_configs import install_args, write_pige_component, write_stock
from test_cycle_runtime import FakeHal, messages, request

from pige_sym.cli.main import main
from pige_sym.cycle.layout import Layout
from pige_sym.cycle.runtime import run_step
from pige_sym.errors import InputError

TRUTH = "EY0A=15,EZ0A=-10,EB0A=60,EC0A=-45,EX0C=12,EY0C=-8,EA0C=40,EB0C=-30"
MODULE = "pige_xyzac_trt"
MAP_OPTIONS = ("--map", "C,A", "--map-step", "45", "--contacts", "4", "--map-sphere", "-25,10,10",
               "--map-sphere", "-15,-15,10")
SPHERES = ([20.0, 10.0, 15.0], [-25.0, 10.0, 10.0], [-15.0, -15.0, 10.0])


def hidden_maps(path: Path) -> Path:
    """Error maps of C (45° grid) for the virtual machine: harmonic 2 and 3 of each motion, µm and µrad."""
    from pige_sym.model.error_motions import axis_motions

    t = np.radians(np.arange(0.0, 360.0, 45.0))
    rng = np.random.default_rng(5)
    motions = {}
    for m in axis_motions("C"):
        size = 1.5 if m.unit == "um" else 15.0
        v = size * (rng.normal() * np.cos(2 * t + 0.3) + rng.normal() * np.sin(3 * t + 1.1))
        motions[m.name] = {"value": [round(float(x), 3) for x in v], "unit": m.unit}
    doc = {"machine": "wC'A'bXYZ(C1)t",
           "error_motions": {"C": {"angle_deg": list(np.degrees(t)), "full_turn": True, **motions}}}
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture
def maps_config(tmp_path: Path) -> Layout:
    ini = write_pige_component(tmp_path / "cfg")
    assert main(install_args(ini, "--kinematics", "pige", *MAP_OPTIONS, "--force")) == 0
    return Layout(ini.parent.resolve())


@pytest.fixture
def pige_hal(monkeypatch: pytest.MonkeyPatch, maps_config: Layout) -> FakeHal:
    from pige_sym.cycle import hal_live
    from pige_sym.cycle.context import read_context

    ctx = read_context(maps_config.config, live=False)
    fake = FakeHal(dict(ctx.file_values))
    monkeypatch.setattr(hal_live, "_run", fake)
    monkeypatch.setattr(hal_live.shutil, "which", lambda name: "/usr/bin/halcmd")
    return fake


def probe_setup(layout: Layout, name: str, k: int, maps: Path, seed: int = 3) -> Path:
    run = request(layout, name, "map", setup=k)
    assert run_step("prepare", run, live=False) == 0, messages(run, "prepare")
    assert main(["simulate", "--instrument", "sphere-probe", "--program", str(run / "program.ngc"), "--pige", TRUTH,
                 "--error-maps", str(maps), "--seed", str(seed), "--noise", "0.3",
                 "--out", str(run / "probe_log.txt")]) == 0
    run_step("analyse", run, live=False)
    return run


def test_install_writes_the_map_settings_and_the_map_pins_in_the_safe_order(maps_config):
    settings = json.loads(maps_config.settings.read_text())
    assert settings["map"] == {"axes": ["C", "A"], "step_deg": 45.0, "setups": 3, "per_direction": [], "ranges": [],
                               "spheres_mm": list(SPHERES[1:])}
    assert settings["probing"]["contacts"] == 4
    lines = [ln.split("#")[0].split() for ln in maps_config.values.read_text().splitlines() if ln.strip()[:1] != "#"]
    pins = [w[1] for w in lines]
    nodes = [i for i, p in enumerate(pins) if p.endswith("-nodes")]
    assert pins[nodes[0]] == pins[nodes[2]] == f"{MODULE}.map-c-nodes"  # 0 first, the size last
    assert [lines[i][2] for i in nodes] == ["0", "0", "0", "0"]  # no map in force yet
    assert nodes[:2] == [8, 9] and nodes[2:] == [8 + 2 + 3 + 7 * 8, len(pins) - 1]
    assert f"{MODULE}.exc-07" in pins and f"{MODULE}.exc-08" not in pins and f"{MODULE}.eya-02" in pins
    again = maps_config.values.read_text()
    assert main(install_args(maps_config.config / "xyzac-trt.ini", "--kinematics", "pige", *MAP_OPTIONS,
                             "--force")) == 0
    assert maps_config.values.read_text() == again  # twice equals once


def test_the_stock_kinematics_refuse_a_map_test_naming_why(tmp_path):
    ini = write_stock(tmp_path / "stock")
    assert main(install_args(ini, *MAP_OPTIONS)) == 2
    assert main(install_args(ini, "--force")) == 0
    layout = Layout(ini.parent.resolve())
    run = request(layout, "m1", "map", setup=1)
    assert run_step("prepare", run, live=False) == 1
    error = messages(run, "prepare")["error"]
    assert "holds no error map" in error and "COMP_FILE" in error


@pytest.mark.parametrize("setup", [None, 0, 4])
def test_a_setup_outside_the_test_is_refused_before_anything_moves(maps_config, setup):
    run = request(maps_config, "m", "map", setup=setup)
    assert run_step("prepare", run, live=False) == 1
    assert "setups 1..3" in messages(run, "prepare")["error"]
    assert not (run / "program.ngc").exists()


def test_the_remap_wants_q_with_p3():
    from pige_sym.cycle import linuxcnc_remap as remap

    assert remap._map_setup("map", {"p": 3.0}).startswith("PIGE M451 P3 probes one setup")
    assert remap._map_setup("map", {"p": 3.0, "q": 2.0}) == 2
    assert isinstance(remap._map_setup("map", {"p": 3.0, "q": 1.5}), str)
    assert remap._map_setup("check", {"p": 0.0, "q": 2.0}) is None


def test_three_setups_then_the_proposal_then_the_entry_in_the_safe_order(maps_config, pige_hal, tmp_path):
    maps = hidden_maps(tmp_path / "maps.json")
    first = probe_setup(maps_config, "s1", 1, maps)
    m = messages(first)
    assert m["error"] is None and m["lines"][0].startswith("PIGE M451 P3 map setup 1 of 3 measured: 24 poses, 96")
    assert "X, Y, Z = -25, 10, 10 mm" in m["lines"][1] and "M451 P3 Q2" in m["lines"][1]
    assert "--map-point" in (first / "log.txt").read_text()
    again = probe_setup(maps_config, "s1b", 1, maps, seed=4)  # setup 1 again: replaces the first
    assert "setups measured: 1;" in messages(again)["lines"][1]
    probe_setup(maps_config, "s3", 3, maps)
    last = probe_setup(maps_config, "s2", 2, maps)
    m = messages(last)
    assert m["error"] is None, m
    assert m["lines"][0].startswith("PIGE M451 P3 map test: FAIL")
    proposal = json.loads(maps_config.proposal.read_text())
    assert proposal["kind"] == "map"
    new = {e["pin"]: e["new"] for e in proposal["entries"]}
    assert {f"{MODULE}.{n}" for n in ("ex0c", "ey0c", "ey0a", "ez0a")} <= set(new)
    assert new[f"{MODULE}.map-c-nodes"] == 8 and new[f"{MODULE}.map-a-nodes"] == 3
    assert new[f"{MODULE}.map-c-step"] == 45
    truth = json.loads(maps.read_text())["error_motions"]["C"]["EXC"]["value"]
    found = [new.get(f"{MODULE}.exc-{k:02d}", 0.0) for k in range(8)]
    assert np.abs(np.array(found) - truth).max() < 0.5, (found, truth)
    assert "s1b" in " ".join(m["lines"]) and "s1 " not in " ".join(m["lines"])

    enter = request(maps_config, "p2", "enter")
    assert run_step("prepare", enter) == 0 and run_step("enter", enter) == 0, messages(enter, "enter")
    sets = [c[2:] for c in pige_hal.commands if c[1] == "setp"]
    names = [s[0] for s in sets]
    assert names[-2:] == [f"{MODULE}.map-c-nodes", f"{MODULE}.map-a-nodes"]  # the node counts last
    assert pige_hal.values[f"{MODULE}.map-c-nodes"] == 8
    assert pige_hal.values[f"{MODULE}.exc-03"] == pytest.approx(new[f"{MODULE}.exc-03"])
    text = maps_config.values.read_text()
    assert f"setp {MODULE}.map-c-nodes 8" in text and text.index(f"{MODULE}.map-c-nodes 0") < text.index(
        f"{MODULE}.exc-00") < text.index(f"{MODULE}.map-c-nodes 8")
    from pige_sym.cycle.context import read_context

    ctx = read_context(maps_config.config, live=False)
    assert ctx.file_values[f"{MODULE}.map-c-nodes"] == 8  # read back: the last line of the pin
    nxt = probe_setup(maps_config, "s4", 2, maps)  # the configuration changed: the test starts afresh
    assert "setups measured: 2;" in messages(nxt)["lines"][1]


def test_a_map_in_force_is_read_back_and_the_proposal_adds_to_it(maps_config, pige_hal):
    from pige_sym.cycle.context import read_context
    from pige_sym.cycle.map_analyse import map_changes

    pige_hal.values |= {f"{MODULE}.map-c-nodes": 8.0, f"{MODULE}.map-c-step": 45.0, f"{MODULE}.map-c-full-turn": 1.0}
    pige_hal.values[f"{MODULE}.exc-02"] = 1.25
    ctx = read_context(maps_config.config)
    assert ctx.live and ctx.in_force[f"{MODULE}.exc-02"] == 1.25

    class Entered:  # the weighed maps: EXC 0.5 at every node of C, nothing on A
        pass

    from pige_sym.model.error_motions import error_maps_from

    doc = {"C": {"angle_deg": [45.0 * k for k in range(8)], "full_turn": True, "value": {"EXC": [0.5] * 8}}}
    entered = Entered()
    entered.error_maps = error_maps_from(doc)  # type: ignore[attr-defined]
    changes = map_changes(ctx, entered)
    assert changes[f"{MODULE}.exc-02"] == 0.5  # in force 1.25 + 0.5: the setups were probed with it acting
    assert changes[f"{MODULE}.map-c-nodes"] == 0.0
    pige_hal.values[f"{MODULE}.map-c-nodes"] = 12.0  # a map on another grid (30 deg) in force: refused
    with pytest.raises(InputError, match="a map of C on another grid is in force"):
        map_changes(read_context(maps_config.config), entered)


def test_safe_order_sets_the_node_count_to_zero_first_and_undoes_in_reverse(maps_config):
    from pige_sym.cycle.context import read_context
    from pige_sym.cycle.map_pins import safe_order

    ctx = read_context(maps_config.config, live=False)
    pins = {p.pin: p for p in ctx.setup.pins}
    in_force = dict(ctx.in_force) | {f"{MODULE}.map-c-nodes": 8.0}
    changes = [(pins[f"{MODULE}.ex0c"], 0.0, 1.0), (pins[f"{MODULE}.exc-01"], 0.0, 0.4)]
    order = [(p.pin, old, new) for p, old, new in safe_order(ctx.setup, in_force, changes)]
    assert order == [(f"{MODULE}.map-c-nodes", 8.0, 0.0), (f"{MODULE}.ex0c", 0.0, 1.0),
                     (f"{MODULE}.exc-01", 0.0, 0.4), (f"{MODULE}.map-c-nodes", 0.0, 8.0)]


def test_an_earlier_install_s_remap_without_q_is_replaced(tmp_path):
    ini = write_stock(tmp_path / "old")
    assert main(install_args(ini, "--force")) == 0
    text = ini.read_text()
    assert "REMAP = M451 modalgroup=10 argspec=pq " in text
    ini.write_text(text.replace("argspec=pq", "argspec=p"))  # as the install wrote it before M451 P3
    assert main(install_args(ini, "--force")) == 0
    again = ini.read_text()
    assert again.count("REMAP = M451 ") == 1 and "REMAP = M451 modalgroup=10 argspec=pq " in again
