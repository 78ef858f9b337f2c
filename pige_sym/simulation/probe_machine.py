"""A virtual probing machine: runs a sphere-probing program on a machine with known errors, writes its log.

The machine reads the program's statements (:func:`pige_sym.nc.probe_readback.probe_operations`, so it runs
exactly what pige wrote) and moves its axes.  The true sphere centre at a pose is
``c(θ) = pivot + R_w(θ)(c₀ − pivot) − d(θ)`` (CONVENTIONS §7: the probe sees ``e = −d``), ``d`` the
deviation the R-test simulator gives for a ball at ``c₀ − pivot`` with the PIGEs and effects
(:func:`pige_sym.simulation.simulator.simulate`, noise-free), and ``c₀`` the nominal sphere plus a set-up
offset.  A probing move stops where the stylus centre reaches the *trigger radius*
``R + r − pre-travel(v)`` from the true centre:

- ``pretravel_um``: constant pre-travel (a calibrated ``R_eff`` absorbs it);
- ``lobing_um``: three-lobed pre-travel of a kinematic probe, ``lobing·cos 3φ`` for a horizontal move of
  azimuth φ (φ = 0 along +X), and ``vertical_um`` more for a move along Z;
- ``noise_um``: trigger scatter along the move (Gaussian, seeded).

The position the controller records is the stop position in its own coordinates, written in the
dialect's log layout with the dialect's digits (LinuxCNC ``%f``; Fanuc DPRNT ``[44]``; Siemens six
decimals; Heidenhain ``%+10.4LF``).  A probing move that reaches its target without touching stops the
run (:class:`~pige_sym.errors.InputError`), as the real controllers do.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import Trajectory
from pige_sym.nc.probe_program import ProbeSetup, nominal_centres
from pige_sym.nc.probe_readback import probe_operations
from pige_sym.simulation.simulator import simulate


@dataclass
class ProbeMachine:
    """The errors and the probe of the virtual machine.

    Attributes
    ----------
    setup : ProbeSetup
        The nominal set-up the program was written for.
    pige : dict of str to float
        PIGEs and zero-position errors [µm, µrad].
    effects : list
        Effect instances (:func:`pige_sym.model.effects.parse_effect`).
    setup_offset_um : (3,) [µm]
        True sphere centre minus the nominal one at the reference pose.
    noise_um, pretravel_um, lobing_um, vertical_um : float [µm]
    seed : int or None
    """

    setup: ProbeSetup
    pige: dict[str, float]
    effects: list[Any] = field(default_factory=list)
    setup_offset_um: tuple[float, float, float] = (0.0, 0.0, 0.0)
    noise_um: float = 0.5
    pretravel_um: float = 0.0
    lobing_um: float = 0.0
    vertical_um: float = 0.0
    seed: int | None = None

    @property
    def centre0_mm(self) -> np.ndarray:
        return np.asarray(self.setup.sphere_mm, dtype=float) + np.asarray(self.setup_offset_um) * 1e-3


def true_centres(machine: ProbeMachine, angles_deg: np.ndarray) -> np.ndarray:
    """True sphere centre at each pose, shape=(n, 3) [mm] (module docstring); row 0 must be the reference."""
    s = machine.setup
    kern = load_kernels(s.machine)
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    traj = Trajectory("probe", tuple(kern.ROTARY_AXES), a, np.arange(len(a), dtype=float), "probe poses")
    ball = machine.centre0_mm - s.pivot_mm
    sim = simulate(kern.MACHINE_CODE, traj, pige=machine.pige, ball_mm=ball, effects=machine.effects, noise_um=0.0,
                   seed=0)
    nominal = nominal_centres(s.machine, a, machine.centre0_mm, s.pivot_mm)
    return nominal - sim.measurement.deviation_um * 1e-3


def _trigger_radius(machine: ProbeMachine, move: np.ndarray) -> float:
    s = machine.setup
    pre = machine.pretravel_um
    if abs(move[2]) > 0.5:
        pre += machine.vertical_um
    else:
        pre += machine.lobing_um * np.cos(3 * np.arctan2(move[1], move[0]))
    return s.r_eff_mm - pre * 1e-3


def _touch(start: np.ndarray, target: np.ndarray, centre: np.ndarray, radius: float, line: int) -> np.ndarray:
    d = target - start
    length = float(np.linalg.norm(d))
    u = d / length
    along = float((centre - start) @ u)
    perp2 = float((centre - start) @ (centre - start)) - along**2
    if perp2 > radius**2 or along - np.sqrt(radius**2 - perp2) > length:
        raise InputError(f"program line {line}: the probing move reached its target without a contact")
    return start + u * (along - np.sqrt(radius**2 - perp2))


def _format_line(dialect: str, pose: int, k: int, xyz: np.ndarray, axes: tuple[str, ...], angles: np.ndarray) -> str:
    if dialect == "linuxcnc":
        nine = dict(zip(("X", "Y", "Z"), xyz, strict=True)) | dict(zip(axes, angles, strict=True))
        return " ".join(f"{nine.get(a, 0.0):f}" for a in ("X", "Y", "Z", "A", "B", "C", "U", "V", "W"))
    if dialect == "fanuc":  # DPRNT: leading zeros as spaces, a space for a positive sign
        xs = "".join(f"{a}{v:9.4f}" for a, v in zip("XYZ", xyz, strict=True))
        return f"PIGE P{pose:4d} K{k:2d} {xs} " + " ".join(f"{a}{v:8.4f}" for a, v in zip(axes, angles, strict=True))
    if dialect == "siemens":
        xs = " ".join(f"{a}{v:.6f}" for a, v in zip("XYZ", xyz, strict=True))
        return f"PIGE P{pose} K{k} {xs} " + " ".join(f"{a}{v:.6f}" for a, v in zip(axes, angles, strict=True))
    xs = " ".join(f"{a}{v:+10.4f}" for a, v in zip("XYZ", xyz, strict=True))
    return f"PIGE P{pose:5.0f} K{k:2.0f} {xs} " + " ".join(f"{a}{v:+10.4f}" for a, v in zip(axes, angles, strict=True))


def run_probe_program(text: str, dialect: str, machine: ProbeMachine, *, path: str = "<program>") -> str:
    """The log the program writes on the virtual machine (module docstring)."""
    kern = load_kernels(machine.setup.machine)
    axes = tuple(kern.ROTARY_AXES)
    ops = probe_operations(text, dialect, path)
    poses = [np.array([op.words.get(a, np.nan) for a in axes]) for op in ops
             if op.kind == "rapid" and any(a in op.words for a in axes)]
    angles = np.array(poses, dtype=float)
    if len(angles) == 0 or np.abs(angles[0]).max() > 0:
        raise InputError("a probing program starts at the reference pose (all rotary angles 0)")
    centres = true_centres(machine, angles)
    rng = np.random.default_rng(machine.seed)
    pos = np.zeros(3)
    pose, k = -1, 0
    out: list[str] = []
    contact = np.zeros(3)
    for op in ops:
        if op.kind == "rapid" and any(a in op.words for a in axes):
            pose, k = pose + 1, 0
            continue
        new = np.array([op.words.get(a, pos[i]) for i, a in enumerate("XYZ")])
        if op.kind == "probe":
            move = (new - pos) / np.linalg.norm(new - pos)
            stop = _touch(pos, new, centres[pose], _trigger_radius(machine, move), op.line)
            contact = stop + move * rng.normal(0.0, machine.noise_um * 1e-3)
            new = contact
        elif op.kind == "log":
            out.append(_format_line(dialect, pose, k, contact, axes, angles[pose]))
            k += 1
            continue
        pos = new
    return "\n".join(out) + "\n"
