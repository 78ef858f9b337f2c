"""Map test design (issue 39 item 3): ``pige plan --map``, ``pige program --map`` and round trips on pige's virtual
machine.

Round trip per machine (an AC and a BC table, a fork head, a table C with a head B): the plan, one probing program
per setup (a different dialect per machine), each run on pige's virtual probing machine with hidden error maps
(``simulate --error-maps``), imported, and all identified jointly with ``identify --map``.  Every value must lie
within 4 standard errors (+0.5 µm or µrad) of the truth's §10 representative, projected here by a least-squares fit
written in the test; the standard errors identify reports must be those the plan predicted; and what the first
setup alone leaves undetermined must be what the plan said it would.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pige_sym.cli.main import main

AC, BC, FORK, MIXED = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"
STEP = 30.0
SPHERE = ["--sphere", "100,20,60", "--sphere-radius", "12.7", "--stylus-radius", "1.5"]
CONTROLLER = ["--rtcp-off", "M429", "--rtcp-on", "M428", "--stylus-tool", "9", "--stylus-length", "120"]
#: machine -> (dialect of its round trip, options of its plan and programs)
CASES = {
    AC: ("heidenhain", []),
    BC: ("siemens", []),
    FORK: ("fanuc", ["--tool", "0,0,-160", "--map-range", "A=-60:60"]),
    MIXED: ("linuxcnc", ["--tool", "0,0,-160", "--map-range", "B=-60:60"]),
}


def _axes(machine: str) -> str:
    return "C," + ("B" if "B" in machine else "A")


def _projected(grid: np.ndarray, values: np.ndarray, positioning: bool) -> np.ndarray:
    """§10's representative, written here: the least-squares residual on 1 (φ) or on 1, cos θ, sin θ."""
    t = np.radians(grid)
    basis = np.ones((t.size, 1)) if positioning else np.column_stack([np.ones_like(t), np.cos(t), np.sin(t)])
    return np.asarray(values - basis @ np.linalg.lstsq(basis, values, rcond=None)[0])


def _truth(grids: dict[str, Any], rng: np.random.Generator, names: dict[str, list[str]]) -> dict[str, Any]:
    """Maps with harmonics 1-3 and a little noise (first harmonics included: the fit must set them aside)."""
    out = {}
    for ax, grid in grids.items():
        g = np.array(grid["angle_deg"])
        t = np.radians(g)
        body: dict[str, Any] = {"angle_deg": g.tolist(), "full_turn": grid["full_turn"]}
        for name in names[ax]:
            size = 1.0 if name[1] in "XYZ" else 6.0
            v = sum(rng.normal(scale=size) * np.cos(h * t + rng.uniform(0, 6.3)) for h in (1, 2, 3))
            body[name] = {"value": (v + rng.normal(scale=0.2 * size, size=t.size)).tolist()}
        out[ax] = body
    return out


def _motions(axis: str) -> list[str]:
    return [f"E{c}{axis}" for c in "XYZABC"]


def _json(capsys: pytest.CaptureFixture[str], args: list[str]) -> dict[str, Any]:
    capsys.readouterr()
    code = main(args)
    out = capsys.readouterr().out
    assert code in (0, 1), out
    return json.loads(out)


def _round_trip(folder: Path, machine: str, capsys: pytest.CaptureFixture[str], *, options: list[str],
                dialect: str, truth_names: dict[str, list[str]] | None = None, seed: int = 5) -> dict[str, Any]:
    """plan → programs → virtual machine with hidden maps → import → identify (module docstring)."""
    probe = ["--machine", machine, *SPHERE]
    plan = _json(capsys, ["plan", "--instrument", "sphere-probe", *probe, *options, "--noise", "0.5", "--json"])
    rng = np.random.default_rng(seed)
    names = truth_names or {ax: _motions(ax) for ax in plan["prediction"]["error_motions"]}
    truth = _truth(plan["prediction"]["error_motions"], rng, names)
    (folder / "truth.json").write_text(json.dumps({"error_motions": truth}), encoding="utf-8")
    from pige_sym.kernels import load_kernels

    pige = {n: float(rng.uniform(-10, 10)) for n in load_kernels(machine).LOCATION_PARAMETERS}
    (folder / "pige.json").write_text(json.dumps({"machine": machine, "pige": pige}), encoding="utf-8")
    assert main(["program", "--instrument", "sphere-probe", *probe, *options, "--dialect", dialect, *CONTROLLER,
                 "--out", str(folder / "map.nc")]) == 0
    csvs = []
    for i in range(1, len(plan["setups"]) + 1):
        prog, log, csv = folder / f"map_{i}.nc", folder / f"log_{i}.txt", folder / f"setup_{i}.csv"
        assert main(["simulate", "--instrument", "sphere-probe", "--dialect", dialect, "--program", str(prog),
                     "--pige", str(folder / "pige.json"), "--error-maps", str(folder / "truth.json"), "--noise",
                     "0.5", "--seed", str(i), "--setup-offset", "30,-20,10", "--out", str(log)]) == 0
        assert main(["import-probe", str(log), "--format", dialect, "--program", str(prog), "--out", str(csv)]) == 0
        csvs.append(str(csv))
    return {"plan": plan, "truth": truth, "csvs": csvs}


def _identify(capsys: pytest.CaptureFixture[str], csvs: list[str], axes: str, *extra: str) -> dict[str, Any]:
    return _json(capsys, ["identify", *csvs, "--map", axes, "--map-step", f"{STEP:g}", "--json", *extra])


#: The default suite's round trips: the AC table (Heidenhain) and the table C with a head B (LinuxCNC, both sides of
#: the machine); the fork head (Fanuc, its inner axis mapped with the stylus at three tools: 5.5 s of CPU) and the
#: BC table (Siemens) run with ``make test-slow`` (every dialect's map programs are still written and read back by
#: ``test_one_program_per_setup_in_every_dialect``, the fork head's among them).
SLOW_TRIPS = (FORK, BC)


@pytest.fixture(scope="module", params=[pytest.param(m, marks=pytest.mark.slow) if m in SLOW_TRIPS else m
                                        for m in CASES])
def case(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    machine = request.param
    dialect, extra = CASES[machine]
    folder = tmp_path_factory.mktemp("map_" + "".join(c for c in machine if c.isalnum()))
    return {"machine": machine, "dialect": dialect, "folder": folder,
            "options": ["--map", _axes(machine), "--map-step", f"{STEP:g}", *extra]}


@pytest.fixture(scope="module")
def trips() -> dict[str, dict[str, Any]]:
    """The round trips run so far (each machine's once, shared by its tests)."""
    return {}


def _trip(case: dict[str, Any], trips: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    m = case["machine"]
    if m not in trips:
        trips[m] = _round_trip(case["folder"], m, capsys, options=case["options"], dialect=case["dialect"])
        trips[m]["out"] = _identify(capsys, trips[m]["csvs"], _axes(m))
    return trips[m]


def test_every_value_of_every_machine_is_found_within_its_standard_error(case: dict[str, Any], trips: Any,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    trip = _trip(case, trips, capsys)
    out, plan = trip["out"], trip["plan"]
    assert plan["complete"] and not out["map_undetermined"]
    z, ratio = [], []
    for ax, body in trip["truth"].items():
        est, pred = out["error_motions"][ax], plan["prediction"]["error_motions"][ax]
        grid = np.array(body["angle_deg"])
        np.testing.assert_allclose(est["angle_deg"], grid)
        for name in _motions(ax):
            value = np.array(est[name]["value"], dtype=float)
            std = np.array(est[name]["std"], dtype=float)
            truth = _projected(grid, np.array(body[name]["value"]), name[1] == name[2])
            assert np.all(np.abs(value - truth) <= 4 * std + 0.5), (name, np.round((value - truth) / std, 2))
            z += list((value - truth) / std)
            ratio += list(std / np.array(pred[name]["std"], dtype=float))
    rms = float(np.sqrt(np.mean(np.square(z))))
    print(f"{case['machine']}: {len(z)} values, RMS z {rms:.2f}, reported/predicted std "
          f"{min(ratio):.3f}-{max(ratio):.3f}")
    assert 0.5 < rms < 1.6, f"standard errors not honest: RMS z-score {rms:.2f}"
    assert 0.8 < min(ratio) and max(ratio) < 1.25, "identify's standard errors are not those the plan predicted"


def test_the_first_setup_alone_leaves_undetermined_what_the_plan_said(case: dict[str, Any], trips: Any,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    trip = _trip(case, trips, capsys)
    alone = _identify(capsys, trip["csvs"][:1], _axes(case["machine"]))
    planned = trip["plan"]["fewer_setups"][0]
    assert planned["setups"] == 1
    determined = sum(v is not None for body in alone["error_motions"].values() for k, m in body.items()
                     if isinstance(m, dict) for v in m["value"])
    assert determined == planned["determined"] < planned["values"]
    assert all("three points" in u["remedy"] for u in alone["map_undetermined"] if u["angle_deg"] is not None)
    inner = [u for u in alone["map_undetermined"] if "see 3 of its 6 motions" in u["why"]]
    assert inner, "one measured point per angle: three of the six motions are not seen"


def test_the_plan_text_states_the_setups_time_and_what_fewer_setups_miss(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["plan", "--instrument", "sphere-probe", "--machine", FORK, *SPHERE, *CASES[FORK][1], "--map", "C,A",
                 "--map-step", "30"])
    text = capsys.readouterr().out
    assert code == 0
    assert "3 setup(s)" in text and "0, 0, -260" in text and "50, 0, -160" in text and "min" in text
    assert "with setup 1 alone:" in text and "tool-side axis" in text
    # without the probe's tool and the controller no program command runs as printed: the plan says what to add
    assert "pige program" not in text and "give --stylus-tool, --stylus-length, --dialect here too" in text
    probe = ["--stylus-tool", "99", "--stylus-length", "120", "--dialect", "linuxcnc", "--rtcp-off", "M429",
             "--rtcp-on", "M428"]
    assert main(["plan", "--instrument", "sphere-probe", "--machine", FORK, *SPHERE, *CASES[FORK][1], "--map", "C,A",
                 "--map-step", "30", *probe]) == 0
    text = capsys.readouterr().out
    assert "pige program --instrument sphere-probe" in text and "--map-setups 3" in text
    assert "--stylus-tool 99 --stylus-length 120" in text and "--out map.ngc" in text


def test_a_head_with_one_stylus_cannot_map_its_inner_axis_and_says_why(capsys: pytest.CaptureFixture[str]) -> None:
    """The fork head's A carries the stylus: one stylus is one point of A's body at every angle."""
    plan = _json(capsys, ["plan", "--instrument", "sphere-probe", "--machine", FORK, *SPHERE, *CASES[FORK][1],
                          "--map", "C,A", "--map-step", "30", "--map-tool", "0,0,-160", "--json"])
    assert not plan["complete"] and len(plan["setups"]) == 1
    a = plan["prediction"]["error_motions"]["A"]
    assert all(v is None for n in _motions("A") for v in a[n]["std"])
    why = [u for u in plan["prediction"]["undetermined"] if u["motion"].endswith("A")]
    assert why and all("stylus or ball at three positions in the spindle" in u["remedy"] for u in why
                       if u["angle_deg"] is not None)
    assert all("its other angles" in u["remedy"] for u in why if u["angle_deg"] is None)
    # the outer C sees the stylus at a different place of its body at every A: one stylus determines it
    c = plan["prediction"]["error_motions"]["C"]
    assert all(v is not None for n in _motions("C") for v in c[n]["std"])


def test_the_ends_of_a_limited_range_are_met_from_one_side_and_their_reversal_is_undetermined(
        capsys: pytest.CaptureFixture[str]) -> None:
    plan = _json(capsys, ["plan", "--instrument", "sphere-probe", "--machine", FORK, *SPHERE, "--tool", "0,0,-160",
                          "--map", "A", "--map-per-direction", "A", "--map-step", "15", "--map-setups", "3", "--json"])
    rev = plan["prediction"]["error_motions"]["A"]["EAA:reversal"]["std"]
    grid = plan["prediction"]["error_motions"]["A"]["angle_deg"]
    # each end is met from inside only: going up from -45, coming down to it, arriving at 45 once
    assert rev[0] is None and rev[-1] is None and all(v is not None for v in rev[1:-1]), dict(zip(grid, rev,
                                                                                                   strict=True))
    ends = [u for u in plan["prediction"]["undetermined"] if u["motion"] == "EAA:reversal"]
    assert [u["angle_deg"] for u in ends] == [grid[0], grid[-1]]
    assert all("not seen" in u["why"] and "from both sides" in u["remedy"] for u in ends)


def test_poses_cover_the_grid_and_per_direction_meets_every_angle_from_both_sides() -> None:
    from pige_sym.identification.maps import MapSpec
    from pige_sym.model.trajectories import approach_directions
    from pige_sym.planning.map_setups import map_poses

    one = map_poses(AC, MapSpec(("C", "A"), 30.0), {"A": (0.0, 90.0)})
    assert one.shape == (48, 2) and not one[0].any()
    pairs = {(a, c) for a, c in one}
    assert pairs == {(a, c) for a in (0.0, 30.0, 60.0, 90.0) for c in np.arange(0.0, 360.0, 30.0)}
    both = map_poses(AC, MapSpec(("C",), 45.0, ("C",)), {"A": (0.0, 90.0)})
    seen = approach_directions(both)
    for a in (0.0, 45.0, 90.0):
        for c in np.arange(0.0, 360.0, 45.0):
            at = (both[:, 0] == a) & (np.mod(both[:, 1], 360.0) == c)
            assert {1, -1} <= set(seen[at, 1].tolist()), (a, c)


def test_the_proposed_points_are_three_not_on_one_line() -> None:
    from pige_sym.identification.maps import MapSpec
    from pige_sym.planning.map_setups import MapTestRequest, propose_points

    def area(p: list[np.ndarray]) -> float:
        return float(np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])))

    table = propose_points(MapTestRequest(AC, "rtest", MapSpec(("C", "A")), {"A": (0.0, 90.0)},
                                          np.array([100.0, 20.0, 60.0])))
    assert len(table) == 3 and area([p for p, _ in table]) > 1e3 and all(t is None for _, t in table)
    assert len({round(p[2], 9) for p, _ in table}) == 1  # same height: the same stem
    head = propose_points(MapTestRequest(FORK, "rtest", MapSpec(("C", "A")), {"A": (-45.0, 45.0)},
                                         np.array([100.0, 20.0, 60.0]), np.array([0.0, 0.0, -160.0])))
    assert area([t for _, t in head]) > 1e3 and all(np.allclose(p, head[0][0]) for p, _ in head)
    mixed = propose_points(MapTestRequest(MIXED, "rtest", MapSpec(("C", "B")), {"B": (-45.0, 45.0)},
                                          np.array([100.0, 20.0, 60.0]), np.array([0.0, 0.0, -160.0])))
    assert area([p for p, _ in mixed]) > 1e3 and area([t for _, t in mixed]) > 1e3


@pytest.mark.parametrize("machine", [AC, FORK, MIXED])
def test_one_program_per_setup_in_every_dialect(machine: str, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Table, head and mixed machines in the four dialects; a head's Heidenhain program is refused with why."""
    tool = ["--tool", "0,0,-160"] if machine != AC else []
    base = ["program", "--instrument", "sphere-probe", "--machine", machine, *SPHERE, *tool, *CONTROLLER, "--map",
            _axes(machine), "--map-step", "45", "--map-setups", "2"]
    for dialect in ("linuxcnc", "fanuc", "siemens", "heidenhain"):
        code = main([*base, "--dialect", dialect, "--out", str(tmp_path / f"{dialect}.nc")])
        if dialect == "heidenhain" and machine != AC:
            assert code == 2 and "cycle 4" in capsys.readouterr().err
            assert not list(tmp_path.glob("heidenhain*"))
            continue
        assert code == 0, capsys.readouterr().err
        assert (tmp_path / f"{dialect}_1.nc").is_file() and (tmp_path / f"{dialect}_2.nc").is_file()
        assert not (tmp_path / f"{dialect}_3.nc").exists()
        assert "read back" in capsys.readouterr().out
    # never over an existing program
    code = main([*base, "--dialect", "linuxcnc", "--out", str(tmp_path / "linuxcnc.nc")])
    assert code == 2 and "--force" in capsys.readouterr().err


def test_a_positioning_map_per_direction_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """C per direction on the AC table: the programs meet every C angle from both sides, the virtual machine turns
    the table to ECC+ or ECC- by the direction it came from, and identify finds both and their reversal."""
    names = {"C": [*(_motions("C")[:5]), "ECC+", "ECC-"], "A": []}
    trip = _round_trip(tmp_path, AC, capsys, dialect="linuxcnc", truth_names=names, seed=11,
                       options=["--map", "C", "--map-per-direction", "C", "--map-step", "45"])
    out = _json(capsys, ["identify", *trip["csvs"], "--map", "C", "--map-per-direction", "C", "--map-step", "45",
                         "--json"])
    truth = trip["truth"]["C"]
    grid = np.array(truth["angle_deg"])
    plus, minus = np.array(truth["ECC+"]["value"]), np.array(truth["ECC-"]["value"])
    est = out["error_motions"]["C"]
    checks = {"ECC": _projected(grid, 0.5 * (plus + minus), True), "ECC:reversal": plus - minus,
              **{n: _projected(grid, np.array(truth[n]["value"]), False) for n in _motions("C")[:5]}}
    for name, expected in checks.items():
        value, std = np.array(est[name]["value"], dtype=float), np.array(est[name]["std"], dtype=float)
        assert np.all(np.abs(value - expected) <= 4 * std + 0.5), (name, np.round((value - expected) / std, 2))


def test_simulate_refuses_an_error_maps_file_it_cannot_read(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "maps.json"
    for body, said in (({"pige": {}}, '"error_motions"'),
                       ({"error_motions": {"C": {"angle_deg": [0, 90, 180, 270], "EQC": {"value": [0, 0, 0, 0]}}}},
                        "EQC"),
                       ({"error_motions": {"C": {"angle_deg": [0, 90, 180, 270], "EXC": {"value": [0, 1, None]}}}},
                        "4 entries")):
        bad.write_text(json.dumps(body), encoding="utf-8")
        code = main(["simulate", "--machine", AC, "--trajectory", "cone-frustum", "--error-maps", str(bad),
                     "--out", str(tmp_path / "run.csv"), "--force"])
        assert code == 2 and said in capsys.readouterr().err
        assert not (tmp_path / "run.csv").exists()


def _maps_of(truth: dict[str, Any]) -> Any:
    from pige_sym.model.error_motions import AxisMaps, ErrorMaps, MapGrid

    return ErrorMaps({ax: AxisMaps(MapGrid(ax, np.array(b["angle_deg"]), b["full_turn"]),
                                   {n: np.array(v["value"]) for n, v in b.items() if isinstance(v, dict)})
                      for ax, b in truth.items()})


def _check_against(result: Any, pred: Any, truth: dict[str, Any]) -> list[float]:
    """Every value of ``result`` within 4 std (+0.5) of the projected truth; reported/predicted std ratios."""
    ratios = []
    for ax, body in truth.items():
        grid = np.array(body["angle_deg"])
        for name in _motions(ax):
            value, std = result.maps[ax].value[name], result.maps[ax].std[name]
            expected = _projected(grid, np.array(body[name]["value"]), name[1] == name[2])
            assert np.all(np.abs(value - expected) <= 4 * std + 0.5), (name, np.round((value - expected) / std, 2))
            ratios += list(std / pred.maps[ax].std[name])
    return ratios


def test_an_rtest_plan_predicts_the_standard_errors_identify_reports() -> None:
    """R-test: three ball positions; runs simulated with hidden maps; identify's std are the plan's."""
    from pige_sym.identification.maps import MapSpec, identify_maps
    from pige_sym.model.trajectories import Trajectory
    from pige_sym.planning.map_plan import plan_map_test
    from pige_sym.planning.map_setups import MapTestRequest
    from pige_sym.simulation.simulator import simulate

    spec = MapSpec(("C", "A"), STEP)
    plan = plan_map_test(MapTestRequest(AC, "rtest", spec, {"A": (0.0, 90.0)}, np.array([120.0, 0.0, 80.0]),
                                        noise_um=0.25, pose_s=12.0))
    assert len(plan.setups) == 3 and plan.prediction.complete and plan.seconds == 3 * 48 * 12.0
    truth = _truth(plan.prediction.to_dict()["error_motions"], np.random.default_rng(2),
                   {"C": _motions("C"), "A": _motions("A")})
    items = []
    for i, s in enumerate(plan.setups):
        traj = Trajectory("map", ("A", "C"), s.angles_deg, np.arange(len(s.angles_deg)) * 12.0, "map grid")
        run = simulate(AC, traj, pige={"EX0C": 5.0, "EB0A": -12.0}, ball_mm=s.point_mm, noise_um=0.25, seed=i,
                       error_maps=_maps_of(truth))
        items.append((f"run{i}", run.measurement))
    ratios = _check_against(identify_maps(items, spec), plan.prediction, truth)
    assert 0.8 < min(ratios) and max(ratios) < 1.25


def test_a_ballbar_plan_names_its_setups_and_predicts_identifys_standard_errors() -> None:
    """Ballbar: one reading per pose, so many setups; the chosen ones simulated with hidden maps and identified."""
    from pige_sym.identification.maps import MapSpec, identify_maps
    from pige_sym.planning.map_ballbar import plan_ballbar_maps
    from pige_sym.planning.map_setups import MapTestRequest
    from pige_sym.simulation.ballbar import simulate_ballbar

    spec = MapSpec(("C",), 45.0)
    plan = plan_ballbar_maps(MapTestRequest(AC, "ballbar", spec, {"A": (0.0, 90.0)}, np.array([100.0, 0.0, 50.0]),
                                            noise_um=0.2, pose_s=12.0))
    assert plan.prediction.complete and 2 <= len(plan.setups) < 12
    k, fewer = plan.fewer[0]
    assert k == 1 and not fewer.complete
    truth = _truth(plan.prediction.to_dict()["error_motions"], np.random.default_rng(4), {"C": _motions("C")})
    items = [(s.label, simulate_ballbar(AC, s.ballbar, pige={"EX0C": 5.0}, noise_um=0.2, seed=i,
                                        error_maps=_maps_of(truth))) for i, s in enumerate(plan.setups)]
    ratios = _check_against(identify_maps(items, spec), plan.prediction, truth)
    print([s.label for s in plan.setups], {n: round(plan.prediction.worst("C", n), 2) for n in _motions("C")},
          f"std ratio {min(ratios):.2f}-{max(ratios):.2f}")
    # identify scales its standard errors by the noise it estimates, here from 26 degrees of freedom: over seeds
    # 0-5 the ratio to the planned ones (the nominal noise) was 0.61-1.03
    assert 0.5 < min(ratios) and max(ratios) < 1.5
    # determined is not precise: two setups leave ECC at ~70 urad; with --target 2 the search keeps adding setups
    assert plan.prediction.worst_std() > 20
    sharp = plan_ballbar_maps(dataclasses.replace(plan.request, target=2.0))
    assert sharp.prediction.worst_std() <= 2.0 and len(sharp.setups) > len(plan.setups)


def test_an_rtest_map_plan_writes_its_poses_for_each_setups_program(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "plan.json"
    assert main(["plan", "--machine", FORK, "--tool", "0,0,-160", "--map", "C,A", "--map-step", "30", "--map-range",
                 "A=-60:60", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    poses = tmp_path / "plan_poses.csv"
    assert poses.is_file() and json.loads(out.read_text())["poses_file"] == str(poses)
    commands = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("pige program")]
    assert len(commands) == 3 and "--tool 50,0,-160" in commands[2]
    assert main(["program", "--machine", FORK, "--trajectory", str(poses), "--ball", "120,0,80", "--tool",
                 "50,0,-160", "--out", str(tmp_path / "map_3.mpf")]) == 0
    assert "61 poses" in capsys.readouterr().out


@pytest.mark.parametrize("args, said", [
    (["--map", "C,X"], "give rotary axes"),
    (["--map", "C", "--map-range", "C=0:90"], "turns fully"),
    (["--map", "C,A", "--map-range", "A=10:90"], "excludes 0"),
    (["--map", "C", "--map-per-direction", "A"], "map the axis too"),
    (["--map", "C,A", "--map-step", "7"], "must divide 360"),
    (["--map", "C,A", "--map-setups", "4"], "give 1 to 3"),
])
def test_map_options_are_refused_in_one_line(args: list[str], said: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plan", "--machine", AC, *args]) == 2
    err = capsys.readouterr().err
    assert said in err and err.count("\n") == 1, err


def test_program_map_is_for_the_sphere_probe(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["program", "--machine", AC, "--map", "C,A", "--out", str(tmp_path / "x.mpf")]) == 2
    assert "--instrument sphere-probe" in capsys.readouterr().err and not (tmp_path / "x.mpf").exists()


def test_a_pose_the_stylus_cannot_reach_is_refused_with_its_setup(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["plan", "--instrument", "sphere-probe", "--machine", FORK, *SPHERE, "--tool", "0,0,-160", "--map",
                 "C,A", "--map-range", "A=-120:120", "--map-step", "30"])
    err = capsys.readouterr().err
    assert code == 2 and "map setup 1 (point 100, 20, 60 mm, tool 0, 0, -160 mm): pose 1 (A=-120" in err
