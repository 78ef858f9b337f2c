"""Commanded axis senses (CONVENTIONS §9): θ = σ·θ_cmd at every reader and writer, recorded in every file.

The oracle for the LinuxCNC statement of §9 is LinuxCNC's own trt inverse kinematics, written here from
``src/emc/kinematics/trtfuncs.c`` (``xyzacKinematicsInverse``, ``xyzbcKinematicsInverse``, LinuxCNC 2.9.0):
with σ = −1 for both axes and the pivots of the configuration's pins, pige's nominal RTCP commands are the
joints LinuxCNC computes, to 1e-9 mm.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pige_sym.cli.main import main
from pige_sym.errors import FileFormatError, InputError
from pige_sym.identification.least_squares import identify
from pige_sym.kernels import load_kernels
from pige_sym.measurements.axis_sense import parse_axis_sense, reconcile, to_commanded, to_conventions
from pige_sym.measurements.ballbar import read_ballbar
from pige_sym.measurements.rtest import read_measurement

AC, BC = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t"


def _trt_inverse_ac(world: np.ndarray, a_deg: float, c_deg: float, pins: dict[str, float]) -> np.ndarray:
    """LinuxCNC 2.9 xyzacKinematicsInverse (trtfuncs.c), tool-offset 0: table-frame point -> joints X Y Z."""
    xr, yr, zr, dy, dz = (pins[k] for k in ("x-rot-point", "y-rot-point", "z-rot-point", "y-offset", "z-offset"))
    a, c = math.radians(a_deg), math.radians(c_deg)
    x, y, z = world - np.array([xr, yr, zr])
    return np.array([
        math.cos(c) * x - math.sin(c) * y + xr,
        math.sin(c) * math.cos(a) * x + math.cos(c) * math.cos(a) * y - math.sin(a) * z - math.cos(a) * dy
        + math.sin(a) * dz + dy + yr,
        math.sin(c) * math.sin(a) * x + math.cos(c) * math.sin(a) * y + math.cos(a) * z - math.sin(a) * dy
        - math.cos(a) * dz + dz + zr])


def _trt_inverse_bc(world: np.ndarray, b_deg: float, c_deg: float, pins: dict[str, float]) -> np.ndarray:
    """LinuxCNC 2.9 xyzbcKinematicsInverse (trtfuncs.c), tool-offset 0."""
    xr, yr, zr, dx, dz = (pins[k] for k in ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "z-offset"))
    b, c = math.radians(b_deg), math.radians(c_deg)
    x, y, z = world - np.array([xr, yr, zr])
    return np.array([
        math.cos(c) * math.cos(b) * x - math.sin(c) * math.cos(b) * y + math.sin(b) * z - math.cos(b) * dx
        - math.sin(b) * dz + dx + xr,
        math.sin(c) * x + math.cos(c) * y + yr,
        -math.cos(c) * math.sin(b) * x + math.sin(c) * math.sin(b) * y + math.cos(b) * z + math.sin(b) * dx
        - math.cos(b) * dz + dz + zr])


@pytest.mark.parametrize("machine", [AC, BC])
def test_linuxcnc_trt_kinematics_turn_the_table_with_sense_minus_one(machine) -> None:
    """§9: the stock trt kinematics are CONVENTIONS' table with σ = −1 for both axes and the pins' pivots."""
    rng = np.random.default_rng(5)
    kern = load_kernels(machine)
    tilt = kern.ROTARY_AXES[0]
    sense = parse_axis_sense(f"{tilt}=-1,C=-1", kern.ROTARY_AXES)
    for _ in range(20):
        pins = {"x-rot-point": rng.uniform(-50, 50), "y-rot-point": rng.uniform(-50, 50),
                "z-rot-point": rng.uniform(-50, 50), "x-offset": rng.uniform(-30, 30), "y-offset": rng.uniform(-30, 30),
                "z-offset": rng.uniform(-30, 30)}
        if tilt == "A":
            pivots = {"A": [0.0, pins["y-rot-point"] + pins["y-offset"], pins["z-rot-point"] + pins["z-offset"]],
                      "C": [pins["x-rot-point"], pins["y-rot-point"], 0.0]}
        else:
            pivots = {"B": [pins["x-rot-point"] + pins["x-offset"], 0.0, pins["z-rot-point"] + pins["z-offset"]],
                      "C": [pins["x-rot-point"], pins["y-rot-point"], 0.0]}
        commanded = np.array([[rng.uniform(-90, 90), rng.uniform(-360, 360)]])
        world = rng.uniform(-100, 100, 3)
        theta = to_conventions(commanded, sense, kern.ROTARY_AXES)
        pige = kern.linear_commands(theta, world, pivots)[0]
        inverse = _trt_inverse_ac if tilt == "A" else _trt_inverse_bc
        assert np.allclose(pige, inverse(world, *commanded[0], pins), atol=1e-9)
        # and with CONVENTIONS' sense (σ = +1) they differ: the stock kinematics turn the other way
        assert not np.allclose(kern.linear_commands(commanded, world, pivots)[0], inverse(world, *commanded[0], pins),
                               atol=1e-3)


def test_a_table_point_10_mm_beside_the_a_line_needs_z_plus_5_at_a30() -> None:
    """The measurement of §9, with LinuxCNC's formula: at A = 30°, a point 10 mm +Y of the A line needs +5 mm Z."""
    pins = dict.fromkeys(("x-rot-point", "y-rot-point", "z-rot-point", "y-offset", "z-offset"), 0.0)
    assert _trt_inverse_ac(np.array([0.0, 10.0, 0.0]), 30.0, 0.0, pins)[2] == pytest.approx(5.0)
    kern = load_kernels(AC)
    theta = to_conventions(np.array([[30.0, 0.0]]), {"A": -1, "C": -1}, kern.ROTARY_AXES)
    assert kern.linear_commands(theta, [0.0, 10.0, 0.0])[0][2] == pytest.approx(5.0)


@given(st.lists(st.sampled_from(["A=-1", "C=-1", "A=+1", "C=1", " A = -1 "]), max_size=2, unique=True))
def test_parse_accepts_the_grammar_and_keeps_only_reversed_axes(items) -> None:
    axes = [i.split("=")[0].strip() for i in items]
    if len(set(axes)) != len(axes):
        with pytest.raises(InputError, match="twice"):
            parse_axis_sense(",".join(items), ("A", "C"))
        return
    sense = parse_axis_sense(",".join(items), ("A", "C"))
    assert set(sense.values()) <= {-1}
    assert sense == {i.split("=")[0].strip(): -1 for i in items if i.replace(" ", "").endswith("=-1")}


@pytest.mark.parametrize("text, fragment", [("B=-1", "not a rotary axis"), ("A=2", "-1"), ("A", "AXIS=-1"),
                                            ("A=-1,A=-1", "twice"), ("C=-0", "-1")])
def test_parse_refuses_with_what_to_fix(text, fragment) -> None:
    with pytest.raises(InputError, match=fragment):
        parse_axis_sense(text, ("A", "C"))


def test_reconcile_refuses_a_conflicting_option() -> None:
    assert reconcile({"A": -1}, None, "f.csv", ("A", "C")) == {"A": -1}
    assert reconcile({"A": -1}, {"A": -1}, "f.csv", ("A", "C")) == {"A": -1}
    with pytest.raises(InputError, match="f.csv records the commanded axis sense A=-1.*--axis-sense says C=-1"):
        reconcile({"A": -1}, {"C": -1}, "f.csv", ("A", "C"))
    angles = np.array([[10.0, -20.0]])
    assert np.array_equal(to_commanded(to_conventions(angles, {"C": -1}, ("A", "C")), {"C": -1}, ("A", "C")), angles)


def test_simulated_files_hold_commanded_angles_and_identify_the_same(tmp_path) -> None:
    plus, minus = tmp_path / "plus.csv", tmp_path / "minus.csv"
    assert main(["simulate", "--pige", "random", "--seed", "3", "--out", str(plus)]) == 0
    assert main(["simulate", "--pige", "random", "--seed", "3", "--axis-sense", "A=-1,C=-1", "--out", str(minus)]) == 0
    assert "# axis_sense: A=-1, C=-1" in minus.read_text() and "axis_sense" not in plus.read_text()
    p, m = read_measurement(plus), read_measurement(minus)
    rows = [ln.split(",") for ln in minus.read_text().splitlines() if ln and not ln.startswith(("#", "t_s"))]
    raw = np.array([[float(x) for x in r[:3]] for r in rows])  # the columns as written: θ_cmd
    assert np.array_equal(raw[:, 1:3], -p.angles_deg + 0.0)
    assert np.array_equal(m.angles_deg, p.angles_deg)  # read back as θ
    assert np.allclose(identify(m).values, identify(p).values, atol=1e-12, equal_nan=True)
    assert json.loads(minus.with_name("minus.truth.json").read_text())["axis_sense"] == {"A": -1, "C": -1}


def test_a_file_with_a_malformed_sense_is_refused_with_its_line(tmp_path) -> None:
    good = tmp_path / "g.csv"
    assert main(["simulate", "--seed", "1", "--axis-sense", "C=-1", "--out", str(good)]) == 0
    bad = tmp_path / "b.csv"
    bad.write_text(good.read_text().replace("# axis_sense: C=-1", "# axis_sense: B=-1"))
    with pytest.raises(FileFormatError, match=r"b.csv:7: axis_sense: .B. is not a rotary axis"):
        read_measurement(bad)


def test_ballbar_files_record_and_convert_the_sense(tmp_path) -> None:
    out = tmp_path / "bb.csv"
    assert main(["simulate", "--instrument", "ballbar", "--setup", "tangential", "--axis", "C", "--pige", "random",
                 "--seed", "4", "--axis-sense", "C=-1", "--out", str(out)]) == 0
    run = read_ballbar(out)
    assert run.axis_sense == {"C": -1} and "# axis_sense: C=-1" in out.read_text()
    raw = [ln.split(",") for ln in out.read_text().splitlines() if ln and not ln.startswith(("#", "t_s"))]
    assert np.allclose(-np.array([float(r[2]) for r in raw]), run.angles_deg[:, 1])


def test_compensation_follows_the_sense_of_the_parameters(tmp_path, capsys) -> None:
    """The same machine measured and compensated in either sense: the same X Y Z, the angles negated."""
    texts = {}
    for name, sense in (("plus", []), ("minus", ["--axis-sense", "A=-1,C=-1"])):
        run, params, prog, comp = (tmp_path / f"{name}{s}" for s in (".csv", ".json", ".ngc", "_comp.ngc"))
        assert main(["simulate", "--pige", "random", "--seed", "7", "--noise", "0", *sense, "--out", str(run)]) == 0
        capsys.readouterr()
        assert main(["identify", str(run), "--json"]) == 0
        params.write_text(capsys.readouterr().out)
        assert main(["program", "--dialect", "linuxcnc", *sense, "--out", str(prog)]) == 0
        assert main(["compensate", str(prog), "--params", str(params), "--out", str(comp)]) == 0
        texts[name] = [ln for ln in comp.read_text().splitlines() if ln.startswith("N")]
    for a, b in zip(texts["plus"], texts["minus"], strict=True):
        wa, wb = dict(w[:1] and (w[0], w[1:]) for w in a.split()[1:]), dict((w[0], w[1:]) for w in b.split()[1:])
        assert {k: v for k, v in wa.items() if k in "XYZFGP"} == {k: v for k, v in wb.items() if k in "XYZFGP"}
        for axis in "AC":
            if axis in wa:
                assert float(wa[axis]) == pytest.approx(-float(wb[axis]), abs=1e-4)
    # a conflicting --axis-sense, or a program whose header records another sense, is refused
    assert main(["compensate", str(tmp_path / "minus.ngc"), "--params", str(tmp_path / "minus.json"),
                 "--axis-sense", "A=-1", "--out", str(tmp_path / "x.ngc")]) == 2
    assert main(["compensate", str(tmp_path / "minus.ngc"), "--params", str(tmp_path / "plus.json"),
                 "--out", str(tmp_path / "y.ngc")]) == 2
    assert "records the commanded axis sense" in capsys.readouterr().err


def test_joint_files_with_different_senses_are_refused(tmp_path, capsys) -> None:
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["simulate", "--seed", "1", "--out", str(a)]) == 0
    assert main(["simulate", "--seed", "2", "--axis-sense", "C=-1", "--out", str(b)]) == 0
    capsys.readouterr()
    assert main(["identify", str(a), str(b)]) == 2
    assert "different commanded axis senses" in capsys.readouterr().err


def test_an_rtest_program_records_its_sense_and_is_read_with_it(tmp_path) -> None:
    from pige_sym.nc.rtest_program import load_test_program

    prog = tmp_path / "r.ngc"
    assert main(["program", "--dialect", "linuxcnc", "--axis-sense", "C=-1", "--out", str(prog)]) == 0
    assert "(pige axis_sense: C=-1)" in prog.read_text()
    plain = load_test_program(AC, "cone-frustum")
    read = load_test_program(AC, str(prog))
    assert read.axis_sense == {"C": -1}
    assert np.allclose(read.angles_deg, plain.angles_deg, atol=1e-4)
    with pytest.raises(InputError, match="records the commanded axis sense"):
        load_test_program(AC, str(prog), axis_sense={"A": -1, "C": -1})


def test_the_report_shows_the_angles_as_commanded(tmp_path) -> None:
    run = tmp_path / "run.csv"
    assert main(["simulate", "--seed", "2", "--axis-sense", "A=-1,C=-1", "--out", str(run)]) == 0
    assert main(["report", str(run), "--out", str(tmp_path / "rep"), "--no-figures"]) == 0
    html = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    m = read_measurement(run)
    assert np.array_equal(m.commanded_deg, -m.angles_deg + 0.0)
    low = f"{m.commanded_deg[:, 0].min():.1f}"
    assert f"A (workpiece side, {low} … 0.0° commanded, sense -1)" in html
