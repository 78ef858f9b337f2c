"""The setups and poses of a map test (``pige plan --map``, ``pige program --map``) and the files they will give.

Poses (:func:`map_poses`)
    The reference pose (every rotary axis at 0), then every grid angle of every rotary axis: the axis nearest
    the measured point (:func:`inner_axis`: the first workpiece-side axis, else the last tool-side one) is swept
    through its grid at each grid angle of the other, and the pose that would repeat the reference right after
    it is left out.  A full-turn axis takes its grid over a turn (0, step, …, 360 − step); any other axis the
    multiples of the step in its range (``--map-range AXIS=lo:hi``; default 0 to 90° for a table's tilt axis,
    −45 to 45° for a head's), which must contain 0.  Per direction (``--map-per-direction``) the swept axis goes
    up through its grid and back down — a full-turn axis on to 360° and back, so every angle is met from both
    sides — and an outer axis is visited out and back, with the sweep at each visit.  An end of a limited range
    is met from inside only, so φ⁺ and φ⁻ cannot be told apart there; the plan says so.

Measured points (:func:`propose_points`)
    CONVENTIONS §10: one measured point per angle gives three numbers, the motions have six; an axis needs three
    points fixed in the body it carries, not on one line, unless another axis moves the point across that body.
    Which body the point is fixed in depends on the side.  On the workpiece side the sphere (the R-test nest,
    the ballbar's table ball) stands on the table: the points are sphere positions, the given one and the same
    turned by 120° and 240° about the inner workpiece-side axis (same height and stem).  On the tool side the
    stylus (the R-test ball) is in the spindle: the points are tool vectors, the given one, one
    ``extension_mm`` longer and one offset ``offset_mm`` across the spindle axis (an extension and an offset
    stylus).  A mixed machine varies both in the same setups.  An outer axis sees the point at a different place
    of its body at every angle of the inner axis, so one setup can determine its map.

The planned files (:func:`setup_file`) are what each setup will produce — an R-test run, a probe import with
the centre covariances of its planned contacts (:func:`~pige_sym.planning.probe.centre_covariances`) — at the
planned poses, with no data; :mod:`pige_sym.identification.map_design` predicts from them.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.identification.map_design import design_sigma
from pige_sym.identification.maps import MapSpec
from pige_sym.kernels import load_kernels
from pige_sym.measurements.ballbar import BallbarRun
from pige_sym.measurements.measurement import Measurement, missing_tool
from pige_sym.measurements.probe_import import INSTRUMENT, covariance_columns
from pige_sym.model.error_motions import axis_direction, check_map_step, is_full_turn
from pige_sym.nc.probe_program import ProbePlan, ProbeSetup, plan_probing
from pige_sym.planning.probe import centre_covariances

INSTRUMENTS = ("sphere-probe", "rtest", "ballbar")
DEFAULT_EXTENSION_MM = 100.0
DEFAULT_OFFSET_MM = 50.0
TABLE_TILT_RANGE_DEG = (0.0, 90.0)
HEAD_TILT_RANGE_DEG = (-45.0, 45.0)


@dataclass(frozen=True)
class MapTestRequest:
    """What a map test is planned for.

    Attributes
    ----------
    machine : str
    instrument : {"sphere-probe", "rtest", "ballbar"}
    spec : MapSpec
        Mapped axes, grid step [deg], axes mapped per approach direction.
    ranges : dict of str to (float, float) [deg]
        The range of every rotary axis that does not turn fully (:func:`map_ranges`).
    point_mm : (3,) [mm]
        The measured point on the workpiece side at the reference pose: sphere centre, R-test ball, table ball.
    tool_mm : (3,) [mm] or None
        Head and mixed machines: the stylus (ball) centre from the last tool-side pivot.
    noise_um : float [µm]
        Contact scatter (probe), noise per component (R-test) or per reading (ballbar).
    points, tools : tuple of (3,) arrays
        Measured points / tool vectors given, one per setup (or one for all), instead of the proposals.
    extension_mm, offset_mm : float [mm]
        The proposed tool vectors (module docstring).
    probe : ProbeSetup or None
        The probing set-up the setups vary (sphere-probe).
    pivots_mm : dict of str to (3,) [mm]
        R-test and ballbar: the nominal pivots (default: every axis line through the origin).
    pose_s, contact_s : float [s]
        Machine time per pose (probe: retract and turn; R-test and ballbar: move and dwell) and per contact.
    setups : int or None
        Exactly this many setups (default: the fewest that determine every value).
    target : float or None
        Ballbar: also keep adding setups until the worst predicted standard error is within it [µm or µrad].
    """

    machine: str
    instrument: str
    spec: MapSpec
    ranges: dict[str, tuple[float, float]]
    point_mm: np.ndarray
    tool_mm: np.ndarray | None = None
    noise_um: float = 0.5
    points: tuple[np.ndarray, ...] = ()
    tools: tuple[np.ndarray, ...] = ()
    extension_mm: float = DEFAULT_EXTENSION_MM
    offset_mm: float = DEFAULT_OFFSET_MM
    probe: ProbeSetup | None = None
    pivots_mm: dict[str, np.ndarray] = field(default_factory=dict)
    pose_s: float = 20.0
    contact_s: float = 8.0
    setups: int | None = None
    target: float | None = None

    def __post_init__(self) -> None:
        if self.instrument not in INSTRUMENTS:
            raise InputError(f"--instrument {self.instrument}: a map test is planned for {', '.join(INSTRUMENTS)}")
        if not (math.isfinite(self.noise_um) and self.noise_um > 0):
            raise InputError(f"--noise {self.noise_um!r}: give the instrument's noise, a finite number > 0 um")
        if self.instrument == "sphere-probe" and self.probe is None:
            raise InputError("a probe map test needs the probing set-up (--sphere, --sphere-radius, --stylus-radius)")


@dataclass
class MapSetup:
    """One setup of a map test: its measured point, tool, poses, machine time and the file it will give.

    Attributes
    ----------
    label : str
    point_mm : (3,) [mm]
    tool_mm : (3,) [mm] or None
    angles_deg : (n, k) [deg]
        θ of every pose, row 0 the reference pose.
    seconds : float [s]
    item : Measurement or BallbarRun
        The planned file (no data).
    sigma_um : float [µm]
        The noise σ_f identify will divide its rows by (:func:`~pige_sym.identification.map_design.design_sigma`).
    contacts : int
        Probe: contacts in all.
    probe : ProbeSetup or None
        Probe: the set-up its program is written for.
    probe_plan : ProbePlan or None
        Probe: its poses' contacts (:func:`~pige_sym.nc.probe_program.plan_probing`).
    ballbar : Any
        Ballbar: its :class:`~pige_sym.simulation.ballbar.BallbarSetup`.
    """

    label: str
    point_mm: np.ndarray
    tool_mm: np.ndarray | None
    angles_deg: np.ndarray
    seconds: float
    item: Measurement | BallbarRun
    sigma_um: float
    contacts: int = 0
    probe: ProbeSetup | None = None
    probe_plan: ProbePlan | None = None
    ballbar: Any = None


def inner_axis(kern: Any) -> str:
    """The rotary axis nearest the measured point: the first workpiece-side axis, else the last tool-side one."""
    return str(kern.WORKPIECE_ROTARY[0] if kern.WORKPIECE_ROTARY else kern.TOOL_ROTARY[-1])


def map_ranges(kern: Any, items: list[str] | None) -> dict[str, tuple[float, float]]:
    """``--map-range AXIS=lo:hi`` items (repeatable or comma-separated) [deg], with the defaults of the module
    docstring for every axis that does not turn fully.

    Raises
    ------
    InputError
        An axis the machine does not have, a full-turn axis, or a range without 0.
    """
    from pige_sym.options import parse_axis_ranges

    axes = tuple(kern.ROTARY_AXES)
    out = parse_axis_ranges(items, "--map-range", axes, max_abs=360.0, example="A=0:90")
    for axis in out:
        if is_full_turn(axis):
            raise InputError(f"--map-range {axis}: {axis} turns fully, its map covers the turn (leave it out)")
    for a in axes:
        if not is_full_turn(a):
            out.setdefault(a, HEAD_TILT_RANGE_DEG if a in kern.TOOL_ROTARY else TABLE_TILT_RANGE_DEG)
            lo, hi = out[a]
            if not lo <= 0.0 <= hi:
                raise InputError(f"--map-range {a}={lo:g}:{hi:g} excludes 0: the test starts at the reference pose "
                                 "(every rotary axis at 0)")
    return out


def axis_nodes(axis: str, step_deg: float, ranges: Mapping[str, tuple[float, float]]) -> np.ndarray:
    """The grid angles an axis visits [deg] (module docstring), shape=(n,)."""
    n = check_map_step(step_deg, axis)
    if n is not None:
        return np.arange(n) * step_deg
    lo, hi = ranges[axis]
    nodes = np.arange(math.ceil(lo / step_deg - 1e-9), math.floor(hi / step_deg + 1e-9) + 1) * step_deg
    if nodes.size < 2:
        raise InputError(f"--map-range {axis}={lo:g}:{hi:g} holds {nodes.size} multiple(s) of --map-step "
                         f"{step_deg:g}: give a wider range or a smaller step")
    return nodes


def _sweep(nodes: np.ndarray, full_turn: bool, both: bool) -> list[float]:
    """The angles of one pass over the grid: up, and with ``both`` back down (module docstring)."""
    up = [float(x) for x in nodes]
    if not both:
        return up
    return up + [up[0] + 360.0] + up[::-1] if full_turn else up + up[-2::-1]


def map_poses(machine: str, spec: MapSpec, ranges: Mapping[str, tuple[float, float]]) -> np.ndarray:
    """The poses of every setup (module docstring), shape=(n, k) [deg] in ``ROTARY_AXES`` order, row 0 the
    reference pose."""
    kern = load_kernels(machine)
    axes = tuple(kern.ROTARY_AXES)
    inner = inner_axis(kern)
    outer = [a for a in axes if a != inner]
    passes = {a: _sweep(axis_nodes(a, spec.step_deg, ranges), is_full_turn(a), a in spec.per_direction)
              for a in axes}
    rows = [np.zeros(len(axes))]
    for combo in itertools.product(*(passes[a] for a in outer)):
        held = dict(zip(outer, combo, strict=True))
        for theta in passes[inner]:
            row = np.array([theta if a == inner else held[a] for a in axes])
            if len(rows) == 1 and not row.any():
                continue  # the reference pose again, right after it
            rows.append(row)
    return np.array(rows)


def _turned(point: np.ndarray, axis: str, pivot: np.ndarray, angle_deg: float) -> np.ndarray:
    u = np.eye(3)[axis_direction(axis)]
    k = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    t = math.radians(angle_deg)
    rot = np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k
    return np.asarray(pivot + rot @ (point - pivot))


def _inner_pivot(request: MapTestRequest, axis: str) -> np.ndarray:
    if request.probe is not None:
        pivots = request.probe.pivots
        return np.asarray(pivots[axis] if isinstance(pivots, Mapping) else pivots, dtype=float)
    return np.asarray(request.pivots_mm.get(axis, np.zeros(3)), dtype=float)


def propose_points(request: MapTestRequest) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """(measured point, tool vector) of every candidate setup, in order (module docstring)."""
    kern = load_kernels(request.machine)
    why = missing_tool(kern.MACHINE_CODE, request.tool_mm)
    if why:
        raise InputError(why + " (the stylus or ball turns with the head)")
    p0 = np.asarray(request.point_mm, dtype=float)
    points: list[np.ndarray] = [np.asarray(p, dtype=float) for p in request.points]
    if not points and any(a in kern.WORKPIECE_ROTARY for a in request.spec.axes):
        inner = kern.WORKPIECE_ROTARY[0]
        pivot = _inner_pivot(request, inner)
        points = [_turned(p0, inner, pivot, a) for a in (0.0, 120.0, 240.0)]
    tools: list[np.ndarray | None] = [np.asarray(t, dtype=float) for t in request.tools]
    if not tools and request.tool_mm is not None and any(a in kern.TOOL_ROTARY for a in request.spec.axes):
        t0 = np.asarray(request.tool_mm, dtype=float)
        across = np.eye(3)[next(j for j in range(3) if j != kern.SPINDLE_DIRECTION)]
        tools = [t0, t0 * (np.linalg.norm(t0) + request.extension_mm) / np.linalg.norm(t0),
                 t0 + request.offset_mm * across]
    points = points or [p0]
    tools = tools or [None if request.tool_mm is None else np.asarray(request.tool_mm, dtype=float)]
    n = max(len(points), len(tools))
    if 1 < len(points) != len(tools) > 1:
        raise InputError(f"{len(points)} measured points (--map-point) and {len(tools)} tools (--map-tool): give as "
                         "many of each, one per setup (or one for all)")
    return [(points[i % len(points)], tools[i % len(tools)]) for i in range(n)]


def setup_file(request: MapTestRequest, label: str, point: np.ndarray, tool: np.ndarray | None,
               angles: np.ndarray) -> MapSetup:
    """The setup and the file it will give (sphere probe or R-test; module docstring)."""
    kern = load_kernels(request.machine)
    axes = tuple(kern.ROTARY_AXES)
    n = angles.shape[0]
    if request.instrument == "rtest":
        m = Measurement(kern.MACHINE_CODE, np.asarray(point, dtype=float), np.arange(n) * request.pose_s, angles,
                        np.zeros((n, 3)), axes, tool_mm=tool, pivots_mm=dict(request.pivots_mm))
        return MapSetup(label, point, tool, angles, n * request.pose_s, m, design_sigma(m, request.noise_um))
    assert request.probe is not None
    setup = dataclasses.replace(request.probe, sphere_mm=np.asarray(point, dtype=float), tool_mm=tool)
    plan = plan_probing(setup, angles, label)
    covs = np.array(centre_covariances(plan, request.noise_um))
    pivots = setup.pivots
    if isinstance(pivots, Mapping):
        ball, per_axis = setup.sphere_mm.copy(), {a: np.asarray(v, dtype=float) for a, v in pivots.items()}
    else:
        ball, per_axis = setup.sphere_mm - pivots, {}
    m = Measurement(kern.MACHINE_CODE, ball, np.arange(n, dtype=float), plan.angles_deg, np.zeros((n, 3)), axes,
                    tool_mm=tool, pivots_mm=per_axis, optional=covariance_columns(covs),
                    metadata={"instrument": INSTRUMENT})
    contacts = sum(len(c) for c in plan.contacts)
    return MapSetup(label, point, tool, angles, n * request.pose_s + contacts * request.contact_s, m,
                    design_sigma(m, request.noise_um), contacts, setup, plan)
