"""A virtual probing machine: runs a sphere-probing program on a machine with known errors, writes its log.

The machine reads the program's statements (:func:`pige_sym.nc.probe_readback.probe_operations`, so it runs
exactly what pige wrote) and moves its axes.  The true sphere centre at a pose is
``c(θ) = pivot + R_w(θ)(c₀ − pivot) − d(θ)`` (CONVENTIONS §7: the probe sees ``e = −d``), ``d`` the
deviation the R-test simulator gives for a ball at ``c₀ − pivot`` with the PIGEs and effects
(:func:`pige_sym.simulation.simulator.simulate`, noise-free) — with ``error_maps``, the rotary axes' error motions
too (CONVENTIONS §10, first order, each pose approached as the program moves to it) — and ``c₀`` the nominal sphere
plus a set-up offset.  A probing move stops where the stylus centre reaches the *trigger radius*
``R + r − pre-travel(v)`` from the true centre:

- ``pretravel_um``: constant pre-travel (a calibrated ``R_eff`` absorbs it);
- ``lobing_um``: three-lobed pre-travel of a kinematic probe, ``lobing·cos 3φ`` for a horizontal move of
  azimuth φ (φ = 0 along +X), and ``vertical_um`` more for a move along Z;
- ``noise_um``: trigger scatter along the move (Gaussian, seeded).

On a head or mixed machine (CONVENTIONS §7) the program commands the linear axes: the stylus centre is at
``X + h_true(θ)``.  The machine works in the program's coordinates, where the sphere appears at
``c_nom(θ) − d(θ) − (R_t − I)·Δ − h(θ)`` (``h = (R_t − I)·tool`` the nominal offset of the head, ``d`` the R-test
deviation of a ball at ``c₀`` and a tool at ``tool + Δ``, first order): ``tool_error_um`` Δ is a stylus centre
that is not where ``--tool`` says (a bent stylus, a wrong tool length; the controller's position at the
reference pose is right).  Lobing and the axial pre-travel turn with the stylus: φ is measured in the stylus
frame ``R_t(θ)`` and "vertical" is along its axis.

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
from pige_sym.measurements.axis_sense import to_conventions
from pige_sym.measurements.probe_head import head_offsets, stylus_frames
from pige_sym.model.error_motions import ErrorMaps
from pige_sym.model.trajectories import Trajectory
from pige_sym.nc.probe_program import ProbeSetup, nominal_centres, table_frames
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
    tool_error_um : (3,) [µm]
        Head machines: the true stylus centre minus ``setup.tool_mm`` (module docstring).
    error_maps : ErrorMaps or None
        Error motions of the rotary axes (CONVENTIONS §10).
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
    tool_error_um: tuple[float, float, float] = (0.0, 0.0, 0.0)
    error_maps: ErrorMaps | None = None

    @property
    def centre0_mm(self) -> np.ndarray:
        return np.asarray(self.setup.sphere_mm, dtype=float) + np.asarray(self.setup_offset_um) * 1e-3


def true_centres(machine: ProbeMachine, angles_deg: np.ndarray) -> np.ndarray:
    """True sphere centre at each pose, shape=(n, 3) [mm] (module docstring); row 0 must be the reference.

    ``angles_deg`` are θ (CONVENTIONS' sense), shape=(n, k) [deg].  On a head machine: where the program's
    coordinates (the linear axes) see it, ``c − h_true``.
    """
    s = machine.setup
    kern = load_kernels(s.machine)
    a = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    traj = Trajectory("probe", tuple(kern.ROTARY_AXES), a, np.arange(len(a), dtype=float), "probe poses")
    pivots = s.pivots
    if isinstance(pivots, dict):
        ball, per_axis = machine.centre0_mm, pivots
    else:
        ball, per_axis = machine.centre0_mm - pivots, None
    delta = np.asarray(machine.tool_error_um, dtype=float) * 1e-3
    tool = None if s.tool_mm is None else np.asarray(s.tool_mm, dtype=float) + delta
    sim = simulate(kern.MACHINE_CODE, traj, pige=machine.pige, ball_mm=ball, pivots_mm=per_axis, tool_mm=tool,
                   effects=machine.effects, noise_um=0.0, seed=0, error_maps=machine.error_maps)
    centres = nominal_centres(s.machine, a, machine.centre0_mm, pivots) - sim.measurement.deviation_um * 1e-3
    if s.tool_mm is None:
        return centres
    head, frames = head_offsets(kern, a, s.tool_mm)
    assert frames is not None
    return centres - (frames @ delta - delta) - head


def _stylus_frame(machine: ProbeMachine, theta: np.ndarray) -> np.ndarray | None:
    """The nominal stylus frame at θ (None on a table machine)."""
    frames = stylus_frames(load_kernels(machine.setup.machine), theta[None])
    return None if frames is None else frames[0]


def _trigger_radius(machine: ProbeMachine, move: np.ndarray, frame: np.ndarray | None = None) -> float:
    s = machine.setup
    move = move if frame is None else frame.T @ move  # in the stylus frame on a head
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
    """The log the program writes on the virtual machine (module docstring).

    Guarded approaches and confirming contacts (:mod:`pige_sym.nc.probe_safety`) behave as on the
    controller: a guarded approach that touches the true sphere, or a confirming contact outside its
    window, stops the run with the program's reason (:class:`~pige_sym.errors.InputError`); neither is
    logged.  The logged angles are the commanded ones; the sphere moves by θ = σ·θ_cmd.
    """
    axes = tuple(load_kernels(machine.setup.machine).ROTARY_AXES)
    ops = probe_operations(text, dialect, path, axes)
    run = _VirtualRun(machine, dialect, axes, _pose_centres(machine, ops, axes))
    for op in ops:
        run.step(op)
    if not run.out:
        raise InputError("the probing program logged no contact")
    return "\n".join(run.out) + "\n"


def _pose_centres(machine: ProbeMachine, ops: list[Any], axes: tuple[str, ...]) -> list[np.ndarray]:
    """The true centre at every rotary positioning of the program, in order.

    The logged poses are simulated together (their order is the time of the drift effects, as the import
    counts it); a positioning without a logged contact (the confirmation at the reference pose) gets the
    centre of its angles alone.
    """
    stops: list[tuple[np.ndarray, bool]] = []
    commanded = np.zeros(len(axes))
    for op in ops:
        if op.kind == "rapid" and any(a in op.words for a in axes):
            commanded = np.array([op.words.get(a, commanded[k]) for k, a in enumerate(axes)])
            stops.append((to_conventions(commanded, machine.setup.axis_sense, axes), False))
        elif op.kind == "log" and stops:
            stops[-1] = (stops[-1][0], True)
    logged = [theta for theta, has_log in stops if has_log]
    if not logged or np.abs(logged[0]).max() > 0:
        raise InputError("a probing program starts at the reference pose (all rotary angles 0)")
    centres = iter(true_centres(machine, np.array(logged)))
    zero = np.zeros((1, len(axes)))
    return [next(centres) if has_log else true_centres(machine, np.vstack([zero, theta[None]]))[-1]
            for theta, has_log in stops]


class _VirtualRun:
    """The axes, the true sphere and the log of one run of a probing program on the virtual machine."""

    def __init__(self, machine: ProbeMachine, dialect: str, axes: tuple[str, ...], centres: list[np.ndarray]) -> None:
        self.m, self.dialect, self.axes = machine, dialect, axes
        self.rng = np.random.default_rng(machine.seed)
        # the confirming contacts scatter too, from their own stream: the logged contacts' noise does not
        # depend on whether the program confirms the sphere first
        self.confirm_rng = np.random.default_rng(None if machine.seed is None else [machine.seed, 17])
        self.pos = np.zeros(3)
        self.commanded = np.zeros(len(axes))
        self.centres = iter(centres)
        self.centre = centres[0] if centres else np.full(3, np.nan)
        self.pose, self.k, self.logged_pose = -1, 0, False
        self.contact = np.zeros(3)
        self.out: list[str] = []
        # TCP kinematics: the program's coordinates are work coordinates, the controller's nominal table motion
        # (R, t) of the commanded pose puts them in the machine; identity: R = I, t = 0
        self.tcp = machine.setup.controller.kinematics == "tcp"
        self.frame = (np.eye(3), np.zeros(3))
        self.work = np.zeros(3)
        self.stylus: np.ndarray | None = None  # the stylus frame on a head (the lobes and the axial pre-travel)

    def step(self, op: Any) -> None:
        if op.kind == "rapid" and any(a in op.words for a in self.axes):
            self.commanded = np.array([op.words.get(a, self.commanded[k]) for k, a in enumerate(self.axes)])
            self.centre = next(self.centres)
            self.logged_pose = False
            s = self.m.setup
            self.stylus = _stylus_frame(self.m, to_conventions(self.commanded, s.axis_sense, self.axes))
            if self.tcp:
                s = self.m.setup
                rot, t = table_frames(s.machine, to_conventions(self.commanded[None], s.axis_sense, self.axes),
                                      s.pivots)
                self.frame = (rot[0], t[0])
                self.pos = self.frame[0] @ self.work + self.frame[1]
            return
        self.work = np.array([op.words.get(a, self.work[i]) for i, a in enumerate("XYZ")])
        new = self.frame[0] @ self.work + self.frame[1]
        if op.kind == "log":
            if not self.logged_pose:
                self.pose, self.k, self.logged_pose = self.pose + 1, 0, True
            logged = self.frame[0].T @ (self.contact - self.frame[1])  # the controller's coordinates
            self.out.append(_format_line(self.dialect, self.pose, self.k, logged, self.axes, self.commanded))
            self.k += 1
            return
        if op.kind in ("probe", "confirm"):
            move = (new - self.pos) / np.linalg.norm(new - self.pos)
            try:
                stop = _touch(self.pos, new, self.centre, _trigger_radius(self.m, move, self.stylus), op.line)
            except InputError:
                if op.kind != "confirm":
                    raise
                raise InputError(f"program line {op.line}: no contact at the confirming move: the program stops "
                                 "(the sphere is not where it expects it; check --sphere, --pivot, the work offset "
                                 "and the stylus length)") from None
            rng = self.confirm_rng if op.kind == "confirm" else self.rng
            self.contact = stop + move * rng.normal(0.0, self.m.noise_um * 1e-3)
            if op.kind == "confirm":
                self._window(op)
            new = self.contact
        elif op.kind == "guard" and _hits(self.pos, new, self.centre, self.m.setup.r_eff_mm):
            raise InputError(f"program line {op.line}: contact during the guarded approach: the program stops "
                             "(the sphere is not where the program expects it)")
        self.pos = new
        self.work = self.frame[0].T @ (new - self.frame[1])

    def _window(self, op: Any) -> None:
        k = "XYZ".index(op.axis)
        if abs(self.contact[k] - op.expected) > op.window:
            raise InputError(f"program line {op.line}: the confirming contact is at {op.axis}{self.contact[k]:.4f}, "
                             f"expected {op.expected:g} +- {op.window:g} mm: the program stops (check --sphere, "
                             "--pivot, the work offset and the stylus length)")


def _hits(a: np.ndarray, b: np.ndarray, centre: np.ndarray, radius: float) -> bool:
    """Whether the segment a-b comes within ``radius`` of ``centre``."""
    d = b - a
    t = 0.0 if not d.any() else float(np.clip((centre - a) @ d / (d @ d), 0.0, 1.0))
    return bool(np.linalg.norm(a + t * d - centre) < radius)
