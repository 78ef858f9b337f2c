"""The correction, two ways, on real LinuxCNC 2.9 (issue 31, item 4; :mod:`corrections` says how each is entered).

From the identity-kinematics probing run of each machine (tests/linuxcnc/conftest.py), pige's identification
is entered into a fresh copy of the shipped configuration, and the machine is probed again in TCP kinematics
(where the kinematics' values act):

- (a) the stock trt pins printed by ``pige compensate --controller linuxcnc --current …`` (``sets`` for the
  netted offsets): the axis-line offsets the second run finds are the first run's errors (truth − entered,
  within noise), the tilts are the true ones (the trt kinematics carry none);
- (b) pige's own kinematics component (``pige gen --target linuxcnc``) with the ``setp`` lines compensate
  prints: all eight PIGEs the second run finds are the first run's errors.  Then, in TCP mode, MDI moves to
  work points around the sphere (at 6 mm, at three of the probed poses): the true tool point lands on each
  commanded point, within 1 µm with the identified values, and to the model's second order with the true
  values entered instead (the kinematics itself, free of identification noise).  The true tool point is the
  exact rigid-body twin's at the joint feedback (pige's model in the true machine gives the same to 1e-5 mm).

Four simulations at once; expected errors compared in units of the second run's standard errors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from corrections import enter_trt_pins, kinematics_changes, pige_kinematics, trt_correction, trt_lines
from loop_setup import MACHINES, SPHERE_MM, ProbeRun, probing_run, run_all

from conftest import TWIN_TOL_MM

pytestmark = pytest.mark.linuxcnc
TIP = ["ptt.tip-x", "ptt.tip-y", "ptt.tip-z"]
JOINTS = [f"joint.{k}.pos-fb" for k in range(5)]
TARGET_OFFSETS_MM = [(0, 0, 0), (6, 0, 0), (0, 6, 0), (-6, 0, 0), (0, -6, 0), (0, 0, 6)]
#: commanded (tilt, C) [deg]: probed poses 3, 5 and 11 of the 13-pose cone of each machine
TARGET_ANGLES = {"AC": [(-26.3266, -102.4775), (-20.0, -180.0), (-38.9517, -336.5675)],
                 "BC": [(-26.3266, -12.4775), (-20.0, -90.0), (-38.9517, -246.5675)]}


def targets(machine: str) -> list[tuple[float, float, float, float, float]]:
    """Work points around the sphere centre at three probed poses: (x, y, z, tilt, c)."""
    return [(*(SPHERE_MM + off), t, c) for t, c in TARGET_ANGLES[machine] for off in TARGET_OFFSETS_MM]


def move_lines(machine: str) -> list[str]:
    """One move per target in work coordinates (TCP); the true machine's probe is off, nothing to avoid."""
    outer = MACHINES[machine].outer
    return [f"G0 X{x:.4f} Y{y:.4f} Z{z:.4f} {outer}{t:g} C{c:g}" for x, y, z, t, c in targets(machine)]


def tcp_move_steps(machine: str, name: str) -> list[dict]:
    """After the probing run: no more trips; the moves with the identified values, then with the true ones."""
    m = MACHINES[machine]
    truth = [f"setp {name}.{k.lower()} {v!r}" for k, v in m.pige.items()]
    return [{"op": "hal", "commands": ["setp ptt.trip-radius -1"]},
            {"op": "mdi", "lines": [f"G43 H{m.stylus[0]}", *move_lines(machine)], "read": TIP + JOINTS},
            {"op": "mdi", "lines": ["M429"]}, {"op": "hal", "commands": truth},
            {"op": "mdi", "lines": ["M428", *move_lines(machine)], "read": TIP + JOINTS}]


def landed(step: dict, pins: list[str]) -> np.ndarray:
    """The readings of ``pins`` at each target (after the step's first line), (n, len(pins))."""
    return np.array([[row[p] for p in pins] for row in step["readings"][1:]])


@pytest.fixture(scope="module")
def identity_runs(table_runs) -> dict[tuple[str, str], ProbeRun]:
    """Both machines' identity-kinematics probing runs (:func:`conftest.table_runs`: made once per session)."""
    return table_runs(*[(k, "identity") for k in sorted(MACHINES)])


def trt_pins_run(first: ProbeRun, root: Path) -> ProbeRun:
    """(a): the stock trt pins ``pige compensate --current`` prints from ``first``'s identification, entered."""
    m = first.machine
    _, pins = trt_correction(m, first.identification_file)
    return probing_run(m, root, "tcp", extra=enter_trt_pins(m.kind, pins), pivots=trt_lines(m.kind, pins))


def pige_kinematics_run(first: ProbeRun, root: Path, machine: str) -> ProbeRun:
    """(b): pige's kinematics component with the lines ``pige compensate`` prints, then the TCP moves."""
    m = first.machine
    name, source, lines = pige_kinematics(m, first.identification_file, root / "kins")
    return probing_run(m, root, "tcp", extra=kinematics_changes(m.kind, name, lines), components={name: source},
                       after=tcp_move_steps(machine, name))


@pytest.fixture(scope="module")
def correction_runs(table_runs, tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str], ProbeRun]:
    """(a) and (b) for both machines, each from its machine's identity run as soon as that is identified: four
    simulations at once."""
    def first(k: str) -> ProbeRun:
        return table_runs((k, "identity"))[(k, "identity")]

    jobs = {}
    for k in MACHINES:
        jobs[(k, "trt")] = lambda k=k: trt_pins_run(first(k), tmp_path_factory.mktemp(f"lcnc_{k}_trt"))
        jobs[(k, "pige")] = lambda k=k: pige_kinematics_run(first(k), tmp_path_factory.mktemp(f"lcnc_{k}_pige"), k)
    return run_all(jobs)


def _errors_in_std(first: dict, second: dict, truth: dict[str, float], entered: list[str]) -> dict[str, float]:
    """(found − expected)/std of the second run: expected truth − first run's value where entered, else truth."""
    return {k: (second["pige"][k] - (truth[k] - (first["pige"][k] if k in entered else 0.0))) / second["std"][k]
            for k in truth}


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_the_stock_trt_pins_leave_the_offsets_within_noise_and_the_tilts(identity_runs, correction_runs, machine):
    first, pr = identity_runs[(machine, "identity")].identification, correction_runs[(machine, "trt")]
    assert pr.run.result["ok"], pr.run.summary()
    second, m = pr.identification, MACHINES[machine]
    offsets = [k for k in m.pige if first["units"][k] == "um"]
    z = _errors_in_std(first, second, m.pige, offsets)
    noise = {k: second["pige"][k] / np.hypot(first["std"][k], second["std"][k]) for k in offsets}
    print(f"{machine} trt pins: errors in std " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items())
          + "; offsets left / noise " + ", ".join(f"{k} {v:+.2f}" for k, v in noise.items()))
    assert all(abs(v) < 4.0 for v in z.values()), z
    assert all(abs(v) < 4.0 for v in noise.values()), noise


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_pige_kinematics_leave_every_pige_within_noise(identity_runs, correction_runs, machine):
    first, pr = identity_runs[(machine, "identity")].identification, correction_runs[(machine, "pige")]
    assert pr.run.result["ok"], pr.run.summary()
    second, m = pr.identification, MACHINES[machine]
    z = _errors_in_std(first, second, m.pige, list(m.pige))
    noise = {k: second["pige"][k] / np.hypot(first["std"][k], second["std"][k]) for k in m.pige}
    print(f"{machine} pige kinematics: errors in std " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items())
          + "; left / noise " + ", ".join(f"{k} {v:+.2f}" for k, v in noise.items()))
    assert all(abs(v) < 4.0 for v in z.values()), z
    assert all(abs(v) < 4.0 for v in noise.values()), noise


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_tcp_moves_put_the_true_tool_point_on_target(correction_runs, machine):
    pr = correction_runs[(machine, "pige")]
    assert pr.run.result["ok"], pr.run.summary()
    steps = pr.run.result["steps"]
    goal = np.array([t[:3] for t in targets(machine)])
    off = {}
    for label, k in (("identified", 4), ("true", 7)):
        model = np.linalg.norm(landed(steps[k], TIP) - goal, axis=1)  # the component's (pige's) model
        twin = np.linalg.norm(pr.table.tip_in_table(landed(steps[k], JOINTS)) - goal, axis=1)  # exact twin
        assert np.abs(model - twin).max() < TWIN_TOL_MM
        off[label] = twin
    print(f"{machine}: true tool point (exact twin) off the commanded work point, {len(goal)} points: identified "
          f"values max {off['identified'].max() * 1e3:.3f} um (RMS {np.sqrt(np.mean(off['identified']**2)) * 1e3:.3f}),"
          f" true values max {off['true'].max() * 1e3:.2e} um")
    assert off["identified"].max() < 1e-3
    assert off["true"].max() < TWIN_TOL_MM
