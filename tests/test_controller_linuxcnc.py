"""LinuxCNC's trt kinematics, written in this test from its source, judge what pige prints for it.

``xyzacKinematicsForward`` / ``xyzacKinematicsInverse`` and ``xyzbc…`` of ``src/emc/kinematics/trtfuncs.c``
(LinuxCNC master, commit 5c41560ebbc3a40f84a5547bc6f7c5cd9278ba6b: lines 155–201 and 203–261 for xyzac,
263–309 and 311–366 for xyzbc), with ``conventional-directions`` = 1 (the ISO rotation senses).  A true
machine is the nominal trt description with its axis lines moved by the PIGEs; the controller runs the
inverse kinematics with its HAL pins, the true machine the forward ones: the tool-point error is the
difference.  It must equal pige's first-order model (an independent check of the conventions), and entering
the pins pige prints must remove it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pige_sym.cli.main import main
from pige_sym.compensation.controllers import format_controller
from pige_sym.compensation.controllers.linuxcnc import linuxcnc_trt_deltas
from pige_sym.compensation.controllers.scope import tool_point_summary
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import make_trajectory

AC, BC = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t"
PINS = ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset")


def _xyzac_inverse(pos: np.ndarray, a: float, c: float, h: dict[str, float]) -> np.ndarray:
    xr, yr, zr, dy, dz = h["x-rot-point"], h["y-rot-point"], h["z-rot-point"], h["y-offset"], h["z-offset"]
    a, c, con = math.radians(a), math.radians(c), 1.0
    x, y, z = pos
    return np.array([
        math.cos(c) * (x - xr) + con * math.sin(c) * (y - yr) + xr,
        -con * math.sin(c) * math.cos(a) * (x - xr) + math.cos(c) * math.cos(a) * (y - yr)
        + con * math.sin(a) * (z - zr) - math.cos(a) * dy - con * math.sin(a) * dz + dy + yr,
        math.sin(c) * math.sin(a) * (x - xr) - con * math.cos(c) * math.sin(a) * (y - yr)
        + math.cos(a) * (z - zr) + con * math.sin(a) * dy - math.cos(a) * dz + dz + zr])


def _xyzac_forward(j: np.ndarray, a: float, c: float, h: dict[str, float]) -> np.ndarray:
    xr, yr, zr, dy, dz = h["x-rot-point"], h["y-rot-point"], h["z-rot-point"], h["y-offset"], h["z-offset"]
    a, c, con = math.radians(a), math.radians(c), 1.0
    jx, jy, jz = j
    return np.array([
        math.cos(c) * (jx - xr) - con * math.sin(c) * math.cos(a) * (jy - dy - yr)
        + math.sin(c) * math.sin(a) * (jz - dz - zr) - con * math.sin(c) * dy + xr,
        con * math.sin(c) * (jx - xr) + math.cos(c) * math.cos(a) * (jy - dy - yr)
        - con * math.cos(c) * math.sin(a) * (jz - dz - zr) + math.cos(c) * dy + yr,
        con * math.sin(a) * (jy - dy - yr) + math.cos(a) * (jz - dz - zr) + dz + zr])


def _xyzbc_inverse(pos: np.ndarray, b: float, c: float, h: dict[str, float]) -> np.ndarray:
    xr, yr, zr, dx, dz = h["x-rot-point"], h["y-rot-point"], h["z-rot-point"], h["x-offset"], h["z-offset"]
    b, c, con = math.radians(b), math.radians(c), 1.0
    x, y, z = pos
    dpx = -math.cos(b) * dx + math.sin(b) * dz + dx
    dpz = -math.sin(b) * dx - math.cos(b) * dz + dz
    return np.array([
        math.cos(c) * math.cos(b) * (x - xr) + con * math.sin(c) * math.cos(b) * (y - yr)
        - con * math.sin(b) * (z - zr) + dpx + xr,
        -con * math.sin(c) * (x - xr) + math.cos(c) * (y - yr) + yr,
        con * math.cos(c) * math.sin(b) * (x - xr) + math.sin(c) * math.sin(b) * (y - yr)
        + math.cos(b) * (z - zr) + dpz + zr])


def _xyzbc_forward(j: np.ndarray, b: float, c: float, h: dict[str, float]) -> np.ndarray:
    xr, yr, zr, dx, dz = h["x-rot-point"], h["y-rot-point"], h["z-rot-point"], h["x-offset"], h["z-offset"]
    b, c, con = math.radians(b), math.radians(c), 1.0
    jx, jy, jz = j
    return np.array([
        math.cos(c) * math.cos(b) * (jx - dx - xr) - con * math.sin(c) * (jy - yr)
        + con * math.cos(c) * math.sin(b) * (jz - dz - zr) + math.cos(c) * dx + xr,
        con * math.sin(c) * math.cos(b) * (jx - dx - xr) + math.cos(c) * (jy - yr)
        + math.sin(c) * math.sin(b) * (jz - dz - zr) + con * math.sin(c) * dx + yr,
        -con * math.sin(b) * (jx - dx - xr) + math.cos(b) * (jz - dz - zr) + dz + zr])


KINS = {AC: (_xyzac_inverse, _xyzac_forward), BC: (_xyzbc_inverse, _xyzbc_forward)}


def _true_pins(machine: str, nominal: dict[str, float], values: dict[str, float]) -> dict[str, float]:
    """The nominal description with the axis lines moved by the PIGEs (µm → mm)."""
    v = {k: x * 1e-3 for k, x in values.items()}
    true = dict(nominal)
    true["x-rot-point"] += v.get("EX0C", 0.0)
    true["y-rot-point"] += v.get("EY0C", 0.0)
    if machine == AC:  # A line at (y-rot-point + y-offset, z-rot-point + z-offset)
        true["y-offset"] += v.get("EY0A", 0.0) - v.get("EY0C", 0.0)
        true["z-offset"] += v.get("EZ0A", 0.0)
    else:  # B line at (x-rot-point + x-offset, z-rot-point + z-offset)
        true["x-offset"] += v.get("EX0B", 0.0) - v.get("EX0C", 0.0)
        true["z-offset"] += v.get("EZ0B", 0.0)
    return true


def _errors_um(machine: str, controller: dict[str, float], true: dict[str, float]) -> np.ndarray:
    """Tool point minus target on the true machine, the controller running its own pins, (n, 3) [µm]."""
    inverse, forward = KINS[machine]
    ball = np.array([120.0, 0.0, 80.0])
    out = []
    for tilt, c in make_trajectory(machine, "cone-frustum").angles_deg:
        joints = inverse(ball, tilt, c, controller)
        out.append((forward(joints, tilt, c, true) - ball) * 1e3)
    return np.array(out)


@pytest.mark.parametrize("machine", [AC, BC])
def test_trt_kinematics_agree_with_the_model_and_the_printed_pins_remove_the_error(machine) -> None:
    kern = load_kernels(machine)
    rng = np.random.default_rng(4)
    positions = [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]
    values = {n: float(rng.uniform(-15, 15)) for n in positions}
    nominal = dict.fromkeys(PINS, 0.0)
    true = _true_pins(machine, nominal, values)
    before = _errors_um(machine, nominal, true)
    # pige's first-order model gives the same tool-point error magnitudes (CONVENTIONS agree with trtfuncs.c)
    angles = make_trajectory(machine, "cone-frustum").angles_deg
    d = kern.deviation(angles, np.array([values.get(n, 0.0) for n in kern.LOCATION_PARAMETERS]), [120.0, 0.0, 80.0])
    np.testing.assert_allclose(np.linalg.norm(before, axis=1), np.linalg.norm(d, axis=1), atol=1e-4)
    assert np.linalg.norm(before, axis=1).max() > 5.0
    # the controller enters what pige prints (absolute setp values from today's pins): no error left
    params = CompensationParameters(kern.MACHINE_CODE, values, dict(kern.UNITS), None, {}, "test", [])
    text = format_controller(params, "linuxcnc", current=nominal)
    module = "xyzac-trt-kins" if machine == AC else "xyzbc-trt-kins"
    entered = {ln.split()[1].removeprefix(module + "."): float(ln.split()[2]) for ln in text.splitlines()
               if ln.startswith(f"setp {module}.")}
    assert set(entered) == set(linuxcnc_trt_deltas(params)[1])
    after = _errors_um(machine, nominal | entered, true)
    assert np.abs(after).max() < 1e-3, np.abs(after).max()


def test_what_linuxcnc_cannot_hold_is_named_with_the_error_it_leaves() -> None:
    kern = load_kernels(AC)
    values = {"EY0A": 5.0, "EZ0A": -3.0, "EX0C": 4.0, "EY0C": 2.0, "EB0A": 30.0, "EA0C": -20.0}
    params = CompensationParameters(kern.MACHINE_CODE, values, dict(kern.UNITS), None, {}, "test", [])
    scope = tool_point_summary(params, "linuxcnc")
    assert scope.entered == ["EY0A", "EZ0A", "EX0C", "EY0C"]
    assert [s.split()[0] for s in scope.not_representable] == ["EB0A", "EA0C"]
    tilts_only = CompensationParameters(kern.MACHINE_CODE, {"EB0A": 30.0, "EA0C": -20.0}, dict(kern.UNITS), None, {},
                                        "test", [])
    assert scope.rmse_table_only_um == pytest.approx(tool_point_summary(tilts_only, "linuxcnc").rmse_before_um,
                                                     rel=1e-6)
    assert scope.rmse_nc_rewrite_um < 0.05 < scope.rmse_table_only_um < scope.rmse_before_um
    text = format_controller(params, "linuxcnc")
    assert "NOT representable" in text and "EB0A +30 urad" in text and "\nsetp xyzac-trt-kins" not in text
    assert "# xyzac-trt-kins.y-offset: add +0.003000" in text
    assert "setp pige_xyzac_trt.eb0a 30.0000" in text  # beside them, pige's component holds every PIGE
    head = format_controller(CompensationParameters("wbXYZCA(C1)t", {}, {}, None, {}, "t", []), "linuxcnc")
    assert "stock trt kinematics" in head and "no mapping" in head and "# pige_xyzac_head.ex0c: not estimated" in head
    with pytest.raises(InputError, match="no mapping.*pige's kinematics component"):
        format_controller(CompensationParameters("wbXYZWCA(C1)t", {}, {}, None, {}, "t", []), "linuxcnc")


def test_cli_prints_setp_lines_from_a_hal_file(tmp_path, capsys) -> None:
    hal = tmp_path / "trt.hal"
    hal.write_text("loadrt xyzac-trt-kins\nsetp xyzac-trt-kins.y-offset 10.5\nsetp xyzac-trt-kins.z-offset -20\n"
                   "setp xyzac-trt-kins.x-rot-point 0\nsetp xyzac-trt-kins.y-rot-point 0\n"
                   "setp xyzac-trt-kins.z-rot-point 0\n")
    params = tmp_path / "p.json"
    params.write_text('{"machine": "wC\'A\'bXYZ(C1)t", "pige": {"EY0A": 5, "EZ0A": -3, "EX0C": 4, "EY0C": 2, '
                      '"EB0A": 0, "EC0A": 0, "EA0C": 0, "EB0C": 0}}')
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc", "--current", str(hal)]) == 0
    out = capsys.readouterr().out
    assert "setp xyzac-trt-kins.y-offset 10.503000" in out and "setp xyzac-trt-kins.z-offset -20.003000" in out
    assert "setp xyzac-trt-kins.x-rot-point 0.004000" in out
