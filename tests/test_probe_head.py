"""Touch probe on head and mixed machines (CONVENTIONS §7, "Head and mixed machines"): the import against an
independent oracle.

The oracle below is written from CONVENTIONS §2–3 and §7 alone, with numpy and nothing of pige_sym: every
rotary axis is an exact rigid motion ``x ↦ q + R(u', s·θ)(x − q)`` about its erroneous line (``q = p + δ``,
``u' = (u + ε × u)/|…|``, Rodrigues), the workpiece chain applied from the workpiece outward, the tool chain
from the bed towards the tool.  At each pose the stylus-tip centre touches the truly placed sphere at
``R + r`` (the sphere on the table turned by the true workpiece chain); the probing moves turn with the head
(one contact along the stylus axis from the spindle side, a ring around it; each contact's scatter lies along
its move); the logged X Y Z is the linear axes' position, i.e. ``tip − T_true(θ)(b0) + b0`` with
``b0 = p_head + tool`` (where the tip would be with the head at its reference pose).  The head's own pivot is
put somewhere else than the table's on purpose: only ``tool`` may matter.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from pige_sym.errors import InputError
from pige_sym.identification.least_squares import identify
from pige_sym.measurements.probe_import import ProbeImport, import_probe_log

FORK = "wbXYZCA(C1)t"
MIXED = "wC'bXYZB(C1)t"
R_SPHERE, R_STYLUS = 12.7, 1.5

# ------------------------------------------------------------------------------------------------ the oracle

_U = {"A": np.array([1.0, 0.0, 0.0]), "B": np.array([0.0, 1.0, 0.0]), "C": np.array([0.0, 0.0, 1.0])}
# CONVENTIONS §3: position errors (µm) and orientation errors (µrad, about the named machine axis)
_ERRORS = {"A": (("EY0A", 1), ("EZ0A", 2), ("EB0A", 1), ("EC0A", 2)),
           "B": (("EX0B", 0), ("EZ0B", 2), ("EA0B", 0), ("EC0B", 2)),
           "C": (("EX0C", 0), ("EY0C", 1), ("EA0C", 0), ("EB0C", 1))}
# the two machines: (workpiece axes from the workpiece outward, tool axes from the bed towards the tool)
_CHAINS = {FORK: ((), ("C", "A")), MIXED: (("C",), ("B",))}


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx @ kx


def _axis_motion(name: str, theta_deg: float, side_sign: float, pivot: np.ndarray, pige: dict[str, float]):
    (pos1, i1), (pos2, i2), (ori1, j1), (ori2, j2) = _ERRORS[name]
    delta, eps = np.zeros(3), np.zeros(3)
    delta[i1], delta[i2] = pige.get(pos1, 0.0) * 1e-3, pige.get(pos2, 0.0) * 1e-3  # µm -> mm
    eps[j1], eps[j2] = pige.get(ori1, 0.0) * 1e-6, pige.get(ori2, 0.0) * 1e-6  # µrad -> rad
    u = _U[name]
    rot = _rodrigues(u + np.cross(eps, u), side_sign * math.radians(theta_deg))
    q = pivot + delta
    return lambda x: q + rot @ (x - q)


def oracle_workpiece(machine: str, angles: dict[str, float], pivot: np.ndarray, pige: dict[str, float], x):
    """Where a workpiece point ``x`` (M at the reference pose) is at the pose, exactly."""
    for name in _CHAINS[machine][0]:  # from the workpiece outward: the innermost axis moves it first
        x = _axis_motion(name, angles[name], -1.0, pivot, pige)(x)
    return x


def oracle_tool(machine: str, angles: dict[str, float], pivot: np.ndarray, pige: dict[str, float], x):
    """Where a spindle-body point ``x`` (ram frame at the reference pose) is at the pose, exactly."""
    for name in reversed(_CHAINS[machine][1]):  # the axis nearest the tool moves it first
        x = _axis_motion(name, angles[name], 1.0, pivot, pige)(x)
    return x


def oracle_log(machine: str, poses: list[dict[str, float]], *, pige: dict[str, float], tool: np.ndarray,
               sphere: np.ndarray, table_pivot: np.ndarray, head_pivot: np.ndarray, sigma_um: float, seed: int,
               moves: str = "axes", layout: str = "linuxcnc") -> str:
    """The probe log of the poses (module docstring); ``moves`` sets the direction of each contact's scatter."""
    rng = np.random.default_rng(seed)
    r_eff = R_SPHERE + R_STYLUS
    b0 = head_pivot + tool
    out = []
    for k, pose in enumerate(poses):
        centre = oracle_workpiece(machine, pose, table_pivot, pige, sphere)
        head = oracle_tool(machine, pose, head_pivot, pige, b0) - b0
        frame = np.eye(3)  # the nominal stylus frame: the tool chain without errors
        for col in range(3):
            frame[:, col] = oracle_tool(machine, pose, np.zeros(3), {}, np.eye(3)[col])
        stem = oracle_workpiece(machine, pose, np.zeros(3), {}, np.array([0.0, 0.0, -1.0]))
        e1, e2, axis = frame[:, 0], frame[:, 1], frame[:, 2]
        normals = [(axis, -axis)]
        for phi in (0.0, 90.0, 180.0, 270.0, 45.0, 225.0):
            across = math.cos(math.radians(phi)) * e1 + math.sin(math.radians(phi)) * e2
            elev = math.radians(20.0 if phi % 90 == 0 else 55.0)
            normals.append((math.cos(elev) * across + math.sin(elev) * axis, -across))
        normals = [(n, m) for n, m in normals if n @ stem < math.cos(math.radians(60.0))][:5]
        for j, (n, move) in enumerate(normals):
            along = move if moves == "axes" else -n
            tip = centre + r_eff * n + along * rng.normal(0.0, sigma_um * 1e-3)
            x = tip - head
            angles = {a: pose[a] for a in sorted(pose)}
            if layout == "linuxcnc":
                nine = {"X": x[0], "Y": x[1], "Z": x[2]} | angles
                out.append(" ".join(f"{nine.get(a, 0.0):f}" for a in "XYZABCUVW"))
            else:
                out.append(f"PIGE P{k} K{j} X{x[0]:.6f} Y{x[1]:.6f} Z{x[2]:.6f} "
                           + " ".join(f"{a}{v:.6f}" for a, v in angles.items()))
    return "\n".join(out) + "\n"


def fork_poses() -> list[dict[str, float]]:
    """37 poses: the reference, then A 15/30/45° each at 12 C positions (185 contacts at five per pose)."""
    return [{"A": 0.0, "C": 0.0}] + [{"A": a, "C": c} for a in (15.0, 30.0, 45.0) for c in range(0, 360, 30)]


def mixed_poses() -> list[dict[str, float]]:
    return [{"B": 0.0, "C": 0.0}] + [{"B": b, "C": c} for b in (-40.0, -20.0, 20.0, 40.0)
                                     for c in (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)]


FORK_TRUTH = {"EY0A": 12.0, "EZ0A": -8.0, "EB0A": 25.0, "EC0A": -15.0, "EX0C": 6.0, "EY0C": -10.0,
              "EA0C": 18.0, "EB0C": -22.0}
MIXED_TRUTH = {"EX0B": -9.0, "EZ0B": 7.0, "EA0B": 20.0, "EC0B": -12.0, "EX0C": 11.0, "EY0C": -5.0,
               "EA0C": -16.0, "EB0C": 24.0}
CASES = {
    FORK: dict(poses=fork_poses, truth=FORK_TRUTH, tool=np.array([0.0, 0.0, -160.0]), sphere=np.array([30.0, -20.0,
               -100.0]), table_pivot=np.zeros(3), head_pivot=np.array([250.0, 40.0, 400.0])),
    MIXED: dict(poses=mixed_poses, truth=MIXED_TRUTH, tool=np.array([1.5, -2.0, -210.0]),
                sphere=np.array([120.0, 30.0, 40.0]), table_pivot=np.array([0.0, 0.0, -50.0]),
                head_pivot=np.array([-80.0, 10.0, 500.0])),
}


def _import(tmp_path: Path, machine: str, seed: int, *, moves: str = "axes", layout: str = "linuxcnc",
            sigma_um: float = 0.5, pige: dict[str, float] | None = None, name: str = "log.txt"):
    case = CASES[machine]
    text = oracle_log(machine, case["poses"](), pige=case["truth"] if pige is None else pige, tool=case["tool"],
                      sphere=case["sphere"], table_pivot=case["table_pivot"], head_pivot=case["head_pivot"],
                      sigma_um=sigma_um, seed=seed, moves=moves, layout=layout)
    path = tmp_path / name
    path.write_text(text)
    spec = ProbeImport(machine, tuple(case["table_pivot"]), R_SPHERE, R_STYLUS, moves=moves,
                       tool_mm=tuple(case["tool"]))
    return import_probe_log(path, layout if layout == "linuxcnc" else "siemens", spec)


def _errors_in_std(machine: str, result) -> dict[str, float]:
    truth = CASES[machine]["truth"]
    return {n: (result.value(n) - truth[n]) / result.std[i] for i, n in enumerate(result.parameters)}


# ------------------------------------------------------------------------------------------------ the oracle itself


def test_the_oracle_follows_the_conventions_senses() -> None:
    """Sanity of the oracle against CONVENTIONS §2: a tool-side A turns +θ about +X, a primed C turns −θ."""
    x = np.array([0.0, 0.0, -100.0])
    np.testing.assert_allclose(oracle_tool(FORK, {"A": 90.0, "C": 0.0}, np.zeros(3), {}, x), [0.0, 100.0, 0.0],
                               atol=1e-12)
    np.testing.assert_allclose(oracle_workpiece(MIXED, {"B": 0.0, "C": 90.0}, np.zeros(3), {}, np.array([1.0, 0, 0])),
                               [0.0, -1.0, 0.0], atol=1e-12)
    # an axis-line offset moves nothing at the reference pose (§3)
    np.testing.assert_allclose(oracle_tool(FORK, {"A": 0.0, "C": 0.0}, np.zeros(3), FORK_TRUTH, x), x, atol=1e-15)


# ------------------------------------------------------------------------------------------------ import + identify


@pytest.mark.parametrize(("machine", "moves", "layout"), [(FORK, "axes", "linuxcnc"), (MIXED, "normal", "siemens"),
                                                          (MIXED, "axes", "linuxcnc"), (FORK, "normal", "siemens")])
def test_oracle_logs_are_imported_with_the_tool_and_identified(tmp_path, machine, moves, layout) -> None:
    m = _import(tmp_path, machine, seed=1, moves=moves, layout=layout)
    assert m.tool_mm is not None and m.metadata["stylus_frame"].startswith("turns with the head")
    result = identify(m)
    truth = CASES[machine]["truth"]
    for i, name in enumerate(result.parameters):
        err = abs(result.value(name) - truth[name])
        assert err <= 4 * result.std[i] + 0.3, (name, err, result.std[i])


def test_a_pure_head_deviation_is_exactly_minus_the_rtest_one(tmp_path) -> None:
    """Without noise on a fork head e = −d holds exactly (no table rotary axis): the identified PIGEs are the
    truth to the rounding of the log's six decimals."""
    result = identify(_import(tmp_path, FORK, seed=0, sigma_um=0.0))
    for name, value in FORK_TRUTH.items():
        assert result.value(name) == pytest.approx(value, abs=0.02)


@pytest.mark.parametrize("machine", [FORK, MIXED])
def test_the_standard_errors_are_honest(tmp_path, machine) -> None:
    """Over 40 oracle logs the errors divided by the reported standard errors have unit spread."""
    z = np.array([list(_errors_in_std(machine, identify(_import(tmp_path, machine, seed=s, sigma_um=1.0))).values())
                  for s in range(40)])
    spread = np.std(z, axis=0)
    assert np.all((spread > 0.7) & (spread < 1.35)), np.round(spread, 2)
    assert np.abs(z).max() < 4.5


def test_a_37_pose_185_contact_head_log_imports_and_identifies_quickly(tmp_path) -> None:
    """The speed target (under 1 s for import + identify; measured here well below, without interpreter start)."""
    text = oracle_log(FORK, fork_poses(), pige=FORK_TRUTH, tool=CASES[FORK]["tool"], sphere=CASES[FORK]["sphere"],
                      table_pivot=np.zeros(3), head_pivot=CASES[FORK]["head_pivot"], sigma_um=0.5, seed=3)
    assert text.count("\n") == 185
    path = tmp_path / "log.txt"
    path.write_text(text)
    spec = ProbeImport(FORK, (0.0, 0.0, 0.0), R_SPHERE, R_STYLUS, tool_mm=tuple(CASES[FORK]["tool"]))
    start = time.perf_counter()
    result = identify(import_probe_log(path, "linuxcnc", spec))
    assert time.perf_counter() - start < 1.0 and result.n_rows == 37


# ------------------------------------------------------------------------------------------------ refusals


def test_a_head_machine_without_its_tool_is_refused_in_one_line(tmp_path) -> None:
    path = tmp_path / "log.txt"
    path.write_text(oracle_log(FORK, fork_poses()[:3], pige={}, tool=CASES[FORK]["tool"], sphere=CASES[FORK]["sphere"],
                               table_pivot=np.zeros(3), head_pivot=np.zeros(3), sigma_um=0.0, seed=0))
    with pytest.raises(InputError, match=r"tool-side rotary axes \(C, A\).*--tool x,y,z") as err:
        import_probe_log(path, "linuxcnc", ProbeImport(FORK, (0.0, 0.0, 0.0), R_SPHERE, R_STYLUS))
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="no tool-side rotary axis"):
        import_probe_log(path, "linuxcnc", ProbeImport("wC'A'bXYZ(C1)t", (0.0, 0.0, 0.0), R_SPHERE, R_STYLUS,
                                                       tool_mm=(0.0, 0.0, -100.0)))


def test_head_files_without_their_tool_are_refused_by_every_command(tmp_path, capsys) -> None:
    """Regression: identify, diagnose, compare, report, compensate and study sobol raised the kernels' ValueError
    (a traceback) for a head machine without its tool; now every one refuses with one line (exit 2)."""
    import json

    from pige_sym.cli.main import main

    csv = tmp_path / "head.csv"
    assert main(["simulate", "--machine", FORK, "--tool", "0,0,-150", "--out", str(csv)]) == 0
    params = tmp_path / "p.json"
    capsys.readouterr()
    assert main(["identify", str(csv), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    params.write_text(json.dumps(doc | {"tool_mm": None}))
    csv.write_text("".join(ln for ln in csv.read_text().splitlines(keepends=True) if "tool_mm" not in ln))
    part = tmp_path / "part.ngc"
    part.write_text("G21 G90\nG0 X10 Y0 Z50 A10 C20\nG1 X20 A15 F500\nM2\n")
    commands = [["identify", str(csv)], ["diagnose", str(csv)], ["compare", str(csv), str(csv)],
                ["report", str(csv), "--out", str(tmp_path / "r.html")],
                ["compensate", str(part), "--params", str(params), "--machine", FORK, "--out", str(tmp_path / "c.ngc")],
                ["study", "sobol", "--machine", FORK], ["study", "projection", "--machine", FORK, "--presets", "2"]]
    for cmd in commands:
        assert main(cmd) == 2, cmd
        err = capsys.readouterr().err.strip()
        assert "tool-side rotary axes (C, A)" in err and "\n" not in err, (cmd, err)
