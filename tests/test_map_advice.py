"""Maps and advice a user can act on (issue 50): follow-up commands that run as printed, undetermined values that
say why and what would determine them, predictions that count what the printed entries enter, the map report's
answer first, one compensation result object.

The data come from the independent implementation of CONVENTIONS §2-§4 and §10 in ``tests/map_oracle.py`` (exact
rotations, no pige code), on a 30° grid; the controller tables are read back by parsers written here.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from map_files import grid_poses, write_setups
from map_oracle import OracleMachine, OracleMap

from pige_sym.cli.main import main

AC = "wC'A'bXYZ(C1)t"
STEP = 30.0
A_GRID = np.arange(-90.0, 0.1, STEP)
C_GRID = np.arange(0.0, 360.0, STEP)
SETUPS = ((110.0, 0.0, 40.0), (-50.0, 95.0, 90.0), (-60.0, -90.0, 140.0))
PIGE = {"EX0C": 4.0, "EY0C": -6.0, "EA0C": 12.0, "EB0C": -9.0, "EY0A": 8.0, "EZ0A": -5.0, "EB0A": 20.0,
        "EC0A": -14.0}


def _maps(rng: np.random.Generator, a_map: bool = True) -> dict[str, OracleMap]:
    """Harmonics 2-4 on C and (``a_map``) on A; A without a map when ``a_map`` is False (its fit is pure noise)."""
    out = {}
    for axis, grid, wraps in (("C", C_GRID, True), ("A", A_GRID, False)):
        t = np.radians(grid)
        names = [f"E{c}{axis}" for c in "XYZABC"]
        scale = 1.0 if (a_map or axis == "C") else 0.0
        values = {n: scale * sum(rng.normal(scale=1.0 if n[1] in "XYZ" else 6.0) * np.cos(h * t + rng.uniform(0, 6.3))
                                 for h in (2, 3, 4)) for n in names}
        out[axis] = OracleMap(grid, values, wraps)
    return out


def _poses() -> list[dict[str, float]]:
    return grid_poses(A_GRID, C_GRID)


def _write(folder: Path, oracle: OracleMachine, setups: tuple[tuple[float, float, float], ...], noise: float,
           seed: int) -> list[str]:
    return write_setups(folder, oracle, setups, _poses(), noise, seed, first=1)


@pytest.fixture(scope="module")
def ac(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[str], OracleMachine]:
    oracle = OracleMachine(("C", "A"), -1, PIGE, _maps(np.random.default_rng(7)))
    return _write(tmp_path_factory.mktemp("ac50"), oracle, SETUPS, 0.15, 1), oracle


def _json(capsys: Any, args: list[str]) -> dict[str, Any]:
    assert main(args) == 0
    return dict(json.loads(capsys.readouterr().out))


# ----------------------------------------------------------------------------------- item 1: the follow-up commands

def test_the_map_programs_print_the_imports_and_identify_with_their_grid_and_directions(
        tmp_path: Path, capsys: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["program", "--instrument", "sphere-probe", "--machine", AC, "--sphere", "100,20,60",
                 "--sphere-radius", "12.7", "--stylus-radius", "1.5", "--rtcp-off", "M429", "--rtcp-on", "M428",
                 "--stylus-tool", "99", "--stylus-length", "120", "--map", "C,A", "--map-step", "30",
                 "--map-per-direction", "C", "--map-setups", "3", "--dialect", "linuxcnc", "--out", "map.ngc"]) == 0
    text = capsys.readouterr().out
    for i in (1, 2, 3):
        assert f"  pige import-probe pige_probe.txt --format linuxcnc --program map_{i}.ngc --out map_{i}.csv" in text
    assert "  pige identify map_1.csv map_2.csv map_3.csv --map C,A --map-step 30 --map-per-direction C" in text
    assert "ALL.csv" not in text and " LOG " not in text


def test_identify_on_a_finer_grid_than_the_files_names_their_grid(ac: Any, capsys: Any) -> None:
    paths, _ = ac
    assert main(["identify", *paths, "--map", "C,A"]) == 0  # the default 15° grid; the files are every 30°
    text = capsys.readouterr().out
    block = text[text.index("not determined by these data"):]
    assert "--map-step 30" in block and "the files measure C every 30°" in block
    assert len([ln for ln in block.splitlines() if ln.startswith("  ")]) <= 3  # one line per axis, not one per angle


def test_files_that_approach_each_angle_both_ways_say_so_without_per_direction() -> None:
    from types import SimpleNamespace

    from pige_sym.identification.map_check import direction_notes
    from pige_sym.identification.maps import MapSpec, _layout

    up = [(0.0, c) for c in C_GRID]
    rows = np.array([(0.0, 0.0), *up, (0.0, 350.0), *up[::-1]])
    items = [("f", SimpleNamespace(angles_deg=rows))]
    spec = MapSpec(("C",), 30.0)
    layout = _layout(items, spec, ("A", "C"))
    notes = direction_notes(items, layout, spec, ("A", "C"))
    assert notes and "--map-per-direction C" in notes[0]
    assert not direction_notes(items, layout, MapSpec(("C",), 30.0, ("C",)), ("A", "C"))


# ----------------------------------------------------------------------------- item 2: why the PIGEs have no value

def test_two_setups_say_why_the_piges_of_c_have_no_value_and_what_determines_them(ac: Any, capsys: Any,
                                                                                   tmp_path: Path) -> None:
    paths, _ = ac
    out = _json(capsys, ["identify", *paths[:2], "--map", "C,A", "--map-step", "30", "--json"])
    hidden = [r for r in out["not_identifiable"] if "EX0C" in r["parameters"]]
    assert hidden and {"EX0C", "EY0C", "EB0C"} <= set(hidden[0]["parameters"])
    why, remedy = hidden[0]["why"], hidden[0]["remedy"]
    assert "line through them moves neither" in why and "(110, 0, 40)" in why and "(-50, 95, 90)" in why
    assert "off the line" in remedy and "identify without mapping C" in remedy
    assert all(r["why"] and r["remedy"] for r in out["not_identifiable"])
    params = tmp_path / "two.json"
    params.write_text(json.dumps(out), encoding="utf-8")
    assert main(["compensate", "--params", str(params), "--controller", "table"]) == 2
    err = capsys.readouterr().err
    assert "to determine them, a setup with the measured point at a further place on the table" in err
    assert "leave these uncorrected, pass --allow-missing" in err
    assert err.index("to determine them") < err.index("--allow-missing")


def test_zero_position_errors_a_probe_cannot_see_say_why(ac: Any, capsys: Any) -> None:
    paths, _ = ac
    out = _json(capsys, ["identify", *paths, "--map", "C,A", "--map-step", "30", "--json"])
    said = {tuple(r["parameters"]): r for r in out["not_identifiable"]}
    assert "angular position" in said[("EC0C",)]["why"] and "stays uncorrected" in said[("EC0C",)]["remedy"]
    pair = next(r for k, r in said.items() if "EA0A" in k)
    assert "EA0C" in pair["parameters"] and "inclinometer" in pair["remedy"]


# ------------------------------------------------------------------------- item 3: rank, condition and covariance

def test_a_map_fit_states_the_piges_rank_condition_observability_and_covariance(ac: Any, capsys: Any,
                                                                                tmp_path: Path) -> None:
    paths, _ = ac
    out = _json(capsys, ["identify", *paths, "--map", "C,A", "--map-step", "30", "--json"])
    assert out["rank"] == 8 and out["n_parameters"] == 10  # the zeros of C and A are not seen (item 2)
    assert out["condition"] is not None and 1.0 < out["condition"] < 1e3
    assert all(v is not None and v > 0 for v in out["observability"].values())
    cov = out["covariance"]
    assert cov is not None and {"EX0C", "EB0A", "C:EXC@0", "A:EAA@-30"} <= set(cov["parameters"])
    m = np.array(cov["matrix"])
    i = cov["parameters"].index("EB0C")
    assert math.isclose(math.sqrt(m[i, i]), out["std"]["EB0C"], rel_tol=1e-9)
    j = cov["parameters"].index("C:EXC@30")
    assert math.isclose(math.sqrt(m[j, j]), out["error_motions"]["C"]["EXC"]["std"][1], rel_tol=1e-9)
    assert main(["identify", *paths, "--map", "C,A", "--map-step", "30"]) == 0
    assert "condition inf" not in capsys.readouterr().out
    params = tmp_path / "maps.json"
    params.write_text(json.dumps(out), encoding="utf-8")
    doc = _json(capsys, ["compensate", "--params", str(params), "--controller", "table", "--json"])
    assert doc["weighing"]["covariance_from"] == "covariance"
    assert not any("as if uncorrelated" in n for n in doc["weighing"]["notes"])


# ---------------------------------------------------------------------------------------- item 4: diagnose --map

def test_a_map_within_its_noise_names_no_harmonic(tmp_path: Path) -> None:
    from pige_sym.diagnosis.map_gain import map_gain
    from pige_sym.identification.maps import MapSpec
    from pige_sym.measurements.sets import read_files

    oracle = OracleMachine(("C", "A"), -1, PIGE, _maps(np.random.default_rng(3), a_map=False))
    paths = _write(tmp_path, oracle, SETUPS, 0.15, 5)
    gain = map_gain(read_files(paths), MapSpec(("C", "A"), 15.0))
    by = {h.motion: h for h in gain.harmonics}
    noise = [h for n, h in by.items() if n.endswith("A")]
    assert noise and not any(h.significant for h in noise), [(h.motion, h.p_value) for h in noise]
    assert all("within its noise" in h.sentence() and "harmonic" not in h.sentence() for h in noise)
    assert by["EAC"].significant and "holds" in by["EAC"].sentence()


@pytest.mark.slow
def test_diagnose_maps_per_direction_leaves_the_mapped_motions_to_the_maps_and_says_what_next(ac: Any,
                                                                                             capsys: Any) -> None:
    paths, _ = ac
    out = _json(capsys, ["diagnose", *paths, "--map", "C,A", "--map-step", "30", "--map-per-direction", "C",
                         "--json"])
    gain = out["map_gain"]
    assert {"angular_error_C", "wobble_A", "backlash_C"} <= set(gain["searched_without"])
    assert not any(f["effect"] in gain["searched_without"] for fd in out["files"] for f in fd["findings"])
    assert gain["next"][1].startswith("  pige identify ") and "--map-per-direction C --json > maps.json" in gain[
        "next"][1]
    assert gain["next"][2] == "  pige compensate --params maps.json --controller table"


# ------------------------------------------------------- item 5: predictions count what the printed lines enter

def _params_file(tmp_path: Path) -> Path:
    """A parameter file with the PIGEs, C's positioning map per direction and A's maps (standard errors, no zeros)."""
    rng = np.random.default_rng(11)
    c = np.radians(C_GRID)
    mean = 6.0 * np.cos(3 * c) + 4.0 * np.sin(2 * c)
    rev = 9.0 + rng.normal(scale=1.0, size=c.size)
    a = np.radians(np.arange(0.0, 90.1, 30.0))
    doc = {"machine": AC, "pige": dict(PIGE), "std": dict.fromkeys(PIGE, 0.3),
           "error_motions": {
               "C": {"angle_deg": list(C_GRID), "full_turn": True,
                     "ECC+": {"value": list(mean + rev / 2), "std": [0.4] * c.size},
                     "ECC-": {"value": list(mean - rev / 2), "std": [0.4] * c.size},
                     "EXC": {"value": list(0.8 * np.cos(2 * c)), "std": [0.05] * c.size}},
               "A": {"angle_deg": [0.0, 30.0, 60.0, 90.0], "full_turn": False,
                     "EAA": {"value": list(8.0 * np.cos(2 * a)), "std": [0.5] * a.size}}}}
    path = tmp_path / "maps.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def _choices(capsys: Any, params: Path, *args: str) -> dict[str, Any]:
    doc = _json(capsys, ["compensate", "--params", str(params), *args, "--json"])
    return {c["label"]: c for c in doc["compensation"]["controller"]["choices"]} | {
        "_none": doc["compensation"]["weighing"]["predicted_before_um"]}


def test_isg_counts_the_kw_ssfk_lists_as_printed(tmp_path: Path, capsys: Any) -> None:
    params = _params_file(tmp_path)
    unit = 1e-4  # deg: 1.7 urad per unit
    choices = _choices(capsys, params, "--controller", "isg", "--isg-unit-deg", str(unit))
    assert main(["compensate", "--params", str(params), "--controller", "isg", "--isg-unit-deg", str(unit)]) == 0
    text = capsys.readouterr().out
    lists = _ssfk_lists(text)
    entered = choices["the kw.ssfk lists"]["entered"]
    # read back here: C's list is its first, A's its second; a value [units] is the axis' error e (sigma +1)
    start, step, pos, neg = lists[0]
    for theta in C_GRID:
        k = int(round((theta / unit - start) / step))
        assert entered[f"C:ECC+@{theta:g}"] == pytest.approx(pos[k] * unit * math.pi / 180 * 1e6, abs=1e-6)
        assert entered[f"C:ECC-@{theta:g}"] == pytest.approx(neg[k] * unit * math.pi / 180 * 1e6, abs=1e-6)
    assert not any(n.startswith("E") and "@" not in n for n in entered)  # no PIGE: the lists hold φ only
    after = choices["the kw.ssfk lists"]["predicted_um"]["expected"]
    assert abs(after - choices["_none"]["expected"]) > 0.05  # the lists are counted (before: the uncorrected figure)


def _ssfk_lists(text: str) -> list[tuple[int, int, dict[int, int], dict[int, int]]]:
    """(kw_startpos, interval, pos, neg) of each printed list, in order."""
    out = []
    for body in text.split("kw.ssfk.unit 1")[1:]:
        start = int(re.search(r"kw\.ssfk\.kw_startpos (-?\d+)", body).group(1))  # type: ignore[union-attr]
        step = int(re.search(r"kw\.ssfk\.interval (\d+)", body).group(1))  # type: ignore[union-attr]
        pos = {int(i): int(v) for i, v in re.findall(r"kw\.ssfk\.table\[(\d+)\]\.pos (-?\d+)", body)}
        neg = {int(i): int(v) for i, v in re.findall(r"kw\.ssfk\.table\[(\d+)\]\.neg (-?\d+)", body)}
        out.append((start, step, pos, neg))
    return out


def test_linuxcnc_counts_the_comp_files_and_the_component_apart(tmp_path: Path, capsys: Any) -> None:
    params = _params_file(tmp_path)
    comp = tmp_path / "comp"
    comp.mkdir()
    choices = _choices(capsys, params, "--controller", "linuxcnc")
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc", "--comp-dir", str(comp)]) == 0
    capsys.readouterr()
    rows = np.loadtxt(comp / "pige_joint4_c.comp")
    entered = choices["the trt pins and the COMP_FILEs"]["entered"]
    for theta in C_GRID:  # a trim is -e, the axis' error in its commanded angle (sigma +1), forward = increasing
        row = rows[np.isclose(rows[:, 0], theta)][0]
        assert entered[f"C:ECC+@{theta:g}"] == pytest.approx(-row[1] * math.pi / 180 * 1e6, abs=1e-6)
        assert entered[f"C:ECC-@{theta:g}"] == pytest.approx(-row[2] * math.pi / 180 * 1e6, abs=1e-6)
    pins, files = choices["the trt pins"], choices["the trt pins and the COMP_FILEs"]
    assert set(pins["entered"]) == {"EY0A", "EZ0A", "EX0C", "EY0C"}
    assert files["predicted_um"]["expected"] != pins["predicted_um"]["expected"]
    component = choices["pige's kinematics component"]
    assert component["own"] is False and "C:EXC@30" in component["entered"] and "EB0A" in component["entered"]


def test_sinumerik_enters_the_mean_of_a_map_per_direction_and_counts_it(tmp_path: Path, capsys: Any) -> None:
    params = _params_file(tmp_path)
    args = ["--controller", "siemens", "--machine-axis", "C=C1", "--machine-axis", "A=A1"]
    choices = _choices(capsys, params, *args)
    assert main(["compensate", "--params", str(params), *args]) == 0
    text = capsys.readouterr().out
    table = {int(k): float(v) for k, v in re.findall(r"\$AA_ENC_COMP\[0,(\d+),C1\]=(-?[\d.]+)", text)}
    entered = choices["the swivel data record and the $AA_ENC_COMP tables"]["entered"]
    for g, theta in enumerate(C_GRID):
        printed = table[g] * math.pi / 180 * 1e6
        assert entered[f"C:ECC+@{theta:g}"] == pytest.approx(printed, abs=1e-6)
        assert entered[f"C:ECC-@{theta:g}"] == pytest.approx(printed, abs=1e-6)


@pytest.mark.parametrize(("controller", "module", "builder", "options"), [
    ("isg", "isg_ssfk", "ssfk_table", {"isg_unit_deg": 1e-4}),
    ("linuxcnc", "linuxcnc_comp", "comp_table", {}),
    ("linuxcnc", "linuxcnc_kins_maps", "slot_values", {}),
    ("siemens", "siemens_lec", "lec_table", {"machine_axes": {"C": "C1", "A": "A1"}}),
])
def test_the_compensation_stage_builds_each_table_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       controller: str, module: str, builder: str,
                                                       options: dict[str, Any]) -> None:
    """One compensate run builds each axis' table once: the printed lines and the prediction read that object
    (before: ISG built each list twice, LinuxCNC each COMP_FILE five times and each axis' component pins three
    times, SINUMERIK each table twice)."""
    import importlib

    from pige_sym.compensation.controllers import ControllerOptions
    from pige_sym.compensation.controllers.tables.positioning import PositioningMap
    from pige_sym.compensation.parameters import load_parameters
    from pige_sym.compensation.stage import compensate
    from pige_sym.model.error_motions import AxisMaps

    tables = importlib.import_module(f"pige_sym.compensation.controllers.tables.{module}")
    real, built = getattr(tables, builder), []

    def counting(*args: Any, **kwargs: Any) -> Any:
        if kwargs.get("values", True):  # SINUMERIK's format check lays the grid out without values
            table = next(a for a in args if isinstance(a, (PositioningMap, AxisMaps)))
            built.append(table.axis if isinstance(table, PositioningMap) else table.grid.axis)
        return real(*args, **kwargs)

    monkeypatch.setattr(tables, builder, counting)
    result = compensate(load_parameters(_params_file(tmp_path)), controller=controller,
                        options=ControllerOptions(**options))
    assert sorted(built) == ["A", "C"], built
    assert result.controller is not None and sorted({t.axis for t in result.controller.tables}) == ["A", "C"]


def _zero_and_maps_file(tmp_path: Path, sigma: int) -> tuple[Path, dict[str, float], dict[str, np.ndarray]]:
    """A parameter file that gives both mapped axes a zero-position error E (EC0C, EA0A) beside their maps φ."""
    zeros = {"EC0C": 30.0, "EA0A": -20.0}
    a_grid = np.arange(0.0, 90.1, 30.0)
    phi = {"C": 6.0 * np.cos(3 * np.radians(C_GRID)) + 4.0 * np.sin(2 * np.radians(C_GRID)),
           "A": 8.0 * np.cos(2 * np.radians(a_grid))}
    doc = {"machine": AC, "pige": PIGE | zeros, "std": dict.fromkeys(PIGE | zeros, 0.3),
           "axis_sense": {"A": sigma, "C": sigma},
           "error_motions": {
               "C": {"angle_deg": list(C_GRID), "full_turn": True,
                     "ECC": {"value": list(phi["C"]), "std": [0.4] * 12}},
               "A": {"angle_deg": list(a_grid), "full_turn": False,
                     "EAA": {"value": list(phi["A"]), "std": [0.4] * 4}}}}
    path = tmp_path / "zeros.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path, zeros, phi


@pytest.mark.parametrize("sigma", [1, -1])
def test_sinumerik_enters_a_mapped_axis_zero_once_and_the_prediction_counts_it_once(tmp_path: Path, capsys: Any,
                                                                                   sigma: int) -> None:
    """The controller rebuilt here from its manuals: TRAORI turns rotary axis 1 (2) by the axis position minus the
    offset angle ``$TC_CARR24 + $TC_CARR64`` (``25 + 65``; W1 "Rotary axis offset"), and the LEC drives the machine
    axis to commanded − value, the value interpolated in the ``$AA_ENC_COMP`` table (K3 pp. 237-240).  For a
    commanded m the axis then stands at m + e − v while TRAORI takes it at m − o: the two printed entries correct
    σ·(v − o) of the axis' error E + φ (CONVENTIONS §9-§10).  Before, E was in both (the table held σ(E + φ)): 2E."""
    from test_table_positioning import siemens_tables, siemens_value

    params, zeros, phi = _zero_and_maps_file(tmp_path, sigma)
    args = ["--controller", "siemens", "--machine-axis", "C=C1", "--machine-axis", "A=A1", "--enter", "all"]
    choices = _choices(capsys, params, *args)
    assert main(["compensate", "--params", str(params), *args]) == 0
    text = capsys.readouterr().out
    axis_one = re.search(r"rotary axis 1 = ([AC]) ", text).group(1)  # type: ignore[union-attr]
    offsets = {k: float(v) for k, v in re.findall(r"^\$TC_CARR(6[45])\[1\]=\$TC_CARR6[45]\[1\]([+-][\d.]+)$", text,
                                                  flags=re.M)}
    tables = siemens_tables(text[: text.index("\nM17") + 4])  # the advice lines follow the program
    model = choices["the swivel data record and the $AA_ENC_COMP tables"]["entered"]
    urad = math.pi / 180 * 1e6
    for axis, grid in (("C", C_GRID), ("A", np.arange(0.0, 90.1, 30.0))):
        offset = offsets["64" if axis == axis_one else "65"]
        zero = f"E{axis}0{axis}"
        for k, theta in enumerate(grid):
            corrected = sigma * (siemens_value(tables[f"{axis}1"], sigma * theta) - offset) * urad
            assert corrected == pytest.approx(zeros[zero] + phi[axis][k], abs=0.01), (axis, theta)  # E once
            counted = model.get(zero, 0.0) + model[f"{axis}:E{axis}{axis}@{theta:g}"]
            assert counted == pytest.approx(corrected, abs=0.01), (axis, theta)  # the prediction counts that
    assert "is entered by the swivel data record's offset angle ($TC_CARR64/65), not by this table" in text


# -------------------------------------------------------------------------------------- item 6: tolerance names

def test_a_tolerance_applies_to_every_accepted_harmonic_of_its_effect(tmp_path: Path) -> None:
    from pige_sym.verdict.check import Estimates, check, read_tolerances

    values = dict(PIGE) | {"angular_error_C@h2.cos_urad": 7.64, "angular_error_C@h2.sin_urad": 1.0,
                           "angular_error_C@h3.cos_urad": 2.0, "angular_error_C@h3.sin_urad": -1.0}
    est = Estimates(AC, "diagnosis", "run.csv", values, dict.fromkeys(values, 0.3), {}, ["angular_error_C"])
    tol = tmp_path / "tol.json"
    tol.write_text(json.dumps({"format": "pige-tolerances 1", "limits": {
        "angular_error_C.cos_urad": 5.0, "angular_error_C@h3.sin_urad": 3.0}}), encoding="utf-8")
    result = check(est, read_tolerances(tol))
    items = {i.name: i for i in result.items}
    assert items["angular_error_C@h2.cos_urad"].status == "fail"
    assert items["angular_error_C@h3.cos_urad"].status == "pass"
    assert items["angular_error_C@h3.sin_urad"].status == "pass"
    assert "angular_error_C.cos_urad" not in items and result.verdict == "fail"


# ------------------------------------------------------------------------------------ item 7: the map report

@pytest.fixture(scope="module")
def map_report(ac: Any) -> Any:
    from pige_sym.identification.maps import MapSpec
    from pige_sym.measurements.sets import read_files
    from pige_sym.report.map_section import gather_maps

    paths, _ = ac
    return gather_maps(read_files(paths), MapSpec(("C", "A"), 30.0))


def test_the_map_report_leads_with_the_maps_answer(map_report: Any) -> None:
    from pige_sym.report.data import ReportData
    from pige_sym.report.html import render_html

    data = ReportData([], (), None, {}, "now")
    data.maps = map_report
    page = render_html(data)
    answer = page[page.index('data-section="answer"'):]
    assert answer.index('data-answer="maps"') < answer.index("</section>")
    for said in ("What they explain.", "What to enter.", "Not determined.", "Predicted tool-point RMS error",
                 "pige compensate --params maps.json --controller table"):
        assert said in answer, said
    assert "CONVENTIONS" not in "".join(h.sentence() for h in map_report.gain.harmonics)
    assert re.search(r"a wobble of the C axis, \d per revolution \(wobble_C\)", answer)


def test_the_maps_plot_titles_speak_plainly(map_report: Any) -> None:
    from pige_sym.identification.map_output import map_figure

    fig = map_figure(map_report.result, "C")
    assert "CONVENTIONS" not in fig.axes[0].get_title()


# ------------------------------------------------------------------------------ item 8: the weighed words, advice

def test_a_value_entered_beyond_its_estimate_says_why_in_plain_words() -> None:
    from pige_sym.compensation.entry_words import why_entered
    from pige_sym.compensation.weighing import entered_values

    x = np.array([11.82, 3.0])  # the EB0C 11.82 ± 14, correlated with a weak EA0C
    cov = np.array([[14.0**2, -0.93 * 14 * 9], [-0.93 * 14 * 9, 9.0**2]])
    c = entered_values(x, cov)
    assert c[1] == 0.0 and abs(c[0]) > abs(x[0])
    text = why_entered(0, ["EB0C", "EA0C"], x, cov, c, "urad")
    assert "not as its estimate +11.82 ± 14 urad" in text and "EA0C (not entered; correlation -0.93)" in text
    assert "weighed down" not in text


def test_advice_when_the_bound_is_above_the_uncorrected_error_or_more_is_wider() -> None:
    from pige_sym.compensation.advice import advice
    from pige_sym.compensation.result import EntryChoice
    from pige_sym.compensation.weighing import ErrorPrediction, Weighing

    w = Weighing({"EB0C": 11.8}, {"EB0C": 14.0}, {"EB0C": 5.0}, {"EB0C": "entered in part"},
                 {"none": ErrorPrediction(7.59, 8.0), "entered": ErrorPrediction(6.9, 8.45),
                  "all_estimates": ErrorPrediction(7.2, 9.6)}, "the axes' travel")
    few = EntryChoice("the trt pins", {"EX0C": 1.0}, ErrorPrediction(5.0, 5.5))
    more = EntryChoice("the trt pins and the COMP_FILEs", {"EX0C": 1.0, "C:ECC+@0": 1.0}, ErrorPrediction(5.1, 6.0))
    said = advice(w, [few, more])
    assert any("8.45 um) is above the error expected without it (7.59 um)" in a for a in said)
    assert any("--enter all" in a and "wider 95 % bound (9.60 um)" in a for a in said)
    assert any("entering the trt pins and the COMP_FILEs gives a wider 95 % bound" in a for a in said)


# ------------------------------------------------------------------------------ item 9: LinuxCNC's files apart

def test_linuxcnc_out_dir_writes_each_target_whole_with_its_nets(tmp_path: Path, capsys: Any) -> None:
    params = _params_file(tmp_path)
    out = tmp_path / "lcnc"
    out.mkdir()
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc", "--out-dir", str(out)]) == 0
    said = capsys.readouterr().out
    names = {"trt-kins.hal", "comp-files.ini", "pige_joint4_c.comp", "pige_joint3_a.comp", "pige-kins.ini",
             "pige-kins.hal"}
    assert {p.name for p in out.iterdir()} == names and all(f"{out / n}" in said for n in names)
    hal = (out / "pige-kins.hal").read_text(encoding="utf-8")
    for net in ("net :tool-offset motion.tooloffset.z => pige_xyzac_trt.tool-offset",
                "net pige-vel-a joint.3.vel-cmd => pige_xyzac_trt.vel-a",
                "net pige-vel-c joint.4.vel-cmd => pige_xyzac_trt.vel-c"):
        assert net in hal
    assert all(ln.startswith(("#", "setp ", "net ")) for ln in hal.splitlines())
    assert all(ln.startswith(("#", "setp ", "sets ")) for ln in (out / "trt-kins.hal").read_text().splitlines())
    ini = (out / "pige-kins.ini").read_text(encoding="utf-8").splitlines()
    assert "[KINS]" in ini and "KINEMATICS = pige_xyzac_trt sparm=identityfirst" in ini and "[TRAJ]" in ini
    assert not any(ln.startswith(("setp", "net")) for ln in ini)
    before = {p.name: p.read_text() for p in out.iterdir()}
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc", "--out-dir", str(out)]) == 2
    assert {p.name: p.read_text() for p in out.iterdir()} == before  # never over a file without --force
    clash = out / "pige-kins.hal"
    clash.write_text(params.read_text())
    assert main(["compensate", "--params", str(clash), "--controller", "linuxcnc", "--out-dir", str(out),
                 "--force"]) == 2  # never over an input
    capsys.readouterr()
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc"]) == 0
    text = capsys.readouterr().out
    sections = [s.rstrip("\n") for s in re.split(r"^# ==== .*\n", text, flags=re.M)[1:]]
    files = [before[n].rstrip("\n") for n in ("trt-kins.hal", "comp-files.ini", "pige-kins.ini", "pige-kins.hal")]
    assert sections[:3] == files[:3] and sections[3].startswith(files[3])  # printed: the same sections whole
    assert all(ln.startswith(("#", "setp ", "net ")) for ln in sections[3].splitlines())  # advice as comments


# ----------------------------------------------------------------- item 10: what the PIGEs hold beside the maps

def test_the_piges_hold_what_the_maps_leave_out_over_a_limited_range(tmp_path: Path, capsys: Any) -> None:
    """The identified PIGEs are the simulated ones plus what the maps alone put in the PIGEs (docs/maps.md)."""
    maps = _maps(np.random.default_rng(7))
    (tmp_path / "both").mkdir()
    (tmp_path / "only").mkdir()
    both = _write(tmp_path / "both", OracleMachine(("C", "A"), -1, PIGE, maps), SETUPS, 0.15, 1)
    only = _write(tmp_path / "only", OracleMachine(("C", "A"), -1, {}, maps), SETUPS, 0.0, 1)
    fit = _json(capsys, ["identify", *both, "--map", "C,A", "--map-step", "30", "--json"])
    part = _json(capsys, ["identify", *only, "--map", "C,A", "--map-step", "30", "--json"])
    moved = [n for n in PIGE if abs(part["pige"][n]) > 4 * fit["std"][n]]
    assert moved, "over A's 0..-90 the maps' harmonics 2-4 put something in the PIGEs"
    for n in PIGE:
        assert abs(fit["pige"][n] - PIGE[n] - part["pige"][n]) < 4 * fit["std"][n] + 0.05, n
    assert main(["identify", *both, "--map", "C,A", "--map-step", "30"]) == 0
    assert "A is mapped over -90..0° only" in capsys.readouterr().out


# ------------------------------------------------------------- the rule: every follow-up command runs as printed

def _commands(text: str) -> list[str]:
    """The commands a CLI output prints on their own lines (``  pige …``, ``#   pige …``)."""
    return [m.group(1).strip() for m in re.finditer(r"^[ \t]*(?:[#;][ \t]*)?(pige [a-z].*)$", text, flags=re.M)]


def _html_commands(page: str) -> list[str]:
    import html

    return [html.unescape(c) for c in re.findall(r'<code class="cmd">(.*?)</code>', page)]


@pytest.mark.slow
def test_every_follow_up_command_of_the_map_workflow_runs_as_printed(tmp_path: Path) -> None:
    """docs/maps.md's workflow on pige's virtual probing machine: plan → program → (run, import) → identify →
    diagnose → compensate → report; every command one of them prints is run as printed, in order."""
    import shlex
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "error_maps_ac.json").write_text((root / "examples" / "error_maps_ac.json").read_text())
    ran: list[str] = []

    def pige(command: str) -> str:
        shell = f'pige() {{ {shlex.quote(sys.executable)} -m pige_sym "$@"; }}; {command}'
        done = subprocess.run(["bash", "-c", shell], cwd=tmp_path, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, f"{command}\n{done.stdout}\n{done.stderr}"
        ran.append(command)
        return done.stdout

    sphere = "--sphere 100,20,60 --sphere-radius 12.7 --stylus-radius 1.5"
    probe = "--rtcp-off M429 --rtcp-on M428 --stylus-tool 99 --stylus-length 120 --dialect linuxcnc"
    plan = pige(f'pige plan --instrument sphere-probe --machine "{AC}" {sphere} {probe} --map C,A --map-step 30 '
                "--map-per-direction C --noise 0.5")
    [program_cmd] = _commands(plan)
    program = pige(program_cmd)
    imports, identify_cmds = [c for c in _commands(program) if "import-probe" in c], [
        c for c in _commands(program) if c.startswith("pige identify")]
    assert len(imports) == 3 and len(identify_cmds) == 1
    truth = "EX0C=4,EY0C=-6,EA0C=12,EB0C=-9,EY0A=8,EZ0A=-5,EB0A=20,EC0A=-14"
    for i, command in enumerate(imports, start=1):  # the machine runs map_i.ngc and writes pige_probe.txt
        pige(f"pige simulate --instrument sphere-probe --dialect linuxcnc --program map_{i}.ngc --pige {truth} "
             f"--seed {i} --error-maps error_maps_ac.json --noise 0.5 --out pige_probe.txt --force")
        pige(command)
    identified = pige(identify_cmds[0])
    assert "not determined by these data" not in identified  # the programs' own grid: every value determined
    csvs = identify_cmds[0].split()[2:5]
    diagnosed = pige(f"pige diagnose {' '.join(csvs)} --map C,A --map-step 30 --map-per-direction C")
    follow = _commands(diagnosed)
    assert follow and follow[0].endswith("--json > maps.json")
    for command in follow:
        out = pige(command)
        for inner in _commands(out):  # the component's build line: pige gen … && sudo halcompile --install …
            first, _, rest = inner.partition(" && ")
            pige(first)
            assert rest.startswith("sudo halcompile --install ") and (tmp_path / rest.split()[-1]).is_file()
    report = pige(f"pige report {' '.join(csvs)} --map C,A --map-step 30 --map-per-direction C --out rep "
                  "--no-figures")
    assert not _commands(report)
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    for command in dict.fromkeys(_html_commands(page)):
        pige(command)
    assert len(ran) >= 16
