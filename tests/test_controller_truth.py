"""The true machine that every controller test drives, written here from CONVENTIONS §2–4 (no pige code).

A rotary axis with nominal direction u through the nominal pivot p really turns about the line through
q = p + δ with direction u' = (u + ε × u)/|u + ε × u| (§3); a tool-side axis turns what it carries by
R(u', θ + E), a workpiece-side axis by R(u', −(θ + E)) (§2), with θ = σ·θ_cmd (§9) and E the
zero-position error.  The workpiece axes are listed from the workpiece outward, the tool axes from the bed
towards the tool; the linear axes carry the tool (the controllers' chains assume it).

:func:`rtest_run` is the R-test of §4 on that machine: a controller model gives, per pose, the linear axes'
displacement that puts its own tool point on its own image of the nest; the true machine then places the
ball and the nest; the deviation is zeroed at the reference pose in the nest's frame.  The controller tests
(``test_controller_<name>.py``) rebuild each controller's chain from its manual and pass it in here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest

from pige_sym.codegen.machine_code import parse_machine_code
from pige_sym.compensation.parameters import CompensationParameters
from pige_sym.kernels import load_kernels
from pige_sym.model.trajectories import make_trajectory

AC, BC, HEAD, MIXED = "wC'A'bXYZ(C1)t", "wC'B'bXYZ(C1)t", "wbXYZCA(C1)t", "wC'bXYZB(C1)t"
SHIPPED = (AC, BC, HEAD, MIXED)
UNIT = {"A": np.array([1.0, 0.0, 0.0]), "B": np.array([0.0, 1.0, 0.0]), "C": np.array([0.0, 0.0, 1.0])}
#: Position-error and orientation-error directions of each axis letter (CONVENTIONS §3 table).
ERROR_AXES = {"A": (1, 2), "B": (0, 2), "C": (0, 1)}


def rotation(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Right-handed rotation by ``angle_rad`` about the unit vector ``axis`` (Rodrigues), (3, 3)."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle_rad) * kx + (1.0 - math.cos(angle_rad)) * kx @ kx


@dataclass
class Machine:
    """A machine with PIGEs: structure, values [µm, µrad], nominal pivots [mm], tool and ball [mm].

    ``senses`` holds σ per rotary axis (default +1); angles handed to :meth:`tool_point` /
    :meth:`table_point` are the commanded ones.
    """

    code: str
    values: dict[str, float]
    pivots: dict[str, np.ndarray]
    ball: np.ndarray
    tool: np.ndarray | None = None
    senses: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        st = parse_machine_code(self.code)
        self.workpiece_axes = [a.name for a in st.workpiece_axes if a.kind == "rotary"]  # workpiece outward
        self.tool_axes = [a.name for a in st.tool_axes if a.kind == "rotary"]  # bed towards the tool
        self.kern = load_kernels(self.code)
        self.rotary = tuple(self.kern.ROTARY_AXES)

    def line(self, axis: str, errors: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Point q [mm] and unit direction u' of the axis line (nominal with ``errors=False``)."""
        i1, i2 = ERROR_AXES[axis[0]]
        v = self.values if errors else {}
        names = [n for n in self.kern.LOCATION_PARAMETERS if n.endswith("0" + axis)]
        q = np.asarray(self.pivots.get(axis, np.zeros(3)), dtype=float).copy()
        q[i1] += v.get(names[0], 0.0) * 1e-3
        q[i2] += v.get(names[1], 0.0) * 1e-3
        eps = np.zeros(3)
        eps[i1], eps[i2] = v.get(names[2], 0.0) * 1e-6, v.get(names[3], 0.0) * 1e-6
        u = UNIT[axis[0]] + np.cross(eps, UNIT[axis[0]])
        return q, u / np.linalg.norm(u)

    def _angle(self, axis: str, commanded_deg: float, errors: bool) -> float:
        zero = self.values.get(f"E{axis[0]}0{axis}", 0.0) * 1e-6 if errors else 0.0
        return self.senses.get(axis, 1) * math.radians(commanded_deg) + zero

    def _motion(self, axis: str, commanded_deg: float, side: int, errors: bool) -> Callable[[np.ndarray], np.ndarray]:
        q, u = self.line(axis, errors)
        r = rotation(u, side * self._angle(axis, commanded_deg, errors))
        return lambda x: q + r @ (np.asarray(x, dtype=float) - q)

    def table_point(self, w: np.ndarray, angles: dict[str, float], errors: bool = True) -> np.ndarray:
        """Where the workpiece point ``w`` (W = M at the reference pose) stands in M [mm]."""
        x = np.asarray(w, dtype=float)
        for ax in self.workpiece_axes:  # the axis carrying the workpiece first
            x = self._motion(ax, angles[ax], -1, errors)(x)
        return x

    def tool_point(self, linear: np.ndarray, angles: dict[str, float], errors: bool = True) -> np.ndarray:
        """The ball on the tool [mm], the linear axes displaced by ``linear`` [mm] (the tool-side pivots are
        given at ``linear`` = 0)."""
        x = self.tool_ball()
        for ax in reversed(self.tool_axes):  # the axis nearest the tool first
            x = self._motion(ax, angles[ax], +1, errors)(x)
        return x + np.asarray(linear, dtype=float)

    def tool_ball(self) -> np.ndarray:
        """The ball on the tool at the reference pose, relative to the tool-side pivots [mm]."""
        if not self.tool_axes:
            return self.ball.copy()
        assert self.tool is not None
        return np.asarray(self.pivots.get(self.tool_axes[-1], np.zeros(3)), dtype=float) + self.tool

    def table_rotation(self, angles: dict[str, float]) -> np.ndarray:
        """Nominal rotation of the workpiece chain, (3, 3)."""
        r = np.eye(3)
        for ax in self.workpiece_axes:
            r = rotation(UNIT[ax[0]], -self._angle(ax, angles[ax], False)) @ r
        return r

    def params(self, values: dict[str, float] | None = None) -> CompensationParameters:
        """The parameter set pige's controller styles print from (all of ``values`` by default)."""
        pivots = {k: [float(x) for x in v] for k, v in self.pivots.items()}
        tool = None if self.tool is None else [float(x) for x in self.tool]
        sense = {a: -1 for a, s in self.senses.items() if s == -1}
        return CompensationParameters(self.kern.MACHINE_CODE, dict(self.values if values is None else values),
                                      dict(self.kern.UNITS), tool, pivots, "test", [], axis_sense=sense)

    def model_um(self, angles: np.ndarray, names: list[str] | None = None, point: np.ndarray | None = None,
                 raw: bool = False) -> np.ndarray:
        """pige's first-order deviation (n, 3) [µm] with the parameters ``names`` (all by default).

        ``raw``: the offset before the R-test's zeroing, for the workpiece ``point`` (the ball by default):
        ``(jacobian + workpiece_rotation @ reference_jacobian) @ params`` (the kernels' own docstring).
        """
        keep = set(self.kern.PARAMETERS if names is None else names)
        vec = np.array([self.values.get(n, 0.0) if n in keep else 0.0 for n in self.kern.PARAMETERS])
        angles = np.atleast_2d(angles) * np.array([self.senses.get(a, 1) for a in self.rotary])  # θ = σ θ_cmd
        pivots = {k: [float(x) for x in v] for k, v in self.pivots.items()}
        ball = self.ball if point is None else point
        if not raw:
            return self.kern.deviation(angles, vec, ball, pivots, self.tool)
        jac = self.kern.jacobian(angles, None, ball, pivots, self.tool)
        ref = self.kern.workpiece_rotation(angles) @ self.kern.reference_jacobian(ball, pivots, self.tool)
        return (jac + ref) @ vec


#: A controller model: commanded angles by axis -> the linear displacement [mm] its RTCP commands.
Controller = Callable[[dict[str, float]], np.ndarray]


def raw_run(machine: Machine, angles: np.ndarray, controller: Callable[[dict[str, float], np.ndarray], np.ndarray],
            point: np.ndarray) -> np.ndarray:
    """Tool ball minus the workpiece ``point`` it was sent to (n, 3) [µm], not zeroed.

    ``controller(pose, point)`` is the linear displacement [mm] its RTCP commands to put the tool ball
    on the workpiece point (its own model of both).
    """
    out = []
    for row in np.atleast_2d(angles):
        pose = dict(zip(machine.rotary, (float(a) for a in row), strict=True))
        linear = controller(pose, point)
        out.append((machine.tool_point(linear, pose) - machine.table_point(point, pose)) * 1e3)
    return np.array(out)


def rtest_run(machine: Machine, angles: np.ndarray, controller: Controller) -> np.ndarray:
    """Ball-minus-nest deviation (n, 3) [µm] on the true machine driven by ``controller``, zeroed at pose 0."""
    d = raw_run(machine, angles, lambda pose, point: controller(pose), machine.ball)
    first = dict(zip(machine.rotary, (float(a) for a in np.atleast_2d(angles)[0]), strict=True))
    assert all(v == 0.0 for v in first.values()), "the first pose must be the reference pose"
    return np.array([di - machine.table_rotation(dict(zip(machine.rotary, row, strict=True))) @ d[0]
                     for di, row in zip(d, np.atleast_2d(angles), strict=True)])


def assert_follows_model(machine: Machine, command: Callable[[dict[str, float], np.ndarray], np.ndarray],
                         angles: np.ndarray, names: list[str] | None) -> float:
    """The tool point of ``machine`` driven by a controller's ``command`` lands where pige's model of the
    parameters ``names`` says, pose by pose as vectors to 1e-3 µm: un-zeroed at two workpiece points and as
    the zeroed R-test deviation.  Returns the largest tool-point error [µm]."""
    worst = 0.0
    for point in (machine.ball, machine.ball + np.array([-70.0, 40.0, 30.0])):
        got = raw_run(machine, angles, command, point)
        np.testing.assert_allclose(got, machine.model_um(angles, names, point, raw=True), atol=1e-3, rtol=0)
        worst = max(worst, float(np.abs(got).max()))
    zeroed = rtest_run(machine, angles, lambda pose: command(pose, machine.ball))
    np.testing.assert_allclose(zeroed, machine.model_um(angles, names), atol=1e-3, rtol=0)
    return worst


def random_machine(code: str, seed: int, size: float = 10.0, senses: dict[str, int] | None = None) -> Machine:
    """Random PIGEs and zero-position errors (±size µm, µrad), random pivots, tool and ball."""
    rng = np.random.default_rng(seed)
    kern = load_kernels(code)
    values = {n: float(rng.uniform(-size, size)) for n in kern.PARAMETERS}
    pivots = {ax: rng.uniform(-60, 60, 3) for ax in kern.ROTARY_AXES}
    tool = np.array([0.0, 0.0, -250.0]) + rng.uniform(-20, 20, 3) if kern.TOOL_ROTARY else None
    ball = np.array([120.0, 0.0, 80.0]) + rng.uniform(-30, 30, 3)
    return Machine(code, values, pivots, ball, tool, dict(senses or {}))


def poses(machine: Machine, seed: int = 0, n: int = 24) -> np.ndarray:
    """The default cone frustum followed by random poses (±110°), reference pose first, (m, 2) [deg]."""
    cone = make_trajectory(machine.kern.MACHINE_CODE, "cone-frustum").angles_deg
    rng = np.random.default_rng(seed)
    return np.vstack([np.zeros((1, 2)), cone, rng.uniform(-110, 110, (n, 2))])


def nominal_rtcp(machine: Machine) -> Controller:
    """A controller that knows the nominal geometry exactly (the reference every chain must reproduce)."""
    def command(pose: dict[str, float]) -> np.ndarray:
        target = machine.table_point(machine.ball, pose, errors=False)
        return target - machine.tool_point(np.zeros(3), pose, errors=False)
    return command


def nominal_rtcp_to(machine: Machine) -> Callable[[dict[str, float], np.ndarray], np.ndarray]:
    """:func:`nominal_rtcp` for any workpiece point."""
    def command(pose: dict[str, float], point: np.ndarray) -> np.ndarray:
        return machine.table_point(point, pose, errors=False) - machine.tool_point(np.zeros(3), pose, errors=False)
    return command


@pytest.mark.parametrize("code", SHIPPED)
def test_the_true_machine_deviates_as_pige_models_it(code: str) -> None:
    """The oracle and pige's first-order kernels agree pose by pose as vectors (differences are second order),
    also with the axes commanded in the reverse sense (σ = −1 on the bed-side axis)."""
    reverse = {parse_machine_code(code).rotary_axes[0].name: -1} if code in (AC, HEAD) else {}
    machine = random_machine(code, 11, senses=reverse)
    angles = poses(machine)
    measured = rtest_run(machine, angles, nominal_rtcp(machine))
    np.testing.assert_allclose(measured, machine.model_um(angles), atol=1e-3, rtol=0)
    assert np.linalg.norm(measured, axis=1).max() > 5.0
    # every parameter matters: each one alone moves the tool where the model says
    for name in machine.kern.PARAMETERS:
        alone = Machine(code, {name: 10.0}, machine.pivots, machine.ball, machine.tool, machine.senses)
        got = rtest_run(alone, angles, nominal_rtcp(alone))
        np.testing.assert_allclose(got, alone.model_um(angles), atol=1e-4, rtol=0, err_msg=name)
        # un-zeroed, at two workpiece points: every parameter shows (also what the R-test's zeroing hides)
        for point in (alone.ball, alone.ball + np.array([-70.0, 40.0, 30.0])):
            raw = raw_run(alone, angles, nominal_rtcp_to(alone), point)
            np.testing.assert_allclose(raw, alone.model_um(angles, point=point, raw=True), atol=1e-4, rtol=0,
                                       err_msg=name)
            assert np.abs(raw).max() > 0.5, name
