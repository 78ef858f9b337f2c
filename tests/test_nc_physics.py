"""Physics: compensated NC programs on an independent exact kinematic chain (Rodrigues, written here).

The chain follows CONVENTIONS §2-3 for the AC tilting table ``wC'A'bXYZ(C1)t``: the C table is
carried by the A cradle, both turn what they carry by −θ (workpiece side); each axis turns about
its *actual* line (pivot + position errors, direction + orientation errors, exactly normalised)
by its commanded angle plus its zero-position error.  The tool point is where X/Y/Z put it.
"""

from __future__ import annotations

import numpy as np
import pytest

from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.compensation.program import compensate_nc
from pige_sym.kernels import load_kernels
from pige_sym.nc.program import make_rtest_program, parse_program

AC = "wC'A'bXYZ(C1)t"
BC = "wC'B'bXYZ(C1)t"
PIVOTS = {"A": [0.0, 20.0, -60.0], "C": [15.0, -10.0, -60.0]}
TRUTH = {"EY0A": 12.0, "EZ0A": -9.0, "EB0A": 25.0, "EC0A": -18.0,
         "EX0C": -14.0, "EY0C": 10.0, "EA0C": 20.0, "EB0C": -22.0, "EA0A": 30.0, "EC0C": -35.0}
PIVOTS_BC = {"B": [20.0, 0.0, -60.0], "C": [15.0, -10.0, -60.0]}
TRUTH_BC = {"EX0B": 12.0, "EZ0B": -9.0, "EA0B": 25.0, "EC0B": -18.0,
            "EX0C": -14.0, "EY0C": 10.0, "EA0C": 20.0, "EB0C": -22.0, "EB0B": 30.0, "EC0C": -35.0}


def rodrigues(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Exact rotation matrix about the unit vector ``axis``."""
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * kx + (1 - np.cos(angle_rad)) * kx @ kx


def machine_point(x_w: np.ndarray, a_deg: float, c_deg: float, errors: dict[str, float],
                  pivots: dict[str, list[float]]) -> np.ndarray:
    """Where the workpiece point ``x_w`` [mm] is in the machine frame at commanded tilt (A or B) and C (exact)."""
    if "B" in pivots:
        return bc_machine_point(x_w, a_deg, c_deg, errors, pivots)
    e = {k: errors.get(k, 0.0) for k in TRUTH}
    u_a = np.array([1.0, e["EC0A"] * 1e-6, -e["EB0A"] * 1e-6])
    u_c = np.array([e["EB0C"] * 1e-6, -e["EA0C"] * 1e-6, 1.0])
    q_a = np.array(pivots["A"]) + np.array([0.0, e["EY0A"], e["EZ0A"]]) * 1e-3
    q_c = np.array(pivots["C"]) + np.array([e["EX0C"], e["EY0C"], 0.0]) * 1e-3
    th_a = np.radians(a_deg) + e["EA0A"] * 1e-6
    th_c = np.radians(c_deg) + e["EC0C"] * 1e-6
    on_cradle = q_c + rodrigues(u_c, -th_c) @ (x_w - q_c)
    return q_a + rodrigues(u_a, -th_a) @ (on_cradle - q_a)


def bc_machine_point(x_w: np.ndarray, b_deg: float, c_deg: float, errors: dict[str, float],
                     pivots: dict[str, list[float]]) -> np.ndarray:
    """The same for the BC table ``wC'B'bXYZ(C1)t`` (B direction (−EC0B, 1, EA0B), CONVENTIONS §3)."""
    e = {k: errors.get(k, 0.0) for k in TRUTH_BC}
    u_b = np.array([-e["EC0B"] * 1e-6, 1.0, e["EA0B"] * 1e-6])
    u_c = np.array([e["EB0C"] * 1e-6, -e["EA0C"] * 1e-6, 1.0])
    q_b = np.array(pivots["B"]) + np.array([e["EX0B"], 0.0, e["EZ0B"]]) * 1e-3
    q_c = np.array(pivots["C"]) + np.array([e["EX0C"], e["EY0C"], 0.0]) * 1e-3
    on_cradle = q_c + rodrigues(u_c, -(np.radians(c_deg) + e["EC0C"] * 1e-6)) @ (x_w - q_c)
    return q_b + rodrigues(u_b, -(np.radians(b_deg) + e["EB0B"] * 1e-6)) @ (on_cradle - q_b)


def tool_direction(a_deg: float, c_deg: float, errors: dict[str, float]) -> np.ndarray:
    """Tool direction (machine Z) seen from the workpiece, exact."""
    e = {k: errors.get(k, 0.0) for k in TRUTH}
    u_a = np.array([1.0, e["EC0A"] * 1e-6, -e["EB0A"] * 1e-6])
    u_c = np.array([e["EB0C"] * 1e-6, -e["EA0C"] * 1e-6, 1.0])
    rot = rodrigues(u_a, -(np.radians(a_deg) + e["EA0A"] * 1e-6)) @ rodrigues(
        u_c, -(np.radians(c_deg) + e["EC0C"] * 1e-6))
    return rot.T @ np.array([0.0, 0.0, 1.0])


def _params(code: str = AC) -> CompensationParameters:
    truth, pivots = (TRUTH_BC, PIVOTS_BC) if code == BC else (TRUTH, PIVOTS)
    return CompensationParameters(load_kernels(code).MACHINE_CODE, dict(truth), {}, None, pivots, "truth", [])


def _poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    angles = np.column_stack([rng.uniform(-90, 30, n), rng.uniform(-180, 180, n)])
    points = rng.uniform(-80, 80, (n, 3)) + [0, 0, 60]
    return angles, points


def _run(program_text: str, axes: tuple[str, str] = ("A", "C")) -> tuple[np.ndarray, np.ndarray, list[bool]]:
    prog = parse_program(program_text, rotary_axes=axes)
    moves = [b for b in prog.blocks if b.is_motion]
    return (np.array([b.after[3:] for b in moves]), np.array([b.after[:3] for b in moves]), [b.rtcp for b in moves])


@pytest.mark.parametrize("code", [AC, BC])
def test_exact_chain_matches_the_nominal_kernels(code):
    kern = load_kernels(code)
    pivots = PIVOTS_BC if code == BC else PIVOTS
    angles, points = _poses(20, 1)
    piv = {k: np.array(v) for k, v in pivots.items()}
    for a, x in zip(angles, points, strict=True):
        np.testing.assert_allclose(kern.linear_commands(a[None], x, piv)[0], machine_point(x, *a, {}, pivots),
                                   atol=1e-9)


@pytest.mark.parametrize("code,rtcp,dialect", [(AC, False, "siemens"), (AC, True, "siemens"), (BC, False, "fanuc"),
                                               (BC, True, "fanuc"), (AC, False, "linuxcnc")])
def test_compensated_program_removes_95_percent_on_the_exact_chain(code, rtcp, dialect):
    truth, pivots = (TRUTH_BC, PIVOTS_BC) if code == BC else (TRUTH, PIVOTS)
    axes = ("B", "C") if code == BC else ("A", "C")
    angles, points = _poses(40, 2)
    nominal = np.array([machine_point(x, *a, {}, pivots) for a, x in zip(angles, points, strict=True)])
    text = make_rtest_program(angles, points if rtcp else nominal, axes, rtcp=rtcp, dialect=dialect)
    result = compensate_nc(text, _params(code), path="p")
    assert result.report.compensated == len(angles) and result.report.dialect == dialect

    def errors(program: str) -> np.ndarray:
        a_cmd, xyz_cmd, flags = _run(program, axes)
        out = []
        for i, (a, xyz) in enumerate(zip(a_cmd, xyz_cmd, strict=True)):
            tool = machine_point(xyz, *a, {}, pivots) if flags[i] else xyz  # the controller's nominal RTCP
            out.append((tool - machine_point(points[i], *a, truth, pivots)) * 1e3)
        return np.linalg.norm(out, axis=1)

    before, after = errors(text), errors(result.text)
    assert np.sqrt((before**2).mean()) > 20.0
    assert np.sqrt((after**2).mean()) <= 0.05 * np.sqrt((before**2).mean()), (before.max(), after.max())


def test_orientation_pole_guard_limits_c_and_still_corrects_the_position():
    angles = np.array([[0.0, 0.0], [0.002, 40.0], [-0.001, 200.0], [30.0, 90.0]])
    points = np.array([[50.0, 10.0, 60.0]] * 4)
    nominal = np.array([machine_point(x, *a, {}, PIVOTS) for a, x in zip(angles, points, strict=True)])
    result = compensate_nc(make_rtest_program(angles, nominal, ("A", "C")), _params(), path="p.mpf")
    a_cmd, xyz_cmd, _ = _run(result.text)
    assert np.abs(a_cmd - angles).max() <= 0.1 + 1e-9
    assert result.report.orientation_limited_lines  # the poles are reported
    before = [np.linalg.norm(nominal[i] - machine_point(points[i], *angles[i], TRUTH, PIVOTS)) for i in range(4)]
    after = [np.linalg.norm(xyz_cmd[i] - machine_point(points[i], *a_cmd[i], TRUTH, PIVOTS)) for i in range(4)]
    assert max(after[1:3]) < 0.05 * max(before[1:3])
    # the orientation is corrected away from the pole
    want = tool_direction(*angles[3], {})
    assert (np.linalg.norm(tool_direction(*a_cmd[3], TRUTH) - want)
            < 0.2 * np.linalg.norm(tool_direction(*angles[3], TRUTH) - want))
