"""LinuxCNC's trt kinematics, written here from its source, judge what ``--controller linuxcnc`` prints.

``xyzacKinematicsInverse`` and ``xyzbcKinematicsInverse`` of ``src/emc/kinematics/trtfuncs.c`` (master,
commit 5c41560ebbc3a40f84a5547bc6f7c5cd9278ba6b, lines 203–261 and 311–366) with ``con`` = ±1 for the pin
``conventional-directions``: ``con`` = −1 is the only behaviour of the installed 2.9.0~pre1 (commit
f1270d6ed7, where these formulas have no ``con``), whose trt kinematics turn both axes against CONVENTIONS'
sense (σ = −1, CONVENTIONS §9); ``con`` = +1 the ISO senses.  The controller runs the inverse kinematics
with its HAL pins: the joints X, Y, Z are where it puts the tool.  The true machine
(:mod:`test_controller_truth`) has the nominal axis lines moved by random PIGEs and the zero-position
errors; the tool point is compared with pige's model, pose by pose as vectors, before and after the printed
pins are entered.  With ``halrun`` (Debian's ``linuxcnc-uspace``), the printed lines also run in real HAL on
top of the stock configuration's own ``net``/``sets``/``setp`` lines, and the pin values HAL then holds are
the ones the chain is checked with.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
from test_controller_truth import AC, BC, Machine, assert_follows_model, poses, random_machine

from pige_sym.cli.main import main
from pige_sym.compensation.controllers.hal_config import read_current
from pige_sym.compensation.controllers.linuxcnc import linuxcnc_trt_deltas
from pige_sym.compensation.controllers.scope import representable, tool_point_summary
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.stage import format_controller
from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels

PINS = ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset")
STOCK = Path("/usr/share/doc/linuxcnc/examples/sample-configs/sim/axis/vismach/5axis/table-rotary-tilting")


def _xyzac_inverse(pos: np.ndarray, a: float, c: float, h: dict[str, float], con: float) -> np.ndarray:
    xr, yr, zr, dy, dz = h["x-rot-point"], h["y-rot-point"], h["z-rot-point"], h["y-offset"], h["z-offset"]
    a, c = math.radians(a), math.radians(c)
    x, y, z = pos
    return np.array([
        math.cos(c) * (x - xr) + con * math.sin(c) * (y - yr) + xr,
        -con * math.sin(c) * math.cos(a) * (x - xr) + math.cos(c) * math.cos(a) * (y - yr)
        + con * math.sin(a) * (z - zr) - math.cos(a) * dy - con * math.sin(a) * dz + dy + yr,
        math.sin(c) * math.sin(a) * (x - xr) - con * math.cos(c) * math.sin(a) * (y - yr)
        + math.cos(a) * (z - zr) + con * math.sin(a) * dy - math.cos(a) * dz + dz + zr])


def _xyzbc_inverse(pos: np.ndarray, b: float, c: float, h: dict[str, float], con: float) -> np.ndarray:
    xr, yr, zr, dx, dz = h["x-rot-point"], h["y-rot-point"], h["z-rot-point"], h["x-offset"], h["z-offset"]
    b, c = math.radians(b), math.radians(c)
    x, y, z = pos
    dpx = -math.cos(b) * dx + con * math.sin(b) * dz + dx
    dpz = -con * math.sin(b) * dx - math.cos(b) * dz + dz
    return np.array([
        math.cos(c) * math.cos(b) * (x - xr) + con * math.sin(c) * math.cos(b) * (y - yr)
        - con * math.sin(b) * (z - zr) + dpx + xr,
        -con * math.sin(c) * (x - xr) + math.cos(c) * (y - yr) + yr,
        con * math.cos(c) * math.sin(b) * (x - xr) + math.sin(c) * math.sin(b) * (y - yr)
        + math.cos(b) * (z - zr) + dpz + zr])


def _nominal_pins(machine: Machine) -> dict[str, float]:
    """The trt description of the nominal axis lines (C at the rot point, the tilt line at rot point + offset)."""
    tilt = machine.workpiece_axes[1]
    pc, pt = np.asarray(machine.pivots["C"]), np.asarray(machine.pivots[tilt])
    pins = dict.fromkeys(PINS, 0.0) | {"x-rot-point": pc[0], "y-rot-point": pc[1], "z-rot-point": 7.5}
    if tilt == "A":
        return pins | {"y-offset": pt[1] - pc[1], "z-offset": pt[2] - 7.5}
    return pins | {"x-offset": pt[0] - pc[0], "z-offset": pt[2] - 7.5}


def _controller(machine: Machine, pins: dict[str, float], con: float):
    tilt = machine.workpiece_axes[1]
    inverse = _xyzac_inverse if tilt == "A" else _xyzbc_inverse

    def command(pose: dict[str, float], point: np.ndarray) -> np.ndarray:
        joints = inverse(np.asarray(point, dtype=float), pose[tilt], pose["C"], pins, con)
        return joints - machine.tool_ball()  # the joints X, Y, Z are the tool's controlled point
    return command


def _check(machine: Machine, pins: dict[str, float], con: float, angles: np.ndarray, names: list[str] | None) -> float:
    return assert_follows_model(machine, _controller(machine, pins, con), angles, names)


def _setp(text: str, module: str) -> dict[str, float]:
    return {ln.split()[1].removeprefix(module + "."): float(ln.split()[2]) for ln in text.splitlines()
            if ln.startswith(f"setp {module}.")}


@pytest.mark.parametrize("code", [AC, BC])
@pytest.mark.parametrize("con", [1.0, -1.0])
def test_the_printed_pins_put_the_tool_where_pige_says(code: str, con: float) -> None:
    """Pose by pose, as vectors: the trt chain with nominal pins deviates as pige's model says; with the
    printed pins, what is left is pige's model of what the pins cannot hold (tilts, zero-position errors)."""
    senses = {} if con > 0 else {"C": -1, ("A" if code == AC else "B"): -1}
    machine = random_machine(code, 4, senses=senses)
    angles = poses(machine, 4)
    nominal = _nominal_pins(machine)
    assert _check(machine, nominal, con, angles, None) > 5.0
    module = "xyzac-trt-kins" if code == AC else "xyzbc-trt-kins"
    text = format_controller(machine.params(), "linuxcnc", current=nominal)
    entered = _setp(text, module)
    assert set(entered) == set(linuxcnc_trt_deltas(machine.params())[1])
    held = representable(machine.params(), "linuxcnc")
    left = [n for n in machine.kern.PARAMETERS if n not in held]
    assert _check(machine, nominal | entered, con, angles, left) > 0.5
    positions = Machine(code, {n: machine.values[n] for n in held}, machine.pivots, machine.ball, None, senses)
    assert _check(positions, nominal | _setp(format_controller(positions.params(), "linuxcnc", current=nominal),
                                             module), con, angles, []) < 1e-3


def test_what_linuxcnc_cannot_hold_is_named_with_the_error_it_leaves() -> None:
    kern = load_kernels(AC)
    values = {"EY0A": 5.0, "EZ0A": -3.0, "EX0C": 4.0, "EY0C": 2.0, "EB0A": 30.0, "EA0C": -20.0}
    params = CompensationParameters(kern.MACHINE_CODE, values, dict(kern.UNITS), None, {}, "test", [])
    scope = tool_point_summary(params, "linuxcnc")
    assert scope.entered == ["EY0A", "EZ0A", "EX0C", "EY0C"]
    assert [s.split()[0] for s in scope.not_representable] == ["EB0A", "EA0C"]
    tilts_only = CompensationParameters(kern.MACHINE_CODE, {"EB0A": 30.0, "EA0C": -20.0}, dict(kern.UNITS), None, {},
                                        "test", [])
    tilts_left = tool_point_summary(tilts_only, "linuxcnc").before
    assert scope.controller_only.expected_um == pytest.approx(tilts_left.expected_um, rel=1e-6)
    assert scope.complete.expected_um < 0.05 < scope.controller_only.expected_um < scope.before.expected_um
    text = format_controller(params, "linuxcnc")
    assert "NOT representable" in text and "EB0A +30 urad" in text and "\nsetp xyzac-trt-kins" not in text
    assert "# xyzac-trt-kins.y-offset: add +0.0030000" in text and "requires LinuxCNC >= 2.9" in text
    assert "setp pige_xyzac_trt.eb0a 30.0000" in text  # beside them, pige's component holds every PIGE
    head = format_controller(CompensationParameters("wbXYZCA(C1)t", {}, {}, None, {}, "t", []), "linuxcnc")
    assert "stock trt kinematics" in head and "no mapping" in head and "# pige_xyzac_head.ex0c: not estimated" in head
    with pytest.raises(InputError, match="no mapping.*pige's kinematics component"):
        format_controller(CompensationParameters("wbXYZWCA(C1)t", {}, {}, None, {}, "t", []), "linuxcnc")


STOCK_LIKE = """[KINS]
KINEMATICS = {module} sparm=identityfirst
JOINTS = 5
[HAL]
HALFILE = LIB:basic_sim.tcl
HALCMD = net  :tool-offset  motion.tooloffset.z
HALCMD = net  :tool-offset  {module}.tool-offset {gui}.tool-offset
HALCMD = net  :{first}-offset     {module}.{first}-offset    {gui}.{first}-offset
HALCMD = net  :z-offset     {module}.z-offset    {gui}.z-offset
HALCMD = sets :{first}-offset     20
HALCMD = sets :z-offset     10
HALCMD = setp {module}.x-rot-point 0
HALCMD = setp {module}.y-rot-point 0
HALCMD = setp {module}.z-rot-point 0
"""


def _stock_like(tmp_path: Path, code: str) -> Path:
    ac = code == AC
    ini = tmp_path / ("xyzac-trt.ini" if ac else "xyzbc-trt.ini")
    ini.write_text(STOCK_LIKE.format(module="xyzac-trt-kins" if ac else "xyzbc-trt-kins",
                                     gui="xyzac-trt-gui" if ac else "xyzbc-trt-gui", first="y" if ac else "x"))
    return ini


def _with_pivots(machine: Machine, pivots: dict[str, tuple[float, float, float]]) -> Machine:
    """``machine`` with other nominal pivots (those of a configuration)."""
    return Machine(machine.code, machine.values, {a: np.array(v) for a, v in pivots.items()}, machine.ball,
                   machine.tool, machine.senses)


def test_the_stock_configuration_gets_sets_lines_and_the_wrong_kinematics_is_refused(tmp_path) -> None:
    machine = _with_pivots(random_machine(AC, 9), {"A": (4.0, 20.0, 10.0), "C": (0.0, 0.0, -3.0)})  # the INI's lines
    ini = _stock_like(tmp_path, AC)
    config = read_current(str(ini))
    assert config.module == "xyzac-trt-kins" and config.nets["y-offset"] == ":y-offset"
    assert config.signals == {":y-offset": 20.0, ":z-offset": 10.0} and config.unread == ["LIB:basic_sim.tcl"]
    text = format_controller(machine.params(), "linuxcnc", current=config)
    deltas = linuxcnc_trt_deltas(machine.params())[1]
    assert f"sets :y-offset {20 + deltas['y-offset']:.7f}" in text and "setp xyzac-trt-kins.y-offset" not in text
    assert f"sets :z-offset {10 + deltas['z-offset']:.7f}" in text
    assert f"setp xyzac-trt-kins.x-rot-point {deltas['x-rot-point']:.7f}" in text
    assert str(ini) not in text.split("not read")[-1].split("\n", 1)[-1]  # no hint names the file given
    with pytest.raises(InputError, match="its kinematics are xyzbc-trt-kins .* needs xyzac-trt-kins"):
        format_controller(machine.params(), "linuxcnc", current=read_current(str(_stock_like(tmp_path, BC))))
    # a pin on a signal that the configuration does not set: the change as a comment, never a guessed line
    bare = tmp_path / "bare.hal"
    bare.write_text("loadrt xyzac-trt-kins\nnet :zo xyzac-trt-kins.z-offset other.pin\n"
                    "setp xyzac-trt-kins.y-offset 3\n")
    machine = _with_pivots(machine, {"A": (0.0, 3.0, 10.0), "C": (0.0, 0.0, 0.0)})  # bare.hal's lines
    text = format_controller(machine.params(), "linuxcnc", current=read_current(str(bare)))
    assert "sets :zo" not in text and "connected to signal :zo, which" in text
    assert f"setp xyzac-trt-kins.y-offset {3 + deltas['y-offset']:.7f}" in text
    assert "# xyzac-trt-kins.x-rot-point is not set in" in text  # HAL starts a pin at 0
    assert f"setp xyzac-trt-kins.x-rot-point {deltas['x-rot-point']:.7f}" in text
    pins_only = format_controller(machine.params(), "linuxcnc", current={"y-offset": 1.0})
    assert "give its value as x-rot-point=VALUE" in pins_only and "INI or HAL file" not in pins_only


@pytest.mark.skipif(not STOCK.is_dir(), reason="LinuxCNC's sample configurations are not installed")
@pytest.mark.parametrize("code", [AC, BC])
def test_cli_reads_the_shipped_configuration(code: str, tmp_path, capsys) -> None:
    params = tmp_path / "p.json"
    params.write_text('{"machine": "%s", "pige": {"EX0C": 4, "EY0C": 2, "EA0C": 0, "EB0C": 0, "%s": 5, "EZ0%s": -3, '
                      '"%s": 0, "%s": 0}, "pivots_mm": {"C": [0, 0, 0], "%s": %s}}'
                      % ((code, "EY0A", "A", "EB0A", "EC0A", "A", "[0, 20, 10]") if code == AC else
                         (code, "EX0B", "B", "EA0B", "EC0B", "B", "[-20, 0, -15]")))  # the stock INI's lines
    ini = STOCK / ("xyzac-trt.ini" if code == AC else "xyzbc-trt.ini")
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc", "--current", str(ini)]) == 0
    out = capsys.readouterr().out
    if code == AC:  # the stock y/z offsets are 20 and 10, on signals; the rot points 0 by setp
        assert "sets :y-offset 20.0030000" in out and "sets :z-offset 9.9970000" in out
    else:  # x/z offsets -20 and -15
        assert "sets :x-offset -19.9990000" in out and "sets :z-offset -15.0030000" in out
    assert "setp " + ("xyzac" if code == AC else "xyzbc") + "-trt-kins.x-rot-point 0.0040000" in out
    other = STOCK / ("xyzbc-trt.ini" if code == AC else "xyzac-trt.ini")
    assert main(["compensate", "--params", str(params), "--controller", "linuxcnc", "--current", str(other)]) == 2


def _halrun(script: str) -> str | None:
    """Run a HAL script in real (non-realtime) HAL, isolated from any other HAL session on this machine (own
    IPC, PID and mount namespaces, a private /tmp); None when LinuxCNC or the namespaces are not available."""
    if shutil.which("halrun") is None or shutil.which("unshare") is None:
        return None
    work = tempfile.mkdtemp(prefix="pige-hal-")
    with open(os.path.join(work, "check.hal"), "w", encoding="utf-8") as fh:
        fh.write(script)
    isolated = ('mount --bind "$0" /mnt && mount -t tmpfs -o mode=1777 tmpfs /tmp && cd /tmp && '
                "RTAPI_UID=65534 RTAPI_FIFO_PATH=/tmp/rtapi_fifo halrun -f /mnt/check.hal")
    try:
        run = subprocess.run(["unshare", "--ipc", "--pid", "--mount", "--fork", "--mount-proc", "sh", "-c", isolated,
                              work], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return None
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return run.stdout + run.stderr


@pytest.mark.parametrize("code", [AC, BC])
def test_the_printed_lines_run_in_real_hal(code: str, tmp_path) -> None:
    """halcmd accepts the printed sets/setp lines on the stock configuration's nets (and refuses setp on a
    netted pin, as the issue measured); the pins HAL then holds put the tool where pige says."""
    machine = random_machine(code, 12)
    module = "xyzac-trt-kins" if code == AC else "xyzbc-trt-kins"
    nominal = _nominal_pins(machine)
    first = "y" if code == AC else "x"
    stock = [f"loadrt {module}", f"net :{first}-offset {module}.{first}-offset",
             f"net :z-offset {module}.z-offset", f"sets :{first}-offset {nominal[first + '-offset']:.7f}",
             f"sets :z-offset {nominal['z-offset']:.7f}"]
    stock += [f"setp {module}.{p} {nominal[p]:.7f}" for p in ("x-rot-point", "y-rot-point", "z-rot-point")]
    hal = tmp_path / "machine.hal"
    hal.write_text("\n".join(stock) + "\n")
    text = format_controller(machine.params(), "linuxcnc", current=read_current(str(hal)))
    printed = [ln for ln in text.splitlines() if ln.startswith((f"setp {module}.", "sets "))]
    assert sum(ln.startswith("sets ") for ln in printed) == 2
    out = _halrun("\n".join(stock + printed + [f"show pin {module}", f"setp {module}.z-offset 1"]) + "\n")
    if out is None or "Component Pins" not in out:
        pytest.skip("LinuxCNC's halrun (or unshare as root) is not available here")
    assert f"pin '{module}.z-offset' is connected to a signal" in out
    held = {m.group(2): float(m.group(1)) for m in re.finditer(rf"float\s+IN\s+(\S+)\s+{module}\.([a-z-]+)", out)}
    printed_values = nominal | {ln.split()[1].split(".")[-1].lstrip(":"): float(ln.split()[2]) for ln in printed}
    for pin in linuxcnc_trt_deltas(machine.params())[1]:  # halcmd shows 7 significant digits (%.7g)
        assert held[pin] == pytest.approx(printed_values[pin], rel=6e-7, abs=1e-12), pin
        assert abs(printed_values[pin] - nominal[pin]) > 0 or pin == "z-rot-point"
    positions = [n for n in machine.kern.PARAMETERS if n in representable(machine.params(), "linuxcnc")]
    left = [n for n in machine.kern.PARAMETERS if n not in positions]
    _check(machine, {p: printed_values.get(p, nominal[p]) for p in PINS}, 1.0, poses(machine, 12, n=6), left)
