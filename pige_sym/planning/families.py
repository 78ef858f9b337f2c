"""Trajectory families the planner searches, axis limits, and the structure effects need.

Limits (``--limits AXIS=lo:hi``)
    Rotary axes in degrees, linear axes X, Y, Z in millimetres (the machine coordinates of
    ``pige program``, i.e. the RTCP commands for the ball).  A rotary axis without a limit
    is endless; the tilt axis (the rotary axis not parallel to the spindle) defaults to
    ±90° and is reported as *assumed*.  The reference pose must lie within the limits.
    A rotary column may be shifted by a multiple of 360° as a whole to fit (same poses).
    Limits are checked at the poses.  Between poses the rotary axes move monotonically,
    and in machine coordinates (``pige program`` without ``--rtcp``) the linear axes move
    on straight lines, so a test whose poses fit stays inside; with ``--rtcp`` (TRAORI)
    the controller's linear path between poses is not checked.

Families (poses after the reference pose; n of them)
    ``cone-frustum``  :func:`pige_sym.model.trajectories.cone_frustum`; half angle and
                      inclination continuous, inclination axis X/Y, branch ±1, turns 1–2;
    ``figure-eight``  :func:`pige_sym.model.trajectories.figure_eight`; both amplitudes and the phase;
    ``steps``         stepped sweeps: at L = 1–3 tilts the rotary axis steps from ``lo`` to
                      ``hi`` and back (every position but the turning one approached from
                      both sides);
    ``free``          n free poses within the limits (optimised with the analytic gradient,
                      see :mod:`pige_sym.planning.prediction`), then ordered by a greedy
                      nearest-neighbour path (largest axis move) from the reference pose.

Structure (what ``--reveal`` forces)
    ``backlash_<AXIS>``: the core poses are visited in increasing order of the axis and then
    retraced in decreasing order, so positions are approached from both sides;
    ``thermal_drift``, ``table_drift``: the reference pose is measured again ``max(2, n // 8)`` times, evenly
    through the test and as the last pose, so a drift shows where every PIGE has no effect.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.kernels import load_kernels
from pige_sym.model.effects import DRIFT_KINDS
from pige_sym.model.trajectories import _roles, cone_directions, figure_eight

DEFAULT_TILT_LIMIT_DEG = 90.0
LINEAR_AXES = ("X", "Y", "Z")


@dataclass
class Limits:
    """Admissible axis ranges.

    Attributes
    ----------
    rotary : dict of str to (float, float) [deg]
        Per rotary axis; ±inf for an endless axis.
    linear : dict of str to (float, float) [mm]
        X, Y, Z commands (only the given ones).
    assumed : list of str
        Axes whose limits were not given (defaults used).
    """

    rotary: dict[str, tuple[float, float]]
    linear: dict[str, tuple[float, float]] = field(default_factory=dict)
    assumed: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        def fin(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"rotary_deg": {a: [fin(lo), fin(hi)] for a, (lo, hi) in self.rotary.items()},
                "linear_mm": {a: [fin(lo), fin(hi)] for a, (lo, hi) in self.linear.items()},
                "assumed": list(self.assumed)}

    def search_bounds(self, axis: str) -> tuple[float, float]:
        """A window of at most 360° inside the axis' limits, containing 0, where poses are searched."""
        lo, hi = self.rotary[axis]
        if not (math.isfinite(lo) or math.isfinite(hi)):
            return -180.0, 180.0
        start = min(max(lo, hi - 360.0, -360.0), 0.0)
        return max(lo, start), min(hi, start + 360.0)


def parse_range(text: str, what: str) -> tuple[float, float]:
    """``lo:hi`` as two finite numbers with lo < hi; InputError naming ``what`` otherwise."""
    lo_s, colon, hi_s = text.partition(":")
    try:
        lo, hi = float(lo_s), float(hi_s)
    except ValueError:
        raise InputError(f"{what}: expected lo:hi numbers, got {text!r}") from None
    if not colon or not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
        raise InputError(f"{what}: expected lo:hi with finite lo < hi, got {text!r}")
    return lo, hi


def parse_limits(items: list[str] | None, kern: Any) -> Limits:
    """``AXIS=lo:hi`` items (repeatable, or comma-separated) for the machine's axes, each once (a rotary one within
    two turns, :func:`~pige_sym.options.parse_axis_ranges`)."""
    from pige_sym.options import parse_axis_ranges

    axes = tuple(kern.ROTARY_AXES)
    rotary: dict[str, tuple[float, float]] = {}
    linear: dict[str, tuple[float, float]] = {}
    for item in [x for it in items or [] for x in it.split(",") if x.strip()]:
        axis, eq, rng = item.partition("=")
        axis = axis.strip().upper()
        if not eq:
            raise InputError(f"--limits: expected AXIS=lo:hi, got {item!r}")
        if axis in rotary or axis in linear:
            raise InputError(f"--limits {axis} is given twice: give each axis once")
        if axis in axes:
            rotary |= parse_axis_ranges([item], "--limits", axes, example=f"{axis}=-90:90")
        elif axis in LINEAR_AXES:
            linear[axis] = parse_range(rng, f"--limits {axis}")
        else:
            raise InputError(f"--limits: {axis!r} is not an axis of {kern.MACHINE_CODE} "
                             f"(rotary {', '.join(axes)}; linear X, Y, Z)")
    assumed = []
    tilt = axes[_roles(kern)[0]] if len(axes) == 2 else None
    for a in axes:
        if a not in rotary:
            if a == tilt:
                rotary[a] = (-DEFAULT_TILT_LIMIT_DEG, DEFAULT_TILT_LIMIT_DEG)
                assumed.append(a)
            else:
                rotary[a] = (-math.inf, math.inf)
        lo, hi = rotary[a]
        if not lo <= 0 <= hi:
            raise InputError(f"--limits {a}={lo:g}:{hi:g} excludes 0: the test starts at the reference pose "
                             "(every rotary axis at 0)")
    return Limits(rotary, linear, assumed)


def fit_rotary(angles: np.ndarray, axes: tuple[str, ...], limits: Limits) -> np.ndarray | None:
    """Shift each column (not the reference row) by a multiple of 360° into the limits, or None."""
    out = angles.copy()
    for k, a in enumerate(axes):
        lo, hi = limits.rotary[a]
        col = out[1:, k]
        if col.size == 0:
            continue
        for shift in sorted((360.0 * s for s in range(-3, 4)), key=abs):
            if col.min() + shift >= lo - 1e-9 and col.max() + shift <= hi + 1e-9:
                out[1:, k] = col + shift
                break
        else:
            return None
    return out


def linear_violation(kern: Any, angles: np.ndarray, setup: Any, limits: Limits) -> np.ndarray:
    """Amount by which each row's X/Y/Z command leaves the linear limits, shape=(n,) [mm]."""
    if not limits.linear:
        return np.zeros(angles.shape[0])
    lin = np.asarray(kern.linear_commands(angles, setup.ball_mm, setup.pivots_mm or None, setup.tool_mm))
    viol = np.zeros(angles.shape[0])
    for a, (lo, hi) in limits.linear.items():
        c = lin[:, LINEAR_AXES.index(a)]
        viol = np.maximum(viol, np.maximum(lo - c, c - hi))
    return np.clip(viol, 0, None)


@dataclass(frozen=True)
class Structure:
    """What the effects to reveal impose on the order and content of the poses.

    Attributes
    ----------
    backlash_axis : int or None
        Rotary axis index whose positions must be approached from both sides.
    reference_returns : int
        Extra measurements of the reference pose.
    """

    backlash_axis: int | None = None
    reference_returns: int = 0

    @classmethod
    def for_reveal(cls, reveal: tuple[str, ...], axes: tuple[str, ...], points: int) -> Structure:
        back = [axes.index(e.split("_", 1)[1]) for e in reveal if e.startswith("backlash_")]
        returns = max(2, points // 8) if set(DRIFT_KINDS) & set(reveal) else 0
        return cls(back[0] if back else None, returns)

    def core_count(self, points: int) -> int:
        """Number of distinct poses to choose for ``points`` measured poses."""
        n = points - self.reference_returns
        if self.backlash_axis is not None:
            n = (n + 2) // 2
        if n < 1:
            raise InputError(f"{points} points leave no room for the poses the effects to reveal need: give more")
        return n

    def expand(self, core: np.ndarray, points: int) -> np.ndarray:
        """Measured poses (no reference row) from the core poses, shape=(points, k)."""
        n = points - self.reference_returns
        if self.backlash_axis is not None:
            fwd = core[np.argsort(core[:, self.backlash_axis], kind="stable")]
            back = fwd[-2::-1] if fwd.shape[0] > 1 else fwd
            poses = np.vstack([fwd, back])[:n]
            while poses.shape[0] < n:  # a single core pose: measure it again
                poses = np.vstack([poses, fwd[:1]])
        else:
            poses = core[:n]
        if self.reference_returns:
            r = self.reference_returns
            slots = [round((i + 1) * n / r) for i in range(r)]
            rows: list[np.ndarray] = []
            for i in range(n):
                rows.append(poses[i])
                if i + 1 in slots:
                    rows.append(np.zeros(core.shape[1]))
            poses = np.array(rows)
        return poses

    def weights(self, core_size: int, points: int) -> np.ndarray:
        """Weight of each core pose in the optimisation: how often it is measured, on average.

        The reference returns carry no PIGE information; the exact counts of a retrace depend on
        the order, so the optimisation spreads them evenly (the final prediction is exact).
        """
        return np.full(core_size, (points - self.reference_returns) / core_size)


@dataclass
class Family:
    """A parametrised trajectory family.

    Attributes
    ----------
    name : str
    bounds : list of (float, float)
        Bounds of the continuous parameters.
    variants : list of dict
        Discrete options, each searched separately.
    make : callable (params, variant, n) -> ndarray, shape=(n, k) [deg]
        The n poses after the reference pose.
    describe : callable (params, variant) -> str
    """

    name: str
    bounds: list[tuple[float, float]]
    variants: list[dict[str, Any]]
    make: Callable[[np.ndarray, dict[str, Any], int], np.ndarray]
    describe: Callable[[np.ndarray, dict[str, Any]], str]


def _cone(machine: str, n: int) -> Family:
    kern = load_kernels(machine)

    def make(x: np.ndarray, v: dict[str, Any], count: int) -> np.ndarray:
        # cone_frustum's poses without its checks and timing (the bounds keep the angles valid)
        per_turn = count // v["turns"]
        directions = cone_directions(float(x[0]), float(x[1]), v["incl_axis"], per_turn, per_turn * v["turns"])
        return np.asarray(kern.angles_for_direction(directions, branch=v["branch"]))

    variants = [{"incl_axis": ax, "branch": br, "turns": t} for ax in ("X", "Y") for br in (1, -1)
                for t in (1, 2) if n % t == 0 and n // t >= 3]
    return Family("cone-frustum", [(5.0, 85.0), (0.0, 80.0)], variants, make,
                  lambda x, v: (f"cone-frustum half_angle={x[0]:.2f} incl={x[1]:.2f} incl_axis={v['incl_axis']} "
                                f"branch={v['branch']} turns={v['turns']}"))


def _figure_eight(machine: str, tilt_max: float) -> Family:
    def make(x: np.ndarray, v: dict[str, Any], count: int) -> np.ndarray:
        tr = figure_eight(machine, amp_tilt=float(x[0]), amp_rotary=float(x[1]), phase_deg=float(x[2]), points=count)
        return tr.angles_deg[1:]

    return Family("figure-eight", [(1.0, max(tilt_max, 1.5)), (1.0, 180.0), (0.0, 360.0)], [{}], make,
                  lambda x, v: f"figure-eight amp_tilt={x[0]:.2f} amp_rotary={x[1]:.2f} phase={x[2]:.1f}")


def stepped_sweeps(tilts: np.ndarray, lo: float, hi: float, count: int, roles: tuple[int, int] | None) -> np.ndarray:
    """Stepped forward-and-back sweeps of the rotary axis at each tilt, shape=(count, k) [deg]."""
    levels = len(tilts)
    per = [count // levels + (1 if i < count % levels else 0) for i in range(levels)]
    rows = []
    for t, m in zip(tilts, per, strict=True):
        fwd_n = (m + 2) // 2
        fwd = np.linspace(lo, hi, max(fwd_n, 1))
        sweep = np.concatenate([fwd, fwd[-2::-1]])[:m]
        for c in sweep:
            if roles is None:
                rows.append([c])
            else:
                r = [0.0, 0.0]
                r[roles[0]], r[roles[1]] = t, c
                rows.append(r)
    return np.array(rows, dtype=float)


def _steps(rot_bounds: tuple[float, float], tilt_bounds: tuple[float, float], roles: tuple[int, int] | None,
           n: int) -> Family:
    def make(x: np.ndarray, v: dict[str, Any], count: int) -> np.ndarray:
        lo, hi = sorted((float(x[0]), float(x[1])))
        tilts = np.zeros(1) if roles is None else np.asarray(x[2:2 + v["levels"]])
        return stepped_sweeps(tilts, lo, hi, count, roles)

    level_options = (1,) if roles is None else tuple(L for L in (1, 2, 3) if n >= 3 * L)
    bounds = [rot_bounds, rot_bounds] + ([tilt_bounds] * 3 if roles is not None else [])
    return Family("steps", bounds, [{"levels": L} for L in level_options or (1,)], make,
                  lambda x, v: (f"steps rotary {min(x[0], x[1]):.2f}..{max(x[0], x[1]):.2f}"
                                + ("" if roles is None else " at tilts "
                                   + "/".join(f"{t:.2f}" for t in x[2:2 + v["levels"]]))))


def families(kern: Any, limits: Limits, n: int) -> list[Family]:
    """The families applicable to the machine (cone and figure-eight need two rotary axes)."""
    axes = tuple(kern.ROTARY_AXES)
    if len(axes) == 1:
        return [_steps(limits.search_bounds(axes[0]), (0.0, 0.0), None, n)]
    tilt, rot = _roles(kern)
    tlo, thi = limits.search_bounds(axes[tilt])
    out = [_figure_eight(kern.MACHINE_CODE, min(-tlo, thi)),
           _steps(limits.search_bounds(axes[rot]), (tlo, thi), (tilt, rot), n)]
    if kern.HAS_DIRECTION_SOLVER:
        out.insert(0, _cone(kern.MACHINE_CODE, n))
    return out


def order_path(poses: np.ndarray) -> np.ndarray:
    """Greedy nearest-neighbour order from the reference pose (distance: largest axis move)."""
    left = list(range(poses.shape[0]))
    cur = np.zeros(poses.shape[1])
    out = []
    while left:
        d = [np.abs(poses[j] - cur).max() for j in left]
        j = left.pop(int(np.argmin(d)))
        out.append(poses[j])
        cur = poses[j]
    return np.array(out).reshape(poses.shape)
